#include "tests/page_measure.h"

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace vellum {
std::vector<cv::Point2d> TrueCorners(cv::Size2d page_mm, const TextureOptions& tex) {
  const int nx = static_cast<int>((page_mm.width - 2 * tex.margin_mm) / tex.square_mm);
  const int ny = static_cast<int>((page_mm.height - 2 * tex.margin_mm) / tex.square_mm);
  const double x0 = 0.5 * (page_mm.width - nx * tex.square_mm);
  const double y0 = 0.5 * (page_mm.height - ny * tex.square_mm);
  std::vector<cv::Point2d> corners;
  for (int j = ny - 1; j >= 1; --j) {
    for (int i = 1; i < nx; ++i)
      corners.emplace_back(x0 + i * tex.square_mm, y0 + j * tex.square_mm);
  }
  return corners;
}

Rigid2D FlatToTrue(const GroundTruth& truth, const PageResult& page) {
  std::vector<cv::Point2d> from, to;
  const Mesh& mesh = page.mesh;
  for (size_t k = 0; k < mesh.kind.size(); ++k) {
    if (mesh.kind[k] != NodeKind::kMeasured) continue;
    const cv::Point px(cvRound(mesh.pixel[k].x), cvRound(mesh.pixel[k].y));
    if (!cv::Rect(0, 0, truth.page.cols, truth.page.rows).contains(px)) continue;
    if (!truth.on_page.empty() && !truth.on_page.at<uint8_t>(px)) continue;
    const cv::Vec2f st = truth.page.at<cv::Vec2f>(px);
    if (!std::isfinite(st[0])) continue;
    from.push_back(page.flat.flat[k]);
    to.emplace_back(st[0], st[1]);
  }
  return FitRigid2D(from, to);
}

std::vector<cv::Point2f> MeasureCorners(const PageResult& page, const Rigid2D& to_true,
                                        const std::vector<cv::Point2d>& truth,
                                        const cv::Mat& image) {
  const RestoreResult& r = page.restored;
  cv::Mat gray = image.empty() ? r.image : image;
  if (gray.channels() == 3) cv::cvtColor(gray, gray, cv::COLOR_BGR2GRAY);
  const Rigid2D back{-to_true.angle, {0, 0}};
  const cv::Point2d shift = back.Apply(-to_true.translation);
  std::vector<cv::Point2f> out;
  for (const cv::Point2d& t : truth) {
    const cv::Point2d flat = back.Apply(t) + shift;
    const cv::Point2d px = ApplyAffine(r.pixel_from_flat, flat);
    const cv::Rect window(cvRound(px.x) - 8, cvRound(px.y) - 8, 17, 17);
    if ((window & cv::Rect(0, 0, gray.cols, gray.rows)) != window ||
        cv::countNonZero(r.mask(window)) < window.area()) {
      out.emplace_back(NAN, NAN);
      continue;
    }
    std::vector<cv::Point2f> c{cv::Point2f(px)};
    cv::cornerSubPix(gray, c, cv::Size(5, 5), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-4));
    out.push_back(c[0]);
  }
  return out;
}

std::vector<cv::Point2f> LayoutControl(const std::vector<cv::Point2d>& truth, double dpi) {
  std::vector<cv::Point2f> control;
  const double px_per_mm = dpi / 25.4;
  for (const cv::Point2d& t : truth) control.emplace_back(t.x * px_per_mm, -t.y * px_per_mm);
  return control;
}

Measured ExperimentOne(const PageResult& page, const std::vector<cv::Point2f>& got,
                       const std::vector<cv::Point2f>& control,
                       const std::vector<cv::Point2d>& truth) {
  std::vector<cv::Point2f> a, b;
  std::vector<cv::Point2d> mm, t, t_mirrored;
  const cv::Matx23d& m = page.restored.pixel_from_flat;
  const cv::Matx22d lin(m(0, 0), m(0, 1), m(1, 0), m(1, 1));
  const cv::Matx22d inv = lin.inv();
  for (size_t k = 0; k < got.size(); ++k) {
    if (!std::isfinite(got[k].x) || !std::isfinite(control[k].x)) continue;
    a.push_back(got[k]);
    b.push_back(control[k]);
    const cv::Vec2d d = inv * cv::Vec2d(got[k].x - m(0, 2), got[k].y - m(1, 2));
    mm.emplace_back(d[0], d[1]);
    t.push_back(truth[k]);
    t_mirrored.emplace_back(truth[k].x, -truth[k].y);
  }
  Measured r;
  r.corners = static_cast<int>(a.size());
  if (a.size() < 8) return r;
  const cv::Mat h = cv::findHomography(a, b, 0);
  std::vector<cv::Point2f> mapped;
  cv::perspectiveTransform(a, mapped, h);
  for (size_t k = 0; k < a.size(); ++k) r.mean_px += cv::norm(mapped[k] - b[k]);
  r.mean_px /= a.size();
  r.mean_mm = r.mean_px / (page.restored.dpi / 25.4);
  const Rigid2D fit = FitRigid2D(mm, t), fit_m = FitRigid2D(mm, t_mirrored);
  for (size_t k = 0; k < mm.size(); ++k) {
    r.rms_mm += std::pow(cv::norm(fit.Apply(mm[k]) - t[k]), 2);
    r.rms_mirrored_mm += std::pow(cv::norm(fit_m.Apply(mm[k]) - t_mirrored[k]), 2);
  }
  r.rms_mm = std::sqrt(r.rms_mm / mm.size());
  r.rms_mirrored_mm = std::sqrt(r.rms_mirrored_mm / mm.size());
  return r;
}

int MaskOffLeaf(const PageResult& result, const Rigid2D& to_true, const Page& page,
                double tolerance_mm, int* leaf, cv::Mat* off) {
  int outside = 0, looked = 0;
  if (off) *off = cv::Mat::zeros(result.restored.mask.size(), CV_8U);
  const double step = tolerance_mm / 3;
  ForLeafPixels(result, to_true, [&](int u, int v, const cv::Point2d& st) {
    ++looked;
    bool near = page.Contains(st.x, st.y);
    for (double ds = -tolerance_mm; ds <= tolerance_mm + 1e-9 && !near; ds += step) {
      for (double dt = -tolerance_mm; dt <= tolerance_mm + 1e-9 && !near; dt += step) {
        near = ds * ds + dt * dt <= tolerance_mm * tolerance_mm + 1e-9 &&
               page.Contains(st.x + ds, st.y + dt);
      }
    }
    if (!near) {
      ++outside;
      if (off) off->at<uint8_t>(v, u) = 255;
    }
  });
  if (leaf) *leaf = looked;
  return outside;
}

GutterTruth TrueGutter(const VirtualGantry& gantry) {
  const GroundTruth& truth = gantry.truth();
  const cv::Size2d size = gantry.pages().at(0).options().size_mm;
  GutterTruth t;
  for (auto& bins : t.innermost) bins.assign(static_cast<size_t>(size.height) + 1, std::nan(""));
  const cv::Rect box = cv::boundingRect(truth.page_index);
  std::vector<double> chords;
  for (int v = 0; v < truth.page_index.rows; ++v) {
    int last_left = -1, first_right = -1;
    for (int u = 0; u < truth.page_index.cols; ++u) {
      const int page = truth.page_index.at<uint8_t>(v, u);
      if (!truth.lit.at<uint8_t>(v, u) || page == 0) continue;
      if (page == 1) last_left = u;
      if (page == 2 && first_right < 0) first_right = u;
      const cv::Vec2f st = truth.page.at<cv::Vec2f>(v, u);
      double& bin = t.innermost[page - 1].at(
          std::clamp(static_cast<int>(st[1]), 0, static_cast<int>(size.height)));
      bin = std::isnan(bin) ? st[0]
            : page == 1     ? std::max<double>(bin, st[0])
                            : std::min<double>(bin, st[0]);
    }
    if (v < box.y + box.height / 10 || v >= box.y + box.height * 9 / 10) continue;
    if (last_left < 0 || first_right < 0) continue;
    chords.push_back(cv::norm(truth.points.at<cv::Vec3f>(v, first_right) -
                              truth.points.at<cv::Vec3f>(v, last_left)));
  }
  std::vector<double> hidden;
  const int rows = static_cast<int>(size.height);
  for (int k = rows / 10; k < rows * 9 / 10; ++k) {
    const double left = t.innermost[0][k], right = t.innermost[1][k];
    if (!std::isnan(left) && !std::isnan(right)) hidden.push_back(size.width - left + right);
  }
  if (!hidden.empty()) {
    std::nth_element(hidden.begin(), hidden.begin() + hidden.size() / 2, hidden.end());
    t.hidden_mm = hidden[hidden.size() / 2];
  }
  if (chords.empty()) return t;
  std::nth_element(chords.begin(), chords.begin() + chords.size() / 2, chords.end());
  t.chord_mm = chords.at(chords.size() / 2);
  return t;
}

}  // namespace vellum
