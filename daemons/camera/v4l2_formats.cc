#include "daemons/camera/v4l2_formats.h"

#include <linux/videodev2.h>

#include <algorithm>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace vellum::station {
namespace {

// The station's preferences, best first. Colour: a Bayer sensor's own samples at the most bits
// (demosaiced here), then the camera's BGR, then YUYV (chroma at half the width), then 8-bit
// Bayer, then MJPEG last: its 8 x 8 blocks and ringing blur the patterns' edges the decoder
// reads. Gray: a monochrome sensor at the most bits, then the colour formats' luma.
constexpr uint32_t kColour[] = {V4L2_PIX_FMT_SRGGB16, V4L2_PIX_FMT_SRGGB12, V4L2_PIX_FMT_SRGGB10,
                                V4L2_PIX_FMT_BGR24,   V4L2_PIX_FMT_YUYV,    V4L2_PIX_FMT_SRGGB8,
                                V4L2_PIX_FMT_MJPEG};
constexpr uint32_t kGray[] = {V4L2_PIX_FMT_Y16, V4L2_PIX_FMT_Y12, V4L2_PIX_FMT_Y10,
                              V4L2_PIX_FMT_GREY};

std::vector<uint32_t> Preference(bool gray_first) {
  std::vector<uint32_t> colour(std::begin(kColour), std::end(kColour));
  std::vector<uint32_t> gray(std::begin(kGray), std::end(kGray));
  std::vector<uint32_t> order = gray_first ? gray : colour;
  const std::vector<uint32_t>& then = gray_first ? colour : gray;
  order.insert(order.end(), then.begin(), then.end());
  return order;
}

std::string SizeText(cv::Size s) {
  return std::to_string(s.width) + "x" + std::to_string(s.height);
}

std::string Offered(const std::vector<DeviceFormat>& offered) {
  std::string text;
  for (const DeviceFormat& f : offered) {
    if (!text.empty()) text += "; ";
    text += FourccText(f.fourcc);
    if (f.emulated) text += " (libv4l2's)";
    for (size_t k = 0; k < f.sizes.size(); ++k) text += (k ? ", " : " ") + SizeText(f.sizes[k]);
  }
  return text.empty() ? "nothing" : text;
}

bool OffersSize(const DeviceFormat& f, cv::Size size) {
  return f.sizes.empty() || std::find(f.sizes.begin(), f.sizes.end(), size) != f.sizes.end();
}

// The samples of a 16-bit container format (low-aligned, little-endian as V4L2 stores them),
// scaled to full scale.
cv::Mat Deep(cv::Size size, int channels, uint32_t bytes_per_line, const uint8_t* data, int bits) {
  cv::Mat wrapped(size, CV_16UC(channels), const_cast<uint8_t*>(data), bytes_per_line);
  cv::Mat out;
  wrapped.convertTo(out, CV_16U, static_cast<double>(1 << (16 - bits)));
  return out;
}

}  // namespace

std::string FourccText(uint32_t fourcc) {
  std::string text(4, ' ');
  for (int k = 0; k < 4; ++k) {
    const char c = static_cast<char>((fourcc >> (8 * k)) & 0xff);
    text[k] = c >= 32 && c < 127 ? c : '?';
  }
  return text;
}

uint32_t FourccFromText(const std::string& text) {
  if (text.empty() || text.size() > 4) return 0;
  uint32_t fourcc = 0;
  for (int k = 0; k < 4; ++k) {
    const unsigned char c = k < static_cast<int>(text.size()) ? text[k] : ' ';
    fourcc |= static_cast<uint32_t>(c) << (8 * k);
  }
  return fourcc;
}

int FormatBits(uint32_t fourcc) {
  switch (fourcc) {
    case V4L2_PIX_FMT_GREY:
    case V4L2_PIX_FMT_BGR24:
    case V4L2_PIX_FMT_YUYV:
    case V4L2_PIX_FMT_SRGGB8:
    case V4L2_PIX_FMT_MJPEG:
      return 8;
    case V4L2_PIX_FMT_Y10:
    case V4L2_PIX_FMT_SRGGB10:
      return 10;
    case V4L2_PIX_FMT_Y12:
    case V4L2_PIX_FMT_SRGGB12:
      return 12;
    case V4L2_PIX_FMT_Y16:
    case V4L2_PIX_FMT_SRGGB16:
      return 16;
    default:
      return 0;
  }
}

bool FormatIsColour(uint32_t fourcc) {
  return std::find(std::begin(kColour), std::end(kColour), fourcc) != std::end(kColour);
}

Status ChooseFormat(const std::vector<DeviceFormat>& offered, const std::string& want,
                    cv::Size size, uint32_t* chosen, std::string* why) {
  const std::string asked = want == "BGR3" ? "auto" : want;  // BGR3: the old name of colour.
  std::vector<uint32_t> order;
  if (asked == "auto" || asked == "GREY") {
    order = Preference(asked == "GREY");
  } else {
    const uint32_t fourcc = FourccFromText(asked);
    if (FormatBits(fourcc) == 0) {
      return Status::Error("format '" + want + "' is not one vellum takes (auto, GREY, " +
                           "or one of Y16, Y12, Y10, GREY, RG16, RG12, RG10, BGR3, YUYV, " +
                           "RGGB, MJPG)");
    }
    order = {fourcc};
  }
  // The camera's own formats before libv4l2's conversions of them.
  for (bool emulated : {false, true}) {
    for (uint32_t fourcc : order) {
      for (const DeviceFormat& f : offered) {
        if (f.fourcc != fourcc || f.emulated != emulated || !OffersSize(f, size)) continue;
        *chosen = fourcc;
        *why = FourccText(fourcc) + " at " + SizeText(size) + ", " +
               std::to_string(FormatBits(fourcc)) + " bits" +
               (FormatIsColour(fourcc) ? "" : ", monochrome") +
               (emulated ? " (converted by libv4l2)" : "") + "; the camera offers " +
               Offered(offered);
        return Status::Ok();
      }
    }
  }
  return Status::Error("no format vellum takes (" + want + ") at " + SizeText(size) +
                       ": the camera offers " + Offered(offered));
}

Status ConvertFrame(uint32_t fourcc, cv::Size size, uint32_t bytes_per_line, const uint8_t* data,
                    size_t used, cv::Mat* image) {
  const int bits = FormatBits(fourcc);
  if (bits == 0)
    return Status::Error("frame format " + FourccText(fourcc) + " is not one vellum takes");
  if (fourcc == V4L2_PIX_FMT_MJPEG) {
    const cv::Mat bytes(1, static_cast<int>(used), CV_8U, const_cast<uint8_t*>(data));
    cv::Mat decoded = used > 0 ? cv::imdecode(bytes, cv::IMREAD_COLOR) : cv::Mat();
    if (decoded.size() != size) {
      return Status::Error("an MJPEG frame of " + std::to_string(used) + " bytes " +
                           (decoded.empty() ? "does not decode" : "decodes to another size"));
    }
    *image = decoded;
    return Status::Ok();
  }
  const int bytes_per_pixel = fourcc == V4L2_PIX_FMT_BGR24  ? 3
                              : fourcc == V4L2_PIX_FMT_YUYV ? 2
                              : bits > 8                    ? 2
                                                            : 1;
  const size_t row = static_cast<size_t>(size.width) * bytes_per_pixel;
  const size_t stride = bytes_per_line > 0 ? bytes_per_line : row;
  if (stride < row || used < stride * (size.height - 1) + row) {
    return Status::Error("a short frame: " + std::to_string(used) + " bytes where " +
                         SizeText(size) + " " + FourccText(fourcc) + " needs " +
                         std::to_string(stride * (size.height - 1) + row));
  }
  uint8_t* bytes = const_cast<uint8_t*>(data);
  switch (fourcc) {
    case V4L2_PIX_FMT_GREY:
      *image = cv::Mat(size, CV_8UC1, bytes, stride).clone();
      break;
    case V4L2_PIX_FMT_BGR24:
      *image = cv::Mat(size, CV_8UC3, bytes, stride).clone();
      break;
    case V4L2_PIX_FMT_YUYV:
      cv::cvtColor(cv::Mat(size, CV_8UC2, bytes, stride), *image, cv::COLOR_YUV2BGR_YUYV);
      break;
    case V4L2_PIX_FMT_SRGGB8:
      // OpenCV names a Bayer pattern by its second row's second and third samples: RGGB is
      // its "BG".
      cv::cvtColor(cv::Mat(size, CV_8UC1, bytes, stride), *image, cv::COLOR_BayerBG2BGR);
      break;
    case V4L2_PIX_FMT_Y10:
    case V4L2_PIX_FMT_Y12:
    case V4L2_PIX_FMT_Y16:
      *image = Deep(size, 1, static_cast<uint32_t>(stride), data, bits);
      break;
    default:  // 10-, 12- and 16-bit RGGB.
      cv::cvtColor(Deep(size, 1, static_cast<uint32_t>(stride), data, bits), *image,
                   cv::COLOR_BayerBG2BGR);
      break;
  }
  return Status::Ok();
}

}  // namespace vellum::station
