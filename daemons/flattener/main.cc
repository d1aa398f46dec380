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
                    "Finds the leaf (or a spread's two pages) in each scan's POINT_CLOUD and\n"
                    "TEXTURE, builds the mass-spring sheet over each page, flattens it, writes\n"
                    "mesh.ply and flat.ply to <data>/scan-<id>/results (pages/<page>/ on a\n"
                    "spread) and publishes FLAT_MESH, page after page.",
                    specs, [](const Flags& flags, Node& node) {
                      FlattenerNodeOptions options;
                      options.data_dir = flags.Get("data");
                      FlattenGroupFromFlags(flags, &options.pipeline);
                      options.fallback_calibration = FallbackCalibrationFromFlags(flags);
                      RequireValid(options);
                      FlattenerNode flattener(&node, options);
                      return node.Run(EverySecond([&] { flattener.Tick(); }));
                    });
}
