#include "daemons/viewer/viewer_draw.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <iterator>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "station/chain.h"

namespace vellum::station {
namespace {

const cv::Scalar kRed(40, 40, 220), kAmber(0, 170, 255), kGreen(60, 190, 60), kCyan(255, 220, 0);
const int kFormFields = static_cast<int>(IdentityForm().size());

// The panels' images as scaled at the last draw, so that an image is scaled once, not at every
// draw: the draws go on while the chain works, on the same cores. Each entry holds its
// source image (a header: its pixels shared), so that no new image can take the source's
// address while the entry stands; images in the state are replaced, never written in place.
// An entry not used by one draw is gone at the next.
class ScaledImages {
 public:
  // Starts a draw: drops what the draw before it did not use.
  void NextDraw() {
    entries_.erase(
        std::remove_if(entries_.begin(), entries_.end(), [](const Entry& e) { return !e.used; }),
        entries_.end());
    for (Entry& e : entries_) e.used = false;
  }
  // `image` (8-bit gray or BGR) as BGR scaled by `s`.
  const cv::Mat& Scaled(const cv::Mat& image, double s) {
    for (Entry& e : entries_) {
      if (e.source.data == image.data && e.source.size() == image.size() &&
          e.source.type() == image.type() && e.scale == s) {
        e.used = true;
        return e.scaled;
      }
    }
    Entry& e = entries_.emplace_back();
    e.source = image;
    e.scale = s;
    e.used = true;
    cv::Mat bgr = image;
    if (bgr.channels() == 1) cv::cvtColor(bgr, bgr, cv::COLOR_GRAY2BGR);
    cv::resize(bgr, e.scaled, cv::Size(), s, s, s < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
    return e.scaled;
  }

 private:
  struct Entry {
    cv::Mat source, scaled;
    double scale = 0;
    bool used = false;
  };
  std::vector<Entry> entries_;
};

ScaledImages& Scaler() {
  thread_local ScaledImages scaled;
  return scaled;
}

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
  const double s = std::min(static_cast<double>(inner.width) / image.cols,
                            static_cast<double>(inner.height) / image.rows);
  const cv::Mat& scaled = Scaler().Scaled(image, s);
  const cv::Rect at(inner.x + (inner.width - scaled.cols) / 2,
                    inner.y + (inner.height - scaled.rows) / 2, scaled.cols, scaled.rows);
  const cv::Rect shown = at & cv::Rect(0, 0, canvas.cols, canvas.rows);
  scaled(shown - at.tl()).copyTo(canvas(shown));
  return shown;
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

cv::Scalar VerdictColour(const std::string& verdict) {
  return verdict == "pass" ? kGreen : verdict == "warn" ? kAmber : kRed;
}

// The view's centre at the camera's own resolution, pixel for pixel (never scaled up), and how
// sharp it is.
void DrawFocus(const ViewerState& s, cv::Mat& canvas, cv::Rect box) {
  cv::rectangle(canvas, box, cv::Scalar(70, 70, 70), 1);
  char caption[128];
  std::snprintf(caption, sizeof(caption),
                "100%% of the view's centre (z: back), focus %.0f, peak %.0f", s.focus_sharpness(),
                s.focus_peak());
  cv::putText(canvas, caption, box.tl() + cv::Point(4, 16), cv::FONT_HERSHEY_SIMPLEX, 0.45,
              cv::Scalar(230, 230, 230), 1, cv::LINE_AA);
  // The focus meter: a bar to the present sharpness, a white tick at the peak held.
  const cv::Rect meter(box.x + 4, box.y + 22, box.width - 8, 8);
  cv::rectangle(canvas, meter, cv::Scalar(70, 70, 70), cv::FILLED);
  if (s.focus_peak() > 0) {
    const double at = std::min(1.0, s.focus_sharpness() / s.focus_peak());
    cv::rectangle(canvas, cv::Rect(meter.x, meter.y, static_cast<int>(at * meter.width), 8),
                  at > 0.95 ? kGreen : kAmber, cv::FILLED);
    cv::line(canvas, cv::Point(meter.br().x - 1, meter.y - 2),
             cv::Point(meter.br().x - 1, meter.br().y + 2), cv::Scalar(200, 200, 200), 2);
  }
  const cv::Rect inner(box.x + 2, box.y + 34, box.width - 4, box.height - 36);
  if (!s.focus().empty()) {
    const cv::Mat& bgr = s.focus();
    const cv::Rect part(0, 0, std::min(bgr.cols, inner.width), std::min(bgr.rows, inner.height));
    const cv::Rect at(inner.x + (inner.width - part.width) / 2,
                      inner.y + (inner.height - part.height) / 2, part.width, part.height);
    bgr(part + cv::Point((bgr.cols - part.width) / 2, (bgr.rows - part.height) / 2))
        .copyTo(canvas(at));
  } else {
    cv::putText(canvas, "(no full-resolution view yet)", inner.tl() + cv::Point(8, 24),
                cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(140, 140, 140), 1, cv::LINE_AA);
  }
}

// The live preview, its clipped pixels in red and the leaf outlined, the leaf hint in cyan, the
// box being dragged, and a line on the leaf; returns where the preview's pixels went.
cv::Rect DrawPreview(const ViewerState& s, cv::Mat& canvas, cv::Rect box) {
  // Held: dimmed, in a picture of its own (never the state's, which the next draw shows again).
  cv::Mat shown = s.preview_shown();
  if (s.capturing() && !shown.empty()) {
    cv::Mat dimmed;
    shown.convertTo(dimmed, -1, 0.45);
    shown = dimmed;
  }
  const cv::Rect at = Panel(canvas, box, shown,
                            s.capturing() ? "camera preview: held while the patterns run"
                                          : "camera preview (clipped in red)");
  if (!at.empty() && s.leaf_hint().area() > 0) {
    const cv::Rect hint(
        at.x + cvRound(s.leaf_hint().x * at.width), at.y + cvRound(s.leaf_hint().y * at.height),
        cvRound(s.leaf_hint().width * at.width), cvRound(s.leaf_hint().height * at.height));
    cv::rectangle(canvas, hint, kCyan, 2);
    cv::putText(canvas, "leaf hint (h: clear)", hint.tl() + cv::Point(4, 14),
                cv::FONT_HERSHEY_SIMPLEX, 0.4, kCyan, 1, cv::LINE_AA);
  }
  const cv::Rect2d& drag = s.dragging();
  if (!at.empty() && drag.area() > 0) {
    cv::rectangle(canvas,
                  cv::Rect(at.x + cvRound(drag.x * at.width), at.y + cvRound(drag.y * at.height),
                           cvRound(drag.width * at.width), cvRound(drag.height * at.height)),
                  kCyan, 1);
  }
  if (!s.preview_leaf().empty()) {
    const bool off = s.preview_leaf() == "off the view", in = s.preview_leaf() == "in view";
    const std::string line = off  ? "LEAF RUNS OFF THE VIEW"
                             : in ? "leaf in view"
                                  : "no outline: " + s.preview_leaf();  // 45 characters at most.
    cv::putText(canvas, line, cv::Point(box.x + 6, box.y + box.height - 8),
                cv::FONT_HERSHEY_SIMPLEX, off ? 0.5 : 0.4,
                off  ? kRed
                : in ? kGreen
                     : cv::Scalar(170, 170, 170),
                off ? 2 : 1, cv::LINE_AA);
  }
  return at;
}

// "NO SIGNAL" over the preview when the camera fell silent for more than 2 s by `now`.
void DrawNoSignal(const ViewerState& s, cv::Mat& canvas, cv::Rect box, Clock::time_point now) {
  const double silent = std::chrono::duration<double>(now - s.preview_at()).count();
  if (!s.has_preview() || silent > 2) {
    const std::string what = !s.has_preview() ? "NO SIGNAL: no camera preview yet"
                                              : "NO SIGNAL: no camera preview for " +
                                                    std::to_string(static_cast<int>(silent)) + " s";
    cv::putText(canvas, what, cv::Point(box.x + 8, box.y + box.height / 2),
                cv::FONT_HERSHEY_SIMPLEX, 0.6, kRed, 2, cv::LINE_AA);
  }
}

// The preview's histogram in `strip`, its top bin red when pixels clip.
void DrawHistogram(const ViewerState& s, cv::Mat& canvas, cv::Rect strip) {
  cv::rectangle(canvas, strip, cv::Scalar(70, 70, 70), 1);
  const cv::Mat& hist = s.preview_histogram();
  const double clipped = s.preview_clipped();
  if (hist.empty()) return;
  double most = 0;
  cv::minMaxLoc(hist, nullptr, &most);
  const double bin_w = static_cast<double>(strip.width - 2) / hist.rows;
  for (int b = 0; b < hist.rows; ++b) {
    const int bar = static_cast<int>((strip.height - 4) * hist.at<float>(b) / std::max(1.0, most));
    const cv::Scalar colour = b == hist.rows - 1 && clipped > 0 ? kRed : cv::Scalar(200, 200, 200);
    cv::rectangle(
        canvas,
        cv::Rect(strip.x + 1 + static_cast<int>(b * bin_w), strip.y + strip.height - 2 - bar,
                 std::max(1, static_cast<int>(bin_w)), bar),
        colour, cv::FILLED);
  }
  // The axis: the levels 0, 64, 128, 192 and 255 under the strip; the clipping end in red.
  for (const int level : {0, 64, 128, 192, 255}) {
    const int x = strip.x + 1 + static_cast<int>(level / 256.0 * (strip.width - 2));
    cv::line(canvas, cv::Point(x, strip.br().y - 3), cv::Point(x, strip.br().y + 2),
             level == 255 && clipped > 0 ? kRed : cv::Scalar(150, 150, 150), 1);
    cv::putText(canvas, std::to_string(level),
                cv::Point(std::min(x, strip.br().x - 22), strip.br().y + 12),
                cv::FONT_HERSHEY_SIMPLEX, 0.3, cv::Scalar(150, 150, 150), 1, cv::LINE_AA);
  }
  char line[64];
  std::snprintf(line, sizeof(line), "clipped %.2f%%", 100 * clipped);
  cv::putText(canvas, line, cv::Point(strip.x + 4, strip.y + 14), cv::FONT_HERSHEY_SIMPLEX, 0.4,
              clipped > 0.005 ? kRed : cv::Scalar(200, 200, 200), 1, cv::LINE_AA);
}

// Each daemon's state and last error from its heartbeat, a line each from `y`, red when silent
// for 3 s; returns the y under them.
int DrawDaemons(const ViewerState& s, cv::Mat& canvas, int y, Clock::time_point now) {
  std::vector<const char*> processes(std::begin(kGantry), std::end(kGantry));
  if (s.statuses().count("vellum-lights")) processes.push_back("vellum-lights");  // Once heard.
  for (const ChainLink& link : kChain) processes.push_back(link.process);
  for (const char* process : processes) {
    auto it = s.statuses().find(process);
    const bool alive = it != s.statuses().end() && now - s.heard(process) < std::chrono::seconds(3);
    std::string line = std::string(process + 7) + ": ";
    if (it == s.statuses().end()) {
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
  return y;
}

// The next scan's identity from `y` on, or its form while it is edited.
void DrawIdentity(const ViewerState& s, cv::Mat& canvas, int y, int width, Clock::time_point now) {
  if (!s.editing()) {
    const ScanIdentity& next = s.next_identity();
    const std::string title =
        AttemptTitle(next, s.NextAttempt(next)) +
        (next.operator_name.empty() ? std::string() : " (" + next.operator_name + ")");
    const size_t chars = static_cast<size_t>(std::max(20, (width - 16) / 8));
    // Each part wrapped to the left column's width, so that nothing runs under the film strip.
    int line_y = y + 12;
    auto say = [&](const std::string& text, double scale, cv::Scalar colour, int thick,
                   size_t most) {
      const std::vector<std::string> lines = Wrap(text, chars);
      for (size_t k = 0; k < std::min(most, lines.size()); ++k, line_y += 16) {
        cv::putText(canvas, lines[k], cv::Point(12, line_y), cv::FONT_HERSHEY_SIMPLEX, scale,
                    colour, thick, cv::LINE_AA);
      }
    };
    if (s.retake()) {
      say("RETAKE (Enter): " + title, 0.45, kAmber, 2, 2);
      say(s.retake_why() + "; u: go on without it, to " + DescribeIdentity(s.sequence_next()), 0.4,
          kAmber, 1, 1);
    } else {
      say("next scan (Enter): " + title + "  (" + ToString(s.object()) + ")", 0.45,
          cv::Scalar(255, 255, 255), 1, 2);
      say("e: edit   o: leaf/book/auto   u: undo the last advance   z: 100% zoom", 0.4,
          cv::Scalar(160, 160, 160), 1, 2);
    }
    const std::string refused = s.Refusal(now);
    if (!refused.empty()) say("cannot scan: " + refused, 0.42, kRed, 1, 2);  // In full.
    return;
  }
  cv::putText(canvas, "identity of the next scan (Tab: next field, Return: done)",
              cv::Point(12, y + 12), cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(255, 255, 255), 1,
              cv::LINE_AA);
  for (int k = 0; k < kFormFields; ++k) {
    const int line_y = y + 18 * (k + 2);
    const bool current = k == s.editing_field();
    if (current) {
      cv::rectangle(canvas, cv::Rect(10, line_y - 14, width - 16, 18), cv::Scalar(90, 60, 20),
                    cv::FILLED);
    }
    const std::string& text = s.sequence_next().*IdentityForm()[k].field;
    std::string value = text + (current ? "_" : "");
    if (IdentityForm()[k].field == &ScanIdentity::side) {  // Chosen, not typed.
      value = "< " + (text.empty() ? std::string("none: pages") : text) + " >" +
              (current ? "  Space: choose" : "");
    }
    cv::putText(canvas, std::string(IdentityForm()[k].name) + ": " + value, cv::Point(14, line_y),
                cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(240, 240, 240), 1, cv::LINE_AA);
  }
}

// The left third: the preview (or the focus view), its histogram, the daemons, the identity;
// returns where the preview's pixels went.
cv::Rect DrawLeft(const ViewerState& s, cv::Mat& canvas, int top, int width,
                  Clock::time_point now) {
  const int h = canvas.rows;
  const int preview_h = (h - top) * 2 / 5;
  const cv::Rect box(8, top, width - 12, preview_h);
  cv::Rect preview_at;
  if (s.zoomed()) {
    DrawFocus(s, canvas, box);
  } else {
    preview_at = DrawPreview(s, canvas, box);
  }
  DrawNoSignal(s, canvas, box, now);
  const cv::Rect strip(8, top + preview_h + 2, width - 12, 36);
  DrawHistogram(s, canvas, strip);
  const int y = DrawDaemons(s, canvas, strip.y + strip.height + 28, now);
  const int form_lines = s.editing() ? kFormFields + 1 : 7;
  DrawIdentity(s, canvas, std::max(y + 6, h - 8 - 18 * form_lines), width, now);
  return preview_at;
}

// One scan of the session in `cell`: a failed one as a red tile marked FAILED, a restored one
// framed in its verdict's colour (white inside for the one shown), titled `title`.
void DrawTile(const ViewerState& s, const ViewerState::SheetEntry& e, const std::string& title,
              cv::Mat& canvas, cv::Rect cell) {
  if (e.failed) {  // Failed before it was restored: a red tile, the folio named.
    cv::putText(canvas, title, cell.tl() + cv::Point(4, 16), cv::FONT_HERSHEY_SIMPLEX, 0.5,
                cv::Scalar(230, 230, 230), 1, cv::LINE_AA);
    cv::putText(canvas, "FAILED", cell.tl() + cv::Point(6, cell.height / 2 + 6),
                cv::FONT_HERSHEY_SIMPLEX, cell.width < 120 ? 0.4 : 0.6, kRed, 2, cv::LINE_AA);
    cv::rectangle(canvas, cell, kRed, 3);
    return;
  }
  const ViewerState::Result& r = *e.result;
  const cv::Scalar colour =
      r.quality.empty() ? cv::Scalar(120, 120, 120) : VerdictColour(r.quality);
  Panel(canvas, cell, r.restored, title);
  cv::rectangle(canvas, cell, colour, 3);
  if (e.index == s.shown_index()) cv::rectangle(canvas, cell, cv::Scalar(255, 255, 255), 1);
}

// A tile's short title for the film strip: "4v", "4v #2" for a retake, "12" for a page.
std::string StripTitle(const ViewerState::SheetEntry& e) {
  const ScanIdentity& id = e.failed ? e.failed->identity : e.result->identity;
  const int attempt = e.failed ? e.failed->attempt : e.result->attempt;
  std::string title = id.folio.empty() ? (id.label.empty() ? "scan" : id.label) : id.folio;
  if (!id.side.empty()) title += id.side.substr(0, 1);
  if (attempt > 1) title += " #" + std::to_string(attempt);
  return title;
}

// The session's film strip along `strip`: its scans in book order, as many as fit, the one shown
// among them (else the last), each a small tile (DrawTile); where each went, into *cells.
void DrawFilmStrip(const ViewerState& s, cv::Mat& canvas, cv::Rect strip,
                   std::vector<cv::Rect>* cells) {
  const std::vector<ViewerState::SheetEntry> entries = s.SheetInBookOrder();
  const int n = static_cast<int>(entries.size());
  if (n == 0) return;
  const int cell_w = std::max(40, (strip.height - 4) * 4 / 3);
  const int fit = std::max(1, strip.width / (cell_w + 4));
  int shown = n - 1;
  for (int k = 0; k < n; ++k) {
    if (entries[k].result && entries[k].index == s.shown_index()) shown = k;
  }
  const int first = std::clamp(shown - fit / 2, 0, std::max(0, n - fit));
  for (int k = first; k < std::min(n, first + fit); ++k) {
    const cv::Rect cell(strip.x + (k - first) * (cell_w + 4), strip.y, cell_w, strip.height - 4);
    DrawTile(s, entries[k], StripTitle(entries[k]), canvas, cell);
    cells->push_back(cell);
  }
  if (first > 0 || first + fit < n) {
    cv::putText(canvas, std::to_string(n) + " scans: c for all", strip.br() + cv::Point(-150, -6),
                cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(200, 200, 200), 1, cv::LINE_AA);
  }
}

void DrawSheet(const ViewerState& s, cv::Mat& canvas, cv::Rect area) {
  const std::vector<ViewerState::SheetEntry> entries = s.SheetInBookOrder();
  cv::rectangle(canvas, area, cv::Scalar(30, 30, 30), cv::FILLED);
  cv::putText(canvas,
              "this session, in book order: " + std::to_string(s.results().size()) + " restored, " +
                  std::to_string(s.failed().size()) + " failed (c: back)",
              area.tl() + cv::Point(6, 18), cv::FONT_HERSHEY_SIMPLEX, 0.55,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  const int n = static_cast<int>(entries.size());
  if (n == 0) return;
  // Columns for about 4:3 cells.
  int cols = 1;
  while (cols * cols * 3 < n * 4) ++cols;
  const int rows = (n + cols - 1) / cols;
  const int cell_w = (area.width - 8) / cols, cell_h = std::min((area.height - 30) / rows, cell_w);
  for (int k = 0; k < n; ++k) {
    const ViewerState::SheetEntry& e = entries[k];
    const cv::Rect cell(area.x + 4 + (k % cols) * cell_w, area.y + 26 + (k / cols) * cell_h,
                        cell_w - 6, cell_h - 6);
    DrawTile(s, e, e.failed ? AttemptTitle(e.failed->identity, e.failed->attempt) : e.result->title,
             canvas, cell);
  }
}

// The header: the progress line (red with a failure, amber for a doubtful result) and the keys.
void DrawHeader(const ViewerState& s, cv::Mat& canvas, int top) {
  const int w = canvas.cols;
  const bool failed = !s.failure().empty();
  if (failed) cv::rectangle(canvas, cv::Rect(0, 0, w, top - 4), kRed, cv::FILLED);
  cv::putText(canvas, "vellum station", cv::Point(12, 28), cv::FONT_HERSHEY_SIMPLEX, 0.8,
              cv::Scalar(255, 255, 255), 2, cv::LINE_AA);
  const bool doubtful = s.progress().find("warning(s)") != std::string::npos;
  // The progress line, cut to end before the keys' help.
  const int help_x = w - 425;
  std::string progress = s.progress();
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
  cv::putText(canvas, "Enter: scan  e: identity  c: sheet  drag: leaf hint  q: quit",
              cv::Point(help_x, 28), cv::FONT_HERSHEY_SIMPLEX, 0.45,
              failed ? cv::Scalar(255, 255, 255) : cv::Scalar(160, 160, 160), 1, cv::LINE_AA);
}

// The restored page in `area`, its quality verdict above it in its colour, and under it a
// doubtful result's warnings in amber, a line each.
void DrawPage(const ViewerState& s, cv::Mat& canvas, cv::Rect area) {
  const ViewerState::Result* r = s.shown();
  static const ViewerState::Result kEmpty;
  const ViewerState::Result& show = r ? *r : kEmpty;
  const bool failed = !s.failure().empty();
  const int top = area.y;
  // The warnings in full, wrapped (8 lines at most, the rest counted).
  const size_t chars = static_cast<size_t>(std::max(20, (area.width - 8) / 8));
  std::vector<std::string> wrapped;
  for (const std::string& w : show.warnings) {
    for (const std::string& line : Wrap("! " + w, chars)) wrapped.push_back(line);
  }
  if (wrapped.size() > 8) {
    wrapped.resize(7);
    wrapped.push_back("(more in the report)");
  }
  const int lines = static_cast<int>(wrapped.size());
  const int warn_h = lines > 0 ? 18 * lines + 8 : 0;
  const int badge_h = show.quality.empty() ? 0 : 24;
  const cv::Rect page(area.x, top + badge_h, area.width, area.height - badge_h - warn_h);
  if (!show.quality.empty()) {
    const cv::Rect badge(page.x, top, page.width, badge_h - 4);
    cv::rectangle(canvas, badge, VerdictColour(show.quality), cv::FILLED);
    std::string verdict = show.quality;
    for (char& c : verdict) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    cv::putText(canvas, "quality: " + verdict, badge.tl() + cv::Point(6, 15),
                cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  }
  std::string caption = "restored page";
  if (r) {
    caption = r->title + " (" + std::to_string(s.shown_index() + 1) + " of " +
              std::to_string(s.results().size()) + ")" +
              (show.warnings.empty() ? "" : ": see the warnings");
    if (failed && r->scan_id != s.failed_scan()) caption = "an earlier scan: " + caption;
  } else if (const ViewerState::Asked* a = s.asked(s.scan())) {
    caption = (failed ? "failed: " : "scanning: ") + AttemptTitle(a->identity, a->attempt);
  }
  Panel(canvas, page, show.restored, caption);
  if (r) {  // Where its files are.
    std::string path = r->results;
    const size_t path_chars = static_cast<size_t>(std::max(20, page.width / 7));
    if (path.size() > path_chars) path = "..." + path.substr(path.size() - path_chars + 3);
    cv::putText(canvas, path, cv::Point(page.x + 4, page.y + page.height - 4),
                cv::FONT_HERSHEY_SIMPLEX, 0.38, cv::Scalar(170, 170, 170), 1, cv::LINE_AA);
  }
  for (int k = 0; k < lines; ++k) {
    cv::putText(canvas, wrapped[k], cv::Point(page.x + 4, page.y + page.height + 18 * (k + 1)),
                cv::FONT_HERSHEY_SIMPLEX, 0.42, kAmber, 1, cv::LINE_AA);
  }
}

// The operator's prompt to switch a light, in blue, in `area`'s width.
void DrawPrompt(const ViewerState& s, cv::Mat& canvas, cv::Rect area) {
  const std::vector<std::string> wrapped =
      Wrap(s.light_prompt(), static_cast<size_t>(std::max(30, (area.width - 32) / 11)));
  const int n = std::min<int>(static_cast<int>(wrapped.size()), 6);
  const cv::Rect box(area.x, area.y, area.width, 30 * n + 60);
  cv::rectangle(canvas, box, cv::Scalar(90, 40, 10), cv::FILLED);
  cv::rectangle(canvas, box, cv::Scalar(255, 160, 60), 3);
  cv::putText(canvas,
              s.prompt().index >= 0 ? "LIGHTS: switch by hand, then press L" : "LIGHTS (L: done)",
              box.tl() + cv::Point(12, 28), cv::FONT_HERSHEY_SIMPLEX, 0.7,
              cv::Scalar(255, 255, 255), 2, cv::LINE_AA);
  for (int k = 0; k < n; ++k) {
    cv::putText(canvas, wrapped[k], box.tl() + cv::Point(12, 58 + 30 * k), cv::FONT_HERSHEY_SIMPLEX,
                0.65, cv::Scalar(255, 230, 200), 1, cv::LINE_AA);
  }
}

// The failure's whole message, in red, in `area`'s width.
void DrawFailure(const ViewerState& s, cv::Mat& canvas, cv::Rect area) {
  const std::vector<std::string> wrapped =
      Wrap(s.failure(), static_cast<size_t>(std::max(30, (area.width - 32) / 9)));
  const int n = std::min<int>(static_cast<int>(wrapped.size()), 8);
  const cv::Rect box(area.x, area.y, area.width, 22 * n + 30 + 22 * 3);
  cv::rectangle(canvas, box, cv::Scalar(20, 20, 60), cv::FILLED);
  cv::rectangle(canvas, box, kRed, 2);
  cv::putText(canvas, s.FailedTitle() + " (scan " + std::to_string(s.failed_scan()) + ") failed:",
              box.tl() + cv::Point(10, 20), cv::FONT_HERSHEY_SIMPLEX, 0.55,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  for (int k = 0; k < n; ++k) {
    cv::putText(canvas, wrapped[k], box.tl() + cv::Point(10, 42 + 22 * k), cv::FONT_HERSHEY_SIMPLEX,
                0.5, cv::Scalar(200, 200, 255), 1, cv::LINE_AA);
  }
  const std::vector<std::string> next = Wrap(
      "next: " + s.FailureNextStep(), static_cast<size_t>(std::max(30, (area.width - 32) / 9)));
  for (size_t k = 0; k < std::min<size_t>(next.size(), 3); ++k) {
    cv::putText(canvas, next[k], box.tl() + cv::Point(10, 42 + 22 * (n + static_cast<int>(k))),
                cv::FONT_HERSHEY_SIMPLEX, 0.5, kAmber, 1, cv::LINE_AA);
  }
}

}  // namespace

cv::Mat DrawViewer(const ViewerState& s, cv::Size size, Clock::time_point now,
                   ViewerLayout* layout) {
  Scaler().NextDraw();
  cv::Mat canvas(size, CV_8UC3, cv::Scalar(30, 30, 30));
  const int w = size.width, h = size.height, top = 44;
  DrawHeader(s, canvas, top);
  // Left: live preview, histogram, the daemons, the next scan's identity.
  const int left_w = w / 3;
  layout->preview = DrawLeft(s, canvas, top, left_w, now);
  // Middle: texture, depth, strain; right: the restored page, large.
  const ViewerState::Result* r = s.shown();
  // Along the bottom of the middle and the right, once the session has a scan: the film strip.
  const bool strip = !s.results().empty() || !s.failed().empty();
  const int strip_h = strip ? kFilmStripHeight - 4 : 0;
  const int mid_x = left_w, mid_w = w / 3, third = (h - top - strip_h) / 3;
  static const ViewerState::Result kEmpty;
  const ViewerState::Result& show = r ? *r : kEmpty;
  Panel(canvas, cv::Rect(mid_x, top, mid_w - 8, third - 4), show.texture,
        "texture and the leaf's outline");
  Panel(canvas, cv::Rect(mid_x, top + third, mid_w - 8, third - 4), show.depth, "depth (mm)");
  Panel(canvas, cv::Rect(mid_x, top + 2 * third, mid_w - 8, third - 4), show.strain,
        "flattening strain");
  DrawPage(s, canvas, cv::Rect(mid_x + mid_w, top, w - mid_x - mid_w - 8, h - top - 8 - strip_h));
  layout->strip.clear();
  if (strip) {
    DrawFilmStrip(s, canvas, cv::Rect(mid_x, h - 4 - strip_h, w - mid_x - 8, strip_h),
                  &layout->strip);
  }
  // Over the middle and the right: the contact sheet, a light prompt, a failure.
  const cv::Rect over(mid_x, top, w - mid_x - 8, h - top - 8);
  if (s.sheet()) DrawSheet(s, canvas, over);
  if (!s.light_prompt().empty()) {
    DrawPrompt(s, canvas, cv::Rect(over.x, top + h / 4, over.width, over.height - h / 4));
  }
  if (!s.failure().empty()) DrawFailure(s, canvas, over);
  if (s.quitting()) {
    const cv::Rect box(w / 2 - 220, h / 2 - 40, 440, 80);
    cv::rectangle(canvas, box, cv::Scalar(60, 60, 60), cv::FILLED);
    cv::rectangle(canvas, box, cv::Scalar(255, 255, 255), 2);
    cv::putText(canvas, "Quit the viewer?", box.tl() + cv::Point(16, 32), cv::FONT_HERSHEY_SIMPLEX,
                0.8, cv::Scalar(255, 255, 255), 2, cv::LINE_AA);
    cv::putText(canvas, "y: quit    any other key: stay", box.tl() + cv::Point(16, 62),
                cv::FONT_HERSHEY_SIMPLEX, 0.55, cv::Scalar(220, 220, 220), 1, cv::LINE_AA);
  }
  return canvas;
}

}  // namespace vellum::station
