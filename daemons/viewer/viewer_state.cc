#include "daemons/viewer/viewer_state.h"

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <tuple>
#include <vector>

#include "core/common/depth.h"
#include "core/common/text.h"
#include "core/outline/outline.h"
#include "io/image_file.h"
#include "station/chain.h"
#include "station/messages.h"

namespace vellum::station {
namespace {

namespace fs = std::filesystem;

const cv::Scalar kRed(40, 40, 220), kGreen(60, 190, 60);

// The preview as the viewer shows it (8-bit BGR, the pixels at the camera's maximum in any
// channel painted red) and its histogram (64 bins of gray); returns the share clipped. Worked
// out once per preview, not at each redraw.
double ClippingView(const cv::Mat& preview, cv::Mat* shown, cv::Mat* hist) {
  const cv::Mat eight = EightBit(preview);
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

// A picture of the scan's report (the first of `names` there), or none.
cv::Mat ReportPicture(const std::string& results, const std::vector<std::string>& names) {
  for (const std::string& name : names) {
    const fs::path p = fs::path(results) / "report" / name;
    cv::Mat picture;
    if (fs::exists(p) && ReadColourImage(p.string(), &picture).ok()) return picture;
  }
  return cv::Mat();
}

// The identity in a scan's report.json (empty when it has none or it cannot be read).
ScanIdentity ReportIdentity(const std::string& results) {
  ScanIdentity id;
  std::ifstream report(fs::path(results) / "report.json");
  const nlohmann::json j = nlohmann::json::parse(report, nullptr, false);
  if (j.is_object() && j.contains("identity") && j["identity"].is_object()) {
    ForEachIdentityField(id, [&](const char* key, std::string& value) {
      if (j["identity"].contains(key) && j["identity"][key].is_string()) value = j["identity"][key];
    });
  }
  return id;
}

// The leading number of a folio ("12" of "12a", "f12" -> 12 too), or a large number when it
// has none: such folios sort after the numbered ones, by their text.
long FolioNumber(const std::string& folio) {
  size_t k = 0;
  while (k < folio.size() && !std::isdigit(static_cast<unsigned char>(folio[k]))) ++k;
  if (k == folio.size()) return std::numeric_limits<long>::max();
  return std::strtol(folio.c_str() + k, nullptr, 10);
}

int SideOrder(const std::string& side) {
  return side == "recto" || side == "left" ? 0 : side == "verso" || side == "right" ? 1 : 2;
}

// The sides a folio is scanned on, in the order the form offers them; "" is none (pages).
const char* const kSides[] = {"recto", "verso", ""};

nlohmann::json IdentityJson(const ScanIdentity& id) {
  nlohmann::json j = nlohmann::json::object();
  ForEachIdentityField(id, [&](const char* key, const std::string& value) {
    if (!value.empty()) j[key] = value;
  });
  return j;
}

ScanIdentity IdentityFromJson(const nlohmann::json& j) {
  ScanIdentity id;
  if (!j.is_object()) return id;
  ForEachIdentityField(id, [&](const char* key, std::string& value) {
    if (j.contains(key) && j[key].is_string()) value = j[key];
  });
  return SanitizedIdentity(id);
}

}  // namespace

const std::vector<FormField>& IdentityForm() {
  static const std::vector<FormField> form = {{"shelfmark", &ScanIdentity::shelfmark},
                                              {"folio", &ScanIdentity::folio},
                                              {"side", &ScanIdentity::side},
                                              {"operator", &ScanIdentity::operator_name},
                                              {"note", &ScanIdentity::note}};
  return form;
}

std::string DescribeIdentity(const ScanIdentity& id) {
  std::string out = IdentityTitle(id);
  if (!id.operator_name.empty()) out += " (" + id.operator_name + ")";
  return out.empty() ? "(no identity: press e)" : out;
}

std::string AttemptTitle(const ScanIdentity& id, int attempt) {
  const std::string title = IdentityTitle(id);
  return (title.empty() ? std::string("(no identity: press e)") : title) +
         (attempt > 1 ? ", attempt " + std::to_string(attempt) + " (retake)" : std::string());
}

std::string ViewerState::FailedTitle() const {
  const Asked* a = asked(failed_scan_);
  return a ? AttemptTitle(a->identity, a->attempt) : "scan " + std::to_string(failed_scan_);
}

std::string ViewerState::FailureNextStep() const {
  if (failure_.empty()) return "";
  std::string remedy = "mend what the message names";
  if (failure_.rfind("vellum-camera", 0) == 0 || failure_.find("no CAPTURE") != std::string::npos) {
    remedy = "the camera stopped: restart vellum-camera";
  } else if (failure_.find("no LIGHT_ON") != std::string::npos) {
    remedy = "no light came on: check vellum-lights (or answer its prompt with l)";
  } else if (failure_.find("disk") != std::string::npos ||
             failure_.find("No space") != std::string::npos) {
    remedy = "the data disk: free space or mend it";
  }
  if (!retake_) return remedy;
  return remedy + ", then Enter to retake " + DescribeIdentity(*retake_);
}

void ViewerState::OnPreview(const cv::Mat& image, Clock::time_point now, bool of_capture) {
  last_preview_ = now;                   // The camera is alive...
  if (capturing_ || of_capture) return;  // ...but shows the patterns: the live frame is held.
  // A picture of its own, never the last one's pixels: the draws keep what they scaled by the
  // pixels' address (viewer_draw.cc), and hold the picture they scaled it from.
  preview_shown_ = cv::Mat();
  preview_clipped_ = ClippingView(image, &preview_shown_, &preview_hist_);
  // The leaf as it is being placed: outlined green, red once it runs off the view.
  const Outline leaf = LeafInPreview(image);
  preview_off_view_ = 0;
  if (!leaf.status.ok()) {
    preview_leaf_ = leaf.status.message();
    return;
  }
  preview_leaf_ = leaf.touches_border ? "off the view" : "in view";
  if (leaf.touches_border)
    preview_off_view_ = ViewSidesReached(leaf.mask, OutlineOptions().border_px);
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(leaf.mask.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
  cv::drawContours(preview_shown_, contours, -1, leaf.touches_border ? kRed : kGreen,
                   std::max(1, image.cols / 160), cv::LINE_AA);
}

void ViewerState::OnFocus(cv::Mat image) {
  image = EightBit(image);
  focus_sharpness_ = Sharpness(image);
  focus_peak_ = std::max(focus_peak_, focus_sharpness_);
  if (image.channels() == 1) cv::cvtColor(image, image, cv::COLOR_GRAY2BGR);
  focus_ = image;
}

void ViewerState::OnPatternShown(const pattern_shown_t& m) {
  Started(m.scan_id);
  capturing_ = true;
  progress_ = "scan " + std::to_string(m.scan_id) + ": " +
              (m.pattern_index < 0 ? std::string("texture")
               : m.pattern_index >= m.pattern_count
                   ? "under the light '" + Printable(m.light.name, 40) + "'"
                   : "pattern " + std::to_string(m.pattern_index + 1) + " of " +
                         std::to_string(m.pattern_count));
}

void ViewerState::OnLightPrompt(const light_t& m) {
  prompt_ = m;
  prompt_.text = Printable(m.text, 300);
  if (prompt_.text.empty()) prompt_.text = "(vellum-lights asks, with no words)";
}

void ViewerState::OnLightOn(const light_t& m) {
  if (m.scan_id == prompt_.scan_id && m.index == prompt_.index) prompt_.text.clear();
}

void ViewerState::Started(int64_t scan_id) {
  if (scan_id == scan_) return;
  scan_ = scan_id;
  shown_ = -1;  // The last result is not this scan's: it goes (Left shows it again).
  if (failed_scan_ != scan_id) failure_.clear();
}

void ViewerState::OfferRetake(int64_t scan_id, const std::string& why) {
  const Asked* a = asked(scan_id);
  if (!a) return;  // Not asked for by this viewer: not its sequence's.
  retake_ = a->identity;
  retake_why_ = why;
}

const ViewerState::Asked* ViewerState::asked(int64_t scan_id) const {
  auto it = asked_.find(scan_id);
  return it == asked_.end() ? nullptr : &it->second;
}

int ViewerState::NextAttempt(const ScanIdentity& identity) const {
  auto it = attempts_.find(IdentitySlug(identity));
  return it == attempts_.end() ? 1 : it->second + 1;
}

std::string ViewerState::Refusal(Clock::time_point now) const {
  if (!has_preview()) return "the camera sends nothing (no preview yet): is vellum-camera running?";
  const double silent = std::chrono::duration<double>(now - last_preview_).count();
  if (silent > 2) {
    return "the camera sends nothing (no preview for " + std::to_string(static_cast<int>(silent)) +
           " s): restart vellum-camera";
  }
  std::vector<const char*> processes(std::begin(kGantry), std::end(kGantry));
  if (statuses_.count("vellum-lights")) processes.push_back("vellum-lights");
  for (const ChainLink& link : kChain) processes.push_back(link.process);
  for (const char* process : processes) {
    auto it = seen_.find(process);
    if (it == seen_.end()) return std::string(process) + " is not heard: is it running?";
    const double quiet = std::chrono::duration<double>(now - it->second).count();
    if (quiet > 3) {
      return std::string(process) + " is silent (" + std::to_string(static_cast<int>(quiet)) +
             " s): restart it";
    }
  }
  return "";
}

void ViewerState::OnStatus(const status_t& m, Clock::time_point now) {
  statuses_[m.process] = m;
  seen_[m.process] = now;
  // The projector no longer scanning: the patterns are off the page, the live view goes on.
  if (m.process == "vellum-projector" && m.state != "scanning") capturing_ = false;
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
  if (const Asked* a = asked(m.last_error_scan_id)) {
    failed_.push_back({m.last_error_scan_id, a->identity, a->attempt, failure_});
    if (failed_.size() > kMaxResults) failed_.pop_front();
  }
  OfferRetake(m.last_error_scan_id, "it failed");
}

Clock::time_point ViewerState::heard(const std::string& process) const {
  auto it = seen_.find(process);
  return it == seen_.end() ? Clock::time_point() : it->second;
}

void ViewerState::ReadPictures(Result* r) {
  if (!r->pictures_pending) return;
  r->pictures_pending = false;
  // The other pictures from the scan's report (the restorer writes it before RESTORED): the
  // texture with the leaf's outline, and a spread's left page for its strain. Read side by side
  // (each is mostly a PNG's inflate).
  const auto read = [r](std::vector<std::string> names) {
    return std::async(
        std::launch::async | std::launch::deferred,
        [results = r->results, names = std::move(names)] { return ReportPicture(results, names); });
  };
  std::future<cv::Mat> texture = read({"outline.png", "texture.png"});
  std::future<cv::Mat> depth = read({"depth.png"});
  r->strain = ReportPicture(r->results, {"strain.png", "strain-left.png"});
  r->texture = texture.get();
  r->depth = depth.get();
}

bool ViewerState::ReadPendingPictures() {
  bool read = false;
  for (Result& r : results_) {
    read = read || r.pictures_pending;
    ReadPictures(&r);
  }
  return read;
}

void ViewerState::OnRestored(const restored_t& m, const cv::Mat& preview, bool read_pictures) {
  Result r;
  r.scan_id = m.scan_id;
  r.results = m.results;
  char summary[96];
  std::snprintf(summary, sizeof(summary), "%dx%d %s", m.width, m.height,
                m.view == "orthographic"
                    ? ("at " + std::to_string(static_cast<int>(m.dpi)) + " dpi").c_str()
                    : "(camera view)");
  r.summary = summary;
  r.restored = preview;
  r.warnings = m.warnings;
  r.quality = m.qc;
  r.pictures_pending = true;
  if (read_pictures) ReadPictures(&r);
  r.identity = ReportIdentity(m.results);
  if (const Asked* a = asked(m.scan_id)) {
    r.identity = a->identity;
    r.attempt = a->attempt;
  }
  r.title = r.identity == ScanIdentity() ? "scan " + std::to_string(m.scan_id)
                                         : AttemptTitle(r.identity, r.attempt);
  if (r.quality == "fail") OfferRetake(m.scan_id, "its verdict is FAIL");
  results_.push_back(r);
  if (results_.size() > kMaxResults) results_.pop_front();
  shown_ = static_cast<int>(results_.size()) - 1;
  // Short enough for the header: the folio, its verdict in the words of the report and the
  // badge (PASS, WARN, FAIL), the size; the warnings are in full under the page.
  std::string verdict = r.quality;
  for (char& c : verdict) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  progress_ = r.title + ": " + (verdict.empty() ? std::string("restored") : verdict) + ", " +
              r.summary +
              (r.warnings.empty()
                   ? std::string()
                   : ", " + std::to_string(r.warnings.size()) + " warning(s) under the page");
}

const ViewerState::Result* ViewerState::shown() const {
  return shown_ >= 0 && shown_ < static_cast<int>(results_.size()) ? &results_[shown_] : nullptr;
}

std::vector<ViewerState::SheetEntry> ViewerState::SheetInBookOrder() const {
  struct Keyed {
    SheetEntry entry;
    const ScanIdentity* identity;
    int attempt;
    int64_t scan_id;
  };
  std::vector<Keyed> all;
  for (size_t k = 0; k < results_.size(); ++k) {
    const Result& r = results_[k];
    all.push_back({{&r, nullptr, static_cast<int>(k)}, &r.identity, r.attempt, r.scan_id});
  }
  for (const Failed& f : failed_)
    all.push_back({{nullptr, &f, -1}, &f.identity, f.attempt, f.scan_id});
  std::stable_sort(all.begin(), all.end(), [](const Keyed& a, const Keyed& b) {
    const ScanIdentity &x = *a.identity, &y = *b.identity;
    return std::make_tuple(x.shelfmark, FolioNumber(x.folio), x.folio, SideOrder(x.side), a.attempt,
                           a.scan_id) < std::make_tuple(y.shelfmark, FolioNumber(y.folio), y.folio,
                                                        SideOrder(y.side), b.attempt, b.scan_id);
  });
  std::vector<SheetEntry> out;
  for (const Keyed& k : all) out.push_back(k.entry);
  return out;
}

std::vector<std::string> ViewerState::warnings() const {
  const Result* r = shown();
  return r ? r->warnings : std::vector<std::string>();
}

std::string ViewerState::quality() const {
  const Result* r = shown();
  return r ? r->quality : std::string();
}

void ViewerState::Type(const std::string& text) {
  if (editing_ < 0 || IdentityForm()[editing_].field == &ScanIdentity::side) return;  // Chosen.
  std::string& field = next_.*IdentityForm()[editing_].field;
  for (const char c : text) {
    if (static_cast<unsigned char>(c) >= 0x20 && field.size() < kMaxIdentityField) field += c;
  }
}

void ViewerState::SetHint(const cv::Rect2d& box) {
  drag_ = cv::Rect2d();
  hint_ = box & cv::Rect2d(0, 0, 1, 1);
  progress_ = "leaf hint drawn: every scan from now on looks for the leaf there (h clears it)";
}

void ViewerState::ActInForm(Action action) {
  const int fields = static_cast<int>(IdentityForm().size());
  std::string& field = next_.*IdentityForm()[editing_].field;
  switch (action) {
    case Action::kFieldNext:
      editing_ = (editing_ + 1) % fields;
      break;
    case Action::kFieldBack:
      editing_ = (editing_ + fields - 1) % fields;
      break;
    case Action::kBackspace:  // One character (UTF-8: its continuation bytes too).
      while (!field.empty() && (static_cast<unsigned char>(field.back()) & 0xc0) == 0x80) {
        field.pop_back();
      }
      if (!field.empty()) field.pop_back();
      break;
    case Action::kChoose:  // The side: recto, verso, none (pages), round again.
      if (IdentityForm()[editing_].field == &ScanIdentity::side) {
        size_t k = 0;
        while (k < std::size(kSides) && field != kSides[k]) ++k;
        field = kSides[(k + 1) % std::size(kSides)];
      }
      break;
    case Action::kFormDone: {
      std::string why;
      next_ = SanitizedIdentity(next_, &why);
      if (!why.empty()) progress_ = "identity: " + why;
      editing_ = -1;
      break;
    }
    default:  // The form has the keyboard: nothing else acts while it is open.
      break;
  }
}

ViewerState::Command ViewerState::RequestScan(int64_t scan_id, Clock::time_point now) {
  Command c;
  const std::string refused = Refusal(now);
  if (!refused.empty()) {
    progress_ = "scan refused: " + refused;
    return c;
  }
  const ScanIdentity identity = next_identity();
  c.kind = Command::Kind::kRequestScan;
  scan_request_t& r = c.request;
  r.scan_id = scan_id;
  r.identity = ToMessage(identity);
  if (identity == ScanIdentity()) r.identity.label = "from vellum-viewer";
  ToLeafHint(hint_, r.leaf_hint);
  r.object = ToString(object_);
  r.live_off_view = ViewSidesText(preview_off_view_);  // The scan cannot pass when so seen.
  Asked asked{identity, 1};
  const std::string slug = IdentitySlug(identity);
  if (!slug.empty()) asked.attempt = ++attempts_[slug];
  asked_[scan_id] = asked;
  while (asked_.size() > 4 * kMaxResults) asked_.erase(asked_.begin());
  progress_ =
      "scan " + std::to_string(r.scan_id) + " requested: " + AttemptTitle(identity, asked.attempt);
  Started(r.scan_id);
  if (retake_) {  // The retake, then the sequence goes on where it was.
    retake_.reset();
    retake_why_.clear();
    return c;
  }
  history_.push_back(next_);
  if (history_.size() > 1000) history_.erase(history_.begin());
  next_ = NextFolio(next_);
  return c;
}

ViewerState::Command ViewerState::LightDone() {
  Command c;
  if (prompt_.text.empty()) return c;
  if (prompt_.index >= 0) {  // The light asked for is on (not the lights off, at the end).
    c.kind = Command::Kind::kLightOn;
    c.light = prompt_;
    c.light.utime = 0;
    c.light.text.clear();
    c.light.source = "operator";
    progress_ = "scan " + std::to_string(c.light.scan_id) + ": the light '" + c.light.light.name +
                "' is on (the operator)";
  }
  prompt_.text.clear();
  return c;
}

ViewerState::Command ViewerState::Act(Action action, int64_t new_scan_id, Clock::time_point now) {
  if (editing_ >= 0) {
    ActInForm(action);
    return Command();
  }
  if (quitting_) {  // Quit? y quits; any other key stays (and does nothing else).
    quitting_ = false;
    Command c;
    if (action == Action::kConfirm) c.kind = Command::Kind::kQuit;
    progress_ = c.kind == Command::Kind::kQuit ? "quitting" : "the viewer stays";
    return c;
  }
  switch (action) {
    case Action::kQuit:
      if (sheet_) {  // Esc leaves the contact sheet, not the viewer.
        sheet_ = false;
        break;
      }
      quitting_ = true;
      progress_ = "quit the viewer? y: quit, any other key: stay";
      break;
    case Action::kScan:
      return RequestScan(new_scan_id, now);
    case Action::kLightDone:
      return LightDone();
    case Action::kSheet:
      sheet_ = !sheet_;
      break;
    case Action::kObject:  // What the sequence's scans are: auto, then a leaf, then an open book.
      object_ = object_ == ObjectKind::kAuto   ? ObjectKind::kLeaf
                : object_ == ObjectKind::kLeaf ? ObjectKind::kBook
                                               : ObjectKind::kAuto;
      progress_ = std::string("the next scans are ") +
                  (object_ == ObjectKind::kLeaf   ? "a single leaf each (never split)"
                   : object_ == ObjectKind::kBook ? "an open book each (two pages)"
                                                  : "leaf or book, as vellum finds (auto)");
      break;
    case Action::kClearHint:
      if (hint_.area() > 0) progress_ = "leaf hint cleared";
      hint_ = drag_ = cv::Rect2d();
      break;
    case Action::kZoom:
      zoom_ = !zoom_;
      if (zoom_) focus_peak_ = focus_sharpness_;  // A new peak to find.
      break;
    case Action::kEdit:
      editing_ = 0;
      break;
    case Action::kUndo:  // The retake offered declined, or else the last advance taken back.
      if (retake_) {
        progress_ = "retake of " + DescribeIdentity(*retake_) +
                    " dropped; next scan: " + DescribeIdentity(next_);
        retake_.reset();
        retake_why_.clear();
      } else if (!history_.empty()) {
        next_ = history_.back();
        history_.pop_back();
        progress_ = "next scan again: " + DescribeIdentity(next_);
      }
      break;
    case Action::kPrevious:
      if (shown_ > 0) --shown_;
      break;
    case Action::kNext:
      if (shown_ + 1 < static_cast<int>(results_.size())) ++shown_;
      break;
    default:  // The form's actions, with the form closed.
      break;
  }
  return Command();
}

std::string ViewerState::SessionJson() const {
  nlohmann::json j;
  j["version"] = 1;
  j["next"] = IdentityJson(next_);
  if (retake_) {
    j["retake"] = IdentityJson(*retake_);
    j["retake_why"] = retake_why_;
  }
  j["object"] = ToString(object_);
  j["attempts"] = attempts_;
  nlohmann::json history = nlohmann::json::array();
  const size_t from = history_.size() > 100 ? history_.size() - 100 : 0;
  for (size_t k = from; k < history_.size(); ++k) history.push_back(IdentityJson(history_[k]));
  j["history"] = history;
  if (hint_.area() > 0) j["leaf_hint"] = {hint_.x, hint_.y, hint_.width, hint_.height};
  return j.dump(2) + "\n";
}

bool ViewerState::LoadSession(const std::string& text, std::string* why) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (!j.is_object() || !j.contains("version") || j["version"] != 1) {
    *why = "not a vellum-viewer session (version 1)";
    return false;
  }
  ObjectKind object = ObjectKind::kAuto;
  if (j.contains("object") &&
      (!j["object"].is_string() || !ParseObjectKind(j["object"], &object))) {
    *why = "object: not auto, leaf or book";
    return false;
  }
  std::map<std::string, int> attempts;
  if (j.contains("attempts")) {
    if (!j["attempts"].is_object()) {
      *why = "attempts: not an object of counts";
      return false;
    }
    for (const auto& [slug, n] : j["attempts"].items()) {
      if (!n.is_number_integer() || n.get<int>() < 0) {
        *why = "attempts: " + slug + " is not a count";
        return false;
      }
      attempts[slug] = n.get<int>();
    }
  }
  cv::Rect2d hint;
  if (j.contains("leaf_hint")) {
    const nlohmann::json& h = j["leaf_hint"];
    if (!h.is_array() || h.size() != 4 || !h[0].is_number() || !h[1].is_number() ||
        !h[2].is_number() || !h[3].is_number()) {
      *why = "leaf_hint: not four numbers";
      return false;
    }
    hint =
        cv::Rect2d(h[0].get<double>(), h[1].get<double>(), h[2].get<double>(), h[3].get<double>()) &
        cv::Rect2d(0, 0, 1, 1);
  }
  next_ = IdentityFromJson(j.value("next", nlohmann::json::object()));
  retake_.reset();
  retake_why_.clear();
  if (j.contains("retake")) {
    retake_ = IdentityFromJson(j["retake"]);
    retake_why_ = j.value("retake_why", std::string());
  }
  object_ = object;
  attempts_ = attempts;
  history_.clear();
  if (j.contains("history") && j["history"].is_array()) {
    for (const nlohmann::json& h : j["history"]) history_.push_back(IdentityFromJson(h));
  }
  hint_ = hint;
  return true;
}

}  // namespace vellum::station
