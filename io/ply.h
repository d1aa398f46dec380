// PLY files: points.ply has one vertex per decoded camera pixel with properties x y z (float,
// mm, world) and u v (float, camera pixel); binary little endian.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace vellum {

struct PlyPoint {
  float x, y, z, u, v;
};

// Writes every finite point of an organised CV_32FC3 point map with its pixel.
Status WritePointsPly(const std::string& path, const cv::Mat& points);
Status ReadPointsPly(const std::string& path, std::vector<PlyPoint>* points);

// A quad mesh: vertices x y z (float, mm) and faces as lists of 4 vertex indices; binary
// little endian. mesh.ply and flat.ply share the vertex order.
Status WriteQuadMeshPly(const std::string& path, const std::vector<cv::Vec3f>& vertices,
                        const std::vector<cv::Vec4i>& quads, const std::string& comment);
Status ReadQuadMeshPly(const std::string& path, std::vector<cv::Vec3f>* vertices,
                       std::vector<cv::Vec4i>* quads);

}  // namespace vellum
