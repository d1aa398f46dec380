#include "core/mesh/mesh.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/depth.h"

namespace vellum {
namespace {

enum class Fit { kOk, kHole, kEdge };

// How far a fit's value can be trusted: its standard error, and whether points surround it (a
// quadratic; at the leaf's edge a plane over the points on one side).
struct FitQuality {
  double sigma_mm = 0;  // The fitted value's standard error.
  double rms_mm = 0;    // The points' scatter about the fit (RMS).
  bool surrounded = false;
  Eigen::Matrix<double, 6, 3> coef = Eigen::Matrix<double, 6, 3>::Zero();  // x, y, z polynomials.
  int hu = 1, hv = 1;  // The window's half-sizes, px: the polynomials' units of offset.

  // The fitted surface at an offset (du, dv) px from where the fit was made.
  cv::Vec3d At(double du, double dv) const {
    const double u = du / hu, v = dv / hv;
    const double m[6] = {1, u, v, u * u, u * v, v * v};
    cv::Vec3d x(0, 0, 0);
    for (int i = 0; i < 6; ++i) {
      for (int c = 0; c < 3; ++c) x[c] += m[i] * coef(i, c);
    }
    return x;
  }
};

// The fit's six monomials du^a dv^b: 1, du, dv, du^2, du dv, dv^2 (du, dv: the pixel offset from
// the node in window half-sizes).
constexpr int kPowerU[6] = {0, 1, 0, 2, 1, 0};
constexpr int kPowerV[6] = {0, 0, 1, 0, 1, 2};

// The normal equations of the least-squares fit of x, y, z as polynomials in (du, dv): sums of
// monomial products (the upper triangle) and of monomials times the coordinates.
struct NormalSums {
  double ata[6][6] = {};
  double atb[6][3] = {};

  // Adds (sign 1) or removes (-1) one point.
  void Add(double du, double dv, const cv::Vec3f& x, double sign) {
    const double m[6] = {1, du, dv, du * du, du * dv, dv * dv};
    for (int i = 0; i < 6; ++i) {
      const double mi = sign * m[i];
      for (int j = i; j < 6; ++j) ata[i][j] += mi * m[j];
      for (int c = 0; c < 3; ++c) atb[i][c] += mi * x[c];
    }
  }
};

// Solves the first `N` terms' normal equations; false if ill-posed.
template <int N>
bool Solve(const NormalSums& sums, Eigen::Matrix<double, 6, 3>* coef) {
  Eigen::Matrix<double, N, N> a;
  Eigen::Matrix<double, N, 3> b;
  for (int i = 0; i < N; ++i) {
    for (int j = i; j < N; ++j) a(i, j) = a(j, i) = sums.ata[i][j];
    for (int c = 0; c < 3; ++c) b(i, c) = sums.atb[i][c];
  }
  const Eigen::LDLT<Eigen::Matrix<double, N, N>> ldlt(a);
  if (ldlt.info() != Eigen::Success || !(ldlt.rcond() > 1e-9)) return false;
  coef->setZero();
  coef->template topRows<N>() = ldlt.solve(b);
  return coef->allFinite();
}

// Least squares of x, y, z as polynomials in (du, dv) with `terms` coefficients (6: quadratic,
// 3: linear); false if ill-posed.
bool Polyfit(const NormalSums& sums, int terms, Eigen::Matrix<double, 6, 3>* coef) {
  return terms == 6 ? Solve<6>(sums, coef) : Solve<3>(sums, coef);
}

// Fits x, y, z of the points around a node as functions of the pixel offset (quadratic where
// there are enough points around it, else linear) and returns their value at the node. The
// fit removes noise and, being of second order, does not flatten the page's curvature. It is
// robust: points far from a first fit (mixed pixels at the page's edge, stray decodes) are
// dropped before the second. A node with data on one side only and none at its own pixel lies
// beyond the data's edge (kEdge): a fit there would extrapolate, so it is left to the skirt.
//
// The sums are separable: along a window row dv is fixed, so each row sums du^0..4 and x du^0..2
// of its points, and the row's sums enter the normal equations with its powers of dv (14
// products a point instead of 39; a window holds a few hundred points).
// A node's window of pixels, and each pixel's offset from the node in half-widths.
struct Window {
  int u0, u1, v0, v1, hu, hv;
  cv::Point2d at;
  double OffsetU(int u) const { return (u - at.x) / hu; }
  double OffsetV(int v) const { return (v - at.y) / hv; }
};

inline bool Usable(const cv::Vec3f& x, uint8_t m) { return m && std::isfinite(x[2]); }

// The normal equations' sums over the window's points (separable by rows: see FitNode), and
// the sums of their offsets (*su, *sv); returns how many points there are.
int SumWindow(const cv::Mat& points, const cv::Mat& mask, const Window& w, NormalSums* sums_out,
              double* su_out, double* sv_out) {
  NormalSums& sums = *sums_out;
  const int u0 = w.u0, u1 = w.u1, v0 = w.v0, v1 = w.v1;
  auto usable = Usable;
  auto offset_u = [&](int u) { return w.OffsetU(u); };
  auto offset_v = [&](int v) { return w.OffsetV(v); };
  int count = 0;
  double su = 0, sv = 0;
  for (int v = v0; v <= v1; ++v) {
    const cv::Vec3f* row = points.ptr<cv::Vec3f>(v);
    const uint8_t* m = mask.ptr<uint8_t>(v);
    double pu[5] = {}, xu[3][3] = {};  // Sums of du^a; of x_k du^a.
    int n = 0;
    for (int u = u0; u <= u1; ++u) {
      if (!usable(row[u], m[u])) continue;
      const double du = offset_u(u), du2 = du * du;
      ++n;
      pu[1] += du;
      pu[2] += du2;
      pu[3] += du2 * du;
      pu[4] += du2 * du2;
      for (int k = 0; k < 3; ++k) {
        xu[k][0] += row[u][k];
        xu[k][1] += row[u][k] * du;
        xu[k][2] += row[u][k] * du2;
      }
    }
    if (n == 0) continue;
    pu[0] = n;
    const double dv = offset_v(v);
    const double pv[5] = {1, dv, dv * dv, dv * dv * dv, dv * dv * dv * dv};
    for (int i = 0; i < 6; ++i) {
      for (int j = i; j < 6; ++j) {
        sums.ata[i][j] += pv[kPowerV[i] + kPowerV[j]] * pu[kPowerU[i] + kPowerU[j]];
      }
      for (int k = 0; k < 3; ++k) sums.atb[i][k] += pv[kPowerV[i]] * xu[k][kPowerU[i]];
    }
    count += n;
    su += pu[1];
    sv += n * dv;
  }
  *su_out = su;
  *sv_out = sv;
  return count;
}

// Whether a point lies at the node's own pixel (within 1.5 px).
bool OwnPoint(const cv::Mat& points, const cv::Mat& mask, const Window& w) {
  const int u0 = w.u0, u1 = w.u1, v0 = w.v0, v1 = w.v1;
  const cv::Point2d at = w.at;
  auto usable = Usable;
  bool own = false;
  for (int v = std::max(v0, static_cast<int>(std::ceil(at.y - 1.5)));
       v <= std::min(v1, static_cast<int>(std::floor(at.y + 1.5))) && !own; ++v) {
    for (int u = std::max(u0, static_cast<int>(std::ceil(at.x - 1.5)));
         u <= std::min(u1, static_cast<int>(std::floor(at.x + 1.5))); ++u) {
      own = own || usable(points.at<cv::Vec3f>(v, u), mask.at<uint8_t>(v, u));
    }
  }
  return own;
}

// Each usable point's squared distance from the fit `c`, in the window's order, and how many
// are within a quarter of kFloor (*small).
void FitResiduals(const cv::Mat& points, const cv::Mat& mask, const Window& w,
                  const Eigen::Matrix<double, 6, 3>& c, double floor_mm,
                  std::vector<double>* residual_out, int* small_out) {
  const int u0 = w.u0, u1 = w.u1, v0 = w.v0, v1 = w.v1;
  auto usable = Usable;
  auto offset_u = [&](int u) { return w.OffsetU(u); };
  auto offset_v = [&](int v) { return w.OffsetV(v); };
  const double kFloor = floor_mm;
  std::vector<double>& residual = *residual_out;
  int& small = *small_out;
  for (int v = v0; v <= v1; ++v) {
    const cv::Vec3f* row = points.ptr<cv::Vec3f>(v);
    const uint8_t* m = mask.ptr<uint8_t>(v);
    // Along the row each coordinate's polynomial is a + b du + g du^2.
    const double dv = offset_v(v);
    double a[3], b[3], g[3];
    for (int k = 0; k < 3; ++k) {
      a[k] = c(0, k) + dv * (c(2, k) + dv * c(5, k));
      b[k] = c(1, k) + dv * c(4, k);
      g[k] = c(3, k);
    }
    for (int u = u0; u <= u1; ++u) {
      if (!usable(row[u], m[u])) continue;
      const double du = offset_u(u);
      double r2 = 0;
      for (int k = 0; k < 3; ++k) {
        const double f = a[k] + du * (b[k] + du * g[k]) - row[u][k];
        r2 += f * f;
      }
      residual.push_back(r2);
      small += r2 <= kFloor * kFloor / 16;
    }
  }
}

// The kept points' squared scatter about the second fit `c` (those with residual at most `cut`).
double RefitScatter(const cv::Mat& points, const cv::Mat& mask, const Window& w,
                    const Eigen::Matrix<double, 6, 3>& c, const std::vector<double>& residual,
                    double cut) {
  const int u0 = w.u0, u1 = w.u1, v0 = w.v0, v1 = w.v1;
  auto usable = Usable;
  auto offset_u = [&](int u) { return w.OffsetU(u); };
  auto offset_v = [&](int v) { return w.OffsetV(v); };
  double refit_r2 = 0;
  size_t at = 0;
  for (int v = v0; v <= v1; ++v) {
    const cv::Vec3f* row = points.ptr<cv::Vec3f>(v);
    const uint8_t* m = mask.ptr<uint8_t>(v);
    const double dv = offset_v(v);
    for (int u = u0; u <= u1; ++u) {
      if (!usable(row[u], m[u])) continue;
      if (residual[at++] > cut) continue;
      const double du = offset_u(u);
      const double mono[6] = {1, du, dv, du * du, du * dv, dv * dv};
      for (int k = 0; k < 3; ++k) {
        double f = -row[u][k];
        for (int t = 0; t < 6; ++t) f += mono[t] * c(t, k);
        refit_r2 += f * f;
      }
    }
  }
  return refit_r2;
}

Fit FitNode(const cv::Mat& points, const cv::Mat& mask, cv::Point2d at, int hu, int hv,
            int min_points, cv::Vec3d* out, FitQuality* quality = nullptr) {
  const int u0 = std::max(0, static_cast<int>(std::floor(at.x)) - hu);
  const int u1 = std::min(points.cols - 1, static_cast<int>(std::ceil(at.x)) + hu);
  const int v0 = std::max(0, static_cast<int>(std::floor(at.y)) - hv);
  const int v1 = std::min(points.rows - 1, static_cast<int>(std::ceil(at.y)) + hv);
  const Window w{u0, u1, v0, v1, hu, hv, at};
  auto offset_u = [&](int u) { return w.OffsetU(u); };
  auto offset_v = [&](int v) { return w.OffsetV(v); };
  auto usable = Usable;
  NormalSums sums;
  double su = 0, sv = 0;
  const int count = SumWindow(points, mask, w, &sums, &su, &sv);
  if (count < min_points) return Fit::kHole;
  // Points on one side only (a node at the page's edge): a quadratic would extrapolate
  // wildly, a plane does not. `own`: a point at the node's own pixel.
  const bool own = OwnPoint(points, mask, w);
  const bool one_sided = std::hypot(su, sv) / count > 0.25;
  if (one_sided && !own) return Fit::kEdge;
  const int terms = (count >= 2 * min_points && !one_sided) ? 6 : 3;
  Eigen::Matrix<double, 6, 3> c;
  if (!Polyfit(sums, terms, &c)) return Fit::kHole;
  // Points further than four times the median residual go, but never closer than 0.2 mm
  // (compared squared). The median is sought only when it is over 0.05 mm (more than half the
  // residuals are): below that the cut is 0.2 mm whatever it is.
  constexpr double kFloor = 0.2;  // mm
  thread_local std::vector<double> residual, sorted;
  residual.clear();
  int small = 0;
  FitResiduals(points, mask, w, c, kFloor, &residual, &small);
  double cut = kFloor * kFloor;
  if (small < count / 2 + 1) {
    sorted = residual;
    std::nth_element(sorted.begin(), sorted.begin() + count / 2, sorted.end());
    cut = std::max(cut, 16.0 * sorted[count / 2]);
  }
  // The second fit: the first's sums less the points dropped (few: the sums stay well scaled);
  // none dropped, the first fit stands.
  int kept = count;
  double kept_r2 = 0;
  size_t i = 0;
  for (int v = v0; v <= v1; ++v) {
    const cv::Vec3f* row = points.ptr<cv::Vec3f>(v);
    const uint8_t* m = mask.ptr<uint8_t>(v);
    for (int u = u0; u <= u1; ++u) {
      if (!usable(row[u], m[u])) continue;
      if (residual[i] > cut) {
        sums.Add(offset_u(u), offset_v(v), row[u], -1);
        --kept;
      } else {
        kept_r2 += residual[i];
      }
      ++i;
    }
  }
  if (kept < min_points || (kept < count && !Polyfit(sums, terms, &c))) return Fit::kHole;
  *out = cv::Vec3d(c(0, 0), c(0, 1), c(0, 2));  // The polynomials at the node (du = dv = 0).
  // The fitted value's standard error: the points' scatter about the fit, over the number of
  // points per coefficient.
  if (quality) {
    quality->sigma_mm = std::sqrt(kept_r2 / std::max(1, kept - terms) * terms / kept);
    // The kept points' scatter about the second fit (the first, pulled by the points dropped,
    // overstates it).
    const double refit_r2 =
        kept < count ? RefitScatter(points, mask, w, c, residual, cut) : kept_r2;
    quality->rms_mm = std::sqrt(refit_r2 / std::max(1, kept - terms));
    quality->surrounded = terms == 6;
    quality->coef = c;
    quality->hu = hu;
    quality->hv = hv;
  }
  return Fit::kOk;
}

// The surface at a pixel, where a node's window is too wide for it (a crease): the points within
// 3 px fitted (a quadratic where they surround it), robust to the stray decode.
constexpr int kSurfaceWindow = 3;  // px
constexpr int kSurfaceMinPoints = 12;
// A bend is told from noise at five standard errors of that fit.
constexpr double kSurfaceSigmas = 5;

// How far `m` stands off the line through `a` and `b` (not off their midpoint: where the surface
// is straight, the point seen halfway between their pixels lies on the line, but off the middle
// wherever perspective foreshortens it).
double OffLine(const cv::Vec3d& a, const cv::Vec3d& b, const cv::Vec3d& m) {
  const cv::Vec3d d = b - a, r = m - a;
  const double len2 = d.dot(d);
  return len2 > 0 ? cv::norm(r - (r.dot(d) / len2) * d) : cv::norm(r);
}

}  // namespace

bool MeshOptions::Check(std::string* why) const {
  if (grid.width < 2 || grid.height < 2 || grid.width > 1000 || grid.height > 1000) {
    *why = "the grid must have 2 to 1000 nodes each way";
    return false;
  }
  if (min_points < 3 || !(fit_window > 0) || skirt_rings < 0 || skirt_rings > 5) {
    *why = "min_points must be >= 3, fit_window > 0, skirt_rings in [0, 5]";
    return false;
  }
  if (!(straight_mm > 0) || !(min_bend_deg >= 0 && min_bend_deg < 45)) {
    *why = "straight_mm must be > 0, min_bend_deg in [0, 45)";
    return false;
  }
  if (!(max_fit_rms_mm > 0)) {
    *why = "max_fit_rms_mm must be > 0";
    return false;
  }
  return true;
}

cv::Mat SegmentPage(const cv::Mat& texture, double fraction, bool largest_only) {
  const cv::Mat gray = EightBitGray(texture);
  cv::Mat smooth;
  cv::GaussianBlur(gray, smooth, cv::Size(5, 5), 0);
  // The bright level: 98th percentile of the histogram.
  int hist[256] = {0};
  for (int v = 0; v < smooth.rows; ++v) {
    const uint8_t* r = smooth.ptr<uint8_t>(v);
    for (int u = 0; u < smooth.cols; ++u) ++hist[r[u]];
  }
  const long target = static_cast<long>(0.98 * smooth.total());
  long acc = 0;
  int bright = 255;
  for (int i = 0; i < 256; ++i) {
    acc += hist[i];
    if (acc >= target) {
      bright = i;
      break;
    }
  }
  cv::Mat mask = smooth > fraction * bright;
  cv::morphologyEx(mask, mask, cv::MORPH_OPEN, cv::getStructuringElement(cv::MORPH_RECT, {3, 3}));
  // Bridge what ink splits (text lines, checkerboard squares meeting at corners).
  const int k = std::max(3, (std::min(mask.cols, mask.rows) / 100) | 1);
  cv::morphologyEx(mask, mask, cv::MORPH_CLOSE,
                   cv::getStructuringElement(cv::MORPH_ELLIPSE, {k, k}));
  if (!largest_only) return mask;
  // Largest region, holes (ink inside the page) filled.
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
  cv::Mat page = cv::Mat::zeros(mask.size(), CV_8U);
  if (contours.empty()) return page;
  size_t best = 0;
  for (size_t k = 1; k < contours.size(); ++k) {
    if (cv::contourArea(contours[k]) > cv::contourArea(contours[best])) best = k;
  }
  cv::drawContours(page, contours, static_cast<int>(best), cv::Scalar(255), cv::FILLED);
  return page;
}

void ConnectSheet(bool bend_springs, const std::function<cv::Point2d(const cv::Vec3d&)>& project,
                  Mesh* out) {
  Mesh& mesh = *out;
  const int g = mesh.cols, h = mesh.rows, n = g * h;
  mesh.springs.clear();
  mesh.quads.clear();
  if (g < 2 || h < 2 || mesh.kind.size() != static_cast<size_t>(n) ||
      mesh.point.size() != static_cast<size_t>(n)) {
    mesh.status = Status::Error("sheet of " + std::to_string(g) + "x" + std::to_string(h) +
                                " nodes has " + std::to_string(mesh.kind.size()) + " kinds and " +
                                std::to_string(mesh.point.size()) + " points");
    return;
  }
  for (int k = 0; k < n; ++k) {
    if (mesh.Active(k) && !(std::isfinite(mesh.point[k][0]) && std::isfinite(mesh.point[k][1]) &&
                            std::isfinite(mesh.point[k][2]))) {
      mesh.status = Status::Error("sheet node " + std::to_string(k) + " is not a finite point");
      return;
    }
  }
  mesh.pixel.assign(n, cv::Point2d(0, 0));
  mesh.measured =
      static_cast<int>(std::count(mesh.kind.begin(), mesh.kind.end(), NodeKind::kMeasured));
  mesh.filled = static_cast<int>(std::count(mesh.kind.begin(), mesh.kind.end(), NodeKind::kFilled));
  mesh.skirt = static_cast<int>(std::count(mesh.kind.begin(), mesh.kind.end(), NodeKind::kSkirt));
  for (int k = 0; k < n; ++k) {
    if (mesh.Active(k)) mesh.pixel[k] = project(mesh.point[k]);
  }
  auto add = [&](int i0, int j0, int i1, int j1, SpringKind kind) {
    if (i0 < 0 || j0 < 0 || i0 >= g || j0 >= h || i1 < 0 || j1 < 0 || i1 >= g || j1 >= h) return;
    const int a = mesh.Index(i0, j0), b = mesh.Index(i1, j1);
    if (!mesh.Active(a) || !mesh.Active(b)) return;
    mesh.springs.push_back({a, b, cv::norm(mesh.point[a] - mesh.point[b]), kind});
  };
  for (int j = 0; j < h; ++j) {
    for (int i = 0; i < g; ++i) {
      add(i, j, i + 1, j, SpringKind::kStructural);
      add(i, j, i, j + 1, SpringKind::kStructural);
      add(i, j, i + 1, j + 1, SpringKind::kShear);
      add(i + 1, j, i, j + 1, SpringKind::kShear);
      if (bend_springs) {
        add(i, j, i + 2, j, SpringKind::kBend);
        add(i, j, i, j + 2, SpringKind::kBend);
      }
      if (i + 1 < g && j + 1 < h) {
        const cv::Vec4i q(mesh.Index(i, j), mesh.Index(i + 1, j), mesh.Index(i + 1, j + 1),
                          mesh.Index(i, j + 1));
        if (mesh.Active(q[0]) && mesh.Active(q[1]) && mesh.Active(q[2]) && mesh.Active(q[3])) {
          mesh.quads.push_back(q);
        }
      }
    }
  }
  for (const Spring& s : mesh.springs) {
    if (!(s.rest_mm > 1e-9)) {
      mesh.status = Status::Error("two sheet nodes coincide (degenerate surface data)");
      return;
    }
  }
  if (mesh.quads.empty()) {
    mesh.status = Status::Error("the page yields no complete grid cell: too few valid points");
    return;
  }
  mesh.status = Status::Ok();
}

double LengthAlongSurface(const cv::Mat& points, const cv::Mat& mask, const cv::Vec3d& a,
                          cv::Point2d pa, const cv::Vec3d& b, cv::Point2d pb, double straight_mm,
                          int depth) {
  // Halving stops at pieces of two pixels (the points' own resolution: a crease rounded over a
  // millimetre is straight at that scale) and after eight halvings whatever the piece.
  constexpr double kShortest = 2.0;  // px
  constexpr int kDeepest = 8;
  const double chord = cv::norm(b - a);
  if (depth >= kDeepest || cv::norm(pb - pa) <= kShortest) return chord;
  const cv::Point2d pm = 0.5 * (pa + pb);
  if (!(pm.x >= 0 && pm.y >= 0 && pm.x <= points.cols - 1 && pm.y <= points.rows - 1)) return chord;
  cv::Vec3d m;
  FitQuality q;
  // Straight unless the middle, with points all round it (not at the leaf's edge, where the rim
  // and what lies beyond crowd a small window), stands off the chord by more than its own noise
  // could: noise taken for a bend would add length wherever the points are poor (dark ink).
  if (FitNode(points, mask, pm, kSurfaceWindow, kSurfaceWindow, kSurfaceMinPoints, &m, &q) !=
          Fit::kOk ||
      !q.surrounded || OffLine(a, b, m) < std::max(straight_mm, kSurfaceSigmas * q.sigma_mm))
    return chord;
  return LengthAlongSurface(points, mask, a, pa, m, pm, straight_mm, depth + 1) +
         LengthAlongSurface(points, mask, m, pm, b, pb, straight_mm, depth + 1);
}

double WarpError(const Mesh& mesh) {
  // Along a grid line the nodes are evenly spaced in the camera image, while the flattened page
  // (lengths on the surface) spaces them by the 3D distance between them: where that changes
  // from one cell to the next (the surface turns from the camera), the restoration's linear
  // interpolation between nodes strays by about an eighth of a cell's pixels times the relative
  // change of the cell's length.
  std::vector<double> errors;
  auto measured = [&](int i, int j) {
    return i >= 0 && j >= 0 && i < mesh.cols && j < mesh.rows &&
           mesh.kind[mesh.Index(i, j)] == NodeKind::kMeasured;
  };
  auto along = [&](int i0, int j0, int i1, int j1, int i2, int j2) {
    if (!measured(i0, j0) || !measured(i1, j1) || !measured(i2, j2)) return 0.0;
    const int a = mesh.Index(i0, j0), b = mesh.Index(i1, j1), c = mesh.Index(i2, j2);
    const double d0 = cv::norm(mesh.point[b] - mesh.point[a]);
    const double d1 = cv::norm(mesh.point[c] - mesh.point[b]);
    const double cell_px =
        0.5 * (cv::norm(mesh.pixel[b] - mesh.pixel[a]) + cv::norm(mesh.pixel[c] - mesh.pixel[b]));
    return d0 + d1 > 0 ? cell_px / 8 * std::fabs(d1 - d0) / (0.5 * (d0 + d1)) : 0.0;
  };
  for (int j = 0; j < mesh.rows; ++j) {
    for (int i = 0; i < mesh.cols; ++i) {
      if (!measured(i, j)) continue;
      errors.push_back(std::max(along(i - 1, j, i, j, i + 1, j), along(i, j - 1, i, j, i, j + 1)));
    }
  }
  if (errors.empty()) return 0;
  const size_t k = std::min(errors.size() - 1, errors.size() * 9 / 10);
  std::nth_element(errors.begin(), errors.begin() + k, errors.end());
  return errors[k];
}

cv::Size GridForError(const Mesh& mesh, double max_error_px, int max_nodes) {
  const double error = WarpError(mesh);
  const double scale = error > max_error_px ? std::sqrt(error / max_error_px) : 1.0;
  auto finer = [&](int n) {
    return std::clamp(static_cast<int>(std::ceil((n - 1) * scale)) + 1, n, max_nodes);
  };
  return {finer(mesh.cols), finer(mesh.rows)};
}

namespace {

// The rest length of each spring between two measured nodes, along the leaf's surface where it
// bends between them. Whether it does is judged on the nodes' own fits (hundreds of points each,
// blind to the point map's small faults: the stripes' bias at the edges of ink), carried to the
// spring's middle and compared with the chord; only a spring that bends is measured along the
// surface, from the surface at its nodes' pixels (a node's fit cuts a crease's corner).
void MeasureAlongSurface(const cv::Mat& points, const cv::Mat& mask,
                         const std::vector<cv::Point2d>& grid_px,
                         const std::vector<FitQuality>& fits, double straight_mm,
                         double min_bend_deg, Mesh* out) {
  const double min_bend = std::tan(min_bend_deg * CV_PI / 180);
  Mesh& mesh = *out;
  const int n = static_cast<int>(mesh.kind.size());
  auto measured = [&](int k) { return mesh.kind[k] == NodeKind::kMeasured; };
  auto fitted_at = [&](int k, cv::Point2d p) {
    return fits[k].At(p.x - grid_px[k].x, p.y - grid_px[k].y);
  };
  std::vector<int> bent;
  std::vector<uint8_t> needed(n, 0);
  for (size_t k = 0; k < mesh.springs.size(); ++k) {
    const Spring& s = mesh.springs[k];
    if (!measured(s.a) || !measured(s.b)) continue;
    const cv::Point2d middle = 0.5 * (grid_px[s.a] + grid_px[s.b]);
    const cv::Vec3d surface = 0.5 * (fitted_at(s.a, middle) + fitted_at(s.b, middle));
    const double noise = std::hypot(fits[s.a].sigma_mm, fits[s.b].sigma_mm);
    const double chord = cv::norm(mesh.point[s.b] - mesh.point[s.a]);
    if (OffLine(mesh.point[s.a], mesh.point[s.b], surface) <
        std::max({straight_mm, kSurfaceSigmas * noise, 0.5 * chord * min_bend}))
      continue;
    bent.push_back(static_cast<int>(k));
    needed[s.a] = needed[s.b] = 1;
  }
  if (bent.empty()) return;
  // The surface at each bent spring's nodes' pixels, where it stands off the node's fit by more
  // than its own noise could.
  std::vector<cv::Vec3d> surface(mesh.point);
  cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& r) {
    for (int k = r.start; k < r.end; ++k) {
      if (!needed[k]) continue;
      cv::Vec3d here;
      FitQuality q;
      if (FitNode(points, mask, mesh.pixel[k], kSurfaceWindow, kSurfaceWindow, kSurfaceMinPoints,
                  &here, &q) == Fit::kOk &&
          q.surrounded &&
          cv::norm(here - mesh.point[k]) > std::max(straight_mm, kSurfaceSigmas * q.sigma_mm)) {
        surface[k] = here;
      }
    }
  });
  cv::parallel_for_(cv::Range(0, static_cast<int>(bent.size())), [&](const cv::Range& r) {
    for (int k = r.start; k < r.end; ++k) {
      Spring& s = mesh.springs[bent[k]];
      s.rest_mm =
          std::max(s.rest_mm, LengthAlongSurface(points, mask, surface[s.a], mesh.pixel[s.a],
                                                 surface[s.b], mesh.pixel[s.b], straight_mm));
    }
  });
  // The other springs at a node that took the surface at its pixel measure from there too: lengths
  // from two places for one node would pull the flattened sheet two ways.
  std::vector<uint8_t> is_bent(mesh.springs.size(), 0);
  for (int k : bent) is_bent[k] = 1;
  for (size_t k = 0; k < mesh.springs.size(); ++k) {
    Spring& s = mesh.springs[k];
    if (is_bent[k] || !measured(s.a) || !measured(s.b)) continue;
    if (surface[s.a] == mesh.point[s.a] && surface[s.b] == mesh.point[s.b]) continue;
    s.rest_mm = cv::norm(surface[s.b] - surface[s.a]);
  }
}

}  // namespace

namespace {

// Each grid node on the page (`grid_px`, `on_page`) fitted to the points around it (FitNode):
// measured, a hole (filled later), or off at the page's edge; a node whose points are strewn far
// off one surface (the window straddling the leaf's silhouette) is a hole when measured nodes
// hold it on all four sides, else off. `fits` (when sized) gets each fit's quality.
void FitNodes(const cv::Mat& points, const cv::Mat& page_mask, const MeshOptions& options,
              const std::vector<cv::Point2d>& grid_px, const std::vector<uint8_t>& on_page, int hu,
              int hv, std::vector<FitQuality>* fits_out, Mesh* out) {
  Mesh& mesh = *out;
  std::vector<FitQuality>& fits = *fits_out;
  const int g = mesh.cols, h = mesh.rows, n = g * h;
  std::vector<uint8_t> strewn(n, 0);
  cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& range) {
    for (int k = range.start; k < range.end; ++k) {
      if (!on_page[k]) continue;
      cv::Vec3d x;
      FitQuality own;
      FitQuality& quality = options.rest_along_surface ? fits[k] : own;
      const Fit fit =
          FitNode(points, page_mask, grid_px[k], hu, hv, options.min_points, &x, &quality);
      if (fit == Fit::kOk && quality.rms_mm > options.max_fit_rms_mm) {
        // Points strewn far off one surface: the window straddles the leaf's silhouette and what
        // lies far behind it, and the fit would place the node in mid-air. Settled below.
        strewn[k] = 1;
      } else if (fit == Fit::kOk) {
        mesh.point[k] = x;
        mesh.kind[k] = NodeKind::kMeasured;
      } else if (fit == Fit::kHole) {
        mesh.kind[k] = NodeKind::kFilled;  // A hole: interpolated below.
      }  // kEdge stays off; the skirt extrapolates it from the page.
    }
  });
  // A strewn node held on all four sides by measured nodes is a hole, filled from them; any other
  // (beside the page's edge, or beside another such node) is off: a hole filled from fewer nodes
  // would copy one of them, and the skirt extrapolates the page's edge from the page.
  for (int k = 0; k < n; ++k) {
    if (!strewn[k]) continue;
    const int i = k % g, j = k / g;
    auto held = [&](int m) { return mesh.kind[m] == NodeKind::kMeasured && !strewn[m]; };
    const bool inside = i > 0 && j > 0 && i + 1 < g && j + 1 < h && held(k - 1) && held(k + 1) &&
                        held(k - g) && held(k + g);
    mesh.kind[k] = inside ? NodeKind::kFilled : NodeKind::kOff;
  }
}

// A hole node held by fewer than two sheet nodes (a page's corner whose points are gone) has
// nothing to interpolate between: it would copy its one neighbour and the two coincide. Such
// nodes are peeled off until every hole node is held on two sides. The skirt does not
// extend over them either: extrapolated from a corner whose points are gone (a curl's corner
// seen edge on), it folds; the sheet loses the corner's cell instead. Returns the nodes peeled.
std::vector<uint8_t> PeelHeldByOne(Mesh* out) {
  Mesh& mesh = *out;
  const int g = mesh.cols, h = mesh.rows, n = g * h;
  std::vector<uint8_t> peeled_off(n, 0);
  for (bool peeled = true; peeled;) {
    peeled = false;
    for (int k = 0; k < n; ++k) {
      if (mesh.kind[k] != NodeKind::kFilled) continue;
      const int i = k % g, j = k / g;
      int held = 0;
      if (i > 0) held += mesh.kind[k - 1] != NodeKind::kOff;
      if (i + 1 < g) held += mesh.kind[k + 1] != NodeKind::kOff;
      if (j > 0) held += mesh.kind[k - g] != NodeKind::kOff;
      if (j + 1 < h) held += mesh.kind[k + g] != NodeKind::kOff;
      if (held < 2) {
        mesh.kind[k] = NodeKind::kOff;
        peeled_off[k] = 1;
        peeled = true;
      }
    }
  }
  return peeled_off;
}

// Holes: harmonic interpolation (Jacobi) from the measured nodes around them; a hole no
// measured node reaches is off.
void FillHoles(Mesh* out) {
  Mesh& mesh = *out;
  const int g = mesh.cols, h = mesh.rows, n = g * h;
  std::vector<int> holes;
  for (int k = 0; k < n; ++k) {
    if (mesh.kind[k] == NodeKind::kFilled) holes.push_back(k);
  }
  std::vector<uint8_t> known(n, 0);
  for (int k = 0; k < n; ++k) known[k] = mesh.kind[k] == NodeKind::kMeasured;
  // Mean of a node's known 4-neighbours; `count` gets how many there are.
  auto neighbour_mean = [&](int k, int* count) {
    const int di[4] = {1, -1, 0, 0}, dj[4] = {0, 0, 1, -1};
    const int i = k % g, j = k / g;
    cv::Vec3d sum(0, 0, 0);
    *count = 0;
    for (int d = 0; d < 4; ++d) {
      const int ii = i + di[d], jj = j + dj[d];
      if (ii < 0 || jj < 0 || ii >= g || jj >= h || !known[mesh.Index(ii, jj)]) continue;
      sum += mesh.point[mesh.Index(ii, jj)];
      ++*count;
    }
    return *count > 0 ? sum / *count : sum;
  };
  // Seed holes outward from known nodes so every hole starts from a sensible value.
  for (bool changed = true; changed;) {
    changed = false;
    for (int k : holes) {
      if (known[k]) continue;
      int c = 0;
      const cv::Vec3d mean = neighbour_mean(k, &c);
      if (c > 0) {
        mesh.point[k] = mean;
        known[k] = 2;
        changed = true;
      }
    }
  }
  for (int it = 0; it < 2000 && !holes.empty(); ++it) {
    double worst = 0;
    for (int k : holes) {
      if (!known[k]) continue;
      int c = 0;
      const cv::Vec3d next = neighbour_mean(k, &c);
      worst = std::max(worst, cv::norm(next - mesh.point[k]));
      mesh.point[k] = next;
    }
    if (worst < 1e-6) break;
  }
  for (int k : holes) {
    if (!known[k]) mesh.kind[k] = NodeKind::kOff;  // Unreachable from any measured node.
  }
}

// Skirt: rings of nodes beyond the page edge, on the page surface extended linearly, so
// the quads that hold the page's edge exist. They never take a position from the table.
void AddSkirt(int rings, const std::vector<uint8_t>& peeled_off, Mesh* out) {
  Mesh& mesh = *out;
  const int g = mesh.cols, h = mesh.rows;
  for (int ring = 0; ring < rings; ++ring) {
    std::vector<std::pair<int, cv::Vec3d>> added;
    for (int j = 0; j < h; ++j) {
      for (int i = 0; i < g; ++i) {
        const int k = mesh.Index(i, j);
        if (mesh.Active(k) || peeled_off[k]) continue;
        cv::Vec3d sum(0, 0, 0);
        int c = 0;
        for (int dj2 = -1; dj2 <= 1; ++dj2) {
          for (int di2 = -1; di2 <= 1; ++di2) {
            if (!di2 && !dj2) continue;
            const int i1 = i + di2, j1 = j + dj2, i2 = i + 2 * di2, j2 = j + 2 * dj2;
            if (i2 < 0 || j2 < 0 || i2 >= g || j2 >= h) continue;
            if (!mesh.Active(mesh.Index(i1, j1)) || !mesh.Active(mesh.Index(i2, j2))) continue;
            sum += 2.0 * mesh.point[mesh.Index(i1, j1)] - mesh.point[mesh.Index(i2, j2)];
            ++c;
          }
        }
        if (c > 0) added.emplace_back(k, sum / c);
      }
    }
    for (const auto& [k, p] : added) {
      mesh.kind[k] = NodeKind::kSkirt;
      mesh.point[k] = p;
    }
  }
}

}  // namespace

Mesh BuildMesh(const cv::Mat& points, const cv::Mat& page_mask, const MeshOptions& options,
               const std::function<cv::Point2d(const cv::Vec3d&)>& project) {
  Mesh mesh;
  std::string why;
  if (!options.Check(&why)) {
    mesh.status = Status::Error("mesh options: " + why);
    return mesh;
  }
  if (points.type() != CV_32FC3 || page_mask.type() != CV_8U || points.size() != page_mask.size()) {
    mesh.status = Status::Error(
        "mesh input: the point map must be CV_32FC3 and the page mask "
        "CV_8U of the same size");
    return mesh;
  }
  const cv::Rect box = cv::boundingRect(page_mask);
  if (box.width < 2 || box.height < 2) {
    mesh.status = Status::Error("no page found in the texture image (empty page mask)");
    return mesh;
  }
  const int g = options.grid.width, h = options.grid.height;
  mesh.cols = g;
  mesh.rows = h;
  const int n = g * h;
  mesh.kind.assign(n, NodeKind::kOff);
  mesh.point.assign(n, cv::Vec3d(0, 0, 0));
  mesh.pixel.assign(n, cv::Point2d(0, 0));
  const double step_u = (box.width - 1.0) / (g - 1), step_v = (box.height - 1.0) / (h - 1);
  // Windows never shrink below 13 x 13 pixels, so fine grids keep smooth, well-averaged nodes.
  const int hu = std::max(6, static_cast<int>(std::lround(options.fit_window * step_u)));
  const int hv = std::max(6, static_cast<int>(std::lround(options.fit_window * step_v)));
  std::vector<cv::Point2d> grid_px(n);
  std::vector<uint8_t> on_page(n, 0);
  std::vector<FitQuality> fits(options.rest_along_surface ? n : 0);
  for (int j = 0; j < h; ++j) {
    for (int i = 0; i < g; ++i) {
      const cv::Point2d p(box.x + i * step_u, box.y + j * step_v);
      grid_px[mesh.Index(i, j)] = p;
      on_page[mesh.Index(i, j)] = page_mask.at<uint8_t>(cvRound(p.y), cvRound(p.x)) != 0;
    }
  }
  FitNodes(points, page_mask, options, grid_px, on_page, hu, hv, &fits, &mesh);
  mesh.measured =
      static_cast<int>(std::count(mesh.kind.begin(), mesh.kind.end(), NodeKind::kMeasured));
  if (mesh.measured == 0) {
    mesh.status = Status::Error("no valid 3D points on the page: nothing to flatten");
    return mesh;
  }
  const std::vector<uint8_t> peeled_off = PeelHeldByOne(&mesh);
  FillHoles(&mesh);
  AddSkirt(options.skirt_rings, peeled_off, &mesh);
  ConnectSheet(options.bend_springs, project, &mesh);
  if (mesh.status.ok() && options.rest_along_surface) {
    MeasureAlongSurface(points, page_mask, grid_px, fits, options.straight_mm, options.min_bend_deg,
                        &mesh);
  }
  return mesh;
}

}  // namespace vellum
