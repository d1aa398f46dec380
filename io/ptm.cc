#include "io/ptm.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <sstream>
#include <vector>

#include "io/write_whole.h"

namespace vellum {

Status WritePtm(const std::string& path, const PtmResult& ptm) {
  if (!ptm.status.ok() || ptm.coefficients.type() != CV_32FC(6) || ptm.rgb.type() != CV_32FC3 ||
      ptm.valid.type() != CV_8U) {
    return Status::Error(path + ": no fitted PTM to write");
  }
  const cv::Size size = ptm.coefficients.size();
  // Each coefficient's range over the fitted pixels, and 0 (a marked pixel's): 256 steps.
  std::array<double, 6> low, high;
  low.fill(0);
  high.fill(0);
  for (int v = 0; v < size.height; ++v) {
    const auto* a = ptm.coefficients.ptr<cv::Vec<float, 6>>(v);
    const uint8_t* ok = ptm.valid.ptr<uint8_t>(v);
    for (int u = 0; u < size.width; ++u) {
      if (!ok[u]) continue;
      for (int k = 0; k < 6; ++k) {
        low[k] = std::min(low[k], static_cast<double>(a[u][k]));
        high[k] = std::max(high[k], static_cast<double>(a[u][k]));
      }
    }
  }
  std::array<double, 6> scale;
  std::array<int, 6> bias;
  for (int k = 0; k < 6; ++k) {
    scale[k] = std::max((high[k] - low[k]) / 255.0, 1e-9);
    bias[k] = std::clamp(static_cast<int>(std::lround(-low[k] / scale[k])), 0, 255);
  }
  std::ostringstream header;
  header.precision(9);
  header << "PTM_1.2\nPTM_FORMAT_LRGB\n" << size.width << "\n" << size.height << "\n";
  for (int k = 0; k < 6; ++k) header << scale[k] << (k < 5 ? " " : "\n");
  for (int k = 0; k < 6; ++k) header << bias[k] << (k < 5 ? " " : "\n");
  std::vector<uint8_t> coefficients(static_cast<size_t>(size.area()) * 6),
      colour(static_cast<size_t>(size.area()) * 3);
  size_t at = 0;
  for (int v = size.height - 1; v >= 0; --v, at += size.width) {  // Bottom row first.
    const auto* a = ptm.coefficients.ptr<cv::Vec<float, 6>>(v);
    const cv::Vec3f* bgr = ptm.rgb.ptr<cv::Vec3f>(v);
    const uint8_t* ok = ptm.valid.ptr<uint8_t>(v);
    for (int u = 0; u < size.width; ++u) {
      uint8_t* c = &coefficients[(at + u) * 6];
      uint8_t* rgb = &colour[(at + u) * 3];
      for (int k = 0; k < 6; ++k) {
        const double value = ok[u] ? a[u][k] : 0.0;
        c[k] = cv::saturate_cast<uint8_t>(value / scale[k] + bias[k]);
      }
      for (int ch = 0; ch < 3; ++ch) {
        rgb[ch] = ok[u] ? cv::saturate_cast<uint8_t>(255.0 * bgr[u][2 - ch]) : 0;
      }
    }
  }
  return WriteWhole(path, [&](const std::string& part) {
    std::ofstream out(part, std::ios::binary | std::ios::trunc);
    const std::string text = header.str();
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    out.write(reinterpret_cast<const char*>(coefficients.data()),
              static_cast<std::streamsize>(coefficients.size()));
    out.write(reinterpret_cast<const char*>(colour.data()),
              static_cast<std::streamsize>(colour.size()));
    out.close();
    if (!out) return Status::Error(path + ": cannot write");
    return Status::Ok();
  });
}

Status ReadPtm(const std::string& path, PtmResult* ptm) {
  *ptm = PtmResult();
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error(path + ": cannot read");
  std::string version, format;
  int width = 0, height = 0;
  std::array<double, 6> scale;
  std::array<int, 6> bias;
  in >> version >> format >> width >> height;
  for (double& s : scale) in >> s;
  for (int& b : bias) in >> b;
  if (!in || version != "PTM_1.2" || format != "PTM_FORMAT_LRGB") {
    return Status::Error(path + ": not a PTM_1.2 PTM_FORMAT_LRGB file");
  }
  if (width <= 0 || height <= 0 || width > 65536 || height > 65536) {
    return Status::Error(path + ": bad size " + std::to_string(width) + "x" +
                         std::to_string(height));
  }
  for (int k = 0; k < 6; ++k) {
    // What a byte can be offset by, and a scale a float holds (the coefficients are floats).
    if (bias[k] < 0 || bias[k] > 255 || !(std::abs(scale[k]) < 1e30)) {
      return Status::Error(path + ": coefficient " + std::to_string(k) + "'s scale " +
                           std::to_string(scale[k]) + " or bias " + std::to_string(bias[k]) +
                           " is out of range (a finite scale, a bias of 0 to 255)");
    }
  }
  in.get();  // The newline after the biases.
  const size_t pixels = static_cast<size_t>(width) * height;
  // The data the header promises must be in the file before it is allocated (a few bytes of
  // header can claim 65536 x 65536 pixels, 38 GB).
  const std::streamoff here = in.tellg();
  in.seekg(0, std::ios::end);
  const std::streamoff left = in.tellg() - here;
  in.seekg(here);
  if (here < 0 || left < static_cast<std::streamoff>(pixels * 9)) {
    return Status::Error(path + ": shorter than its size says (" + std::to_string(width) + "x" +
                         std::to_string(height) + " pixels need " + std::to_string(pixels * 9) +
                         " bytes after the header)");
  }
  std::vector<uint8_t> coefficients(pixels * 6), colour(pixels * 3);
  in.read(reinterpret_cast<char*>(coefficients.data()),
          static_cast<std::streamsize>(coefficients.size()));
  in.read(reinterpret_cast<char*>(colour.data()), static_cast<std::streamsize>(colour.size()));
  if (!in) return Status::Error(path + ": shorter than its size says");
  ptm->coefficients = cv::Mat::zeros(height, width, CV_32FC(6));
  ptm->rgb = cv::Mat::zeros(height, width, CV_32FC3);
  ptm->valid = cv::Mat::zeros(height, width, CV_8U);
  size_t at = 0;
  for (int v = height - 1; v >= 0; --v, at += width) {
    auto* a = ptm->coefficients.ptr<cv::Vec<float, 6>>(v);
    cv::Vec3f* bgr = ptm->rgb.ptr<cv::Vec3f>(v);
    uint8_t* ok = ptm->valid.ptr<uint8_t>(v);
    for (int u = 0; u < width; ++u) {
      const uint8_t* c = &coefficients[(at + u) * 6];
      const uint8_t* rgb = &colour[(at + u) * 3];
      for (int k = 0; k < 6; ++k) a[u][k] = static_cast<float>((c[k] - bias[k]) * scale[k]);
      for (int ch = 0; ch < 3; ++ch) bgr[u][2 - ch] = rgb[ch] / 255.0f;
      ok[u] = (rgb[0] | rgb[1] | rgb[2]) ? 255 : 0;
      ptm->solved += ok[u] != 0;
    }
  }
  ptm->status = Status::Ok();
  return Status::Ok();
}

}  // namespace vellum
