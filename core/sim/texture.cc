#include "core/sim/texture.h"

#include <algorithm>
#include <cmath>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace vellum {
namespace {

constexpr double kTextPxPerMm = 8.0;

cv::Mat MakeText(cv::Size2d page_mm, uint64_t seed) {
  cv::Mat img(cv::Size(static_cast<int>(page_mm.width * kTextPxPerMm),
                       static_cast<int>(page_mm.height * kTextPxPerMm)),
              CV_8U, cv::Scalar(255));
  cv::RNG rng(seed);
  const std::string letters = "abcdefghijklmnopqrstuvwxyz";
  const int margin = static_cast<int>(15 * kTextPxPerMm);
  const int line_px = static_cast<int>(7 * kTextPxPerMm);
  for (int y = margin; y < img.rows - margin; y += line_px) {
    int x = margin;
    while (true) {
      std::string word;
      const int len = rng.uniform(2, 9);
      for (int i = 0; i < len; ++i) word += letters[rng.uniform(0, 26)];
      int baseline = 0;
      const double scale = 1.6;
      const cv::Size ts = cv::getTextSize(word, cv::FONT_HERSHEY_COMPLEX, scale, 3, &baseline);
      if (x + ts.width > img.cols - margin) break;
      cv::putText(img, word, cv::Point(x, y), cv::FONT_HERSHEY_COMPLEX, scale, cv::Scalar(0), 3,
                  cv::LINE_AA);
      x += ts.width + ts.height / 2;
    }
  }
  return img;
}

}  // namespace

const char* ToString(TextureKind kind) {
  switch (kind) {
    case TextureKind::kPlain:
      return "plain";
    case TextureKind::kCheckerboard:
      return "checkerboard";
    case TextureKind::kText:
      return "text";
    case TextureKind::kImage:
      return "image";
  }
  return "?";
}

bool ParseTextureKind(const std::string& text, TextureKind* kind) {
  for (TextureKind k :
       {TextureKind::kPlain, TextureKind::kCheckerboard, TextureKind::kText, TextureKind::kImage}) {
    if (text == ToString(k)) {
      *kind = k;
      return true;
    }
  }
  return false;
}

bool TextureOptions::Check(std::string* why) const {
  auto share = [](double x) { return x >= 0 && x <= 1; };
  if (!share(paper_albedo) || !share(ink_albedo) || !(square_mm > 0) || !(margin_mm >= 0)) {
    *why = "texture: paper_albedo and ink_albedo must be in [0, 1], square_mm > 0, margin_mm >= 0";
    return false;
  }
  if (kind == TextureKind::kImage && (image.empty() || image.depth() != CV_8U ||
                                      (image.channels() != 1 && image.channels() != 3))) {
    *why = "texture: an image page needs an 8-bit gray or BGR image";
    return false;
  }
  return true;
}

PageTexture::PageTexture(const TextureOptions& options, cv::Size2d page_size_mm)
    : options_(options), page_size_(page_size_mm) {
  if (std::string why; !options.Check(&why)) throw std::invalid_argument(why);
  cv::Mat gray;
  if (options.kind == TextureKind::kText) {
    gray = MakeText(page_size_mm, options.seed);
  } else if (options.kind == TextureKind::kImage) {
    if (options.image.channels() == 3) {
      cv::cvtColor(options.image, gray, cv::COLOR_BGR2GRAY);
      // Each channel against the gray, both lifted off zero so that ink keeps a finite hue.
      cv::Mat colour, luma;
      options.image.convertTo(colour, CV_32FC3, 1.0, 8.0);
      gray.convertTo(luma, CV_32F, 1.0, 8.0);
      cv::Mat luma3;
      cv::merge(std::vector<cv::Mat>{luma, luma, luma}, luma3);
      cv::divide(colour, luma3, tint_);
      if (cv::norm(tint_ - cv::Scalar::all(1), cv::NORM_INF) < 1e-3) tint_.release();  // Gray.
    } else {
      gray = options.image;
    }
  }
  if (!gray.empty()) {
    // 0 -> ink, 255 -> paper.
    gray.convertTo(albedo_, CV_32F, (options.paper_albedo - options.ink_albedo) / 255.0,
                   options.ink_albedo);
    px_per_mm_x_ = albedo_.cols / page_size_mm.width;
    px_per_mm_y_ = albedo_.rows / page_size_mm.height;
  }
}

double PageTexture::Albedo(double s, double t) const {
  switch (options_.kind) {
    case TextureKind::kPlain:
      return options_.paper_albedo;
    case TextureKind::kCheckerboard: {
      // Whole squares centred on the page, inside a margin of bare paper.
      const double m = options_.margin_mm, q = options_.square_mm;
      const int nx = static_cast<int>((page_size_.width - 2 * m) / q);
      const int ny = static_cast<int>((page_size_.height - 2 * m) / q);
      const double x0 = 0.5 * (page_size_.width - nx * q), y0 = 0.5 * (page_size_.height - ny * q);
      const double u = (s - x0) / q, v = (t - y0) / q;
      if (u < 0 || v < 0 || u >= nx || v >= ny) return options_.paper_albedo;
      const long i = static_cast<long>(std::floor(u)), j = static_cast<long>(std::floor(v));
      return ((i + j) & 1) ? options_.paper_albedo : options_.ink_albedo;
    }
    case TextureKind::kText:
    case TextureKind::kImage: {
      // Bilinear lookup, pixel centres at (i + 0.5) / px_per_mm. The image's top row is the
      // page's top edge, t = height (t runs up the page, as world y does on the table), so the
      // page reads the right way up from above: in the texture and in the restored page.
      const double x = std::clamp(s * px_per_mm_x_ - 0.5, 0.0, albedo_.cols - 1.0);
      const double y =
          std::clamp((page_size_.height - t) * px_per_mm_y_ - 0.5, 0.0, albedo_.rows - 1.0);
      const int x0 = std::min(static_cast<int>(x), albedo_.cols - 2);
      const int y0 = std::min(static_cast<int>(y), albedo_.rows - 2);
      const double fx = x - x0, fy = y - y0;
      const float* r0 = albedo_.ptr<float>(y0);
      const float* r1 = albedo_.ptr<float>(y0 + 1);
      return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) +
             fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
    }
  }
  return options_.paper_albedo;
}

cv::Vec3d PageTexture::Tint(double s, double t) const {
  if (tint_.empty()) return cv::Vec3d(1, 1, 1);
  const int x = std::clamp(static_cast<int>(s * px_per_mm_x_), 0, tint_.cols - 1);
  const int y =
      std::clamp(static_cast<int>((page_size_.height - t) * px_per_mm_y_), 0, tint_.rows - 1);
  return cv::Vec3d(tint_.at<cv::Vec3f>(y, x));
}

}  // namespace vellum
