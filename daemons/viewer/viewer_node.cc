#include "daemons/viewer/viewer_node.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/text.h"
#include "core/outline/outline.h"
#include "io/image_file.h"
#include "station/chain.h"
#include "station/messages.h"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/scan_request_t.hpp"

namespace vellum::station {
namespace {

namespace fs = std::filesystem;

// Draws `image` scaled to fit `box` of `canvas` (centred), with a caption above.
// Returns where the image went on the canvas (empty when there is none).
cv::Rect Panel(cv::Mat& canvas, cv::Rect box, const cv::Mat& image, const std::string& caption) {
  cv::rectangle(canvas, box, cv::Scalar(70, 70, 70), 1);
  cv::putText(canvas, caption, box.tl() + cv::Point(4, 16), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(230, 230, 230), 1, cv::LINE_AA);
  const cv::Rect inner(box.x + 2, box.y + 22, box.width - 4, box.height - 24);
  if (image.empty()) {
    cv::putText(canvas, "(none yet)", inner.tl() + cv::Point(8, 24), cv::FONT_HERSHEY_SIMPLEX, 0.5,
                cv::Scalar(140, 140, 140), 1, cv::LINE_AA);
    return cv::Rect();
  }
  cv::Mat bgr = image;
  if (bgr.channels() == 1) cv::cvtColor(bgr, bgr, cv::COLOR_GRAY2BGR);
  const double s = std::min(static_cast<double>(inner.width) / bgr.cols,
                            static_cast<double>(inner.height) / bgr.rows);
  cv::Mat scaled;
  cv::resize(bgr, scaled, cv::Size(), s, s, s < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
  const cv::Rect at(inner.x + (inner.width - scaled.cols) / 2,
                    inner.y + (inner.height - scaled.rows) / 2, scaled.cols, scaled.rows);
  const cv::Rect shown = at & cv::Rect(0, 0, canvas.cols, canvas.rows);
  scaled(shown - at.tl()).copyTo(canvas(shown));
  return shown;
}

// The identity form's fields, in order.
struct FormField {
  const char* name;
  std::string ScanIdentity::*field;
};
constexpr FormField kForm[] = {{"shelfmark", &ScanIdentity::shelfmark},
                               {"folio", &ScanIdentity::folio},
                               {"side", &ScanIdentity::side},
                               {"operator", &ScanIdentity::operator_name},
                               {"note", &ScanIdentity::note}};
constexpr int kFormFields = static_cast<int>(std::size(kForm));

// "MS 12, 3 recto (A. Scribe)"; "(no identity)".
std::string Describe(const ScanIdentity& id) {
  std::string out = IdentityTitle(id);
  if (!id.operator_name.empty()) out += " (" + id.operator_name + ")";
  return out.empty() ? "(no identity: press e)" : out;
}

// Splits `text` into lines of at most `chars` characters, at spaces where it can.
std::vector<std::string> Wrap(const std::string& text, size_t chars) {
  std::vector<std::string> lines;
  size_t at = 0;
  while (at < text.size()) {
    size_t end = std::min(text.size(), at + chars);
    if (end < text.size()) {
      const size_t space = text.rfind(' ', end);
      if (space != std::string::npos && space > at) end = space;
    }
    lines.push_back(text.substr(at, end - at));
    at = end;
    while (at < text.size() && text[at] == ' ') ++at;
  }
  return lines;
}

const cv::Scalar kRed(40, 40, 220), kAmber(0, 170, 255), kGreen(60, 190, 60), kCyan(255, 220, 0);

// The preview as the viewer shows it (8-bit BGR, the pixels at the camera's maximum in any
// channel painted red) and its histogram (64 bins of gray); returns the share clipped. Worked
// out once per preview, not at each redraw.
double ClippingView(const cv::Mat& preview, cv::Mat* shown, cv::Mat* hist) {
  cv::Mat eight = preview;
  if (eight.depth() != CV_8U) preview.convertTo(eight, CV_8U, 1.0 / 257);
  cv::Mat top = eight.reshape(1, eight.rows * eight.cols);
  cv::reduce(top, top, 1, cv::REDUCE_MAX);
  const cv::Mat clipped = top.reshape(1, eight.rows) >= 255;
  cv::Mat gray = eight;
  if (eight.channels() == 3) {
    cv::cvtColor(eight, gray, cv::COLOR_BGR2GRAY);
    *shown = eight.clone();
  } else {
    cv::cvtColor(eight, *shown, cv::COLOR_GRAY2BGR);
  }
  shown->setTo(cv::Scalar(0, 0, 255), clipped);
  const int channels[] = {0};
  const int bins[] = {64};
  const float range[] = {0, 256};
  const float* ranges[] = {range};
  cv::calcHist(&gray, 1, channels, cv::Mat(), *hist, 1, bins, ranges);
  return static_cast<double>(cv::countNonZero(clipped)) / clipped.total();
}

// How sharp an 8-bit image is: the variance of its Laplacian (higher is sharper; compared
// while focusing).
double Sharpness(const cv::Mat& image) {
  cv::Mat gray = image;
  if (gray.channels() == 3) cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  cv::Mat laplacian;
  cv::Laplacian(gray, laplacian, CV_64F);
  cv::Scalar mean, stddev;
  cv::meanStdDev(laplacian, mean, stddev);
  return stddev[0] * stddev[0];
}

cv::Scalar VerdictColour(const std::string& verdict) {
  return verdict == "pass" ? kGreen : verdict == "warn" ? kAmber : kRed;
}

}  // namespace

ViewerNode::ViewerNode(Node* node, std::unique_ptr<display::Window> window)
    : node_(node), window_(std::move(window)) {
  // Text input only while the form is open: a key that opens it (e) must not also type itself
  // into it, as SDL sends both a key and its text while text input is on.
  window_->TextInput(false);
  node->Subscribe<image_t>(channel::kPreview, [this](const image_t& m) {
    cv::Mat image;
    const Status s = FromMessage(m, &image);
    if (!s.ok()) return node_->Error("PREVIEW: " + s.message());
    preview_ = image;
    last_preview_ = Clock::now();
    preview_clipped_ = ClippingView(image, &preview_shown_, &preview_hist_);
    // The leaf as it is being placed: outlined green, red once it runs off the view.
    const Outline leaf = LeafInPreview(image);
    if (leaf.status.ok()) {
      preview_leaf_ = leaf.touches_border ? "off the view" : "in view";
      std::vector<std::vector<cv::Point>> contours;
      cv::findContours(leaf.mask.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
      cv::drawContours(preview_shown_, contours, -1, leaf.touches_border ? kRed : kGreen,
                       std::max(1, image.cols / 160), cv::LINE_AA);
    } else {
      preview_leaf_ = leaf.status.message();
    }
  });
  node->Subscribe<image_t>(channel::kPreviewFocus, [this](const image_t& m) {
    cv::Mat image;
    const Status s = FromMessage(m, &image);
    if (!s.ok()) return node_->Error("PREVIEW_FOCUS: " + s.message());
    if (image.depth() != CV_8U) image.convertTo(image, CV_8U, 1.0 / 257);
    focus_sharpness_ = Sharpness(image);
    if (image.channels() == 1) cv::cvtColor(image, image, cv::COLOR_GRAY2BGR);
    focus_ = image;
  });
  node->Subscribe<pattern_shown_t>(channel::kPatternShown, [this](const pattern_shown_t& m) {
    Started(m.scan_id);
    progress_ = "scan " + std::to_string(m.scan_id) + ": " +
                (m.pattern_index < 0 ? std::string("texture")
                 : m.pattern_index >= m.pattern_count
                     ? "under the light '" + Printable(m.light.name, 40) + "'"
                     : "pattern " + std::to_string(m.pattern_index + 1) + " of " +
                           std::to_string(m.pattern_count));
  });
  node->Subscribe<light_t>(channel::kLightPrompt, [this](const light_t& m) {
    prompt_ = m;
    prompt_.text = Printable(m.text, 300);
    if (prompt_.text.empty()) prompt_.text = "(vellum-lights asks, with no words)";
  });
  node->Subscribe<light_t>(channel::kLightOn, [this](const light_t& m) {
    if (m.scan_id == prompt_.scan_id && m.index == prompt_.index) prompt_.text.clear();
  });
  node->Subscribe<status_t>(StatusChannel("vellum-lights"),
                            [this](const status_t& m) { OnStatus(m); });
  auto on_status = [this](const status_t& m) { OnStatus(m); };
  for (const char* process : kGantry) node->Subscribe<status_t>(StatusChannel(process), on_status);
  for (const ChainLink& link : kChain) {
    node->Subscribe<status_t>(StatusChannel(link.process), on_status);
  }
  node->Subscribe<restored_t>(channel::kRestored, [this](const restored_t& m) { OnRestored(m); });
}

void ViewerNode::Started(int64_t scan_id) {
  if (scan_id == scan_) return;
  scan_ = scan_id;
  if (failed_scan_ != scan_id) failure_.clear();
}

void ViewerNode::OnStatus(const status_t& m) {
  statuses_[m.process] = m;
  seen_[m.process] = Clock::now();
  if (m.state == "busy") {
    progress_ = "scan " + std::to_string(m.scan_id) + ": " + m.process.substr(7) + " " + m.detail;
  }
  // A new error about a scan (an old one, from before this viewer listened, is not news): the
  // scan failed. The header turns red with the whole message.
  auto known = error_utime_.find(m.process);
  const bool news = known != error_utime_.end() && m.last_error_utime > known->second;
  error_utime_[m.process] = m.last_error_utime;
  if (!news || m.last_error_scan_id <= 0 || m.last_error.empty()) return;
  if (scan_ != 0 && m.last_error_scan_id != scan_) return;  // Not the scan in progress.
  scan_ = failed_scan_ = m.last_error_scan_id;
  failure_ = m.process + ": " + m.last_error;
  progress_ = "scan " + std::to_string(m.last_error_scan_id) + " FAILED";
}

void ViewerNode::Tick() {
  std::vector<display::Window::Input> input;
  if (!window_->Poll(&input)) node_->Stop();
  for (const display::Window::Input& in : input) {
    if (in.mouse != display::Window::Input::Mouse::kNone) {
      OnMouse(in);
    } else if (in.key != 0) {
      OnKey(in.key);
    } else if (editing_ >= 0) {
      OnText(in.text);
    }
  }
  if (Clock::now() < next_draw_) return;
  next_draw_ = Clock::now() + std::chrono::milliseconds(100);
  window_->Show(Draw());
}

void ViewerNode::OnMouse(const display::Window::Input& in) {
  using Mouse = display::Window::Input::Mouse;
  const cv::Rect at = preview_at_;
  if (editing_ >= 0 || zoom_ || at.empty()) return;
  const cv::Point p(std::clamp(in.at.x, at.x, at.br().x), std::clamp(in.at.y, at.y, at.br().y));
  if (in.mouse == Mouse::kDown) {
    if (!at.contains(in.at)) return;  // Only a drag begun on the preview draws.
    drag_from_ = drag_to_ = p;
    return;
  }
  if (drag_from_.x < 0) return;
  drag_to_ = p;
  if (in.mouse != Mouse::kUp) return;
  const cv::Rect box(drag_from_, drag_to_);
  drag_from_ = cv::Point(-1, -1);
  if (box.width < 4 || box.height < 4) {  // A click: no hint.
    ClearHint();
    return;
  }
  hint_ = cv::Rect2d(
      static_cast<double>(box.x - at.x) / at.width, static_cast<double>(box.y - at.y) / at.height,
      static_cast<double>(box.width) / at.width, static_cast<double>(box.height) / at.height);
  progress_ = "leaf hint drawn: every scan from now on looks for the leaf there (h clears it)";
}

void ViewerNode::ClearHint() {
  if (hint_.area() > 0) progress_ = "leaf hint cleared";
  hint_ = cv::Rect2d();
}

void ViewerNode::OnText(const std::string& text) {
  std::string& field = next_.*kForm[editing_].field;
  for (const char c : text) {
    if (static_cast<unsigned char>(c) >= 0x20 && field.size() < kMaxIdentityField) field += c;
  }
}

void ViewerNode::OnKey(SDL_Keycode key) {
  if (editing_ >= 0) {  // The form has the keyboard: letters arrive as text (OnText).
    std::string& field = next_.*kForm[editing_].field;
    switch (key) {
      case SDLK_TAB:
      case SDLK_DOWN:
        editing_ = (editing_ + 1) % kFormFields;
        break;
      case SDLK_UP:
        editing_ = (editing_ + kFormFields - 1) % kFormFields;
        break;
      case SDLK_BACKSPACE:  // One character (UTF-8: its continuation bytes too).
        while (!field.empty() && (static_cast<unsigned char>(field.back()) & 0xc0) == 0x80) {
          field.pop_back();
        }
        if (!field.empty()) field.pop_back();
        break;
      case SDLK_RETURN:
      case SDLK_KP_ENTER:
      case SDLK_ESCAPE: {
        std::string why;
        next_ = SanitizedIdentity(next_, &why);
        if (!why.empty()) progress_ = "identity: " + why;
        editing_ = -1;
        window_->TextInput(false);
        node_->SetState("idle");
        break;
      }
      default:
        break;
    }
    return;
  }
  switch (key) {
    case SDLK_q:
    case SDLK_ESCAPE:
      node_->Stop();
      break;
    case SDLK_s: {
      scan_request_t r{};
      r.scan_id = NowUtime();
      r.identity = ToMessage(next_);
      if (next_ == ScanIdentity()) r.identity.label = "from vellum-viewer";
      ToLeafHint(hint_, r.leaf_hint);
      r.object = ToString(object_);
      node_->Publish(channel::kScanRequest, &r);
      progress_ = "scan " + std::to_string(r.scan_id) + " requested: " + Describe(next_);
      Started(r.scan_id);
      history_.push_back(next_);
      if (history_.size() > 1000) history_.erase(history_.begin());
      next_ = NextFolio(next_);
      break;
    }
    case SDLK_c:
      sheet_ = !sheet_;
      break;
    case SDLK_o:  // What the sequence's scans are: auto, then a leaf, then an open book.
      object_ = object_ == ObjectKind::kAuto   ? ObjectKind::kLeaf
                : object_ == ObjectKind::kLeaf ? ObjectKind::kBook
                                               : ObjectKind::kAuto;
      progress_ = std::string("the next scans are ") +
                  (object_ == ObjectKind::kLeaf   ? "a single leaf each (never split)"
                   : object_ == ObjectKind::kBook ? "an open book each (two pages)"
                                                  : "leaf or book, as vellum finds (auto)");
      break;
    case SDLK_h:
      ClearHint();
      break;
    case SDLK_l:  // The operator has switched the light asked for (or off, at the end).
      if (!prompt_.text.empty()) {
        if (prompt_.index >= 0) {
          light_t on = prompt_;
          on.utime = 0;
          on.text.clear();
          on.source = "operator";
          node_->Publish(channel::kLightOn, &on);
          progress_ = "scan " + std::to_string(on.scan_id) + ": the light '" + on.light.name +
                      "' is on (the operator)";
        }
        prompt_.text.clear();
      }
      break;
    case SDLK_z:
      zoom_ = !zoom_;
      break;
    case SDLK_e:
      editing_ = 0;
      window_->TextInput(true);
      node_->SetState("editing", 0, "the next scan's identity");  // The form has the keyboard.
      break;
    case SDLK_u:  // The last advance taken back: the next scan is of that folio again.
      if (!history_.empty()) {
        next_ = history_.back();
        history_.pop_back();
        progress_ = "next scan again: " + Describe(next_);
      }
      break;
    case SDLK_LEFT:
      if (shown_ > 0) --shown_;
      break;
    case SDLK_RIGHT:
      if (shown_ + 1 < static_cast<int>(results_.size())) ++shown_;
      break;
    default:
      break;
  }
}

void ViewerNode::OnRestored(const restored_t& m) {
  Result r;
  r.scan_id = m.scan_id;
  r.results = m.results;
  char summary[160];
  std::snprintf(summary, sizeof(summary), "scan %lld: %dx%d %s", static_cast<long long>(m.scan_id),
                m.width, m.height,
                m.view == "orthographic"
                    ? (std::to_string(static_cast<int>(m.dpi)) + " dpi").c_str()
                    : "camera view");
  r.summary = summary;
  const Status s = FromMessage(m.preview, &r.restored);
  if (!s.ok()) {
    node_->Error("RESTORED of scan " + std::to_string(m.scan_id) + ": preview: " + s.message(),
                 m.scan_id);
  }
  r.warnings = m.warnings;
  r.quality = m.qc;
  // The other pictures from the scan's report (the restorer writes it before RESTORED): the
  // texture with the leaf's outline, and a spread's left page for its strain.
  auto load = [&](std::initializer_list<const char*> names) {
    for (const char* name : names) {
      const fs::path p = fs::path(m.results) / "report" / name;
      cv::Mat picture;
      if (fs::exists(p) && ReadColourImage(p.string(), &picture).ok()) return picture;
    }
    return cv::Mat();
  };
  r.texture = load({"outline.png", "texture.png"});
  // Its title: the identity in its report.
  r.title = "scan " + std::to_string(m.scan_id);
  std::ifstream report(fs::path(m.results) / "report.json");
  const nlohmann::json j = nlohmann::json::parse(report, nullptr, false);
  if (j.is_object() && j.contains("identity") && j["identity"].is_object()) {
    ScanIdentity id;
    ForEachIdentityField(id, [&](const char* key, std::string& value) {
      if (j["identity"].contains(key) && j["identity"][key].is_string()) value = j["identity"][key];
    });
    if (!(id == ScanIdentity())) r.title = Describe(id);
  }
  r.depth = load({"depth.png"});
  r.strain = load({"strain.png", "strain-left.png"});
  results_.push_back(r);
  if (results_.size() > 50) results_.pop_front();
  shown_ = static_cast<int>(results_.size()) - 1;
  progress_ =
      r.summary + " restored" + (r.quality.empty() ? std::string() : ", quality " + r.quality) +
      (r.warnings.empty()
           ? std::string()
           : " with " + std::to_string(r.warnings.size()) + " warning(s): check before delivering");
}

std::vector<std::string> ViewerNode::warnings() const {
  if (shown_ < 0 || shown_ >= static_cast<int>(results_.size())) return {};
  return results_[shown_].warnings;
}

std::string ViewerNode::quality() const {
  if (shown_ < 0 || shown_ >= static_cast<int>(results_.size())) return "";
  return results_[shown_].quality;
}

void ViewerNode::DrawLeft(cv::Mat& canvas, int top, int width) const {
  const int h = canvas.rows;
  // The live preview, its clipped pixels in red; "NO SIGNAL" when the camera falls silent.
  const int preview_h = (h - top) * 2 / 5;
  const cv::Rect box(8, top, width - 12, preview_h);
  if (zoom_) {
    // The centre at the camera's own resolution, pixel for pixel (never scaled up), and how
    // sharp it is.
    cv::rectangle(canvas, box, cv::Scalar(70, 70, 70), 1);
    char caption[96];
    std::snprintf(caption, sizeof(caption), "100%% of the view's centre (z: back), focus %.0f",
                  focus_sharpness_);
    cv::putText(canvas, caption, box.tl() + cv::Point(4, 16), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                cv::Scalar(230, 230, 230), 1, cv::LINE_AA);
    const cv::Rect inner(box.x + 2, box.y + 22, box.width - 4, box.height - 24);
    if (!focus_.empty()) {
      const cv::Mat& bgr = focus_;
      const cv::Rect part(0, 0, std::min(bgr.cols, inner.width), std::min(bgr.rows, inner.height));
      const cv::Rect at(inner.x + (inner.width - part.width) / 2,
                        inner.y + (inner.height - part.height) / 2, part.width, part.height);
      bgr(part + cv::Point((bgr.cols - part.width) / 2, (bgr.rows - part.height) / 2))
          .copyTo(canvas(at));
    } else {
      cv::putText(canvas, "(no full-resolution view yet)", inner.tl() + cv::Point(8, 24),
                  cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(140, 140, 140), 1, cv::LINE_AA);
    }
  } else {
    preview_at_ = Panel(canvas, box, preview_shown_, "camera preview (clipped in red)");
    // The leaf hint in cyan, and the box being dragged.
    const cv::Rect at = preview_at_;
    if (!at.empty() && hint_.area() > 0) {
      const cv::Rect hint(at.x + cvRound(hint_.x * at.width), at.y + cvRound(hint_.y * at.height),
                          cvRound(hint_.width * at.width), cvRound(hint_.height * at.height));
      cv::rectangle(canvas, hint, kCyan, 2);
      cv::putText(canvas, "leaf hint (h: clear)", hint.tl() + cv::Point(4, 14),
                  cv::FONT_HERSHEY_SIMPLEX, 0.4, kCyan, 1, cv::LINE_AA);
    }
    if (drag_from_.x >= 0) cv::rectangle(canvas, cv::Rect(drag_from_, drag_to_), kCyan, 1);
    if (!preview_leaf_.empty()) {
      const bool off = preview_leaf_ == "off the view", in = preview_leaf_ == "in view";
      const std::string line = off  ? "LEAF RUNS OFF THE VIEW"
                               : in ? "leaf in view"
                                    : "no outline: " + preview_leaf_;  // 45 characters at most.
      cv::putText(canvas, line, cv::Point(box.x + 6, box.y + box.height - 8),
                  cv::FONT_HERSHEY_SIMPLEX, off ? 0.5 : 0.4,
                  off  ? kRed
                  : in ? kGreen
                       : cv::Scalar(170, 170, 170),
                  off ? 2 : 1, cv::LINE_AA);
    }
  }
  const double silent = std::chrono::duration<double>(Clock::now() - last_preview_).count();
  if (preview_.empty() || silent > 2) {
    const std::string what = preview_.empty() ? "NO SIGNAL: no camera preview yet"
                                              : "NO SIGNAL: no camera preview for " +
                                                    std::to_string(static_cast<int>(silent)) + " s";
    cv::putText(canvas, what, cv::Point(box.x + 8, box.y + box.height / 2),
                cv::FONT_HERSHEY_SIMPLEX, 0.6, kRed, 2, cv::LINE_AA);
  }
  // The histogram under it, its top bin red when pixels clip.
  const cv::Rect strip(8, top + preview_h + 2, width - 12, 36);
  cv::rectangle(canvas, strip, cv::Scalar(70, 70, 70), 1);
  const cv::Mat& hist = preview_hist_;
  const double clipped = preview_clipped_;
  if (!hist.empty()) {
    double most = 0;
    cv::minMaxLoc(hist, nullptr, &most);
    const double bin_w = static_cast<double>(strip.width - 2) / hist.rows;
    for (int b = 0; b < hist.rows; ++b) {
      const int bar =
          static_cast<int>((strip.height - 4) * hist.at<float>(b) / std::max(1.0, most));
      const cv::Scalar colour =
          b == hist.rows - 1 && clipped > 0 ? kRed : cv::Scalar(200, 200, 200);
      cv::rectangle(
          canvas,
          cv::Rect(strip.x + 1 + static_cast<int>(b * bin_w), strip.y + strip.height - 2 - bar,
                   std::max(1, static_cast<int>(bin_w)), bar),
          colour, cv::FILLED);
    }
    char line[64];
    std::snprintf(line, sizeof(line), "clipped %.2f%%", 100 * clipped);
    cv::putText(canvas, line, cv::Point(strip.x + 4, strip.y + 14), cv::FONT_HERSHEY_SIMPLEX, 0.4,
                clipped > 0.005 ? kRed : cv::Scalar(200, 200, 200), 1, cv::LINE_AA);
  }
  // The daemons.
  int y = strip.y + strip.height + 18;
  std::vector<const char*> processes(std::begin(kGantry), std::end(kGantry));
  if (statuses_.count("vellum-lights")) processes.push_back("vellum-lights");  // Once heard.
  for (const ChainLink& link : kChain) processes.push_back(link.process);
  for (const char* process : processes) {
    auto it = statuses_.find(process);
    const bool alive =
        it != statuses_.end() && Clock::now() - seen_.at(process) < std::chrono::seconds(3);
    std::string line = std::string(process + 7) + ": ";
    if (it == statuses_.end()) {
      line += "not seen";
    } else {
      line += alive ? it->second.state : "silent (" + it->second.state + ")";
      if (!it->second.last_error.empty()) line += " | " + it->second.last_error;
    }
    if (line.size() > 70) line = line.substr(0, 67) + "...";
    const cv::Scalar colour = !alive                          ? cv::Scalar(80, 80, 230)
                              : it->second.last_error.empty() ? cv::Scalar(120, 230, 120)
                                                              : cv::Scalar(80, 190, 240);
    cv::circle(canvas, cv::Point(18, y - 5), 5, colour, cv::FILLED, cv::LINE_AA);
    cv::putText(canvas, line, cv::Point(30, y), cv::FONT_HERSHEY_SIMPLEX, 0.42,
                cv::Scalar(220, 220, 220), 1, cv::LINE_AA);
    y += 18;
  }
  // The next scan's identity; the form when it is edited.
  const int form_lines = editing_ >= 0 ? kFormFields + 1 : 2;
  y = std::max(y + 6, h - 8 - 18 * form_lines);
  if (editing_ < 0) {
    cv::putText(canvas, "next scan: " + Describe(next_) + "  (" + ToString(object_) + ")",
                cv::Point(12, y + 12), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1,
                cv::LINE_AA);
    cv::putText(canvas, "e: edit   o: leaf/book/auto   u: undo the last advance   z: 100% zoom",
                cv::Point(12, y + 30), cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(160, 160, 160), 1,
                cv::LINE_AA);
    return;
  }
  cv::putText(canvas, "identity of the next scan (Tab: next field, Return: done)",
              cv::Point(12, y + 12), cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(255, 255, 255), 1,
              cv::LINE_AA);
  for (int k = 0; k < kFormFields; ++k) {
    const int line_y = y + 18 * (k + 2);
    const bool current = k == editing_;
    if (current) {
      cv::rectangle(canvas, cv::Rect(10, line_y - 14, width - 16, 18), cv::Scalar(90, 60, 20),
                    cv::FILLED);
    }
    const std::string value = next_.*kForm[k].field + (current ? "_" : "");
    cv::putText(canvas, std::string(kForm[k].name) + ": " + value, cv::Point(14, line_y),
                cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(240, 240, 240), 1, cv::LINE_AA);
  }
}

void ViewerNode::DrawSheet(cv::Mat& canvas, cv::Rect area) const {
  cv::rectangle(canvas, area, cv::Scalar(30, 30, 30), cv::FILLED);
  cv::putText(canvas, "this session: " + std::to_string(results_.size()) + " scan(s) (c: back)",
              area.tl() + cv::Point(6, 18), cv::FONT_HERSHEY_SIMPLEX, 0.55,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  const int n = static_cast<int>(results_.size());
  if (n == 0) return;
  // Columns for about 4:3 cells, newest first.
  int cols = 1;
  while (cols * cols * 3 < n * 4) ++cols;
  const int rows = (n + cols - 1) / cols;
  const int cell_w = (area.width - 8) / cols, cell_h = std::min((area.height - 30) / rows, cell_w);
  for (int k = 0; k < n; ++k) {
    const Result& r = results_[n - 1 - k];
    const cv::Rect cell(area.x + 4 + (k % cols) * cell_w, area.y + 26 + (k / cols) * cell_h,
                        cell_w - 6, cell_h - 6);
    const cv::Scalar colour =
        r.quality.empty() ? cv::Scalar(120, 120, 120) : VerdictColour(r.quality);
    Panel(canvas, cell, r.restored, r.title);
    cv::rectangle(canvas, cell, colour, 3);
    if (k == n - 1 - shown_) cv::rectangle(canvas, cell, cv::Scalar(255, 255, 255), 1);
  }
}

cv::Mat ViewerNode::Draw() const {
  const cv::Size size = window_->size();
  cv::Mat canvas(size, CV_8UC3, cv::Scalar(30, 30, 30));
  const int w = size.width, h = size.height, top = 44;
  // The header: red, with the scan's failure, when the scan in progress failed.
  const bool failed = !failure_.empty();
  if (failed) cv::rectangle(canvas, cv::Rect(0, 0, w, top - 4), kRed, cv::FILLED);
  cv::putText(canvas, "vellum station", cv::Point(12, 28), cv::FONT_HERSHEY_SIMPLEX, 0.8,
              cv::Scalar(255, 255, 255), 2, cv::LINE_AA);
  const bool doubtful = progress_.find("warning(s)") != std::string::npos;
  // The progress line, cut to end before the keys' help.
  const int help_x = w - 390;
  std::string progress = progress_;
  int baseline = 0;
  while (progress.size() > 4 &&
         230 + cv::getTextSize(progress, cv::FONT_HERSHEY_SIMPLEX, 0.6, failed ? 2 : 1, &baseline)
                     .width >
             help_x - 10) {
    progress = progress.substr(0, progress.size() - 4) + "...";
  }
  cv::putText(canvas, progress, cv::Point(230, 28), cv::FONT_HERSHEY_SIMPLEX, 0.6,
              failed     ? cv::Scalar(255, 255, 255)
              : doubtful ? kAmber
                         : cv::Scalar(120, 220, 255),
              failed ? 2 : 1, cv::LINE_AA);
  cv::putText(canvas, "s: scan  e: identity  c: sheet  drag: leaf hint  q: quit",
              cv::Point(help_x, 28), cv::FONT_HERSHEY_SIMPLEX, 0.45,
              failed ? cv::Scalar(255, 255, 255) : cv::Scalar(160, 160, 160), 1, cv::LINE_AA);
  // Left: live preview, histogram, the daemons, the next scan's identity.
  const int left_w = w / 3;
  DrawLeft(canvas, top, left_w);
  // Middle: texture, depth, strain; right: the restored page, large.
  const Result* r =
      shown_ >= 0 && shown_ < static_cast<int>(results_.size()) ? &results_[shown_] : nullptr;
  const int mid_x = left_w, mid_w = w / 3, third = (h - top) / 3;
  static const Result kEmpty;
  const Result& show = r ? *r : kEmpty;
  Panel(canvas, cv::Rect(mid_x, top, mid_w - 8, third - 4), show.texture,
        "texture and the leaf's outline");
  Panel(canvas, cv::Rect(mid_x, top + third, mid_w - 8, third - 4), show.depth, "depth (mm)");
  Panel(canvas, cv::Rect(mid_x, top + 2 * third, mid_w - 8, third - 4), show.strain,
        "flattening strain");
  // The restored page, its quality verdict above it in its colour, and under it a doubtful
  // result's warnings in amber, a line each.
  const int lines = std::min<int>(static_cast<int>(show.warnings.size()), 6);
  const int warn_h = lines > 0 ? 18 * lines + 8 : 0;
  const int badge_h = show.quality.empty() ? 0 : 24;
  const cv::Rect page(mid_x + mid_w, top + badge_h, w - mid_x - mid_w - 8,
                      h - top - badge_h - 8 - warn_h);
  if (!show.quality.empty()) {
    const cv::Rect badge(page.x, top, page.width, badge_h - 4);
    cv::rectangle(canvas, badge, VerdictColour(show.quality), cv::FILLED);
    std::string verdict = show.quality;
    for (char& c : verdict) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    cv::putText(canvas, "quality: " + verdict, badge.tl() + cv::Point(6, 15),
                cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  }
  std::string caption =
      show.warnings.empty() ? "restored page" : "restored page: DOUBTFUL, see the warnings";
  if (failed && r && r->scan_id != failed_scan_) {
    caption = "an earlier scan (" + std::to_string(r->scan_id) + "); scan " +
              std::to_string(failed_scan_) + " failed";
  }
  Panel(canvas, page, show.restored, caption);
  const size_t chars = static_cast<size_t>(std::max(20, page.width / 8));
  for (int k = 0; k < lines; ++k) {
    std::string line = "! " + show.warnings[k];
    if (line.size() > chars) line = line.substr(0, chars - 3) + "...";
    cv::putText(canvas, line, cv::Point(page.x + 4, page.y + page.height + 18 * (k + 1)),
                cv::FONT_HERSHEY_SIMPLEX, 0.42, kAmber, 1, cv::LINE_AA);
  }
  if (sheet_) DrawSheet(canvas, cv::Rect(mid_x, top, w - mid_x - 8, h - top - 8));
  // The operator's prompt to switch a light, over the middle and the right, in blue.
  if (!prompt_.text.empty()) {
    const std::vector<std::string> wrapped =
        Wrap(prompt_.text, static_cast<size_t>(std::max(30, (w - mid_x - 40) / 11)));
    const int n = std::min<int>(static_cast<int>(wrapped.size()), 6);
    const cv::Rect box(mid_x, top + h / 4, w - mid_x - 8, 30 * n + 60);
    cv::rectangle(canvas, box, cv::Scalar(90, 40, 10), cv::FILLED);
    cv::rectangle(canvas, box, cv::Scalar(255, 160, 60), 3);
    cv::putText(canvas,
                prompt_.index >= 0 ? "LIGHTS: switch by hand, then press L" : "LIGHTS (L: done)",
                box.tl() + cv::Point(12, 28), cv::FONT_HERSHEY_SIMPLEX, 0.7,
                cv::Scalar(255, 255, 255), 2, cv::LINE_AA);
    for (int k = 0; k < n; ++k) {
      cv::putText(canvas, wrapped[k], box.tl() + cv::Point(12, 58 + 30 * k),
                  cv::FONT_HERSHEY_SIMPLEX, 0.65, cv::Scalar(255, 230, 200), 1, cv::LINE_AA);
    }
  }
  // The failure's whole message, over the middle and the right, in red.
  if (failed) {
    const std::vector<std::string> wrapped =
        Wrap(failure_, static_cast<size_t>(std::max(30, (w - mid_x - 40) / 9)));
    const int n = std::min<int>(static_cast<int>(wrapped.size()), 8);
    const cv::Rect box(mid_x, top, w - mid_x - 8, 22 * n + 30);
    cv::rectangle(canvas, box, cv::Scalar(20, 20, 60), cv::FILLED);
    cv::rectangle(canvas, box, kRed, 2);
    cv::putText(canvas,
                "scan " + std::to_string(failed_scan_) + " failed:", box.tl() + cv::Point(10, 20),
                cv::FONT_HERSHEY_SIMPLEX, 0.55, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
    for (int k = 0; k < n; ++k) {
      cv::putText(canvas, wrapped[k], box.tl() + cv::Point(10, 42 + 22 * k),
                  cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(200, 200, 255), 1, cv::LINE_AA);
    }
  }
  return canvas;
}

}  // namespace vellum::station
