// Calibration YAML (cv::FileStorage) with the keys of docs/formats.md: camera_size, camera_matrix,
// camera_distortion, camera_rotation, camera_translation and the same with projector_.
#pragma once

#include <string>

#include "core/common/status.h"
#include "core/geometry/calibration.h"
#include "core/shading/albedo.h"

namespace vellum {

// Reads and checks a calibration. Errors name the file and the key.
Status ReadCalibration(const std::string& path, Calibration* calibration);
Status WriteCalibration(const std::string& path, const Calibration& calibration);

// A checksum of the calibration's values (not of its file, which may be written in other ways):
// the SHA-256 of every number in a fixed order and precision (%.17g), as 64 hex digits. The
// same calibration gives the same checksum from a file, the station's message or a rig (zero
// counts as zero whatever its sign).
std::string CalibrationSha256(const Calibration& calibration);

// The projector's flat field (`vellum calibrate flatfield`, core/shading/albedo.h) as YAML
// (cv::FileStorage): projector_size, cell_px, reference_mm and gain (a CV_32F matrix, one value
// per cell, .nan where not measured). Errors name the file and the key.
Status ReadFlatField(const std::string& path, FlatField* field);
Status WriteFlatField(const std::string& path, const FlatField& field);
// The studio lamps' field (core/shading/albedo.h) as OpenCV FileStorage YAML: camera_size,
// cell_px, lamps (N x 3, world mm) and gain (a value per cell, one channel per texture channel).
Status ReadStudioField(const std::string& path, StudioField* field);
Status WriteStudioField(const std::string& path, const StudioField& field);

}  // namespace vellum
