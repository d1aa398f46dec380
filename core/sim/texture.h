// Page albedo for the virtual gantry: what the page looks like (paper, ink).
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>

namespace vellum {

enum class TextureKind { kPlain, kCheckerboard, kText, kImage };

const char* ToString(TextureKind kind);
bool ParseTextureKind(const std::string& text, TextureKind* kind);

struct TextureOptions {
  TextureKind kind = TextureKind::kCheckerboard;
  double paper_albedo = 0.85;  // Reflectance of bare paper, 0..1.
  double ink_albedo = 0.08;    // Reflectance of ink, 0..1.
  double square_mm = 10.0;     // kCheckerboard: square side, mm.
  double margin_mm = 10.0;     // kCheckerboard: bare paper around the board, mm.
  uint64_t seed = 1;           // kText: seed of the generated text.
  cv::Mat image;  // kImage: 8-bit gray or BGR image covering the whole page, top row at its top.

  bool Check(std::string* why) const;
};

class PageTexture {
 public:
  // Options that fail their Check() throw std::invalid_argument.
  PageTexture(const TextureOptions& options, cv::Size2d page_size_mm);
  // Albedo (0..1) at page coordinate (s, t) mm.
  double Albedo(double s, double t) const;
  // A colour image's hue at (s, t): each channel's albedo over Albedo (B, G, R); (1, 1, 1) for
  // gray kinds. The structured-light frames see Albedo; the studio-lit texture sees the colour.
  cv::Vec3d Tint(double s, double t) const;
  bool coloured() const { return !tint_.empty(); }

 private:
  TextureOptions options_;
  cv::Size2d page_size_;
  cv::Mat albedo_;  // CV_32F albedo image for kText and kImage.
  cv::Mat tint_;    // CV_32FC3 per-channel ratio to the gray, for a colour kImage; else empty.
  double px_per_mm_x_ = 1.0, px_per_mm_y_ = 1.0;
};

}  // namespace vellum
