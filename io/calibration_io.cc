#include "io/calibration_io.h"

#include <cmath>
#include <cstdio>
#include <opencv2/core.hpp>

#include "io/manifest.h"
#include "io/write_whole.h"
#include "io/yaml_guard.h"

namespace vellum {
namespace {

// Reads a numeric matrix node of any depth into doubles, accepting rows x cols or its
// transpose when `either_orientation` (a 3x1 translation may come as 1x3).
bool ReadMatrix(const cv::FileNode& node, int rows, int cols, bool either_orientation, cv::Mat* out,
                std::string* why) {
  if (node.empty() || node.isNone()) {
    *why = "is missing";
    return false;
  }
  if (!MatrixNodeAtMost(node, 64)) {
    *why = "declares a matrix far larger than " + std::to_string(rows) + "x" + std::to_string(cols);
    return false;
  }
  cv::Mat m;
  try {
    node >> m;
  } catch (const std::exception&) {
    m.release();
  }
  if (m.empty()) {
    *why = "is not an !!opencv-matrix";
    return false;
  }
  if (m.channels() != 1) {
    *why = "must have one channel";
    return false;
  }
  if (m.rows == rows && m.cols == cols) {
    m.convertTo(*out, CV_64F);
  } else if (either_orientation && m.rows == cols && m.cols == rows) {
    cv::Mat t = m.t();
    t.convertTo(*out, CV_64F);
  } else {
    *why = "must be " + std::to_string(rows) + "x" + std::to_string(cols) + ", found " +
           std::to_string(m.rows) + "x" + std::to_string(m.cols);
    return false;
  }
  for (int i = 0; i < rows * cols; ++i) {
    if (!std::isfinite(out->at<double>(i))) {
      *why = "holds a NaN or infinity";
      return false;
    }
  }
  return true;
}

Status ReadDevice(const cv::FileStorage& fs, const std::string& path, const std::string& prefix,
                  CameraModel* model) {
  std::string why;
  auto fail = [&](const std::string& key) {
    return Status::Error(path + ": key '" + prefix + key + "' " + why);
  };
  why = ReadSizeNode(fs[prefix + "size"], &model->size);
  if (!why.empty()) return fail("size");
  cv::Mat m;
  if (!ReadMatrix(fs[prefix + "matrix"], 3, 3, false, &m, &why)) return fail("matrix");
  model->matrix = cv::Matx33d(m.ptr<double>());
  if (!ReadMatrix(fs[prefix + "distortion"], 1, 5, true, &m, &why)) return fail("distortion");
  model->distortion = cv::Vec<double, 5>(m.ptr<double>());
  if (!ReadMatrix(fs[prefix + "rotation"], 3, 3, false, &m, &why)) return fail("rotation");
  model->rotation = cv::Matx33d(m.ptr<double>());
  if (!ReadMatrix(fs[prefix + "translation"], 3, 1, true, &m, &why)) return fail("translation");
  model->translation = cv::Vec3d(m.ptr<double>());
  if (!model->Check(&why)) {
    return Status::Error(path + ": " + prefix.substr(0, prefix.size() - 1) + ": " + why);
  }
  return Status::Ok();
}

void WriteDevice(cv::FileStorage& fs, const std::string& prefix, const CameraModel& model) {
  fs << prefix + "size" << model.size;
  fs << prefix + "matrix" << cv::Mat(model.matrix);
  fs << prefix + "distortion" << cv::Mat(model.distortion).t();
  fs << prefix + "rotation" << cv::Mat(model.rotation);
  fs << prefix + "translation" << cv::Mat(model.translation);
}

}  // namespace

// The optional working volume: `working_volume_z: [ low, high ]` (mm) or a 1x2 matrix.
bool ReadVolume(const cv::FileNode& node, Calibration* calibration, std::string* why) {
  if (node.empty() || node.isNone()) return true;
  if (node.isSeq()) {
    auto number = [](const cv::FileNode& n) { return n.isReal() || n.isInt(); };
    if (node.size() != 2 || !number(node[0]) || !number(node[1])) {
      *why = "must be a [ low, high ] sequence of two numbers, mm";
      return false;
    }
    calibration->min_z_mm = static_cast<double>(node[0]);
    calibration->max_z_mm = static_cast<double>(node[1]);
    return true;
  }
  cv::Mat m;
  if (!ReadMatrix(node, 1, 2, true, &m, why)) return false;
  calibration->min_z_mm = m.at<double>(0);
  calibration->max_z_mm = m.at<double>(1);
  return true;
}

Status ReadCalibration(const std::string& path, Calibration* calibration) {
  const std::string problem = YamlTextProblem(path);
  if (!problem.empty()) return Status::Error(path + ": " + problem);
  cv::FileStorage fs;
  try {
    if (!fs.open(path, cv::FileStorage::READ)) {
      return Status::Error(path + ": cannot open the calibration file");
    }
  } catch (const std::exception&) {
    return Status::Error(path + ": not a valid OpenCV YAML/XML calibration file");
  }
  if (!fs.root().isMap()) {
    return Status::Error(path +
                         ": not a calibration (expected a map of keys, see docs/formats.md)");
  }
  *calibration = Calibration();  // What the file leaves out takes its default.
  Status s = Status::Ok();
  try {
    s = ReadDevice(fs, path, "camera_", &calibration->camera);
    if (s.ok()) s = ReadDevice(fs, path, "projector_", &calibration->projector);
    std::string why;
    if (s.ok() && !ReadVolume(fs["working_volume_z"], calibration, &why)) {
      s = Status::Error(path + ": working_volume_z " + why);
    }
    // The optional measured scale error (`vellum calibrate` writes it).
    const cv::FileNode scale = fs["scale_error_percent"];
    if (s.ok() && !scale.empty() && !scale.isNone()) {
      if (!(scale.isReal() || scale.isInt()) || !(static_cast<double>(scale) >= 0)) {
        s = Status::Error(path + ": scale_error_percent must be a number >= 0 (%)");
      } else {
        calibration->scale_error_percent = static_cast<double>(scale);
      }
    }
  } catch (const std::exception& e) {
    s = Status::Error(path + ": malformed: " + e.what());
  }
  if (!s.ok()) return s;
  std::string why;
  if (!calibration->Check(&why)) return Status::Error(path + ": " + why);
  return Status::Ok();
}

Status WriteCalibration(const std::string& path, const Calibration& calibration) {
  return WriteWhole(path, [&](const std::string& part) {
    try {
      cv::FileStorage fs(part, cv::FileStorage::WRITE);
      if (!fs.isOpened()) return Status::Error(path + ": cannot write the calibration file");
      WriteDevice(fs, "camera_", calibration.camera);
      WriteDevice(fs, "projector_", calibration.projector);
      fs << "working_volume_z"
         << "[" << calibration.min_z_mm << calibration.max_z_mm << "]";
      if (std::isfinite(calibration.scale_error_percent))
        fs << "scale_error_percent" << calibration.scale_error_percent;
      fs.release();
    } catch (const cv::Exception& e) {
      return Status::Error(path + ": cannot write the calibration file: " + e.what());
    }
    return Status::Ok();
  });
}

Status ReadFlatField(const std::string& path, FlatField* field) {
  const std::string problem = YamlTextProblem(path);
  if (!problem.empty()) return Status::Error(path + ": " + problem);
  *field = FlatField();
  try {
    cv::FileStorage fs;
    if (!fs.open(path, cv::FileStorage::READ)) {
      return Status::Error(path + ": cannot open the flat field");
    }
    if (!fs.root().isMap()) return Status::Error(path + ": not a flat field (expected keys)");
    cv::Size size;
    const std::string size_problem = ReadSizeNode(fs["projector_size"], &size);
    const cv::FileNode cell = fs["cell_px"], reference = fs["reference_mm"];
    cv::Mat gain;
    fs["gain"] >> gain;
    if (!size_problem.empty()) {
      return Status::Error(path + ": key 'projector_size' " + size_problem);
    }
    if (!cell.isInt() || static_cast<int>(cell) < 1 || static_cast<int>(cell) > kMaxImageSide) {
      return Status::Error(path + ": cell_px must be an integer from 1 to " +
                           std::to_string(kMaxImageSide));
    }
    if (!(reference.isReal() || reference.isInt()) || !(static_cast<double>(reference) > 0)) {
      return Status::Error(path + ": reference_mm must be a number > 0");
    }
    const int c = static_cast<int>(cell);
    const cv::Size cells((size.width + c - 1) / c, (size.height + c - 1) / c);
    if (gain.empty() || gain.size() != cells) {
      return Status::Error(path + ": gain must be a " + std::to_string(cells.width) + "x" +
                           std::to_string(cells.height) + " matrix (a value per " +
                           std::to_string(c) + " px cell of the projector)");
    }
    gain.convertTo(field->gain, CV_32F);
    field->cell_px = c;
    field->reference_mm = static_cast<double>(reference);
    field->projector_size = size;
  } catch (const std::exception& e) {
    *field = FlatField();
    return Status::Error(path + ": malformed flat field: " + e.what());
  }
  return Status::Ok();
}

Status WriteFlatField(const std::string& path, const FlatField& field) {
  try {
    cv::FileStorage fs(path, cv::FileStorage::WRITE);
    if (!fs.isOpened()) return Status::Error(path + ": cannot write the flat field");
    fs << "projector_size" << field.projector_size;
    fs << "cell_px" << field.cell_px;
    fs << "reference_mm" << field.reference_mm;
    fs << "gain" << field.gain;
  } catch (const cv::Exception& e) {
    return Status::Error(path + ": cannot write the flat field: " + e.what());
  }
  return Status::Ok();
}

Status ReadStudioField(const std::string& path, StudioField* field) {
  const std::string problem = YamlTextProblem(path);
  if (!problem.empty()) return Status::Error(path + ": " + problem);
  *field = StudioField();
  try {
    cv::FileStorage fs;
    if (!fs.open(path, cv::FileStorage::READ)) {
      return Status::Error(path + ": cannot open the studio field");
    }
    if (!fs.root().isMap()) return Status::Error(path + ": not a studio field (expected keys)");
    cv::Size size;
    const std::string size_problem = ReadSizeNode(fs["camera_size"], &size);
    const cv::FileNode cell = fs["cell_px"];
    cv::Mat gain, lamps;
    fs["gain"] >> gain;
    fs["lamps"] >> lamps;
    if (!size_problem.empty()) return Status::Error(path + ": key 'camera_size' " + size_problem);
    if (!cell.isInt() || static_cast<int>(cell) < 1 || static_cast<int>(cell) > kMaxImageSide) {
      return Status::Error(path + ": cell_px must be an integer from 1 to " +
                           std::to_string(kMaxImageSide));
    }
    if (lamps.empty() || lamps.cols != 3 || lamps.channels() != 1) {
      return Status::Error(path + ": lamps must be an N x 3 matrix (x, y, z mm of each lamp)");
    }
    const int c = static_cast<int>(cell);
    const cv::Size cells((size.width + c - 1) / c, (size.height + c - 1) / c);
    if (gain.empty() || gain.size() != cells || (gain.channels() != 1 && gain.channels() != 3)) {
      return Status::Error(path + ": gain must be a " + std::to_string(cells.width) + "x" +
                           std::to_string(cells.height) +
                           " matrix of 1 or 3 channels (a value per " + std::to_string(c) +
                           " px cell of the camera)");
    }
    gain.convertTo(field->gain, CV_32F);
    lamps.convertTo(lamps, CV_64F);
    for (int k = 0; k < lamps.rows; ++k) {
      const cv::Vec3d lamp(lamps.at<double>(k, 0), lamps.at<double>(k, 1), lamps.at<double>(k, 2));
      if (!std::isfinite(lamp.dot(lamp))) return Status::Error(path + ": a lamp is not finite");
      field->lamps.push_back(lamp);
    }
    field->cell_px = c;
    field->camera_size = size;
  } catch (const std::exception& e) {
    *field = StudioField();
    return Status::Error(path + ": malformed studio field: " + e.what());
  }
  return Status::Ok();
}

Status WriteStudioField(const std::string& path, const StudioField& field) {
  try {
    cv::FileStorage fs(path, cv::FileStorage::WRITE);
    if (!fs.isOpened()) return Status::Error(path + ": cannot write the studio field");
    fs << "camera_size" << field.camera_size;
    fs << "cell_px" << field.cell_px;
    cv::Mat lamps(static_cast<int>(field.lamps.size()), 3, CV_64F);
    for (int k = 0; k < lamps.rows; ++k) {
      for (int c = 0; c < 3; ++c) lamps.at<double>(k, c) = field.lamps[k][c];
    }
    fs << "lamps" << lamps;
    fs << "gain" << field.gain;
  } catch (const cv::Exception& e) {
    return Status::Error(path + ": cannot write the studio field: " + e.what());
  }
  return Status::Ok();
}

std::string CalibrationSha256(const Calibration& calibration) {
  std::string text;
  auto add = [&](double v) {
    char buf[40];
    // + 0.0 makes -0 plain 0: a YAML writer may drop the sign of zero (OpenCV's does).
    std::snprintf(buf, sizeof(buf), "%.17g\n", v + 0.0);
    text += buf;
  };
  for (const CameraModel* device : {&calibration.camera, &calibration.projector}) {
    add(device->size.width);
    add(device->size.height);
    for (int k = 0; k < 9; ++k) add(device->matrix.val[k]);
    for (int k = 0; k < 5; ++k) add(device->distortion[k]);
    for (int k = 0; k < 9; ++k) add(device->rotation.val[k]);
    for (int k = 0; k < 3; ++k) add(device->translation[k]);
  }
  add(calibration.min_z_mm);
  add(calibration.max_z_mm);
  // Only when measured: a calibration without it keeps the checksum it always had.
  if (std::isfinite(calibration.scale_error_percent)) add(calibration.scale_error_percent);
  return Sha256OfBytes(text);
}

}  // namespace vellum
