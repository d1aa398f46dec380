// vellum-decoder: records each scan's captures to disk as they arrive (raw/captures.lcmlog and
// the scan directory), and once a scan is complete decodes it and publishes CORRESPONDENCE.
// It sees every scan through to RESTORED: a scan complete on disk stays pending until its
// RESTORED (or an error about it from a processing daemon) is seen, and when a processing
// daemon restarts, or the decoder itself, every pending scan is decoded again from disk.
#include <atomic>
#include <chrono>
#include <filesystem>
#include <map>
#include <memory>

#include "cli/options.h"
#include "daemons/common/daemon.h"
#include "daemons/common/messages.h"
#include "daemons/common/scan_store.h"
#include "vellum/restored_t.hpp"
#include "vellum/status_t.hpp"

namespace vellum::station {
namespace {

class DecoderNode {
 public:
  DecoderNode(Node* node, const Flags& flags)
      : node_(node),
        data_(flags.Get("data")),
        decoder_(DecodeOptionsFromFlags(flags)),
        timeout_s_(flags.GetDouble("scan-timeout", 1, 3600)) {
    // Each message goes to the scan's log at once, on the LCM thread (an append and a flush),
    // so that a crash loses nothing received; the rest is done on the worker.
    node->Subscribe<capture_t>(channel::kCapture, [this](const capture_t& msg) {
      Log(channel::kCapture, msg.scan_id, msg.utime, Encode(msg));
      auto copy = std::make_shared<capture_t>(msg);
      last_capture_ = std::chrono::steady_clock::now();
      node_->Post([this, copy] { OnCapture(*copy); });
    });
    node->Subscribe<calibration_t>(channel::kCalibration, [this](const calibration_t& msg) {
      Log(channel::kCalibration, msg.scan_id, msg.utime, Encode(msg));
      auto copy = std::make_shared<calibration_t>(msg);
      node_->Post([this, copy] { OnCalibration(*copy); });
    });
    node->Subscribe<restored_t>(channel::kRestored, [this](const restored_t& msg) {
      const int64_t id = msg.scan_id;
      node_->Post([this, id] { ClearPending(ScanFolder::For(data_, id)); });
    });
    for (const char* process : kDownstream) {
      node->Subscribe<status_t>(StatusChannel(process),
                                [this](const status_t& msg) { OnDownstreamStatus(msg); });
    }
  }

  // On the LCM thread: an incomplete scan with no capture for a while is given up.
  void Tick() {
    if (!waiting_ || std::chrono::steady_clock::now() - last_capture_ <
                         std::chrono::duration<double>(timeout_s_)) {
      return;
    }
    waiting_ = false;
    node_->Post([this] {
      if (set_.Started() && !set_.Complete()) Abandon("no capture for " + Seconds() + " s");
    });
  }

 private:
  void Log(const char* channel, int64_t scan_id, int64_t utime, const std::vector<uint8_t>& bytes) {
    if (scan_id <= 0) {
      node_->Error(std::string(channel) + ": scan_id " + std::to_string(scan_id) + " refused");
      return;
    }
    const Status s = log_.Append(ScanFolder::For(data_, scan_id), scan_id, channel, utime, bytes);
    if (log_.trimmed() > 0) {
      node_->Log("scan " + std::to_string(scan_id) + ": cut a torn last event (" +
                 std::to_string(log_.trimmed()) +
                 " bytes, a write cut short) off the scan's log before appending");
    }
    if (!s.ok()) {
      node_->Error("scan " + std::to_string(scan_id) + ": recording failed: " + s.message(),
                   scan_id);
    }
  }

  // On the LCM thread. A new pid is a restarted daemon: whatever it held is lost. An error it
  // reports about a pending scan ends that scan with a status the operator sees.
  void OnDownstreamStatus(const status_t& msg) {
    if (downstream_.count(msg.process) == 0) node_->Count("processing daemons heard");
    Seen& seen = downstream_[msg.process];
    if (seen.pid != 0 && msg.pid != seen.pid) {
      const std::string why = msg.process + " restarted";
      node_->Post([this, why] { ResendPending(why); });
    }
    seen.pid = msg.pid;
    // Scans left pending by an earlier run (a daemon stopped while a scan was on its way) go
    // again once every processing daemon is listening.
    if (!resent_at_start_ && downstream_.size() == std::size(kDownstream)) {
      resent_at_start_ = true;
      node_->Post([this] { ResendPending("the station stopped"); });
    }
    if (msg.last_error_utime > seen.error_utime && msg.last_error_scan_id > 0 &&
        seen.error_utime != -1) {
      const int64_t id = msg.last_error_scan_id;
      node_->Post([this, id] { ClearPending(ScanFolder::For(data_, id)); });
    }
    seen.error_utime = msg.last_error_utime;
  }

  // Sends every pending scan down the pipeline again, decoded afresh from its folder.
  void ResendPending(const std::string& why) {
    for (int64_t id : FindPending(data_)) {
      if (set_.Started() && set_.scan_id() == id && !set_.Complete()) continue;
      const ScanFolder folder = ScanFolder::For(data_, id);
      if (RestoredSinceSent(folder)) {  // Its RESTORED went out while this process was away.
        ClearPending(folder);
        continue;
      }
      const int attempts = PendingAttempts(folder);
      if (attempts >= kMaxAttempts) {
        ClearPending(folder);
        node_->Error("scan " + std::to_string(id) + " failed: not restored after " +
                         std::to_string(attempts) + " attempts (the last ended when " + why +
                         "); its captures are kept in " + folder.raw() +
                         " (`vellum process --scan " + folder.raw() + "` restores it by hand)",
                     id);
        node_->Count("scans failed");
        continue;
      }
      Scan scan;
      Status s = ReadScan(folder.raw(), &scan);
      if (s.ok()) s = MarkPending(folder, attempts + 1);
      if (!s.ok()) {
        ClearPending(folder);
        node_->Error(
            "scan " + std::to_string(id) + " failed: cannot process it again: " + s.message(), id);
        node_->Count("scans failed");
        continue;
      }
      node_->Log("scan " + std::to_string(id) + ": " + why + " before the scan was restored; " +
                 "processing it again from " + folder.raw() + " (attempt " +
                 std::to_string(attempts + 1) + " of " + std::to_string(kMaxAttempts) + ")");
      node_->Count("scans sent again");
      DecodeAndPublish(id, scan);
    }
  }

  // The restorer wrote the scan's results after the scan was last sent down the pipeline.
  static bool RestoredSinceSent(const ScanFolder& folder) {
    std::error_code a, b;
    const auto sent = std::filesystem::last_write_time(folder.pending(), a);
    const auto restored = std::filesystem::last_write_time(folder.results() + "/restored.json", b);
    return !a && !b && restored >= sent;
  }

  std::string Seconds() const { return std::to_string(static_cast<int>(timeout_s_)); }

  void Abandon(const std::string& why) {
    node_->Error("scan " + std::to_string(set_.scan_id()) + " failed: " + why + "; " +
                     set_.Missing() + "; the captures received are kept in " +
                     ScanFolder::For(data_, set_.scan_id()).raw(),
                 set_.scan_id());
    node_->Count("scans failed");
    set_ = CaptureSet();
    recording_ = 0;
    node_->SetState("idle");
  }

  // Opens the scan's folder on its first message.
  bool Begin(int64_t scan_id) {
    if (recording_ == scan_id && !set_.Complete()) return true;
    if (recording_ == scan_id)
      node_->Log("scan " + std::to_string(scan_id) + " again: recording anew");
    if (set_.Started() && !set_.Complete()) {
      Abandon("scan " + std::to_string(scan_id) + " started before it was complete");
    }
    set_ = CaptureSet();
    recording_ = scan_id;
    int resumed = 0;
    const Status s = recorder_.Open(ScanFolder::For(data_, scan_id), scan_id, &set_, &resumed);
    if (!s.ok()) {
      node_->Error("scan " + std::to_string(scan_id) + ": cannot record: " + s.message(), scan_id);
      return false;
    }
    node_->Log(
        "scan " + std::to_string(scan_id) + ": recording to " +
        ScanFolder::For(data_, scan_id).raw() +
        (resumed ? " (continuing: " + std::to_string(resumed) + " captures already there)" : ""));
    return true;
  }

  void OnCalibration(const calibration_t& msg) {
    if (!Begin(msg.scan_id)) return;
    const Status s = recorder_.Write(msg);
    if (!s.ok()) node_->Error("scan " + std::to_string(msg.scan_id) + ": " + s.message());
  }

  void OnCapture(const capture_t& msg) {
    if (!Begin(msg.scan_id)) return;
    if (set_.Has(msg.pattern_index)) return;  // Taken up from the log after a restart.
    Status s = set_.Add(msg);
    if (!s.ok()) {
      node_->Error(s.message(), msg.scan_id);
      return;
    }
    cv::Mat image;
    FromMessage(msg.image, &image);  // Checked by Add.
    s = recorder_.Write(msg, image);
    if (!s.ok()) {
      node_->Error("scan " + std::to_string(msg.scan_id) + " failed: recording: " + s.message(),
                   msg.scan_id);
      set_ = CaptureSet();
      recording_ = 0;
      node_->Count("scans failed");
      node_->SetState("idle");
      return;
    }
    waiting_ = true;
    node_->SetState(
        "recording", msg.scan_id,
        "capture " + std::to_string(set_.Received()) + " of " + std::to_string(set_.Expected()));
    if (set_.Complete()) Process();
  }

  void Process() {
    waiting_ = false;
    const int64_t id = set_.scan_id();
    const Scan scan = set_.ToScan();
    Status s = recorder_.Finish(scan);
    if (s.ok()) s = MarkPending(ScanFolder::For(data_, id), 1);
    if (!s.ok()) {
      node_->Error("scan " + std::to_string(id) + ": " + s.message(), id);
      return;
    }
    node_->Count("scans recorded");
    DecodeAndPublish(id, scan);
  }

  void DecodeAndPublish(int64_t id, const Scan& scan) {
    node_->SetState("busy", id, "decoding");
    const int64_t start = NowUtime();
    decoder_.Decode(scan.sequence, scan.frames, &decoded_);
    if (!decoded_.status.ok()) {
      ClearPending(ScanFolder::For(data_, id));  // Failed with a status: not sent again.
      node_->Error("scan " + std::to_string(id) + ": " + decoded_.status.message(), id);
      node_->SetState("idle");
      return;
    }
    scan_stats_t stats{};
    AddDecodeStats(decoded_.stats, SecondsSince(start), &stats);
    stats.camera_width = scan.camera_size.width;
    stats.camera_height = scan.camera_size.height;
    stats.projector_width = scan.sequence.projector_size.width;
    stats.projector_height = scan.sequence.projector_size.height;
    stats.patterns = static_cast<int32_t>(scan.sequence.patterns.size());
    std::vector<correspondence_t> chunks =
        ToMessages(id, decoded_, scan.sequence.projector_size, stats);
    node_->PublishChunks(channel::kCorrespondence, &chunks);
    node_->Count("scans decoded");
    node_->Log("scan " + std::to_string(id) + ": decoded " + std::to_string(decoded_.stats.valid) +
               " pixels in " + std::to_string(stats.decode_s) + " s");
    node_->SetState("idle");
  }

  // The processing daemons downstream, and the most times a scan is sent to them.
  static constexpr const char* kDownstream[] = {"vellum-triangulator", "vellum-flattener",
                                                "vellum-restorer"};
  static constexpr int kMaxAttempts = 3;
  struct Seen {
    int32_t pid = 0;
    int64_t error_utime = -1;  // -1: no status yet (its old errors are not news).
  };

  Node* node_;
  std::string data_;
  Decoder decoder_;
  double timeout_s_;
  // Worker thread only:
  CaptureSet set_;
  int64_t recording_ = 0;  // The scan whose folder is open.
  ScanRecorder recorder_;
  // LCM thread only:
  CaptureLog log_;
  DecodeResult decoded_;
  // LCM thread only:
  std::chrono::steady_clock::time_point last_capture_;
  std::map<std::string, Seen> downstream_;
  bool resent_at_start_ = false;
  std::atomic<bool> waiting_{false};  // A scan is being captured (set by the worker).
};

}  // namespace
}  // namespace vellum::station

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  std::vector<Flags::Spec> specs = Join(DaemonFlagSpecs(true), DecodeFlagSpecs());
  specs.push_back({"scan-timeout", "S", "give up an incomplete scan after this long", "30"});
  return DaemonMain(
      argc, argv, "vellum-decoder",
      "Records every scan's CAPTURE messages to <data>/scan-<id>/raw (captures.lcmlog, the scan\n"
      "directory of DESIGN.md, calibration.yaml) as they arrive, then decodes the complete\n"
      "scan and publishes CORRESPONDENCE (in row chunks).",
      specs, [](const Flags& flags, Node& node) {
        DecoderNode decoder(&node, flags);
        return node.Run([&] { decoder.Tick(); });
      });
}
