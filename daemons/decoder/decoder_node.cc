#include "daemons/decoder/decoder_node.h"

#include <filesystem>
#include <memory>
#include <stdexcept>

#include "pipeline/pipeline.h"
#include "station/chain.h"
#include "station/messages.h"

namespace vellum::station {

namespace {

// The data folder's lock, before anything reads or writes there; throws when another decoder
// holds it.
std::unique_ptr<DataLock> LockData(const std::string& data_dir) {
  auto lock = std::make_unique<DataLock>();
  const Status s = lock->Take(data_dir, "vellum-decoder");
  if (!s.ok()) throw std::runtime_error(s.message());
  return lock;
}

}  // namespace

bool DecoderNodeOptions::Check(std::string* why) const {
  if (data_dir.empty() || !(scan_timeout_s > 0)) {
    *why = "decoder: data_dir must be named and scan_timeout_s > 0";
    return false;
  }
  return decode.Check(why);
}

DecoderNode::DecoderNode(Node* node, const DecoderNodeOptions& options)
    : node_(node),
      options_(options),
      lock_(LockData(options.data_dir)),
      decoder_(options.decode),
      supervisor_(node, options.data_dir,
                  [this](int64_t id, const Scan& scan) { return Send(id, scan); }),
      gate_(options.data_dir) {
  // Each message the gate admits goes to the scan's log at once, on the LCM thread (an append
  // and a flush), so that a crash loses nothing received; the rest is done on the worker.
  node->Subscribe<scan_started_t>(channel::kScanStarted, [this](const scan_started_t& msg) {
    if (!Admitted(gate_.Start(msg), msg.scan_id)) return;  // That scan cannot be recorded.
    node_->Count("scans started");
    last_capture_ = node_->Now();  // The texture is awaited from now.
    // The scan's folder, named after what is scanned; found by its id from here on. A retake of
    // a folio sets the earlier attempts aside (kept whole).
    const std::string slug = IdentitySlug(FromMessage(msg.identity));
    for (const std::string& aside : SetAsideEarlierAttempts(options_.data_dir, msg.scan_id, slug)) {
      node_->Count("retakes");
      node_->Log("scan " + std::to_string(msg.scan_id) + ": a retake of " + slug +
                 "; the earlier attempt is kept in " + aside);
    }
    std::error_code ec;
    std::filesystem::create_directories(ScanFolder::New(options_.data_dir, msg.scan_id, slug).raw(),
                                        ec);  // A failure shows as the log's.
    if (!Log(channel::kScanStarted, msg.scan_id, msg.utime, Encode(msg))) return;
    const int64_t id = msg.scan_id;
    // Begin takes the identity from the log, where this SCAN_STARTED now is.
    node_->Post([this, id] { Begin(id); }, "a SCAN_STARTED");
  });
  node->Subscribe<capture_t>(channel::kCapture, [this](const capture_t& msg) {
    // A capture that contradicts itself is refused before it reaches the scan's log (which
    // would then no longer export).
    const Status ok = CheckCapture(msg);
    if (!ok.ok()) {
      node_->Count("captures refused");
      if (!gate_.Holds(msg.scan_id, msg.session) || !ClaimsAPattern(msg)) {
        // Not one of the scan's captures (no projector takes it for one): the scan goes on.
        node_->Error("CAPTURE refused, not recorded: " + ok.message());
        return;
      }
      // One of the scan's captures, and bad: the scan cannot be whole (its projector took this
      // capture for the pattern's and moved on), so it fails now, not at its timeout.
      gate_.Close(msg.scan_id);
      const int64_t id = msg.scan_id;
      const std::string why = "CAPTURE refused, not recorded: " + ok.message();
      node_->Post([this, id, why] {
        if (recording_ == id) Abandon(why);
      });
      return;
    }
    const ScanGate::Decision d = gate_.Admit(msg);
    if (d.verdict == ScanGate::Verdict::kDuplicate) {
      node_->Count(d.counter);
      const int64_t id = msg.scan_id;
      const std::string why = d.why;
      node_->Post([this, id, why] {
        if (recording_ == id) Abandon(why);
      });
      return;
    }
    // Not an error of the scan: a stray capture must not fail the scan in progress.
    if (!Admitted(d, 0)) return;
    if (d.resumed)
      node_->Log("scan " + std::to_string(msg.scan_id) + ": taken up again after a restart");
    if (!Log(channel::kCapture, msg.scan_id, msg.utime, Encode(msg))) return;
    auto copy = std::make_shared<capture_t>(msg);
    last_capture_ = node_->Now();
    awaiting_light_ = false;
    node_->Post([this, copy] { OnCapture(*copy); }, "a CAPTURE");
  });
  node->Subscribe<light_t>(channel::kLightRequest, [this](const light_t& msg) {
    if (!gate_.Holds(msg.scan_id, msg.session)) return;
    awaiting_light_ = msg.index >= 0;
    last_capture_ = node_->Now();
  });
  node->Subscribe<calibration_t>(channel::kCalibration, [this](const calibration_t& msg) {
    if (!Admitted(gate_.AdmitCalibration(msg), 0)) return;
    if (!Log(channel::kCalibration, msg.scan_id, msg.utime, Encode(msg))) return;
    auto copy = std::make_shared<calibration_t>(msg);
    node_->Post([this, copy] { OnCalibration(*copy); }, "a CALIBRATION");
  });
}

bool DecoderNode::Admitted(const ScanGate::Decision& d, int64_t error_scan_id) {
  if (d.verdict == ScanGate::Verdict::kRecord) return true;
  if (d.why.empty()) return false;  // Nothing to record, nothing wrong.
  node_->Count(d.counter);
  // A flood of refusals is counted, and reported at most once a second per reason.
  const auto now = node_->Now();
  auto& last = refusal_reported_[d.counter];
  if (last == Clock::time_point() || now - last >= std::chrono::seconds(1)) {
    last = now;
    node_->Error(d.why, error_scan_id);
  }
  return false;
}

void DecoderNode::Tick() {
  if (!waiting_ || awaiting_light_ ||
      node_->Now() - last_capture_ < std::chrono::duration<double>(options_.scan_timeout_s)) {
    return;
  }
  waiting_ = false;
  node_->Post([this] {
    if (recording_ != 0 && !set_.Complete()) {
      Abandon("no capture for " + std::to_string(static_cast<int>(options_.scan_timeout_s)) + " s");
    }
  });
}

bool DecoderNode::Log(const char* channel, int64_t scan_id, int64_t utime,
                      const std::vector<uint8_t>& bytes) {
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
  Fail(recording_, why + (set_.Started() ? "; " + set_.Missing() : std::string()) +
                       "; the captures received are kept in " +
                       ScanFolder::For(options_.data_dir, recording_).raw());
}

void DecoderNode::Fail(int64_t id, const std::string& why) {
  gate_.Close(id);  // Nothing more of it is recorded.
  const ScanFolder folder = ScanFolder::For(options_.data_dir, id);
  const Status marked = MarkFailed(folder, why);
  node_->Count(counter::kScansFailed);  // Before the error goes out with the count.
  node_->Error(
      "scan " + std::to_string(id) + " failed: " + why +
          (marked.ok() ? "" : " (and it could not be marked failed: " + marked.message() + ")"),
      id);
  Stop();
}

bool DecoderNode::Begin(int64_t scan_id) {
  if (recording_ == scan_id) return !set_.Complete();
  if (recording_ != 0 && !set_.Complete()) {
    Abandon("scan " + std::to_string(scan_id) + " started before it was complete");
  }
  set_ = CaptureSet();
  recording_ = scan_id;
  supervisor_.Recording(scan_id);
  waiting_ = true;
  int resumed = 0;
  started_ = scan_started_t{};
  const ScanFolder folder = ScanFolder::For(options_.data_dir, scan_id);
  const Status s = recorder_.Open(folder, scan_id, &set_, &resumed, &started_);
  if (!s.ok()) {
    Fail(scan_id, "cannot record: " + s.message());
    return false;
  }
  // The decoder takes each frame up as it comes (Stream), those the log already held (it ran
  // ahead of this thread, or a restart) first; or it reads them from the folder.
  stream_id_ = scan_id;
  stream_begun_ = false;
  if (resumed > 0 && set_.Started()) {
    const Scan held = set_.ToScan();
    const int patterns = static_cast<int>(held.sequence.patterns.size());
    for (int k = 0; k < patterns; ++k) {
      if (set_.Has(k)) {
        StreamFrame(scan_id, held.sequence.projector_size, patterns, k, held.sequence.patterns[k],
                    held.frames[k]);
      }
    }
    if (set_.Has(-1)) SendTexture(scan_id, held.texture, started_.light_count);
  }
  set_.KeepFrames(false);
  node_->Log(
      "scan " + std::to_string(scan_id) + ": recording to " + folder.raw() +
      (resumed ? " (continuing: " + std::to_string(resumed) + " captures already there)" : ""));
  node_->SetState("recording", scan_id, "waiting for the texture");
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
      Fail(msg.scan_id, s.message());
      return;
    }
    cv::Mat image;
    s = FromMessage(msg.image, &image);  // Checked by Add.
    if (s.ok()) s = recorder_.Write(msg, image);
    if (!s.ok()) {
      Fail(msg.scan_id, "recording: " + s.message());
      return;
    }
    Stream(msg, image);
    if (msg.pattern_index < 0) SendTexture(msg.scan_id, image, started_.light_count);
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
  Scan scan = set_.ToScan();
  FromStarted(started_, &scan);
  const Status s = recorder_.Finish(scan);
  if (!s.ok()) {
    Fail(id, s.message());
    return;
  }
  Stop();
  node_->Count("scans recorded");
  supervisor_.Recorded(id, scan);
}

void DecoderNode::Stream(const capture_t& msg, const cv::Mat& image) {
  PatternSpec spec;
  if (msg.pattern_index < 0 || msg.pattern_index >= msg.pattern_count) return;  // Not a pattern.
  if (!FromMessage(msg.pattern, &spec).ok()) {
    stream_id_ = 0;
    return;
  }
  StreamFrame(msg.scan_id, cv::Size(msg.projector_width, msg.projector_height), msg.pattern_count,
              msg.pattern_index, spec, image);
}

void DecoderNode::StreamFrame(int64_t scan_id, cv::Size projector, int count, int index,
                              const PatternSpec& spec, const cv::Mat& image) {
  if (scan_id != stream_id_) return;
  if (!stream_begun_) {
    PatternOptions options;
    options.projector_size = projector;
    std::string why;
    stream_begun_ = options.Check(&why);
    if (stream_begun_) stream_sequence_ = MakePatternSequence(options);
    stream_begun_ = stream_begun_ && static_cast<int>(stream_sequence_.patterns.size()) == count &&
                    decoder_.Begin(stream_sequence_, image.size()).ok();
    if (!stream_begun_) {
      stream_id_ = 0;  // Another sequence: decoded from the folder once complete.
      return;
    }
  }
  if (index < 0 || index >= count || !(spec == stream_sequence_.patterns[index]) ||
      !decoder_.Add(index, image).ok()) {
    stream_id_ = 0;
    stream_begun_ = false;
  }
}

void DecoderNode::SendTexture(int64_t id, const cv::Mat& texture, int light_count) {
  std::vector<texture_t> chunks = TextureMessages(id, texture, light_count);
  node_->PublishChunks(channel::kTexture, &chunks);
  texture_sent_ = id;
}

Status DecoderNode::Send(int64_t id, const Scan& scan) {
  node_->SetState("busy", id, "decoding");
  // The texture went on as it was recorded, unless this is a send from the folder.
  const int lights = static_cast<int>(scan.lights.size());
  if (texture_sent_ != id || lights != started_.light_count) SendTexture(id, scan.texture, lights);
  texture_sent_ = 0;
  for (const ScanLight& light : scan.lights) {  // At the camera's depth, as the texture.
    std::vector<texture_t> chunks = TextureMessages(id, light.image, lights, &light);
    node_->PublishChunks(channel::kLightTexture, &chunks);
  }
  // Taken up as it came when the whole scan was; else read from its folder as it is decoded
  // (which ends any other scan's stream: that one is read from its folder in turn).
  const bool streamed = id == stream_id_ && stream_begun_ &&
                        decoder_.Received() == static_cast<int>(scan.sequence.patterns.size()) &&
                        scan.sequence.patterns == stream_sequence_.patterns;
  stream_id_ = 0;
  stream_begun_ = false;
  node_->Count(streamed ? "scans decoded as captured" : "scans decoded from their folder");
  // The pipeline's decode step, with this node's decoder (its buffers kept between scans).
  PipelineOptions options;
  options.decode = options_.decode;
  options.limits = options_.limits;
  ScanWork work;
  work.scan = scan;
  work.frames_dir = streamed ? std::string() : ScanFolder::For(options_.data_dir, id).raw();
  work.decoder = &decoder_;
  work.context = ScanContext::Of(scan);  // The calibration's part is the triangulator's.
  std::swap(work.decoded, decoded_);
  const Status decoded = Pipeline(options).Run(Step::kDecode, Step::kDecode, &work);
  std::swap(work.decoded, decoded_);
  if (!decoded.ok()) {
    supervisor_.Failed(id, "decoding failed: " + decoded.message());  // Not sent again.
    node_->Error("scan " + std::to_string(id) + ": " + decoded.message(), id);
    node_->SetState("idle");
    return decoded;
  }
  const StageReport& report = work.stages.back();
  // The projector's light goes only to a restorer that makes the albedo from it.
  DecodeResult sent = decoded_;  // Its maps' headers: nothing copied.
  if (!supervisor_.LightWanted()) sent.amplitude = cv::Mat();
  // Each chunk made as it is sent, into one message.
  static_cast<void>(node_->PublishChunks(
      channel::kCorrespondence,
      CorrespondenceChunks(id, sent, scan.sequence.projector_size, work.context, work.stages)));
  AnnounceHandedOn(node_, id, channel::kCorrespondence, "scans decoded");
  node_->Log("scan " + std::to_string(id) + ": decoded " + std::to_string(decoded_.stats.valid) +
             " pixels in " + std::to_string(report.seconds) + " s");
  node_->SetState("idle");
  return Status::Ok();
}

}  // namespace vellum::station
