// vellum-camera: on each PATTERN_SHOWN, captures the first frame whose exposure starts after
// it and publishes CAPTURE (the frame, the pattern, the scan). Backends: v4l2 (libv4l2) and
// sim (the virtual gantry renders what the camera would see under the pattern shown).
#include <chrono>
#include <memory>
#include <opencv2/imgproc.hpp>

#include "cli/options.h"
#include "core/io/calibration_io.h"
#include "core/sim/gantry.h"
#include "daemons/camera/v4l2_camera.h"
#include "daemons/common/daemon.h"
#include "daemons/common/messages.h"
#include "vellum/capture_t.hpp"
#include "vellum/pattern_shown_t.hpp"

namespace vellum::station {
namespace {

class CameraNode {
 public:
  CameraNode(Node* node, const Flags& flags) : node_(node) {
    const std::string backend = flags.Get("backend");
    if (backend == "sim") {
      Calibration rig = DefaultRig();
      if (!flags.Get("rig").empty()) {
        const Status s = ReadCalibration(flags.Get("rig"), &rig);
        if (!s.ok()) throw UsageError(s.message());
      }
      PageOptions page;
      TextureOptions texture;
      LightOptions light;
      const Status s = SimOptionsFromFlags(flags, &page, &texture, &light, &seed_);
      if (!s.ok()) throw UsageError("--texture " + s.message());
      node->Log("sim: tracing a " + std::string(ToString(page.shape)) + " page for a " +
                SizeText(rig.camera.size) + " camera");
      gantry_ = std::make_unique<VirtualGantry>(rig, page, texture, light);
      // The idle preview, rendered once now: at full resolution a render takes a second or
      // more, which must not sit in the worker's queue when a scan's first pattern comes.
      sim_preview_ = gantry_->RenderTexture(seed_);
    } else if (backend == "v4l2") {
      V4l2Options o;
      o.device = flags.Get("device");
      o.size = flags.GetSize("size");
      const std::string format = flags.Get("format");
      if (format != "BGR3" && format != "GREY") {
        throw UsageError("--format must be BGR3 or GREY, got '" + format + "'");
      }
      o.gray = format == "GREY";
      o.exposure = flags.GetInt("exposure", -1, 1 << 24);
      o.gain = flags.GetInt("gain", -1, 1 << 16);
      v4l2_ = std::make_unique<V4l2Camera>();
      const Status s = v4l2_->Open(o);
      if (!s.ok()) throw std::runtime_error(s.message());
    } else {
      throw UsageError("--backend must be sim or v4l2, got '" + backend + "'");
    }
    node->Subscribe<pattern_shown_t>(channel::kPatternShown, [this](const pattern_shown_t& m) {
      busy_until_ = std::chrono::steady_clock::now() + std::chrono::seconds(2);
      node_->Post([this, m] { OnShown(m); });
    });
    preview_period_ = std::chrono::duration<double>(1.0 / flags.GetDouble("preview-hz", 0.1, 30));
  }

  // On the LCM thread: a live preview while no scan is running.
  void Tick() {
    const auto now = std::chrono::steady_clock::now();
    if (now < busy_until_ || now < next_preview_ || node_->Pending() > 0) return;
    next_preview_ =
        now + std::chrono::duration_cast<std::chrono::steady_clock::duration>(preview_period_);
    node_->Post([this] {
      cv::Mat image;
      int64_t exposure = NowUtime();
      if (gantry_) {
        image = sim_preview_;
      } else if (!v4l2_->Capture(NowUtime(), &image, &exposure).ok()) {
        return;
      }
      PublishPreview(image, exposure, 0, -1, 0);
    });
  }

 private:
  // A copy at most 640 pixels wide on PREVIEW, so that viewers never pull full frames.
  void PublishPreview(const cv::Mat& image, int64_t utime, int64_t scan_id, int index, int count) {
    cv::Mat small = image;
    if (image.cols > 640) {
      const double s = 640.0 / image.cols;
      cv::resize(image, small, cv::Size(), s, s, cv::INTER_AREA);
    }
    image_t p{};
    ToMessage(small, &p);
    p.utime = utime;
    p.scan_id = scan_id;
    p.pattern_index = index;
    p.pattern_count = count;
    node_->Publish(channel::kPreview, &p);
  }

  void OnShown(const pattern_shown_t& m) {
    const std::string where =
        "scan " + std::to_string(m.scan_id) + ", pattern " + std::to_string(m.pattern_index);
    PatternSpec spec;
    Status s = FromMessage(m.pattern, &spec);
    if (!s.ok()) return node_->Error(where + ": PATTERN_SHOWN: " + s.message(), m.scan_id);
    const cv::Size projector(m.projector_width, m.projector_height);
    node_->SetState(
        "capturing", m.scan_id,
        "pattern " + std::to_string(m.pattern_index) + " of " + std::to_string(m.pattern_count));
    cv::Mat image;
    int64_t exposure = 0;
    if (gantry_) {
      if (projector != gantry_->rig().projector.size) {
        return node_->Error(where + ": the projector shows " + SizeText(projector) +
                                " images but the sim rig's projector is " +
                                SizeText(gantry_->rig().projector.size),
                            m.scan_id);
      }
      exposure = std::max(NowUtime(), m.utime + 1);
      const uint64_t seed = seed_ * 1000003ULL + static_cast<uint64_t>(m.pattern_index + 1);
      image = m.pattern_index < 0 ? gantry_->RenderTexture(seed)
                                  : gantry_->RenderFrame(RenderPattern(spec, projector), seed);
    } else {
      s = v4l2_->Capture(m.utime, &image, &exposure);
      if (!s.ok()) return node_->Error(where + ": " + s.message(), m.scan_id);
      if (m.pattern_index >= 0 && image.channels() == 3) {
        cv::cvtColor(image, image, cv::COLOR_BGR2GRAY);
      }
    }
    capture_t c{};
    c.scan_id = m.scan_id;
    c.pattern_index = m.pattern_index;
    c.pattern_count = m.pattern_count;
    c.projector_width = m.projector_width;
    c.projector_height = m.projector_height;
    c.pattern = m.pattern;
    c.shown_utime = m.utime;
    ToMessage(image, &c.image);
    c.image.utime = exposure;
    c.image.scan_id = m.scan_id;
    c.image.pattern_index = m.pattern_index;
    c.image.pattern_count = m.pattern_count;
    c.image.seq = node_->Counter("frames captured");
    node_->Publish(channel::kCapture, &c);
    node_->Count("frames captured");
    PublishPreview(image, exposure, m.scan_id, m.pattern_index, m.pattern_count);
    if (m.pattern_index + 1 == m.pattern_count) node_->SetState("idle", m.scan_id, "scan captured");
  }

  Node* node_;
  std::unique_ptr<VirtualGantry> gantry_;
  uint64_t seed_ = 1;
  std::unique_ptr<V4l2Camera> v4l2_;
  cv::Mat sim_preview_;  // Set before Run, read-only after.
  // LCM thread only:
  std::chrono::steady_clock::time_point busy_until_, next_preview_;
  std::chrono::duration<double> preview_period_{0.5};
};

}  // namespace
}  // namespace vellum::station

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  const std::vector<Flags::Spec> own = {
      {"backend", "NAME", "v4l2 (a real camera) or sim (the virtual gantry)", "sim"},
      {"device", "PATH", "v4l2: the camera device", "/dev/video0"},
      {"size", "WxH", "v4l2: frame size", "1600x1200"},
      {"format", "FOURCC", "v4l2: BGR3 (colour texture) or GREY (monochrome camera)", "BGR3"},
      {"exposure", "N", "v4l2: manual exposure, 100 us units; -1 = camera's setting", "-1"},
      {"gain", "N", "v4l2: gain; -1 = camera's setting", "-1"},
      {"rig", "FILE", "sim: the rig's calibration (default: the built-in default rig)", ""},
      {"preview-hz", "HZ", "live preview rate on PREVIEW while idle", "2"},
  };
  return DaemonMain(argc, argv, "vellum-camera",
                    "Captures a frame for each PATTERN_SHOWN (the first whose exposure starts\n"
                    "after it) and publishes CAPTURE: the texture in colour, patterns in gray.",
                    Join(Join(DaemonFlagSpecs(false), own), SimFlagSpecs("sim: ")),
                    [](const Flags& flags, Node& node) {
                      CameraNode camera(&node, flags);
                      return node.Run([&] { camera.Tick(); });
                    });
}
