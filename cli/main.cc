// vellum: the station's command-line tool.
#include <cstdio>
#include <opencv2/core/utility.hpp>
#include <string>
#include <vector>

#include "cli/commands.h"
#include "flags/flags.h"

namespace {

constexpr char kUsage[] =
    "usage: vellum COMMAND [flags]\n"
    "\n"
    "Restores images of warped documents from structured-light scans.\n"
    "\n"
    "commands:\n"
    "  patterns   write the projector pattern images and scan.yaml of a scan\n"
    "  render     render a scan of a warped page with the virtual gantry\n"
    "  process    process a scan directory into the restored page (and 3D products)\n"
    "  scan       ask the station for a scan and follow it to the restored page\n"
    "  watch      follow the station's bus until scans are restored\n"
    "  sheet      write the contact sheet of a station's data folder (DATA/index.html)\n"
    "  manifest   write or check a folder's SHA-256 manifest (manifest write|check DIR)\n"
    "  iiif       write IIIF manifests of restored scans, for an image server\n"
    "  collection reprocess a folder of scans by provenance (plan | run | status)\n"
    "  export     write a recorded scan log as a scan directory (vellum export LOG DIR)\n"
    "  import     write a scan directory as a scan log (vellum import DIR LOG)\n"
    "  calibrate  calibrate camera, projector and table from board poses, the display's lag\n"
    "             (capture | solve | flatfield | studio | latency)\n"
    "\n"
    "Run 'vellum COMMAND --help' for a command's flags.\n";

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h" ||
      std::string(argv[1]) == "help") {
    std::fputs(kUsage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  cv::setNumThreads(cv::getNumberOfCPUs());
  const std::string command = argv[1];
  const std::vector<std::string> args(argv + 2, argv + argc);
  try {
    if (command == "patterns") return vellum::RunPatterns(args);
    if (command == "render") return vellum::RunRender(args);
    if (command == "process") return vellum::RunProcess(args);
    if (command == "scan") return vellum::RunScan(args);
    if (command == "watch") return vellum::RunWatch(args);
    if (command == "sheet") return vellum::RunSheet(args);
    if (command == "manifest") return vellum::RunManifest(args);
    if (command == "iiif") return vellum::RunIiif(args);
    if (command == "collection") return vellum::RunCollection(args);
    if (command == "export") return vellum::RunExport(args);
    if (command == "import") return vellum::RunImport(args);
    if (command == "calibrate") return vellum::RunCalibrate(args);
    std::fprintf(stderr, "vellum: unknown command '%s'\n\n%s", command.c_str(), kUsage);
    return 2;
  } catch (const vellum::UsageError& e) {
    std::fprintf(stderr, "vellum %s: %s\n", command.c_str(), e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "vellum %s: error: %s\n", command.c_str(), e.what());
    return 1;
  }
}
