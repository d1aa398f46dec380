// vellum iiif: IIIF Presentation 3 manifests of restored scans (io/iiif.h), for an image server
// serving a folder (scripts/serve-iiif.sh).
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "cli/commands.h"
#include "io/iiif.h"

namespace vellum {
namespace fs = std::filesystem;
namespace {

// The URL of a file under the served root.
std::string UrlOf(const std::string& base, const std::string& root, const fs::path& file) {
  std::string url;
  const Status s = UrlUnderRoot(base, root, file.string(), &url);
  if (!s.ok()) throw UsageError(s.message());
  return url;
}

}  // namespace

int RunIiif(const std::vector<std::string>& args) {
  Flags flags(
      "vellum iiif --root DIR --base URL [--sequence FILE --label TEXT] RESULTS...",
      "Writes an IIIF Presentation 3 manifest for each scan's results folder\n"
      "(RESULTS/iiif-manifest.json): one canvas per restored page (two for a spread), sized to\n"
      "its image, with the physical-dimensions service (physicalScale = 25.4 / dpi, in mm) so\n"
      "that IIIF viewers show the page at true scale. Each page's image is its\n"
      "restored_pyramid.tif (written by `vellum process` and the station), served by an IIIF\n"
      "image server at URL/iiif/ with identifiers relative to DIR: scripts/serve-iiif.sh DIR\n"
      "runs IIPImage behind lighttpd that way, and serves the manifests from DIR too.\n"
      "--sequence writes one more manifest over every page of the folders, in the order given\n"
      "(a volume's leaves).",
      {{"root", "DIR", "the folder the web server serves (the results must lie under it)", ""},
       {"base", "URL", "the web server's URL for DIR, e.g. http://127.0.0.1:8080", ""},
       {"sequence", "FILE", "also write a manifest of every page, in order, here (under DIR)", ""},
       {"label", "TEXT", "the sequence manifest's label", "vellum sequence"}});
  std::vector<std::string> results, rest;
  SplitPositional(args, &results, &rest);
  if (!flags.Parse(rest)) return 0;
  const std::string root = flags.Require("root");
  std::string base = flags.Require("base");
  while (!base.empty() && base.back() == '/') base.pop_back();
  if (results.empty()) throw UsageError("give at least one results folder (see --help)");
  const std::string image_base = base + "/iiif";
  std::vector<IiifCanvas> all;
  for (const std::string& dir : results) {
    std::vector<IiifCanvas> canvases;
    const Status s = ReadIiifCanvases(dir, root, image_base, &canvases);
    if (!s.ok()) {
      std::fprintf(stderr, "vellum iiif: %s\n", s.message().c_str());
      return 1;
    }
    const fs::path file = fs::path(dir) / kIiifManifestName;
    const Status w = WriteJsonFile(
        file.string(), IiifManifest(UrlOf(base, root, file), canvases.front().label, canvases));
    if (!w.ok()) {
      std::fprintf(stderr, "vellum iiif: %s\n", w.message().c_str());
      return 1;
    }
    std::printf("%zu page(s) -> %s\n", canvases.size(), file.string().c_str());
    all.insert(all.end(), canvases.begin(), canvases.end());
  }
  if (!flags.Get("sequence").empty()) {
    const fs::path file = flags.Get("sequence");
    const Status w = WriteJsonFile(file.string(),
                                   IiifManifest(UrlOf(base, root, file), flags.Get("label"), all));
    if (!w.ok()) {
      std::fprintf(stderr, "vellum iiif: %s\n", w.message().c_str());
      return 1;
    }
    std::printf("%zu page(s) in sequence -> %s\n", all.size(), file.string().c_str());
  }
  return 0;
}

}  // namespace vellum
