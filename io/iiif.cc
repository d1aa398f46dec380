#include "io/iiif.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <vips/vips8>

#include "core/patterns/scan.h"
#include "io/vips.h"
#include "io/write_whole.h"

namespace vellum {
namespace fs = std::filesystem;
namespace {

// An Image API identifier: the path with every byte outside the unreserved set (and '/')
// percent-encoded.
std::string EncodeIdentifier(const std::string& path) {
  std::string out;
  for (const unsigned char c : path) {
    if (std::isalnum(c) || c == '-' || c == '.' || c == '_' || c == '~') {
      out += static_cast<char>(c);
    } else {
      char hex[4];
      std::snprintf(hex, sizeof(hex), "%%%02X", c);
      out += hex;
    }
  }
  return out;
}

Json Label(const std::string& text) { return {{"en", Json::array({text})}}; }

// One page's canvas from its restored.json in `dir`.
Status ReadCanvas(const fs::path& dir, const std::string& page, const fs::path& root,
                  const std::string& image_base, IiifCanvas* canvas) {
  const fs::path json_path = dir / "restored.json";
  std::ifstream in(json_path);
  if (!in) return Status::Error(json_path.string() + ": cannot read (is this a results folder?)");
  Json r;
  try {
    r = Json::parse(in);
  } catch (const std::exception& e) {
    return Status::Error(json_path.string() + ": not JSON: " + e.what());
  }
  if (!r.is_object() || !r.contains("width") || !r.contains("height") || !r["width"].is_number() ||
      !r["height"].is_number()) {
    return Status::Error(json_path.string() + ": no width and height");
  }
  const fs::path pyramid = dir / kPyramidName;
  if (!fs::exists(pyramid)) return Status::Error(pyramid.string() + ": missing");
  std::string rel;
  const Status under = PathUnderRoot(root.string(), pyramid.string(), &rel);
  if (!under.ok()) return under;
  canvas->width = r["width"].get<int>();
  canvas->height = r["height"].get<int>();
  canvas->dpi = r.contains("dpi") && r["dpi"].is_number() ? r["dpi"].get<double>() : 0;
  ScanIdentity identity;
  if (r.contains("identity") && r["identity"].is_object()) {
    ForEachIdentityField(identity, [&](const char* key, std::string& field) {
      if (r["identity"].contains(key) && r["identity"][key].is_string())
        field = r["identity"][key].get<std::string>();
    });
  }
  canvas->label = IdentityTitle(identity);
  if (canvas->label.empty()) canvas->label = dir.parent_path().filename().string();
  if (!page.empty()) canvas->label += ", " + page;
  canvas->image_id = image_base + "/" + EncodeIdentifier(rel);
  return Status::Ok();
}

}  // namespace

Status PathUnderRoot(const std::string& root, const std::string& file, std::string* relative) {
  std::error_code ec;
  const fs::path rel =
      fs::relative(fs::weakly_canonical(file, ec), fs::weakly_canonical(root, ec), ec);
  if (ec || rel.empty() || *rel.begin() == "..") {
    return Status::Error(file + ": not under the served folder " + root);
  }
  *relative = rel.generic_string();
  return Status::Ok();
}

Status UrlUnderRoot(const std::string& base, const std::string& root, const std::string& file,
                    std::string* url) {
  std::string rel;
  const Status s = PathUnderRoot(root, file, &rel);
  if (!s.ok()) return s;
  *url = base + "/" + rel;
  return Status::Ok();
}

Status WritePyramidalTiff(const std::string& tif, const std::string& pyramid) {
  Status s = StartVips();
  if (!s.ok()) return s;
  // Made in memory and written by us: libvips 8.14's pyramid writer, failing to write (a full
  // disk), crashes the process as it cleans up (the path of libvips's GitHub issue 3411); a buffer
  // cannot fail so, and the file's write failure is an error like any other.
  std::string bytes;
  try {
    vips::VImage image = vips::VImage::new_from_file(tif.c_str());
    VipsBlob* blob =
        image.tiffsave_buffer(vips::VImage::option()
                                  ->set("tile", true)
                                  ->set("pyramid", true)
                                  ->set("tile_width", 256)
                                  ->set("tile_height", 256)
                                  ->set("compression", VIPS_FOREIGN_TIFF_COMPRESSION_LZW));
    size_t size = 0;
    const void* data = vips_blob_get(blob, &size);
    bytes.assign(static_cast<const char*>(data), size);
    vips_area_unref(VIPS_AREA(blob));
  } catch (const vips::VError& e) {
    return Status::Error(pyramid + ": cannot write the pyramidal TIFF: " + VipsErrorText(e.what()));
  }
  return WriteWhole(pyramid, [&](const std::string& part) {
    std::ofstream out(part, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) {
      return Status::Error(part + ": cannot write the pyramidal TIFF (" + std::strerror(errno) +
                           ")");
    }
    return Status::Ok();
  });
}

Status ReadIiifCanvases(const std::string& results, const std::string& root,
                        const std::string& image_base, std::vector<IiifCanvas>* canvases) {
  canvases->clear();
  const fs::path dir(results);
  if (fs::exists(dir / "restored.json")) {
    IiifCanvas c;
    const Status s = ReadCanvas(dir, "", root, image_base, &c);
    if (!s.ok()) return s;
    canvases->push_back(c);
    return Status::Ok();
  }
  for (const char* page : {"left", "right"}) {
    const fs::path page_dir = dir / "pages" / page;
    if (!fs::exists(page_dir / "restored.json")) continue;
    IiifCanvas c;
    const Status s = ReadCanvas(page_dir, page, root, image_base, &c);
    if (!s.ok()) return s;
    canvases->push_back(c);
  }
  if (canvases->empty()) {
    return Status::Error(results +
                         ": no restored page (restored.json, or pages/left and "
                         "pages/right)");
  }
  return Status::Ok();
}

Json IiifManifest(const std::string& id, const std::string& label,
                  const std::vector<IiifCanvas>& canvases) {
  Json items = Json::array();
  for (size_t k = 0; k < canvases.size(); ++k) {
    const IiifCanvas& c = canvases[k];
    const std::string canvas_id = id + "/canvas/" + std::to_string(k + 1);
    Json image = {
        {"id", c.image_id + "/full/full/0/default.jpg"},
        {"type", "Image"},
        {"format", "image/jpeg"},
        {"width", c.width},
        {"height", c.height},
        // An Image API 2 service (IIPImage 1.1's), named as Presentation 3 names
        // the older services: @id and @type.
        {"service", Json::array({{{"@id", c.image_id},
                                  {"@type", "ImageService2"},
                                  {"profile", "http://iiif.io/api/image/2/level1.json"}}})}};
    Json annotation = {{"id", canvas_id + "/annotation/1"},
                       {"type", "Annotation"},
                       {"motivation", "painting"},
                       {"body", image},
                       {"target", canvas_id}};
    Json canvas = {{"id", canvas_id},
                   {"type", "Canvas"},
                   {"label", Label(c.label)},
                   {"width", c.width},
                   {"height", c.height},
                   {"items", Json::array({{{"id", canvas_id + "/page/1"},
                                           {"type", "AnnotationPage"},
                                           {"items", Json::array({annotation})}}})}};
    if (c.dpi > 0) {
      // The physical-dimensions service: millimetres per canvas pixel.
      canvas["service"] =
          Json::array({{{"id", canvas_id + "/physdim"},
                        {"type", "PhysicalDimensions"},
                        {"@context", "http://iiif.io/api/annex/services/physdim/1/context.json"},
                        {"profile", "http://iiif.io/api/annex/services/physdim"},
                        {"physicalScale", 25.4 / c.dpi},
                        {"physicalUnits", "mm"}}});
    }
    items.push_back(canvas);
  }
  return {{"@context", "http://iiif.io/api/presentation/3/context.json"},
          {"id", id},
          {"type", "Manifest"},
          {"label", Label(label)},
          {"items", items}};
}

}  // namespace vellum
