// Accuracy of a measured point map against the virtual gantry's ground truth.
#pragma once

#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "core/common/status.h"
#include "core/mesh/mesh.h"
#include "core/patterns/patterns.h"
#include "core/patterns/scan.h"
#include "core/shading/albedo.h"
#include "core/sim/gantry.h"

namespace vellum {

struct PointErrorStats {
  int page_lit_pixels = 0;  // Page pixels the projector lights directly.
  int valid = 0;            // Of those, pixels with a measured point.
  double valid_fraction = 0;
  double median_mm = 0, rms_mm = 0, p99_mm = 0, max_mm = 0;  // 3D error over valid page pixels.
  int beyond_1mm = 0;  // Valid page pixels more than 1 mm off.
  int flying = 0;      // Points anywhere (page, table, support, lit or not) more than 1 mm from the
                       // true surface within 2 px of their pixel: in mid-air.
};

// Compares a CV_32FC3 point map with the truth over page pixels lit by the projector.
PointErrorStats ComparePoints(const GroundTruth& truth, const cv::Mat& points);

struct FlatErrorStats {
  int nodes = 0;                  // Sheet nodes on the page (measured or filled) compared.
  double rms_mm = 0, max_mm = 0;  // Flat node vs true page coordinate, after a rigid fit.
  double mean_edge_error = 0;     // Mean |flat edge / true geodesic length - 1| over springs.
  bool mirrored = false;          // A reflection fits better than the rigid motion.
};

// The truth of one of the gantry's pages (`index` as in page_index: 1 for the first): its own
// on_page mask, new (the truth's other fields shared).
GroundTruth OnePage(const GroundTruth& truth, int index);

// Compares a flattened sheet with the true flat page: each page node's true page coordinate
// is the truth at its camera pixel; geodesic lengths on a developable page are flat lengths.
FlatErrorStats CompareFlat(const GroundTruth& truth, const Mesh& mesh,
                           const std::vector<cv::Point2d>& flat);

// Renders one camera frame per pattern of the sequence; frame k uses noise seed seed + k + 1.
std::vector<cv::Mat> RenderSequence(const VirtualGantry& gantry, const PatternSequence& sequence,
                                    uint64_t seed);

// A whole simulated scan: the gantry (with its truth), the default pattern sequence for the
// rig's projector, the frames and the texture frame, all from one seed.
struct SimulatedScan {
  std::unique_ptr<VirtualGantry> gantry;
  PatternSequence sequence;
  std::vector<cv::Mat> frames;
  cv::Mat texture;
};
SimulatedScan SimulateScan(const Calibration& rig, PageShape shape, uint64_t seed,
                           const TextureOptions& texture = TextureOptions());
// The same for any page, in any scene, under any light.
SimulatedScan SimulateScan(const Calibration& rig, const PageOptions& page,
                           const TextureOptions& texture, const SceneOptions& scene, uint64_t seed,
                           const LightOptions& light = LightOptions());
// The scan's extra images under `lights` (VirtualGantry::RenderLight, noise seed seed + 1001 +
// k), named as they are, each distant light with its direction (a fluorescence none).
std::vector<ScanLight> RenderLights(const VirtualGantry& gantry,
                                    const std::vector<SceneLight>& lights, uint64_t seed);
// The simulated scan as a scan directory holds it (sequence, camera size, texture, frames), for
// what processes scans.
Scan AsScan(const SimulatedScan& sim);

// The camera's true sampling of the gantry's (first) page, ppi, from its exact geometry: at a
// grid of points (s, t) of the page `step_mm` apart (uniform in page area, as restored pixels
// are in flat area), 25.4 times the smallest singular value of d(camera pixel) / d(s, t), by
// central differences.
std::vector<double> TrueSampling(const VirtualGantry& gantry, double step_mm);

// The projector's flat field and the studio lamps' field measured on the virtual gantry as
// `vellum calibrate flatfield` and `vellum calibrate studio` measure them at a real one: a plain
// target of `albedo` larger than the view (420 x 320 mm) scanned under `light` (noise seed
// `seed`), decoded, triangulated and measured (MeasureFlatField, MeasureStudioField). An error
// names the field that could not be measured.
Status MeasureFieldsOnWhiteTarget(const Calibration& rig, const LightOptions& light, double albedo,
                                  uint64_t seed, FlatField* flat, StudioField* studio);

// Intersection over union of two masks (CV_8U, nonzero = in); 0 if both are empty.
double MaskIoU(const cv::Mat& a, const cv::Mat& b);

}  // namespace vellum
