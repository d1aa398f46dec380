// vellum-restorer: FLAT_MESH + TEXTURE -> the restored page and the scan's report -> RESTORED
// (daemons/restorer/restorer_node.h).
#include "daemons/restorer/restorer_node.h"
#include "flags/options.h"
#include "station/daemon.h"

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  std::vector<Flags::Spec> specs = Join(DaemonFlagSpecs(true), RestoreFlagSpecs());
  specs.push_back(FallbackCalibrationSpec());
  return DaemonMain(argc, argv, "vellum-restorer",
                    "Restores each scan's TEXTURE through its FLAT_MESH: writes restored.tif,\n"
                    "restored.json, report.html and report.json to the scan's results folder\n"
                    "(with --flatfield and --studio-field also restored_albedo.tif and\n"
                    "restored_reflectance.tif, from the POINT_CLOUD it then hears too)\n"
                    "in <data>/scan-<id>[-<slug>]/results, the scan's SHA-256 manifest of raw/\n"
                    "and results/ (its folder's manifest-sha256.txt), rewrites the contact sheet\n"
                    "<data>/index.html, and publishes RESTORED (the results folder, the quality\n"
                    "verdict and a preview of at most 1 Mpixel).",
                    specs, [](const Flags& flags, Node& node) {
                      RestorerNodeOptions options;
                      options.data_dir = flags.Get("data");
                      RestoreGroupFromFlags(flags, &options.pipeline);
                      options.fallback_calibration = FallbackCalibrationFromFlags(flags);
                      RequireValid(options);
                      RestorerNode restorer(&node, options);
                      return node.Run(EverySecond([&] { restorer.Tick(); }));
                    });
}
