#include "core/shading/photometric.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

namespace vellum {
namespace {

// Each light's image as a share of its full scale, gray (CV_32F), and with `colours` in colour
// too (CV_32FC3, BGR; a gray image as gray). An error names the image that is not 8 or 16 bit,
// gray or colour, of the first's size.
Status LightLevels(const std::vector<cv::Mat>& images, std::vector<cv::Mat>* levels,
                   std::vector<cv::Mat>* colours = nullptr) {
  levels->assign(images.size(), cv::Mat());
  if (colours) colours->assign(images.size(), cv::Mat());
  for (size_t k = 0; k < images.size(); ++k) {
    const cv::Mat& im = images[k];
    if (im.empty() || im.size() != images[0].size() ||
        (im.depth() != CV_8U && im.depth() != CV_16U) ||
        (im.channels() != 1 && im.channels() != 3)) {
      return Status::Error("light image " + std::to_string(k) +
                           " must be 8 or 16 bit, gray or colour, of the first's size");
    }
    const double full = im.depth() == CV_8U ? 255.0 : 65535.0;
    cv::Mat gray = im;
    if (im.channels() == 3) cv::cvtColor(im, gray, cv::COLOR_BGR2GRAY);
    gray.convertTo((*levels)[k], CV_32F, 1.0 / full);
    if (colours) {
      cv::Mat bgr = im;
      if (im.channels() == 1) cv::cvtColor(im, bgr, cv::COLOR_GRAY2BGR);
      bgr.convertTo((*colours)[k], CV_32FC3, 1.0 / full);
    }
  }
  return Status::Ok();
}

}  // namespace

bool PhotometricOptions::Check(std::string* why) const {
  if (!(min_level >= 0 && min_level < max_level && max_level <= 1)) {
    *why = "photometric: min_level and max_level must hold 0 <= min_level < max_level <= 1";
    return false;
  }
  return true;
}

PhotometricResult PhotometricNormals(const std::vector<cv::Mat>& images,
                                     const std::vector<cv::Vec3d>& directions, const cv::Mat& mask,
                                     const PhotometricOptions& options) {
  PhotometricResult result;
  if (std::string why; !options.Check(&why)) {
    result.status = Status::Error(why);
    return result;
  }
  if (images.size() < 3 || images.size() != directions.size()) {
    result.status = Status::Error(
        "photometric normals need three or more lights, each with a "
        "direction (got " +
        std::to_string(images.size()) + " images and " + std::to_string(directions.size()) +
        " directions)");
    return result;
  }
  const cv::Size size = images[0].size();
  std::vector<cv::Mat> levels;
  if (const Status s = LightLevels(images, &levels); !s.ok()) {
    result.status = s;
    return result;
  }
  for (size_t k = 0; k < images.size(); ++k) {
    const double norm = cv::norm(directions[k]);
    if (!(norm > 1e-9)) {
      result.status = Status::Error("light " + std::to_string(k) + " has no direction");
      return result;
    }
  }
  if (!mask.empty() && (mask.type() != CV_8U || mask.size() != size)) {
    result.status = Status::Error("the mask must be CV_8U of the images' size");
    return result;
  }
  std::vector<cv::Vec3d> l(directions.size());
  for (size_t k = 0; k < l.size(); ++k) l[k] = cv::normalize(directions[k]);
  result.normals = cv::Mat::zeros(size, CV_32FC3);
  result.albedo = cv::Mat::zeros(size, CV_32F);
  result.valid = cv::Mat::zeros(size, CV_8U);
  const float lo = static_cast<float>(options.min_level),
              hi = static_cast<float>(options.max_level);
  const int n = static_cast<int>(l.size());
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& range) {
    std::vector<const float*> rows(n);
    for (int v = range.start; v < range.end; ++v) {
      for (int k = 0; k < n; ++k) rows[k] = levels[k].ptr<float>(v);
      const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(v);
      cv::Vec3f* normal = result.normals.ptr<cv::Vec3f>(v);
      float* albedo = result.albedo.ptr<float>(v);
      uint8_t* valid = result.valid.ptr<uint8_t>(v);
      for (int u = 0; u < size.width; ++u) {
        if (m && !m[u]) continue;
        // Normal equations over the lights that light the pixel: (sum l l^T) g = sum level l.
        cv::Matx33d a = cv::Matx33d::zeros();
        cv::Vec3d b(0, 0, 0);
        int used = 0;
        for (int k = 0; k < n; ++k) {
          const float level = rows[k][u];
          if (level < lo || level > hi) continue;
          a += l[k] * l[k].t();
          b += level * l[k];
          ++used;
        }
        if (used < 3) continue;
        // Lights (nearly) in one plane cannot fix the normal.
        if (!(std::fabs(cv::determinant(a)) > 1e-6)) continue;
        const cv::Vec3d g = a.solve(b, cv::DECOMP_CHOLESKY);
        const double rho = cv::norm(g);
        if (!(rho > 1e-9)) continue;
        cv::Vec3d nn = g / rho;
        if (nn[2] < 0) continue;  // Facing away from the camera: not a surface it sees.
        normal[u] = cv::Vec3f(nn);
        albedo[u] = static_cast<float>(rho);
        valid[u] = 255;
      }
    }
  });
  result.solved = cv::countNonZero(result.valid);
  const int wanted = mask.empty() ? size.area() : cv::countNonZero(mask);
  result.marked = wanted - result.solved;
  result.status = Status::Ok();
  return result;
}

PtmResult FitPtm(const std::vector<cv::Mat>& images, const std::vector<cv::Vec3d>& directions,
                 const cv::Mat& right, const cv::Mat& up, const PhotometricOptions& options) {
  PtmResult result;
  if (std::string why; !options.Check(&why)) {
    result.status = Status::Error(why);
    return result;
  }
  if (images.size() < 6 || images.size() != directions.size() || right.type() != CV_32FC3 ||
      up.type() != CV_32FC3 || right.size() != images[0].size() || up.size() != right.size()) {
    result.status = Status::Error(
        "a PTM needs six or more lights, each with a direction, and the page's frame (got " +
        std::to_string(images.size()) + " images and " + std::to_string(directions.size()) +
        " directions)");
    return result;
  }
  double low = 1, high = -1;
  for (const cv::Vec3d& d : directions) {
    const double z = d[2] / std::max(1e-12, cv::norm(d));
    low = std::min(low, z), high = std::max(high, z);
  }
  if (!(high - low > 0.05)) {
    result.status = Status::Error(
        "a PTM needs lights at two or more elevations (these are all within 3 degrees of one: "
        "the fit cannot tell lu^2 + lv^2 from a constant)");
    return result;
  }
  const cv::Size size = images[0].size();
  const int n = static_cast<int>(images.size());
  std::vector<cv::Mat> levels, colours;
  if (const Status s = LightLevels(images, &levels, &colours); !s.ok()) {
    result.status = s;
    return result;
  }
  result.coefficients = cv::Mat::zeros(size, CV_32FC(6));
  result.rgb = cv::Mat::zeros(size, CV_32FC3);
  result.valid = cv::Mat::zeros(size, CV_8U);
  std::atomic<int> solved{0};
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& rows) {
    int mine = 0;
    for (int v = rows.start; v < rows.end; ++v) {
      const cv::Vec3f* r = right.ptr<cv::Vec3f>(v);
      const cv::Vec3f* p = up.ptr<cv::Vec3f>(v);
      auto* out = result.coefficients.ptr<cv::Vec<float, 6>>(v);
      cv::Vec3f* rgb = result.rgb.ptr<cv::Vec3f>(v);
      uint8_t* ok = result.valid.ptr<uint8_t>(v);
      for (int u = 0; u < size.width; ++u) {
        if (r[u].dot(r[u]) < 0.25f || p[u].dot(p[u]) < 0.25f) continue;  // Off the sheet.
        cv::Matx<double, 6, 6> ata = cv::Matx<double, 6, 6>::zeros();
        cv::Vec<double, 6> atb(0, 0, 0, 0, 0, 0);
        cv::Vec3d colour(0, 0, 0);
        double luminance = 0;
        int used = 0;
        for (int k = 0; k < n; ++k) {
          const float level = levels[k].at<float>(v, u);
          // Clipped, or turned away from the light (the polynomial cannot bend to a clamp at 0).
          if (!(level <= options.max_level) || !(level >= options.min_level)) continue;
          const cv::Vec3d d = directions[k];
          const double lu = d.dot(cv::Vec3d(r[u])), lv = d.dot(cv::Vec3d(p[u]));
          const cv::Vec<double, 6> row(lu * lu, lv * lv, lu * lv, lu, lv, 1.0);
          ata += row * row.t();
          atb += row * static_cast<double>(level);
          colour += cv::Vec3d(colours[k].at<cv::Vec3f>(v, u));
          luminance += level;
          ++used;
        }
        if (used < 6) continue;
        cv::Vec<double, 6> a;
        if (!cv::solve(ata, atb, a, cv::DECOMP_CHOLESKY)) continue;
        out[u] = cv::Vec<float, 6>(a);
        for (int c = 0; c < 3; ++c) {
          rgb[u][c] = luminance > 0 ? static_cast<float>(std::min(1.0, colour[c] / luminance)) : 0;
        }
        ok[u] = 255;
        ++mine;
      }
    }
    solved += mine;
  });
  result.solved = solved;
  result.status = result.solved > 0
                      ? Status::Ok()
                      : Status::Error("PTM: no pixel with six or more unclipped lights");
  return result;
}

cv::Mat NormalsOnPage(const cv::Mat& normals, const cv::Mat& right, const cv::Mat& up,
                      const cv::Mat& normal) {
  CV_Assert(normals.type() == CV_32FC3 && right.type() == CV_32FC3 && up.type() == CV_32FC3 &&
            normal.type() == CV_32FC3 && right.size() == normals.size() &&
            up.size() == normals.size() && normal.size() == normals.size());
  cv::Mat out = cv::Mat::zeros(normals.size(), CV_32FC3);
  for (int v = 0; v < normals.rows; ++v) {
    const cv::Vec3f* n = normals.ptr<cv::Vec3f>(v);
    const cv::Vec3f* r = right.ptr<cv::Vec3f>(v);
    const cv::Vec3f* p = up.ptr<cv::Vec3f>(v);
    const cv::Vec3f* z = normal.ptr<cv::Vec3f>(v);
    cv::Vec3f* o = out.ptr<cv::Vec3f>(v);
    for (int u = 0; u < normals.cols; ++u) {
      const float length = static_cast<float>(cv::norm(n[u]));
      if (length < 0.5f || z[u].dot(z[u]) < 0.5f) continue;
      const cv::Vec3f w = n[u] / length;
      o[u] = cv::normalize(cv::Vec3f(w.dot(r[u]), w.dot(p[u]), w.dot(z[u])));
    }
  }
  return out;
}

cv::Mat NormalMapImage(const cv::Mat& normals) {
  CV_Assert(normals.type() == CV_32FC3);
  cv::Mat out = cv::Mat::zeros(normals.size(), CV_16UC3);
  for (int v = 0; v < normals.rows; ++v) {
    const cv::Vec3f* n = normals.ptr<cv::Vec3f>(v);
    cv::Vec3w* o = out.ptr<cv::Vec3w>(v);
    for (int u = 0; u < normals.cols; ++u) {
      if (n[u].dot(n[u]) < 0.25f) continue;
      auto enc = [](float c) { return cv::saturate_cast<uint16_t>((c + 1.0f) * 0.5f * 65535.0f); };
      o[u] = cv::Vec3w(enc(n[u][2]), enc(n[u][1]), enc(n[u][0]));  // B = z, G = y, R = x.
    }
  }
  return out;
}

}  // namespace vellum
