// An ICC profile for the tests that hand vellum a camera's own profile (--camera-icc).
#pragma once

#include <gtest/gtest.h>
#include <lcms2.h>

#include <filesystem>

namespace vellum {

// Writes an ICC profile as a colour target's software would for a camera: gray (the gantry's
// camera is gray) or RGB (Adobe RGB (1998) primaries), gamma 2.2, D65 white, named `name`.
inline void WriteCameraProfile(const std::filesystem::path& file, bool rgb, const char* name) {
  cmsToneCurve* gamma = cmsBuildGamma(nullptr, 2.2);
  cmsCIExyY d65;
  cmsWhitePointFromTemp(&d65, 6504);
  cmsHPROFILE profile = nullptr;
  if (rgb) {
    const cmsCIExyYTRIPLE primaries = {{0.64, 0.33, 1}, {0.21, 0.71, 1}, {0.15, 0.06, 1}};
    cmsToneCurve* curves[3] = {gamma, gamma, gamma};
    profile = cmsCreateRGBProfile(&d65, &primaries, curves);
  } else {
    profile = cmsCreateGrayProfile(&d65, gamma);
  }
  cmsMLU* description = cmsMLUalloc(nullptr, 1);
  cmsMLUsetASCII(description, "en", "US", name);
  cmsWriteTag(profile, cmsSigProfileDescriptionTag, description);
  cmsMLUfree(description);
  ASSERT_TRUE(cmsSaveProfileToFile(profile, file.c_str()));
  cmsCloseProfile(profile);
  cmsFreeToneCurve(gamma);
}

}  // namespace vellum
