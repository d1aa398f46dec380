// The polynomial texture map file (.ptm, version 1.2, Malzbender and Gelb, HP Labs 2001): what
// RTI viewers open to relight a page interactively. vellum writes PTM_FORMAT_LRGB: six luminance
// coefficients a byte each per pixel (coefficient = (byte - bias) * scale, one scale and bias per
// coefficient for the whole map), then the pixel's colour (R, G, B bytes); both blocks in reversed
// scanline order (the bottom row first), little-endian, no separators.
#pragma once

#include <string>

#include "core/common/status.h"
#include "core/shading/photometric.h"

namespace vellum {

// Writes `ptm` (FitPtm) to `path`; marked pixels are black (every coefficient 0, colour 0).
Status WritePtm(const std::string& path, const PtmResult& ptm);

// Reads what WritePtm writes (PTM_1.2, PTM_FORMAT_LRGB): coefficients (dequantised) and colour
// as PtmResult (valid: where the colour is not black). Errors name the file and the problem.
Status ReadPtm(const std::string& path, PtmResult* ptm);

}  // namespace vellum
