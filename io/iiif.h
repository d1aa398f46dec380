// IIIF for the restored pages: a pyramidal tiled TIFF of each production master (written with
// libvips, so an image server such as IIPImage serves its tiles without decoding the whole
// page), and IIIF Presentation 3 manifests, one per scan and one per sequence of scans, with one
// canvas per page sized to its image and the physical-dimensions service (physicalScale =
// 25.4 / dpi mm per pixel), so that any IIIF viewer shows the page at true scale.
//
// Where the images are served: an image server whose IIIF endpoint is `image_base` (e.g.
// http://host:8080/iiif) and whose identifiers are file paths relative to a served `root`
// folder, '/' encoded as %2F as the Image API asks (scripts/serve-iiif.sh runs IIPImage that
// way behind lighttpd).
#pragma once

#include <string>
#include <vector>

#include "core/common/status.h"
#include "io/json.h"

namespace vellum {

// The pyramid's name beside each restored.tif.
inline constexpr const char* kPyramidName = "restored_pyramid.tif";
// The scan's own manifest, in its results folder.
inline constexpr const char* kIiifManifestName = "iiif-manifest.json";

// Writes `tif` as a tiled (256 x 256), pyramidal, LZW-compressed TIFF `pyramid`, keeping its
// resolution, ICC profile and XMP. LZW, not deflate: the same size within 3% at 24 MP, written
// in a fifth of the time (libvips' deflate takes 0.85-0.97 s for a 12 MP page, LZW 0.2 s), and
// TIFF's baseline, which every reader has.
Status WritePyramidalTiff(const std::string& tif, const std::string& pyramid);

// `file`'s path relative to the served folder `root` ('/' between folders), as the web server
// and the image server see it; an error when it does not lie under `root`.
Status PathUnderRoot(const std::string& root, const std::string& file, std::string* relative);

// The URL of `file` under the served folder `root`, whose web server's URL is `base`
// ("http://host:8080"): base + "/" + its relative path; an error when it does not lie under `root`.
Status UrlUnderRoot(const std::string& base, const std::string& root, const std::string& file,
                    std::string* url);

// One restored page as a canvas.
struct IiifCanvas {
  std::string label;     // "MS 12, 3 recto", "MS 12, 3v-4r, left"
  std::string image_id;  // The image service's id: image_base + "/" + encoded identifier.
  int width = 0, height = 0;
  double dpi = 0;  // 0: camera view, no true scale (no physical-dimensions service).
};

// The canvases of one scan's results folder (its restored.json, or pages/left and pages/right
// for a spread), each image served from its pyramid under `root`. An error names the file.
Status ReadIiifCanvases(const std::string& results, const std::string& root,
                        const std::string& image_base, std::vector<IiifCanvas>* canvases);

// A Presentation 3 manifest `id` labelled `label` over `canvases`, in order.
Json IiifManifest(const std::string& id, const std::string& label,
                  const std::vector<IiifCanvas>& canvases);

}  // namespace vellum
