#include "io/image_file.h"

#include <fcntl.h>
#include <png.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <vector>
#include <vips/vips8>

#include "io/vips.h"
#include "io/write_whole.h"

namespace vellum {
namespace {

// libpng's errors end in a longjmp back to ReadPng; its message is kept here.
void PngError(png_structp png, png_const_charp message) {
  auto* why = static_cast<std::string*>(png_get_error_ptr(png));
  if (why) *why = message;
  png_longjmp(png, 1);
}
void PngWarning(png_structp, png_const_charp) {}

// Reads a PNG into *image. Only plain data lives in this function between setjmp and longjmp:
// the image is allocated, and the row pointers made, before the rows are read.
bool ReadPng(std::FILE* file, cv::Mat* image, std::string* why) {
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, why, PngError, PngWarning);
  if (!png) return false;
  png_infop info = png_create_info_struct(png);
  // Set after setjmp and read after a longjmp: volatile, so its value then is the one set.
  png_bytep* volatile rows = nullptr;
  if (!info || setjmp(png_jmpbuf(png))) {
    png_free(png, rows);
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  png_init_io(png, file);
  png_read_info(png, info);
  const int colour = png_get_color_type(png, info);
  const int depth = png_get_bit_depth(png, info);
  if (colour == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (colour == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  png_set_strip_alpha(png);            // Also a palette's or a colour key's transparency.
  if (depth == 16) png_set_swap(png);  // PNG's samples are big-endian.
  png_set_bgr(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  const int channels = png_get_channels(png, info);
  const int bits = png_get_bit_depth(png, info);
  if ((channels != 1 && channels != 3) || (bits != 8 && bits != 16)) {
    *why = "an unusual PNG layout (" + std::to_string(channels) + " channels of " +
           std::to_string(bits) + " bits)";
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  const int rows_n = static_cast<int>(png_get_image_height(png, info));
  const int cols_n = static_cast<int>(png_get_image_width(png, info));
  image->create(rows_n, cols_n, CV_MAKETYPE(bits == 16 ? CV_16U : CV_8U, channels));
  rows = static_cast<png_bytep*>(png_malloc(png, sizeof(png_bytep) * rows_n));
  for (int y = 0; y < rows_n; ++y) rows[y] = image->ptr<png_byte>(y);
  png_read_image(png, rows);
  png_read_end(png, nullptr);
  png_free(png, rows);
  png_destroy_read_struct(&png, &info, nullptr);
  return true;
}

// A vips image over `image` (held, in RGB order for 8- and 16-bit colour, in *hold).
vips::VImage ToVips(const cv::Mat& image, cv::Mat* hold) {
  VipsBandFormat format = VIPS_FORMAT_UCHAR;
  switch (image.depth()) {
    case CV_8U:
      format = VIPS_FORMAT_UCHAR;
      break;
    case CV_16U:
      format = VIPS_FORMAT_USHORT;
      break;
    case CV_32F:
      format = VIPS_FORMAT_FLOAT;
      break;
    default:
      throw vips::VError("only 8-bit, 16-bit and float images are written");
  }
  if (image.channels() != 1 && image.channels() != 3) {
    throw vips::VError("only gray and colour images are written");
  }
  if (image.channels() == 3 && image.depth() != CV_32F) {
    cv::cvtColor(image, *hold, cv::COLOR_BGR2RGB);
  } else {
    *hold = image.isContinuous() ? image : image.clone();
  }
  vips::VImage out =
      vips::VImage::new_from_memory(hold->data, hold->total() * hold->elemSize(), hold->cols,
                                    hold->rows, hold->channels(), format);
  // A gray or colour image, not a multiband one: TIFF's photometric tag follows it.
  return out.copy(vips::VImage::option()->set(
      "interpretation",
      hold->channels() == 3
          ? (format == VIPS_FORMAT_USHORT ? VIPS_INTERPRETATION_RGB16 : VIPS_INTERPRETATION_sRGB)
          : (format == VIPS_FORMAT_USHORT ? VIPS_INTERPRETATION_GREY16 : VIPS_INTERPRETATION_B_W)));
}

// Any other format, by libvips: its first three bands (or its first), in BGR order.
Status ReadWithVips(const std::string& path, cv::Mat* image) {
  Status s = CheckVipsLoader(path);
  if (!s.ok()) return s;
  try {
    vips::VImage in = vips::VImage::new_from_file(
        path.c_str(), vips::VImage::option()->set("access", VIPS_ACCESS_SEQUENTIAL));
    // As OpenCV's readers: no image over 2^30 pixels (a header may claim gigabytes).
    if (static_cast<double>(in.width()) * in.height() > double{1 << 30}) {
      return Status::Error(path + ": its header claims " + std::to_string(in.width()) + "x" +
                           std::to_string(in.height()) + " pixels; not read");
    }
    // Colour that is not RGB (a CMYK or CIELAB file) goes to sRGB first, through the file's
    // own profile or libvips' fallback for its space: its first three bands are not R, G, B.
    switch (in.interpretation()) {
      case VIPS_INTERPRETATION_CMYK:
      case VIPS_INTERPRETATION_LAB:
      case VIPS_INTERPRETATION_LABQ:
      case VIPS_INTERPRETATION_LABS:
      case VIPS_INTERPRETATION_LCH:
      case VIPS_INTERPRETATION_CMC:
      case VIPS_INTERPRETATION_XYZ:
      case VIPS_INTERPRETATION_YXY:
      case VIPS_INTERPRETATION_HSV:
        in = in.colourspace(in.format() == VIPS_FORMAT_USHORT ? VIPS_INTERPRETATION_RGB16
                                                              : VIPS_INTERPRETATION_sRGB);
        break;
      default:
        break;
    }
    const int bands = in.bands() >= 3 ? 3 : 1;
    if (in.bands() != bands) in = in.extract_band(0, vips::VImage::option()->set("n", bands));
    const VipsBandFormat format = in.format();
    int depth = CV_8U;
    if (format == VIPS_FORMAT_USHORT) {
      depth = CV_16U;
    } else if (format == VIPS_FORMAT_FLOAT || format == VIPS_FORMAT_DOUBLE) {
      if (format == VIPS_FORMAT_DOUBLE) in = in.cast(VIPS_FORMAT_FLOAT);
      depth = CV_32F;
    } else if (format != VIPS_FORMAT_UCHAR) {
      // Signed or 32-bit integers have no one meaning as light: cast, they would be clipped.
      return Status::Error(path + ": its samples are " +
                           vips_enum_nick(VIPS_TYPE_BAND_FORMAT, format) +
                           "; images are read with 8- or 16-bit unsigned, or floating-point, "
                           "samples");
    }
    cv::Mat read(in.height(), in.width(), CV_MAKETYPE(depth, bands));
    size_t bytes = 0;
    void* pixels = in.write_to_memory(&bytes);
    if (bytes != read.total() * read.elemSize()) {
      g_free(pixels);
      return Status::Error(path + ": not a readable image");
    }
    std::memcpy(read.data, pixels, bytes);
    g_free(pixels);
    if (bands == 3 && depth != CV_32F) cv::cvtColor(read, read, cv::COLOR_RGB2BGR);
    *image = read;
  } catch (const vips::VError&) {
    return Status::Error(path + ": not a readable image");
  }
  return Status::Ok();
}

// Writes `image` with `save` (a libvips saver and its options, given the image and the name to
// write), whole or not at all (WriteWhole); errors name the file.
template <typename Save>
Status SaveWithVips(const std::string& path, const cv::Mat& image, const Save& save) {
  if (image.empty()) return Status::Error(path + ": cannot write an empty image");
  const Status s = StartVips();
  if (!s.ok()) return Status::Error(path + ": cannot write image: " + s.message());
  return WriteWhole(path, [&](const std::string& part) {
    try {
      cv::Mat hold;
      save(ToVips(image, &hold), part);
    } catch (const vips::VError& e) {
      return Status::Error(path + ": cannot write image: " + VipsErrorText(e.what()));
    }
    return Status::Ok();
  });
}

}  // namespace

Status CheckReadable(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return Status::Error(path + ": is a folder, not a file");
  }
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd >= 0) {
    ::close(fd);
    return Status::Ok();
  }
  const int error = errno;
  switch (error) {
    case ENOENT:
      return Status::Error(path + ": file is missing");
    case EACCES:
    case EPERM:
      return Status::Error(path + ": permission denied (this process may not read it; ls -l " +
                           "shows who may)");
    default:
      return Status::Error(path + ": cannot open (" + std::strerror(error) + ")");
  }
}

Status ReadImage(const std::string& path, cv::Mat* image) {
  const Status readable = CheckReadable(path);
  if (!readable.ok()) return readable;
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (!file) return Status::Error(path + ": cannot open (" + std::strerror(errno) + ")");
  unsigned char signature[8] = {};
  const bool png = std::fread(signature, 1, 8, file) == 8 && png_sig_cmp(signature, 0, 8) == 0;
  if (!png) {
    std::fclose(file);
    return ReadWithVips(path, image);
  }
  std::rewind(file);
  std::string why;
  const bool ok = ReadPng(file, image, &why);
  std::fclose(file);
  if (!ok) {
    image->release();
    return Status::Error(path + ": not a readable image" + (why.empty() ? "" : " (" + why + ")"));
  }
  return Status::Ok();
}

Status ReadColourImage(const std::string& path, cv::Mat* image) {
  cv::Mat read;
  const Status s = ReadImage(path, &read);
  if (!s.ok()) return s;
  if (read.depth() != CV_8U) return Status::Error(path + ": not an 8-bit image");
  if (read.channels() == 1) cv::cvtColor(read, read, cv::COLOR_GRAY2BGR);
  *image = read;
  return Status::Ok();
}

Status WritePng(const std::string& path, const cv::Mat& image, const PngWriting& how) {
  if (!image.empty() && image.depth() != CV_8U && image.depth() != CV_16U) {
    return Status::Error(path + ": a PNG holds 8- or 16-bit samples");
  }
  return SaveWithVips(path, image, [&](const vips::VImage& in, const std::string& to) {
    in.pngsave(to.c_str(), vips::VImage::option()
                               ->set("compression", how.level)
                               ->set("filter", how.filters ? VIPS_FOREIGN_PNG_FILTER_ALL
                                                           : VIPS_FOREIGN_PNG_FILTER_NONE)
                               ->set("strip", true));
  });
}

Status WriteTiff(const std::string& path, const cv::Mat& image, double dpi) {
  return SaveWithVips(path, image, [&](const vips::VImage& in, const std::string& to) {
    auto options = vips::VImage::option()
                       ->set("compression", VIPS_FOREIGN_TIFF_COMPRESSION_LZW)
                       ->set("strip", true);
    if (dpi > 0) {
      // libvips keeps resolution in pixels per millimetre and writes it in the unit asked for.
      options->set("xres", dpi / 25.4)
          ->set("yres", dpi / 25.4)
          ->set("resunit", VIPS_FOREIGN_TIFF_RESUNIT_INCH);
    }
    in.tiffsave(to.c_str(), options);
  });
}

Status WriteImage(const std::string& path, const cv::Mat& image) {
  const std::string ext = std::filesystem::path(path).extension().string();
  if (ext == ".png") return WritePng(path, image);
  if (ext == ".tif" || ext == ".tiff") return WriteTiff(path, image);
  return Status::Error(path + ": cannot write image: the name must end in .png, .tif or .tiff");
}

}  // namespace vellum
