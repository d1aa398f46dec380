#include "core/sim/evaluate.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "core/decode/decode.h"
#include "core/geometry/rigid2d.h"
#include "core/geometry/triangulate.h"

namespace vellum {

PointErrorStats ComparePoints(const GroundTruth& truth, const cv::Mat& points) {
  PointErrorStats st;
  std::vector<double> errors;
  double sum2 = 0;
  for (int v = 0; v < points.rows; ++v) {
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    const cv::Vec3f* t = truth.points.ptr<cv::Vec3f>(v);
    const uint8_t* page = truth.on_page.ptr<uint8_t>(v);
    const uint8_t* lit = truth.lit.ptr<uint8_t>(v);
    for (int u = 0; u < points.cols; ++u) {
      if (!std::isfinite(p[u][0])) {
        st.page_lit_pixels += page[u] && lit[u];
        continue;
      }
      const double e = cv::norm(cv::Vec3d(p[u]) - cv::Vec3d(t[u]));
      if (e > 1.0) {
        // In mid-air: more than 1 mm from the true surface near the pixel too (on a surface
        // seen nearly edge-on, a fraction of a pixel sideways is a millimetre in depth).
        double nearest = e;
        for (int dv = -2; dv <= 2; ++dv) {
          for (int du = -2; du <= 2; ++du) {
            const int uu = u + du, vv = v + dv;
            if (uu < 0 || vv < 0 || uu >= points.cols || vv >= points.rows) continue;
            const cv::Vec3f q = truth.points.at<cv::Vec3f>(vv, uu);
            if (std::isfinite(q[0]))
              nearest = std::min(nearest, cv::norm(cv::Vec3d(p[u]) - cv::Vec3d(q)));
          }
        }
        st.flying += nearest > 1.0;
      }
      if (!page[u] || !lit[u]) continue;
      ++st.page_lit_pixels;
      st.beyond_1mm += e > 1.0;
      errors.push_back(e);
      sum2 += e * e;
    }
  }
  st.valid = static_cast<int>(errors.size());
  if (st.page_lit_pixels > 0)
    st.valid_fraction = static_cast<double>(st.valid) / st.page_lit_pixels;
  if (errors.empty()) return st;
  auto quantile = [&](double q) {
    const size_t k =
        std::min(errors.size() - 1, static_cast<size_t>(q * (errors.size() - 1) + 0.5));
    std::nth_element(errors.begin(), errors.begin() + k, errors.end());
    return errors[k];
  };
  st.median_mm = quantile(0.5);
  st.p99_mm = quantile(0.99);
  st.max_mm = *std::max_element(errors.begin(), errors.end());
  st.rms_mm = std::sqrt(sum2 / errors.size());
  return st;
}

GroundTruth OnePage(const GroundTruth& truth, int index) {
  GroundTruth one = truth;
  // A new mask: the comparison assigned to the copy's header would be written into the buffer
  // the copy shares with `truth`.
  one.on_page = cv::Mat(truth.page_index == index);
  return one;
}

FlatErrorStats CompareFlat(const GroundTruth& truth, const Mesh& mesh,
                           const std::vector<cv::Point2d>& flat) {
  FlatErrorStats st;
  std::vector<cv::Point2d> from, to, to_mirror;
  std::vector<int> nodes;
  std::vector<cv::Point2d> page(mesh.kind.size(), cv::Point2d(NAN, NAN));
  for (size_t k = 0; k < mesh.kind.size(); ++k) {
    if (mesh.kind[k] != NodeKind::kMeasured && mesh.kind[k] != NodeKind::kFilled) continue;
    const cv::Point px(cvRound(mesh.pixel[k].x), cvRound(mesh.pixel[k].y));
    if (!cv::Rect(0, 0, truth.page.cols, truth.page.rows).contains(px)) continue;
    if (!truth.on_page.at<uint8_t>(px)) continue;
    // The truth at the node's own (sub-pixel) position: bilinear in the page coordinates, where
    // the four pixels around it see this page (beside another page, at a gutter with no gap,
    // the coordinates are that page's: a blend of the two is no truth).
    const cv::Point2d p = mesh.pixel[k];
    const int u0 = std::min(static_cast<int>(p.x), truth.page.cols - 2);
    const int v0 = std::min(static_cast<int>(p.y), truth.page.rows - 2);
    const cv::Rect around(u0, v0, 2, 2);
    if (cv::countNonZero(truth.on_page(around)) < 4) continue;
    const double fu = p.x - u0, fv = p.y - v0;
    const cv::Vec2f st2 = (1 - fv) * ((1 - fu) * truth.page.at<cv::Vec2f>(v0, u0) +
                                      fu * truth.page.at<cv::Vec2f>(v0, u0 + 1)) +
                          fv * ((1 - fu) * truth.page.at<cv::Vec2f>(v0 + 1, u0) +
                                fu * truth.page.at<cv::Vec2f>(v0 + 1, u0 + 1));
    if (!std::isfinite(st2[0])) continue;
    page[k] = cv::Point2d(st2[0], st2[1]);
    from.push_back(flat[k]);
    to.push_back(page[k]);
    to_mirror.emplace_back(st2[0], -st2[1]);
    nodes.push_back(static_cast<int>(k));
  }
  st.nodes = static_cast<int>(nodes.size());
  if (nodes.empty()) return st;
  const Rigid2D fit = FitRigid2D(from, to), fit_m = FitRigid2D(from, to_mirror);
  double sum2 = 0, sum2_m = 0;
  for (size_t k = 0; k < from.size(); ++k) {
    const double e = cv::norm(fit.Apply(from[k]) - to[k]);
    sum2 += e * e;
    st.max_mm = std::max(st.max_mm, e);
    const double em = cv::norm(fit_m.Apply(from[k]) - to_mirror[k]);
    sum2_m += em * em;
  }
  st.rms_mm = std::sqrt(sum2 / from.size());
  st.mirrored = sum2_m < sum2;
  double edge = 0;
  int edges = 0;
  for (const Spring& s : mesh.springs) {
    if (!std::isfinite(page[s.a].x) || !std::isfinite(page[s.b].x)) continue;
    const double truth_len = cv::norm(page[s.a] - page[s.b]);
    edge += std::fabs(cv::norm(flat[s.a] - flat[s.b]) / truth_len - 1.0);
    ++edges;
  }
  st.mean_edge_error = edges ? edge / edges : 0;
  return st;
}

std::vector<cv::Mat> RenderSequence(const VirtualGantry& gantry, const PatternSequence& sequence,
                                    uint64_t seed) {
  std::vector<cv::Mat> frames;
  frames.reserve(sequence.patterns.size());
  for (size_t k = 0; k < sequence.patterns.size(); ++k) {
    frames.push_back(gantry.RenderFrame(
        RenderPattern(sequence.patterns[k], sequence.projector_size), seed + k + 1));
  }
  return frames;
}

SimulatedScan SimulateScan(const Calibration& rig, PageShape shape, uint64_t seed,
                           const TextureOptions& texture) {
  PageOptions page;
  page.shape = shape;
  return SimulateScan(rig, page, texture, SceneOptions(), seed);
}

std::vector<ScanLight> RenderLights(const VirtualGantry& gantry,
                                    const std::vector<SceneLight>& lights, uint64_t seed) {
  std::vector<ScanLight> out;
  for (size_t k = 0; k < lights.size(); ++k) {
    ScanLight light;
    light.name = lights[k].name;
    if (lights[k].kind == SceneLight::Kind::kDistant) {
      light.direction = cv::normalize(lights[k].direction);
    }
    light.image = gantry.RenderLight(lights[k], seed + 1001 + k);
    out.push_back(light);
  }
  return out;
}

Scan AsScan(const SimulatedScan& sim) {
  Scan scan;
  scan.sequence = sim.sequence;
  scan.camera_size = sim.gantry->rig().camera.size;
  scan.texture = sim.texture;
  scan.frames = sim.frames;
  return scan;
}

double MaskIoU(const cv::Mat& a, const cv::Mat& b) {
  const cv::Mat in_a = a != 0, in_b = b != 0;
  const int both = cv::countNonZero(in_a & in_b), either = cv::countNonZero(in_a | in_b);
  return either > 0 ? static_cast<double>(both) / either : 0.0;
}

SimulatedScan SimulateScan(const Calibration& rig, const PageOptions& page,
                           const TextureOptions& texture, const SceneOptions& scene, uint64_t seed,
                           const LightOptions& light) {
  SimulatedScan scan;
  scan.gantry = std::make_unique<VirtualGantry>(rig, page, texture, light, scene);
  scan.sequence = MakePatternSequence(PatternOptions{rig.projector.size});
  scan.frames = RenderSequence(*scan.gantry, scan.sequence, seed);
  scan.texture = scan.gantry->RenderTexture(seed);
  return scan;
}

std::vector<double> TrueSampling(const VirtualGantry& gantry, double step_mm) {
  const Page& page = gantry.pages().front();
  const cv::Size2d size = page.options().size_mm;
  const CameraModel& camera = gantry.rig().camera;
  std::vector<double> out;
  const double h = 0.05;
  for (double t = step_mm; t < size.height - step_mm; t += step_mm) {
    for (double s = step_mm; s < size.width - step_mm; s += step_mm) {
      const cv::Point2d ds =
          (camera.Project(page.Point(s + h, t)) - camera.Project(page.Point(s - h, t))) / (2 * h);
      const cv::Point2d dt =
          (camera.Project(page.Point(s, t + h)) - camera.Project(page.Point(s, t - h))) / (2 * h);
      cv::Mat w;
      cv::SVD::compute(cv::Mat(cv::Matx22d(ds.x, dt.x, ds.y, dt.y)), w);
      out.push_back(25.4 * w.at<double>(1));
    }
  }
  return out;
}

Status MeasureFieldsOnWhiteTarget(const Calibration& rig, const LightOptions& light, double albedo,
                                  uint64_t seed, FlatField* flat, StudioField* studio) {
  TextureOptions plain;
  plain.kind = TextureKind::kPlain;
  plain.paper_albedo = albedo;
  PageOptions target;
  target.size_mm = {420, 320};  // More than the camera's view.
  const SimulatedScan white = SimulateScan(rig, target, plain, SceneOptions(), seed, light);
  const DecodeResult decoded = Decode(white.sequence, white.frames);
  const PointMap map = Triangulator(rig).Triangulate(decoded);
  FlatFieldOptions options;
  options.target_albedo = albedo;
  Status s = Status::Ok();
  *flat = MeasureFlatField(decoded.amplitude, map.points, rig, options, &s);
  if (!s.ok()) return Status::Error("the flat field: " + s.message());
  *studio = MeasureStudioField(white.texture, rig.camera, light.studio_lamps, albedo, &s);
  if (!s.ok()) return Status::Error("the studio field: " + s.message());
  return Status::Ok();
}

}  // namespace vellum
