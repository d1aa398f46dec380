// vellum-triangulator: CORRESPONDENCE -> the point map -> POINT_CLOUD
// (daemons/triangulator/triangulator_node.h).
#include "daemons/triangulator/triangulator_node.h"
#include "flags/options.h"
#include "station/daemon.h"

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  std::vector<Flags::Spec> specs = Join(DaemonFlagSpecs(true), TriangulateFlagSpecs());
  specs.push_back(FallbackCalibrationSpec());
  return DaemonMain(argc, argv, "vellum-triangulator",
                    "Triangulates each scan's CORRESPONDENCE with the scan's CALIBRATION, writes\n"
                    "points.ply and depth.png to <data>/scan-<id>/results and publishes\n"
                    "POINT_CLOUD (in row chunks).",
                    specs, [](const Flags& flags, Node& node) {
                      TriangulatorNodeOptions options;
                      options.data_dir = flags.Get("data");
                      options.triangulate = TriangulateOptionsFromFlags(flags);
                      options.fallback_calibration = FallbackCalibrationFromFlags(flags);
                      RequireValid(options);
                      TriangulatorNode triangulator(&node, options);
                      return node.Run(EverySecond([&] { triangulator.Tick(); }));
                    });
}
