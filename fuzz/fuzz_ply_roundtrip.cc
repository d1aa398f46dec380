// libFuzzer: the PLY writers and readers round trip. The input's bytes become an organised
// point map (with NaNs where they fall) and a quad mesh; what is written must read back equal.
#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include "io/ply.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vellum;
  namespace fs = std::filesystem;
  if (size < 2 || size > (1u << 16)) return 0;
  static const fs::path dir =
      fs::temp_directory_path() / ("vellum_fuzz_ply_" + std::to_string(getpid()));
  static const bool made = fs::create_directories(dir) || fs::exists(dir);
  (void)made;
  const int width = 1 + data[0] % 16;
  const size_t count = (size - 1) / sizeof(float);
  const int height = static_cast<int>(count / (3 * width));
  if (height < 1) return 0;
  cv::Mat points(height, width, CV_32FC3);
  std::memcpy(points.data, data + 1, static_cast<size_t>(height) * width * 12);
  const std::string ply = (dir / "points.ply").string();
  if (!WritePointsPly(ply, points).ok()) std::abort();
  std::vector<PlyPoint> back;
  if (!ReadPointsPly(ply, &back).ok()) std::abort();
  size_t k = 0;
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const cv::Vec3f p = points.at<cv::Vec3f>(v, u);
      if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]))) continue;
      if (k >= back.size()) std::abort();
      const PlyPoint& q = back[k++];
      if (std::memcmp(&q.x, &p[0], 4) || std::memcmp(&q.y, &p[1], 4) ||
          std::memcmp(&q.z, &p[2], 4) || q.u != u || q.v != v) {
        std::abort();
      }
    }
  }
  // The same values as a quad mesh: vertices, and quads over consecutive vertices.
  std::vector<cv::Vec3f> vertices(points.begin<cv::Vec3f>(), points.end<cv::Vec3f>());
  std::vector<cv::Vec4i> quads;
  for (int q = 0; q + 3 < static_cast<int>(vertices.size()); q += 4) {
    quads.emplace_back(q, q + 1, q + 2, q + 3);
  }
  const std::string mesh = (dir / "mesh.ply").string();
  if (!WriteQuadMeshPly(mesh, vertices, quads, "fuzz").ok()) std::abort();
  std::vector<cv::Vec3f> v2;
  std::vector<cv::Vec4i> q2;
  if (!ReadQuadMeshPly(mesh, &v2, &q2).ok()) std::abort();
  if (v2.size() != vertices.size() || q2 != quads) std::abort();
  if (!vertices.empty() &&
      std::memcmp(v2.data(), vertices.data(), vertices.size() * sizeof(cv::Vec3f)) != 0) {
    std::abort();
  }
  return 0;
}
