// vellum-decoder: records every scan to disk as it arrives, decodes each complete scan and
// sends it down the processing chain; supervises the chain (daemons/decoder/decoder_node.h).
#include "daemons/decoder/decoder_node.h"
#include "flags/options.h"
#include "station/daemon.h"

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  std::vector<Flags::Spec> specs = Join(DaemonFlagSpecs(true), DecodeFlagSpecs());
  specs.push_back({"scan-timeout", "S", "give up an incomplete scan after this long", "30"});
  return DaemonMain(
      argc, argv, "vellum-decoder",
      "Records every scan's CAPTURE messages to <data>/scan-<id>[-<slug>]/raw (the slug from\n"
      "the scan's identity; captures.lcmlog, the scan directory of docs/formats.md,\n"
      "calibration.yaml) as they arrive, then sends the complete scan down the chain: TEXTURE\n"
      "and the decoded CORRESPONDENCE (in row chunks). A retake of a folio moves the earlier\n"
      "attempt into <data>/retaken/. Supervises the chain: a scan a processing daemon died\n"
      "holding is sent again from disk, at most twice, then parked (raw/failed.txt).",
      specs, [](const Flags& flags, Node& node) {
        DecoderNodeOptions options;
        options.data_dir = flags.Get("data");
        options.decode = DecodeOptionsFromFlags(flags);
        options.scan_timeout_s = flags.GetDouble("scan-timeout", 1, 3600);
        RequireValid(options);
        DecoderNode decoder(&node, options);
        return node.Run([&] { decoder.Tick(); });
      });
}
