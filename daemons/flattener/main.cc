// vellum-flattener: POINT_CLOUD + TEXTURE -> the flattened sheet -> FLAT_MESH
// (daemons/flattener/flattener_node.h).
#include "daemons/flattener/flattener_node.h"
#include "flags/options.h"
#include "station/daemon.h"

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  std::vector<Flags::Spec> specs = Join(DaemonFlagSpecs(true), FlattenFlagSpecs());
  specs.push_back(FallbackCalibrationSpec());
  return DaemonMain(argc, argv, "vellum-flattener",
                    "Builds the mass-spring sheet over each scan's POINT_CLOUD (the page found in\n"
                    "its TEXTURE), flattens it, writes mesh.ply and flat.ply to\n"
                    "<data>/scan-<id>/results and publishes FLAT_MESH.",
                    specs, [](const Flags& flags, Node& node) {
                      FlattenerNodeOptions options;
                      options.data_dir = flags.Get("data");
                      options.mesh = MeshOptionsFromFlags(flags);
                      options.flatten = FlattenOptionsFromFlags(flags);
                      options.fallback_calibration = FallbackCalibrationFromFlags(flags);
                      FlattenerNode flattener(&node, options);
                      return node.Run(EverySecond([&] { flattener.Tick(); }));
                    });
}
