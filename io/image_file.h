// Image files, without OpenCV's imgcodecs: on Debian it links GDAL, GDCM, Poppler, HDF5 and a
// hundred more libraries, which cost every vellum process some 120 ms of dynamic linking before
// main (a third of `vellum process`'s time outside its stages). PNG is read by libpng, straight
// into the image; everything else, and every write, goes through libvips.
//
// Images are OpenCV's: 8- or 16-bit (or float) samples, gray or colour, colour in BGR order.
// In files colour is RGB, as every other program expects; float images are written as they are
// (a point map's x y z in that order).
#pragma once

#include <opencv2/core.hpp>
#include <string>

#include "core/common/status.h"

namespace vellum {

// Reads an image file: gray or BGR, 8 or 16 bits a sample as the file has them (a PNG of 1, 2
// or 4 bits, or of a palette, is widened to 8; alpha is dropped; CMYK or CIELAB colour is
// converted to sRGB, through the file's profile if it has one; floating-point samples are read
// as float; signed or 32-bit integer samples are refused). Errors name the file.
Status ReadImage(const std::string& path, cv::Mat* image);

// Whether this process can open `path` to read it; the error says why as the system does (the
// file is missing, permission is denied, it is a folder, ...), naming the file. Every reader of a
// scan's files asks it first, so that no refusal is reported as a format problem.
Status CheckReadable(const std::string& path);
// Reads an 8-bit image as colour (BGR; gray is widened), for showing or as a texture; an
// error for another depth.
Status ReadColourImage(const std::string& path, cv::Mat* image);

// How a PNG is written: zlib's level (0 stores), and whether rows are filtered (each row
// predicted from its neighbours: smaller files, slower writes; no use on noisy fringes).
struct PngWriting {
  int level = 1;
  bool filters = false;
};

// Writes an image as a PNG (8- or 16-bit, gray or colour).
Status WritePng(const std::string& path, const cv::Mat& image, const PngWriting& how = {});

// Writes an image as a TIFF (8-, 16-bit or float, gray or colour; LZW), with its resolution
// tags when dpi > 0.
Status WriteTiff(const std::string& path, const cv::Mat& image, double dpi = 0);

// Writes an image in the format its name ends in (.png, .tif or .tiff).
Status WriteImage(const std::string& path, const cv::Mat& image);

}  // namespace vellum
