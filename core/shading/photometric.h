// Photometric normals (Woodham 1980): with three or more images of the page in one
// pose, each under one distant light of known direction, the surface's normal at each camera
// pixel is what explains the levels it saw. Seen on the flattened page, in the page's own frame,
// they show fine relief (ruling, prickings, erased and embossed lines) that the structured light
// cannot resolve.
//
// The model: a Lambertian page, each light distant (one direction over the page) and of the same
// strength, the camera's response linear. At a pixel, level_k = albedo * (n . l_k) for each light
// that lights it, so g = albedo * n is the least-squares solution over those lights. A light is
// left out at a pixel where its level is near black (the point is turned away from it, or in a
// shadow) or clipped; a pixel with fewer than three lights left is marked. Not modelled: shadows
// one part of the page casts on another under a raking light (a curl's on the flat part: its
// level drops and the normal leans away from that light), interreflection and gloss.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace vellum {

struct PhotometricOptions {
  double min_level = 0.03;  // Share of full scale below which a light is taken as not lighting.
  double max_level = 0.98;  // Share of full scale above which it is taken as clipped.

  bool Check(std::string* why) const;
};

struct PhotometricResult {
  Status status = Status::Error("photometric normals not computed");
  cv::Mat normals;  // CV_32FC3 unit world normal per camera pixel (towards the camera); 0: marked.
  cv::Mat albedo;   // CV_32F the albedo times the lights' strength, in shares of full scale.
  cv::Mat valid;    // CV_8U 255 where solved.
  int solved = 0, marked = 0;  // Pixels of the mask solved, and marked (under three lights).
};

// `images`: one per light, the camera's size, 8 or 16 bit, gray (a colour one is taken as its
// luminance); `directions`: unit vectors from the page towards each light (world); `mask`:
// CV_8U, nonzero where wanted (empty: everywhere).
PhotometricResult PhotometricNormals(const std::vector<cv::Mat>& images,
                                     const std::vector<cv::Vec3d>& directions, const cv::Mat& mask,
                                     const PhotometricOptions& options = PhotometricOptions());

// World normals restored onto the flat page (`normals`, CV_32FC3, through the page's sheet) in the
// page's own frame at each pixel (`right`, `up`, `normal`: RestoredSheetFrame): x to the image's
// right, y up, z out of the page; unit, CV_32FC3. A pixel whose restored normal is shorter than
// half (it drew on marked pixels) or that is off the sheet is 0.
cv::Mat NormalsOnPage(const cv::Mat& normals, const cv::Mat& right, const cv::Mat& up,
                      const cv::Mat& normal);

// A polynomial texture map of the flat page (Malzbender, Gelb and Wolters 2001; the PTM of
// cultural-heritage RTI): at each restored pixel, the luminance under a distant light as a
// biquadratic in the light's direction projected on the page there (lu, lv: its components along
// the page's own right and up, RestoredSheetFrame), L = a0 lu^2 + a1 lv^2 + a2 lu lv + a3 lu +
// a4 lv + a5, fitted by least squares to the restored images of six or more lights of known
// direction (at two or more elevations: lights all at one elevation leave lu^2 + lv^2 constant,
// and the fit singular). A light is left out at a pixel where it is clipped; a pixel with fewer
// than six left is marked. The colour is the pixel's mean over the lights, as a share of its
// luminance (a gray page: white), so that colour = L * rgb.
struct PtmResult {
  Status status = Status::Error("PTM not fitted");
  cv::Mat coefficients;  // CV_32FC(6): a0 .. a5, L in shares of full scale; 0 where marked.
  cv::Mat rgb;           // CV_32FC3 (B, G, R), each a share of the luminance, at most 1.
  cv::Mat valid;         // CV_8U 255 where fitted.
  int solved = 0;
};
// `images`: the restored lights (8 or 16 bit, gray or colour, one size); `directions`: unit,
// world, towards each light; `right`, `up`: RestoredSheetFrame's (zero off the sheet).
PtmResult FitPtm(const std::vector<cv::Mat>& images, const std::vector<cv::Vec3d>& directions,
                 const cv::Mat& right, const cv::Mat& up,
                 const PhotometricOptions& options = PhotometricOptions());
// The fitted luminance at one pixel for a light at (lu, lv).
inline double PtmLuminance(const cv::Vec<float, 6>& a, double lu, double lv) {
  return a[0] * lu * lu + a[1] * lv * lv + a[2] * lu * lv + a[3] * lu + a[4] * lv + a[5];
}

// A normal map as an image (the usual tangent-space encoding: each component c as (c + 1) / 2 of
// full scale): CV_16UC3 in OpenCV's BGR order, so a file reader sees R = x, G = y, B = z; 0 (not
// a unit normal) where `normals` is 0.
cv::Mat NormalMapImage(const cv::Mat& normals);

}  // namespace vellum
