#include "daemons/decoder/decoder_node.h"

#include <memory>

#include "pipeline/stages.h"
#include "station/chain.h"
#include "station/messages.h"

namespace vellum::station {

DecoderNode::DecoderNode(Node* node, const DecoderNodeOptions& options)
    : node_(node),
      options_(options),
      decoder_(options.decode),
      supervisor_(node, options.data_dir,
                  [this](int64_t id, const Scan& scan) { return Send(id, scan); }) {
  // Each message goes to the scan's log at once, on the LCM thread (an append and a flush),
  // so that a crash loses nothing received; the rest is done on the worker.
  node->Subscribe<capture_t>(channel::kCapture, [this](const capture_t& msg) {
    // A capture that contradicts itself is refused before it reaches the scan's log (which
    // would then no longer export).
    const Status ok = CheckCapture(msg);
    if (!ok.ok()) {
      node_->Count("captures refused");
      node_->Error("CAPTURE refused, not recorded: " + ok.message(), msg.scan_id);
      return;
    }
    if (!Log(channel::kCapture, msg.scan_id, msg.utime, Encode(msg))) return;
    auto copy = std::make_shared<capture_t>(msg);
    last_capture_ = std::chrono::steady_clock::now();
    node_->Post([this, copy] { OnCapture(*copy); }, "a CAPTURE");
  });
  node->Subscribe<calibration_t>(channel::kCalibration, [this](const calibration_t& msg) {
    if (!Log(channel::kCalibration, msg.scan_id, msg.utime, Encode(msg))) return;
    auto copy = std::make_shared<calibration_t>(msg);
    node_->Post([this, copy] { OnCalibration(*copy); }, "a CALIBRATION");
  });
}

void DecoderNode::Tick() {
  if (!waiting_ || std::chrono::steady_clock::now() - last_capture_ <
                       std::chrono::duration<double>(options_.scan_timeout_s)) {
    return;
  }
  waiting_ = false;
  node_->Post([this] {
    if (set_.Started() && !set_.Complete()) {
      Abandon("no capture for " + std::to_string(static_cast<int>(options_.scan_timeout_s)) + " s");
    }
  });
}

bool DecoderNode::Log(const char* channel, int64_t scan_id, int64_t utime,
                      const std::vector<uint8_t>& bytes) {
  if (scan_id <= 0) {
    node_->Error(std::string(channel) + ": scan_id " + std::to_string(scan_id) + " refused");
    return false;
  }
  const Status s =
      log_.Append(ScanFolder::For(options_.data_dir, scan_id), scan_id, channel, utime, bytes);
  if (log_.trimmed() > 0) {
    node_->Log("scan " + std::to_string(scan_id) + ": cut a torn last event (" +
               std::to_string(log_.trimmed()) +
               " bytes, a write cut short) off the scan's log before appending");
  }
  if (!s.ok()) {
    node_->Error("scan " + std::to_string(scan_id) + ": recording failed: " + s.message(), scan_id);
  }
  return true;  // Recorded or not, the capture is taken (the worker reports what fails next).
}

void DecoderNode::Stop() {
  set_ = CaptureSet();
  recording_ = 0;
  supervisor_.Recording(0);
  node_->SetState("idle");
}

void DecoderNode::Abandon(const std::string& why) {
  node_->Count("scans failed");  // Before the error goes out with the count.
  node_->Error("scan " + std::to_string(set_.scan_id()) + " failed: " + why + "; " +
                   set_.Missing() + "; the captures received are kept in " +
                   ScanFolder::For(options_.data_dir, set_.scan_id()).raw(),
               set_.scan_id());
  Stop();
}

bool DecoderNode::Begin(int64_t scan_id) {
  if (recording_ == scan_id && !set_.Complete()) return true;
  if (recording_ == scan_id) {
    node_->Log("scan " + std::to_string(scan_id) + " again: recording anew");
  }
  if (set_.Started() && !set_.Complete()) {
    Abandon("scan " + std::to_string(scan_id) + " started before it was complete");
  }
  set_ = CaptureSet();
  recording_ = scan_id;
  supervisor_.Recording(scan_id);
  int resumed = 0;
  const ScanFolder folder = ScanFolder::For(options_.data_dir, scan_id);
  const Status s = recorder_.Open(folder, scan_id, &set_, &resumed);
  if (!s.ok()) {
    node_->Error("scan " + std::to_string(scan_id) + ": cannot record: " + s.message(), scan_id);
    return false;
  }
  node_->Log(
      "scan " + std::to_string(scan_id) + ": recording to " + folder.raw() +
      (resumed ? " (continuing: " + std::to_string(resumed) + " captures already there)" : ""));
  return true;
}

void DecoderNode::OnCalibration(const calibration_t& msg) {
  if (!Begin(msg.scan_id)) return;
  const Status s = recorder_.Write(msg);
  if (!s.ok()) node_->Error("scan " + std::to_string(msg.scan_id) + ": " + s.message());
}

void DecoderNode::OnCapture(const capture_t& msg) {
  if (!Begin(msg.scan_id)) return;
  // A capture already taken up from the scan's log (after a restart, or when the log ran ahead
  // of this thread) is not added twice; it still counts as the scan going on.
  if (!set_.Has(msg.pattern_index)) {
    Status s = set_.Add(msg);
    if (!s.ok()) {
      node_->Error(s.message(), msg.scan_id);
      return;
    }
    cv::Mat image;
    s = FromMessage(msg.image, &image);  // Checked by Add.
    if (s.ok()) s = recorder_.Write(msg, image);
    if (!s.ok()) {
      node_->Count("scans failed");  // Before the error goes out with the count.
      node_->Error("scan " + std::to_string(msg.scan_id) + " failed: recording: " + s.message(),
                   msg.scan_id);
      Stop();
      return;
    }
  }
  waiting_ = true;
  node_->SetState(
      "recording", msg.scan_id,
      "capture " + std::to_string(set_.Received()) + " of " + std::to_string(set_.Expected()));
  if (set_.Complete()) Complete();
}

void DecoderNode::Complete() {
  waiting_ = false;
  supervisor_.Recording(0);
  const int64_t id = set_.scan_id();
  const Scan scan = set_.ToScan();
  const Status s = recorder_.Finish(scan);
  if (!s.ok()) {
    node_->Error("scan " + std::to_string(id) + ": " + s.message(), id);
    return;
  }
  node_->Count("scans recorded");
  supervisor_.Recorded(id, scan);
}

Status DecoderNode::Send(int64_t id, const Scan& scan) {
  node_->SetState("busy", id, "decoding");
  std::vector<texture_t> texture = ToMessages(id, scan.texture);
  node_->PublishChunks(channel::kTexture, &texture);
  const StageReport report = DecodeStage(scan, &decoder_, &decoded_);
  if (!report.status.ok()) {
    supervisor_.Failed(id);  // Failed with a status: not sent again.
    node_->Error("scan " + std::to_string(id) + ": " + report.status.message(), id);
    node_->SetState("idle");
    return report.status;
  }
  std::vector<correspondence_t> chunks =
      ToMessages(id, decoded_, scan.sequence.projector_size, {report});
  node_->PublishChunks(channel::kCorrespondence, &chunks);
  node_->Count("scans decoded");
  AnnounceHandedOn(node_, id, channel::kCorrespondence);
  node_->Log("scan " + std::to_string(id) + ": decoded " + std::to_string(decoded_.stats.valid) +
             " pixels in " + std::to_string(report.seconds) + " s");
  node_->SetState("idle");
  return Status::Ok();
}

}  // namespace vellum::station
