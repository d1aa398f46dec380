#include "pipeline/report.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <sstream>

#include "core/common/text.h"
#include "core/patterns/scan.h"
#include "io/json.h"
#include "pipeline/qc.h"

namespace vellum {
namespace fs = std::filesystem;
namespace {

std::string Number(double v, int precision = 3) {
  std::ostringstream o;
  o.precision(precision);
  o << v;
  return o.str();
}

// The pictures a report can show (written by the stages to report/; a page of a spread has its
// own, named <stem>-<page>.png), in the order shown.
struct Picture {
  const char* stem;
  const char* caption;
};
constexpr Picture kPictures[] = {
    {"report/texture", "Texture: the page under studio light, as the camera saw it."},
    {"report/outline",
     "The leaf found: its outline (and holes) over the texture; on a spread, each page in its "
     "own colour."},
    {"report/valid",
     "Valid pixels: white where a 3D point was measured (black: ink, shadow, table beyond the "
     "projector, rejected)."},
    {"report/depth", "Height above the table, mm (colour bar on the right)."},
    {"report/grid", "The restored page with the flattened sheet's grid (every 4th line)."},
    {"report/strain",
     "Residual strain of each quad after flattening (mean relative spring-length error); high "
     "values mark stretch or creases the flat page cannot keep."},
    {"report/sampling",
     "The camera's true sampling of the restored page (from the warp's Jacobian): what detail "
     "the page can hold, whatever dpi it is written at."},
    {"report/before_after",
     "The centre of the page before (left, camera) and after (right, restored)."},
    {"report/relief",
     "The flat page's relief from its photometric normals (three or more raking lights), lit "
     "from the top left: ruling, prickings and embossed lines show; black where no normal was "
     "found (too dark under the lights, the rim)."},
};

// report.json's sections in their order; a section no stage fills is left out.
constexpr const char* kSections[] = {
    "options",    "sizes",     "stages_seconds", "stages_peak_memory_mb",
    "pixels",     "height_mm", "outline",        "sheet",
    "flattening", "restored",  "sampling"};

// A FADGI level as the report says it: "3-star", or "below 1-star".
std::string StarLevel(int stars) {
  return stars > 0 ? std::to_string(stars) + "-star" : "below 1-star";
}

std::string PictureFile(const Picture& p, const std::string& page) {
  return std::string(p.stem) + (page.empty() ? "" : "-" + page) + ".png";
}

std::string StageKey(const StageReport& stage) {
  return stage.page.empty() ? stage.stage : stage.stage + " " + stage.page;
}

Json ToJson(const ReportValue& v) { return v.is_text ? Json(v.text) : JsonNumber(v.number); }

// The page's head and style, and its title.
void HtmlHead(const std::string& title, std::ostringstream* out) {
  std::ostringstream& h = *out;
  h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>vellum: "
    << HtmlEscape(title) << "</title>\n<style>\n"
    << "body{font-family:sans-serif;margin:2em;max-width:1500px;color:#222}\n"
    << "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:4px "
       "10px;text-align:left}\nfigure{margin:1.5em 0}img{max-width:100%;border:1px solid "
       "#ccc}\nfigcaption{color:#555;margin-top:4px}.identity{font-size:1.1em}\n"
       "figure.restored img{height:min(85vh,1200px);width:auto;max-width:100%;"
       "object-fit:contain;object-position:left top}\n"
       ".warn{color:#a40}.fail{color:#a11}\n"
       ".warnings{border:2px solid #a40;padding:0.5em 1em;background:#fff6f0}\n"
       ".qc{border:3px solid;padding:0.2em 1em;margin:1em 0}.qc h2{margin:0.3em 0}\n"
       ".qc-pass{border-color:#2a2;color:#161}.qc-warn{border-color:#d90;color:#850}"
       ".qc-fail{border-color:#c22;color:#a11}tr.qc-pass td,tr.qc-warn td,tr.qc-fail td"
       "{color:inherit}\n"
       "</style></head><body>\n";
  h << "<h1>vellum: " << HtmlEscape(title) << "</h1>\n";
}

// What was scanned (the scan's identity) and when this report was made; then quality
// control: the verdict in its colour, and each check.
void HtmlIdentityAndQuality(const ProcessReport& r, std::ostringstream* out) {
  std::ostringstream& h = *out;
  // What was scanned (the scan's identity) and when this report was made.
  std::string identity;
  for (const char* key : {"shelfmark", "folio", "side", "label", "operator", "note"}) {
    const std::string value = r.Text("identity", key);
    if (value.empty()) continue;
    identity += (identity.empty() ? "" : " &middot; ") + std::string("<b>") + key + "</b> " +
                HtmlEscape(value);
  }
  const std::time_t now = std::time(nullptr);
  char made[64];
  std::strftime(made, sizeof(made), "%Y-%m-%d %H:%M:%S UTC", std::gmtime(&now));
  h << "<p class=identity>" << (identity.empty() ? "No catalogue identity given." : identity)
    << "<br>Report made " << made << ".</p>\n";
  // Quality control first: the verdict in its colour, and each check.
  const QcResult qc = AssessQuality(r);
  h << "<div class=\"qc qc-" << VerdictName(qc.verdict)
    << "\"><h2>Quality: " << VerdictName(qc.verdict) << "</h2>\n";
  if (r.target.any()) {
    h << "<p>Judged against the collection's target: " << HtmlEscape(r.target.Describe())
      << ".</p>\n";
  }
  h << "<table>\n";
  for (const QcCheck& c : qc.checks) {
    h << "<tr class=\"qc-" << VerdictName(c.verdict) << "\"><th>" << HtmlEscape(c.name)
      << "</th><td>" << VerdictName(c.verdict) << "</td><td>" << HtmlEscape(c.detail)
      << "</td></tr>\n";
  }
  h << "</table></div>\n";
}

// The restored page(s), whole, each linking to its full-resolution TIFF.
void HtmlRestoredPages(const ProcessReport& r, std::ostringstream* out) {
  std::ostringstream& h = *out;
  // The restored page(s), whole, each linking to its full-resolution TIFF.
  const std::vector<std::string> written = r.Outputs();
  for (const std::string& page : r.Pages()) {
    const std::string picture = "report/restored" + (page.empty() ? "" : "-" + page) + ".png";
    if (std::find(written.begin(), written.end(), picture) == written.end()) continue;
    const std::string tif = page.empty() ? "restored.tif" : "pages/" + page + "/restored.tif";
    const double bar = r.Number("restored", "scale_bar_mm", page);
    std::ostringstream caption;
    caption << (page.empty() ? "The restored page" : "The " + page + " page, restored");
    if (r.Find("restored", "leaf_width_mm", page)) {
      caption << ": the leaf " << Number(r.Number("restored", "leaf_width_mm", page), 4) << " x "
              << Number(r.Number("restored", "leaf_height_mm", page), 4) << " mm";
    }
    if (bar > 0) {
      caption << ", " << Number(r.Number("restored", "dpi", page), 4) << " ppi; the scale bar is "
              << Number(bar) << " mm";
    } else {
      caption << " (camera view: no true scale)";
    }
    h << "<figure class=restored><a href=\"" << tif << "\"><img src=\"" << picture << "\" alt=\""
      << HtmlEscape(caption.str()) << "\"></a><figcaption>" << HtmlEscape(caption.str())
      << ". Full resolution: <a href=\"" << tif << "\">" << tif << "</a></figcaption></figure>\n";
  }
}

// The warnings, then the FADGI figures vellum can vouch for.
void HtmlWarningsAndFadgi(const ProcessReport& r, std::ostringstream* out) {
  std::ostringstream& h = *out;
  const std::vector<Warning> warnings = r.Warnings();
  if (!warnings.empty()) {
    // Headed with the verdict, in the same words as the viewer's badge and `vellum scan`.
    const QcVerdict verdict = AssessQuality(r).verdict;
    std::string word = VerdictName(verdict);
    for (char& c : word) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    h << "<div class=warnings><h2 class=\"" << VerdictName(verdict) << "\">" << word
      << ": what makes this scan doubtful, and what to do</h2>\n<ul>\n";
    for (const Warning& w : warnings) {
      h << "<li><b>" << HtmlEscape(w.code) << "</b>: " << HtmlEscape(w.message) << "</li>\n";
    }
    h << "</ul></div>\n";
  }
  // The FADGI figures vellum can vouch for.
  const std::vector<FadgiPage> fadgi = AssessFadgi(r);
  if (!fadgi.empty()) {
    h << "<h2>FADGI figures</h2>\n<table>\n";
    for (const FadgiPage& page : fadgi) {
      const std::string of = page.page.empty() ? "" : " (" + page.page + ")";
      for (const FadgiFigure& f : page.figures) {
        h << "<tr><th>" << HtmlEscape(f.name + of) << "</th><td>" << HtmlEscape(f.value)
          << "</td><td>" << StarLevel(f.stars) << "</td><td>" << HtmlEscape(f.basis)
          << "</td></tr>\n";
      }
      h << "<tr><th>level" << HtmlEscape(of) << "</th><td colspan=3><b>" << StarLevel(page.stars)
        << "</b> in what vellum measures (tone, colour and noise need a target and are not "
           "judged here)</td></tr>\n";
    }
    h << "</table>\n";
  }
}

// The key figures: pixels, the leaf, each page's strain, sheet, size; heights and sizes.
void HtmlKeyFigures(const ProcessReport& r, std::ostringstream* out) {
  std::ostringstream& h = *out;
  const double pixels = r.Number("pixels", "camera"), valid = r.Number("pixels", "valid");
  h << "<h2>Key figures</h2>\n<table>\n";
  h << "<tr><th>Valid pixels</th><td>" << valid << " of " << pixels << " ("
    << Number(pixels > 0 ? 100.0 * valid / pixels : 0) << "%); leaf "
    << r.Number("outline", "leaf_pixels") << "</td></tr>\n";
  if (r.Find("outline", "method")) {
    h << "<tr><th>Leaf found by</th><td>" << HtmlEscape(r.Text("outline", "method")) << ", rim "
      << Number(100 * r.Number("outline", "confidence")) << "% set apart, "
      << r.Number("outline", "holes") << " holes, " << r.Number("outline", "pages")
      << " page(s)</td></tr>\n";
  }
  for (const std::string& page : r.Pages()) {
    const std::string of = page.empty() ? "" : " (" + page + ")";
    const double folded = r.Number("flattening", "folded_quads", page);
    h << "<tr><th>Residual strain" << of << "</th><td>mean "
      << Number(r.Number("flattening", "mean_strain", page)) << ", max "
      << Number(r.Number("flattening", "max_strain", page))
      << (folded > 0 ? ", <span class=warn>" : ", ") << folded << " folded quads"
      << (folded > 0 ? "</span>" : "") << "</td></tr>\n";
    h << "<tr><th>Sheet" << of << "</th><td>" << HtmlEscape(r.Text("sheet", "grid", page)) << ", "
      << HtmlEscape(r.Text("flattening", "solver", page)) << ", "
      << r.Number("flattening", "iterations", page) << " iterations</td></tr>\n";
    if (r.Find("restored", "width", page)) {
      h << "<tr><th>Restored" << of << "</th><td>" << r.Number("restored", "width", page) << " x "
        << r.Number("restored", "height", page) << " px, "
        << (r.Text("options", "view") == "orthographic"
                ? Number(r.Number("restored", "dpi", page), 4) + " dpi (orthographic), turned " +
                      Number(r.Number("restored", "rotation_deg", page)) + " degrees"
                : std::string("camera view"))
        << "</td></tr>\n";
    }
    if (r.Find("restored", "leaf_width_mm", page)) {
      h << "<tr><th>Leaf size" << of << "</th><td>"
        << Number(r.Number("restored", "leaf_width_mm", page), 4) << " x "
        << Number(r.Number("restored", "leaf_height_mm", page), 4) << " mm</td></tr>\n";
    }
  }
  h << "<tr><th>Height</th><td>" << Number(r.Number("height_mm", "min")) << " .. "
    << Number(r.Number("height_mm", "max")) << " mm</td></tr>\n";
  h << "<tr><th>Sizes</th><td>camera " << HtmlEscape(r.Text("sizes", "camera")) << ", projector "
    << HtmlEscape(r.Text("sizes", "projector")) << ", " << r.Number("sizes", "patterns")
    << " patterns</td></tr>\n";
}

// Each stage's time and peak memory, then the pictures the stages wrote, the scan's own first.
void HtmlTimingsAndPictures(const ProcessReport& r, std::ostringstream* out) {
  std::ostringstream& h = *out;
  h << "</table>\n<h2>Stage timings and memory</h2>\n<table>\n";
  double total = 0;
  for (const StageReport& stage : r.stages) {
    h << "<tr><th>" << HtmlEscape(StageKey(stage)) << "</th><td>" << Number(stage.seconds)
      << " s</td><td>"
      << (stage.peak_memory_mb > 0
              ? "peak memory " + Number(std::round(stage.peak_memory_mb)) + " MB"
              : std::string())
      << "</td></tr>\n";
    total += stage.seconds;
  }
  h << "<tr><th>total</th><td>" << Number(total) << " s</td></tr>\n</table>\n";
  h << "<h2>Pictures</h2>\n";
  const std::vector<std::string> outputs = r.Outputs();
  std::vector<std::string> pages = r.Pages();
  if (pages.size() > 1) pages.insert(pages.begin(), "");  // The scan's own pictures first.
  for (const std::string& page : pages) {
    for (const Picture& p : kPictures) {
      const std::string file = PictureFile(p, page);
      if (std::find(outputs.begin(), outputs.end(), file) == outputs.end()) continue;
      const std::string caption = (page.empty() ? "" : "The " + page + " page. ") + p.caption;
      h << "<figure><img src=\"" << file << "\" alt=\"" << HtmlEscape(caption) << "\"><figcaption>"
        << HtmlEscape(caption) << "</figcaption></figure>\n";
    }
  }
}

// Where the scan and calibration came from and the options, and the page's end.
void HtmlConfiguration(const ProcessReport& r, std::ostringstream* out) {
  std::ostringstream& h = *out;
  h << "<h2>Configuration</h2>\n<table>\n";
  h << "<tr><th>scan</th><td>" << HtmlEscape(r.scan) << "</td></tr>\n";
  h << "<tr><th>calibration</th><td>" << HtmlEscape(r.calibration) << "</td></tr>\n";
  for (const StageReport& stage : r.stages) {
    if (!stage.page.empty()) continue;
    for (const ReportValue& v : stage.values) {
      if (v.section != "options") continue;
      h << "<tr><th>" << HtmlEscape(v.key) << "</th><td>"
        << (v.is_text ? HtmlEscape(v.text) : Number(v.number, 6)) << "</td></tr>\n";
    }
  }
  h << "</table>\n";
  // For tests and the curious: how many pictures loaded (body data-images="loaded/total").
  h << "<script>window.addEventListener('load',function(){var im=document.images,n=0;"
       "for(var i=0;i<im.length;i++)if(im[i].complete&&im[i].naturalWidth>0)n++;"
       "document.body.setAttribute('data-images',n+'/'+im.length);});</script>\n";
  h << "</body></html>\n";
}

Status WriteHtml(const std::string& dir, const std::string& title, const ProcessReport& r) {
  std::ostringstream h;
  // Headed with the folio it shows ("MS 12, 4 verso"), as the viewer and the contact sheet name
  // it, then what the caller calls it (the scan's folder).
  ScanIdentity identity;
  ForEachIdentityField(
      identity, [&](const char* key, std::string& value) { value = r.Text("identity", key); });
  const std::string named = IdentityTitle(identity);
  HtmlHead(named.empty() ? title : named + " (" + title + ")", &h);
  HtmlIdentityAndQuality(r, &h);
  HtmlRestoredPages(r, &h);
  HtmlWarningsAndFadgi(r, &h);
  HtmlKeyFigures(r, &h);
  HtmlTimingsAndPictures(r, &h);
  HtmlConfiguration(r, &h);
  return WriteTextFile((fs::path(dir) / "report.html").string(), h.str());
}

// The sections of the stages of one page ("" the scan's own), in report.json's order.
Json Sections(const ProcessReport& r, const std::string& page) {
  Json j = Json::object();
  auto section_of = [&](const ReportValue& v) {
    return std::find_if(std::begin(kSections), std::end(kSections),
                        [&](const char* k) { return v.section == k; }) != std::end(kSections);
  };
  for (const char* section : kSections) {
    Json s = Json::object();
    if (std::string(section) == "stages_seconds" && page.empty()) {
      double total = 0;
      for (const StageReport& stage : r.stages) {
        s[StageKey(stage)] = JsonNumber(stage.seconds);
        total += stage.seconds;
      }
      s["total"] = JsonNumber(total);
    }
    if (std::string(section) == "stages_peak_memory_mb" && page.empty()) {
      // The process's peak resident memory as each stage ended (it only grows); a stage run in
      // another process (a daemon's, reported over the bus) has none.
      for (const StageReport& stage : r.stages) {
        if (stage.peak_memory_mb > 0)
          s[StageKey(stage)] = JsonNumber(std::round(stage.peak_memory_mb));
      }
    }
    for (const StageReport& stage : r.stages) {
      if (stage.page != page) continue;
      for (const ReportValue& v : stage.values) {
        if (v.section == section) s[v.key] = ToJson(v);
      }
    }
    if (!s.empty()) j[section] = s;
  }
  // Sections outside the usual ones, in the order the stages set them.
  for (const StageReport& stage : r.stages) {
    if (stage.page != page) continue;
    for (const ReportValue& v : stage.values) {
      if (!section_of(v)) j[v.section][v.key] = ToJson(v);
    }
  }
  return j;
}

Status WriteJson(const std::string& dir, const ProcessReport& r) {
  Json j;
  j["scan"] = r.scan;
  j["calibration"] = r.calibration;
  const Json scan_sections = Sections(r, "");
  for (const auto& [key, value] : scan_sections.items()) j[key] = value;
  const std::vector<std::string> pages = r.Pages();
  if (pages.size() > 1 || !pages.front().empty()) {
    Json list = Json::array();
    for (const std::string& page : pages) {
      Json entry;
      entry["page"] = page;
      const Json page_sections = Sections(r, page);
      for (const auto& [key, value] : page_sections.items()) entry[key] = value;
      list.push_back(entry);
    }
    j["pages"] = list;
  }
  Json warnings = Json::array();
  for (const Warning& w : r.Warnings())
    warnings.push_back({{"code", w.code}, {"message", w.message}});
  j["warnings"] = warnings;
  const QcResult qc = AssessQuality(r);
  Json checks = Json::array();
  for (const QcCheck& c : qc.checks) {
    checks.push_back({{"name", c.name}, {"verdict", VerdictName(c.verdict)}, {"detail", c.detail}});
  }
  j["qc"] = {{"verdict", VerdictName(qc.verdict)}, {"checks", checks}};
  if (r.target.any()) j["qc"]["target"] = r.target.Describe();
  Json fadgi = Json::array();
  for (const FadgiPage& page : AssessFadgi(r)) {
    Json figures = Json::array();
    for (const FadgiFigure& f : page.figures) {
      figures.push_back(
          {{"name", f.name}, {"value", f.value}, {"stars", f.stars}, {"basis", f.basis}});
    }
    fadgi.push_back({{"page", page.page}, {"stars", page.stars}, {"figures", figures}});
  }
  j["fadgi"] = fadgi;
  j["outputs"] = r.Outputs();
  return WriteJsonFile((fs::path(dir) / "report.json").string(), j);
}

}  // namespace

std::string LeafHintText(const cv::Rect& hint) {
  return std::to_string(hint.x) + "," + std::to_string(hint.y) + "," + std::to_string(hint.width) +
         "," + std::to_string(hint.height);
}

bool ParseLeafHint(const std::string& text, cv::Rect* hint) {
  int x = 0, y = 0, w = 0, h = 0;
  char end = 0;
  if (std::sscanf(text.c_str(), "%d,%d,%d,%d%c", &x, &y, &w, &h, &end) != 4 || x < 0 || y < 0 ||
      w <= 0 || h <= 0) {
    return false;
  }
  *hint = cv::Rect(x, y, w, h);
  return true;
}

void StageReport::Text(const std::string& section, const std::string& key,
                       const std::string& value) {
  ReportValue v;
  v.section = section;
  v.key = key;
  v.is_text = true;
  v.text = value;
  values.push_back(std::move(v));
}

void StageReport::Number(const std::string& section, const std::string& key, double value) {
  ReportValue v;
  v.section = section;
  v.key = key;
  v.number = value;
  values.push_back(std::move(v));
}

void StageReport::Warn(const std::string& code, const std::string& message) {
  warnings.push_back({code, message});
}

std::string QcTarget::Describe() const {
  std::string out;
  auto add = [&](const std::string& part) { out += (out.empty() ? "" : ", ") + part; };
  if (fadgi_stars > 0) add("FADGI " + std::to_string(fadgi_stars) + "-star");
  if (ppi > 0) add(std::to_string(static_cast<int>(std::lround(ppi))) + " ppi");
  if (bits > 0) add(std::to_string(bits) + " bits");
  return out;
}

bool QcTarget::Check(std::string* why) const {
  if (fadgi_stars < 0 || fadgi_stars > 4) {
    *why = "target: fadgi_stars must be 0 (none) to 4, got " + std::to_string(fadgi_stars);
    return false;
  }
  if (!(ppi >= 0 && ppi <= 10000)) {
    *why = "target: ppi must be 0 (none) to 10000";
    return false;
  }
  if (bits != 0 && bits != 8 && bits != 16) {
    *why = "target: bits must be 0 (none), 8 or 16, got " + std::to_string(bits);
    return false;
  }
  return true;
}

const ReportValue* ProcessReport::Find(const std::string& section, const std::string& key,
                                       const std::string& page) const {
  return FindValue(stages, section, key, page);
}

const ReportValue* FindValue(const std::vector<StageReport>& stages, const std::string& section,
                             const std::string& key, const std::string& page) {
  const ReportValue* found = nullptr;
  for (const StageReport& stage : stages) {
    if (stage.page != page) continue;
    for (const ReportValue& v : stage.values) {
      if (v.section == section && v.key == key) found = &v;
    }
  }
  return found;
}

double ProcessReport::Number(const std::string& section, const std::string& key,
                             const std::string& page) const {
  const ReportValue* v = Find(section, key, page);
  return v && !v->is_text ? v->number : 0.0;
}

std::string ProcessReport::Text(const std::string& section, const std::string& key,
                                const std::string& page) const {
  const ReportValue* v = Find(section, key, page);
  return v && v->is_text ? v->text : std::string();
}

std::vector<std::string> ProcessReport::Pages() const {
  std::vector<std::string> pages;
  for (const StageReport& stage : stages) {
    if (!stage.page.empty() && std::find(pages.begin(), pages.end(), stage.page) == pages.end()) {
      pages.push_back(stage.page);
    }
  }
  if (pages.empty()) pages.push_back("");
  return pages;
}

std::vector<Warning> ProcessReport::Warnings() const {
  std::vector<Warning> all;
  for (const StageReport& stage : stages) {
    for (const Warning& w : stage.warnings) {
      all.push_back(
          {w.code, stage.page.empty() ? w.message : "the " + stage.page + " page: " + w.message});
    }
  }
  return all;
}

std::vector<std::string> ProcessReport::Outputs() const {
  std::vector<std::string> all;
  for (const StageReport& stage : stages) {
    all.insert(all.end(), stage.outputs.begin(), stage.outputs.end());
  }
  all.insert(all.end(), outputs.begin(), outputs.end());
  return all;
}

Status WriteReports(const std::string& dir, const std::string& title, ProcessReport* report) {
  Status s = WriteHtml(dir, title, *report);
  if (!s.ok()) return s;
  report->outputs.push_back("report.html");
  report->outputs.push_back("report.json");
  s = WriteJson(dir, *report);
  if (!s.ok()) report->outputs.pop_back();
  return s;
}

}  // namespace vellum
