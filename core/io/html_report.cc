#include "core/io/html_report.h"

#include <filesystem>
#include <fstream>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "core/io/scan_io.h"
#include "core/report/pictures.h"

namespace vellum {
namespace fs = std::filesystem;
namespace {

std::string Escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '<')
      out += "&lt;";
    else if (c == '>')
      out += "&gt;";
    else if (c == '&')
      out += "&amp;";
    else if (c == '"')
      out += "&quot;";
    else
      out += c;
  }
  return out;
}

std::string Number(double v, int precision = 3) {
  std::ostringstream o;
  o.precision(precision);
  o << v;
  return o.str();
}

// At most 1400 pixels across, 8-bit: a report that opens quickly.
cv::Mat ForPage(const cv::Mat& image) {
  cv::Mat out = image;
  if (out.depth() != CV_8U) out.convertTo(out, CV_8U, 1.0 / 257);
  if (out.cols > 1400) {
    const double s = 1400.0 / out.cols;
    cv::resize(out, out, cv::Size(), s, s, cv::INTER_AREA);
  }
  return out;
}

}  // namespace

Status WriteHtmlReport(const std::string& dir, const HtmlReportInput& in) {
  const std::string pictures = (fs::path(dir) / "report").string();
  Status s = MakeDirectories(pictures);
  if (!s.ok()) return s;
  struct Figure {
    std::string file, caption;
  };
  std::vector<Figure> figures;
  auto add = [&](const std::string& name, const cv::Mat& image, const std::string& caption) {
    if (image.empty()) return Status::Ok();
    figures.push_back({"report/" + name, caption});
    return WriteImage((fs::path(pictures) / name).string(), ForPage(image));
  };
  s = add("texture.png", in.texture, "Texture: the page under studio light, as the camera saw it.");
  double zmin = 0, zmax = 0;
  if (s.ok() && !in.points.empty()) {
    s = add("valid.png", ValidMask(in.points),
            "Valid pixels: white where a 3D point was measured (black: ink, shadow, table "
            "beyond the projector, rejected).");
    if (s.ok()) {
      s = add("depth.png", DepthWithColourBar(in.points, &zmin, &zmax),
              "Height above the table, mm (colour bar on the right).");
    }
  }
  const bool sheet = in.mesh && in.flat && in.restored && in.restored->status.ok();
  if (s.ok() && sheet) {
    s = add("grid.png", GridOverPage(*in.mesh, *in.flat, *in.restored, in.camera),
            "The restored page with the flattened sheet's grid (every 4th line).");
  }
  if (s.ok() && sheet) {
    s = add("strain.png", StrainPicture(*in.mesh, *in.flat, *in.restored, in.camera),
            "Residual strain of each quad after flattening (mean relative spring-length "
            "error); high values mark stretch or creases the flat page cannot keep.");
  }
  if (s.ok() && sheet) {
    s = add("before_after.png",
            BeforeAfter(in.texture, *in.mesh, *in.flat, *in.restored, in.camera),
            "The centre of the page before (left, camera) and after (right, restored).");
  }
  if (!s.ok()) return s;

  std::ostringstream h;
  h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>vellum: "
    << Escape(in.title) << "</title>\n<style>\n"
    << "body{font-family:sans-serif;margin:2em;max-width:1500px;color:#222}\n"
    << "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:4px "
       "10px;text-align:left}\nfigure{margin:1.5em 0}img{max-width:100%;border:1px solid "
       "#ccc}\nfigcaption{color:#555;margin-top:4px}.warn{color:#a40}\n</style></head><body>\n";
  h << "<h1>vellum: " << Escape(in.title) << "</h1>\n";
  if (in.figures) {
    const ProcessReport& r = *in.figures;
    const double pct = r.pixels > 0 ? 100.0 * r.valid / r.pixels : 0;
    h << "<h2>Key figures</h2>\n<table>\n";
    h << "<tr><th>Valid pixels</th><td>" << r.valid << " of " << r.pixels << " (" << Number(pct)
      << "%); page " << r.page << "</td></tr>\n";
    h << "<tr><th>Residual strain</th><td>mean " << Number(r.mean_strain) << ", max "
      << Number(r.max_strain) << (r.folded_quads ? ", <span class=warn>" : ", ") << r.folded_quads
      << " folded quads" << (r.folded_quads ? "</span>" : "") << "</td></tr>\n";
    h << "<tr><th>Solver</th><td>" << Escape(r.solver) << ", " << r.iterations
      << " iterations</td></tr>\n";
    if (in.restored) {
      h << "<tr><th>Restored</th><td>" << in.restored->image.cols << " x "
        << in.restored->image.rows << " px, "
        << (in.restored->view == RestoreView::kOrthographic
                ? Number(in.restored->dpi, 4) + " dpi (orthographic)"
                : std::string("camera view"))
        << "</td></tr>\n";
    }
    h << "<tr><th>Height</th><td>" << Number(r.z_min_mm) << " .. " << Number(r.z_max_mm)
      << " mm</td></tr>\n";
    h << "<tr><th>Sizes</th><td>camera " << SizeText(r.camera) << ", projector "
      << SizeText(r.projector) << ", " << r.patterns << " patterns</td></tr>\n";
    h << "</table>\n<h2>Stage timings</h2>\n<table>\n";
    double total = 0;
    for (const auto& [name, seconds] : r.stages_seconds) {
      h << "<tr><th>" << Escape(name) << "</th><td>" << Number(seconds) << " s</td></tr>\n";
      total += seconds;
    }
    h << "<tr><th>total</th><td>" << Number(total) << " s</td></tr>\n</table>\n";
  }
  h << "<h2>Pictures</h2>\n";
  for (const Figure& f : figures) {
    h << "<figure><img src=\"" << f.file << "\" alt=\"" << Escape(f.caption) << "\"><figcaption>"
      << Escape(f.caption) << "</figcaption></figure>\n";
  }
  if (in.figures) {
    h << "<h2>Configuration</h2>\n<table>\n";
    h << "<tr><th>scan</th><td>" << Escape(in.figures->scan) << "</td></tr>\n";
    h << "<tr><th>calibration</th><td>" << Escape(in.figures->calibration) << "</td></tr>\n";
    for (const auto& [key, value] : in.figures->text_options) {
      h << "<tr><th>" << Escape(key) << "</th><td>" << Escape(value) << "</td></tr>\n";
    }
    for (const auto& [key, value] : in.figures->number_options) {
      h << "<tr><th>" << Escape(key) << "</th><td>" << Number(value, 6) << "</td></tr>\n";
    }
    h << "</table>\n";
  }
  // For tests and the curious: how many pictures loaded (body data-images="loaded/total").
  h << "<script>window.addEventListener('load',function(){var im=document.images,n=0;"
       "for(var i=0;i<im.length;i++)if(im[i].complete&&im[i].naturalWidth>0)n++;"
       "document.body.setAttribute('data-images',n+'/'+im.length);});</script>\n";
  h << "</body></html>\n";
  const std::string path = (fs::path(dir) / "report.html").string();
  std::ofstream out(path);
  out << h.str();
  out.close();
  if (!out) return Status::Error(path + ": cannot write");
  return Status::Ok();
}

}  // namespace vellum
