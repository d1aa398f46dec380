#include "io/ply.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "io/write_whole.h"

namespace vellum {
namespace {

// Bytes from the read position to the end of the file (the position is kept).
uint64_t BytesLeft(std::ifstream& f) {
  const std::streampos here = f.tellg();
  f.seekg(0, std::ios::end);
  const std::streampos end = f.tellg();
  f.seekg(here);
  return here < 0 || end < here ? 0 : static_cast<uint64_t>(end - here);
}

// The writers proper, to the temporary name WriteWhole gives them.
Status WritePointsPlyTo(const std::string& path, const cv::Mat& points);
Status WriteQuadMeshPlyTo(const std::string& path, const std::vector<cv::Vec3f>& vertices,
                          const std::vector<cv::Vec4i>& quads, const std::string& comment);

}  // namespace

Status WritePointsPly(const std::string& path, const cv::Mat& points) {
  if (points.type() != CV_32FC3) return Status::Error(path + ": point map must be CV_32FC3");
  return WriteWhole(path, [&](const std::string& part) { return WritePointsPlyTo(part, points); });
}

namespace {

Status WritePointsPlyTo(const std::string& path, const cv::Mat& points) {
  auto finite = [](const cv::Vec3f& p) {
    return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
  };
  size_t count = 0;
  for (int v = 0; v < points.rows; ++v) {
    const cv::Vec3f* row = points.ptr<cv::Vec3f>(v);
    for (int u = 0; u < points.cols; ++u) count += finite(row[u]);
  }
  std::ofstream f(path, std::ios::binary);
  if (!f) return Status::Error(path + ": cannot open for writing");
  f << "ply\nformat binary_little_endian 1.0\n"
    << "comment vellum points: x y z world frame mm (z = 0 on the table), u v camera pixel\n"
    << "element vertex " << count << "\n"
    << "property float x\nproperty float y\nproperty float z\n"
    << "property float u\nproperty float v\nend_header\n";
  static_assert(sizeof(PlyPoint) == 20, "PlyPoint must be packed");
  // Written a few rows at a time through one small buffer: a 24 MP scan's cloud is some 500 MB.
  std::vector<PlyPoint> out;
  out.reserve(static_cast<size_t>(points.cols) * 32);
  auto flush = [&] {
    f.write(reinterpret_cast<const char*>(out.data()),
            static_cast<std::streamsize>(out.size() * sizeof(PlyPoint)));
    out.clear();
  };
  for (int v = 0; v < points.rows; ++v) {
    const cv::Vec3f* row = points.ptr<cv::Vec3f>(v);
    for (int u = 0; u < points.cols; ++u) {
      if (finite(row[u])) {
        out.push_back(
            {row[u][0], row[u][1], row[u][2], static_cast<float>(u), static_cast<float>(v)});
      }
    }
    if (out.size() + static_cast<size_t>(points.cols) > out.capacity()) flush();
  }
  flush();
  f.close();
  if (!f) return Status::Error(path + ": write failed (" + std::strerror(errno) + ")");
  return Status::Ok();
}

}  // namespace

Status ReadPointsPly(const std::string& path, std::vector<PlyPoint>* points) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return Status::Error(path + ": cannot open");
  std::string line;
  std::getline(f, line);
  if (line != "ply") return Status::Error(path + ": not a PLY file");
  long count = -1;
  std::vector<std::string> props;
  bool binary_le = false;
  while (std::getline(f, line)) {
    if (line == "end_header") break;
    std::istringstream is(line);
    std::string word;
    is >> word;
    if (word == "format") {
      std::string fmt;
      is >> fmt;
      binary_le = fmt == "binary_little_endian";
    } else if (word == "element") {
      std::string name;
      is >> name >> count;
      if (name != "vertex") return Status::Error(path + ": expected a vertex element");
    } else if (word == "property") {
      std::string type, name;
      is >> type >> name;
      if (type != "float") return Status::Error(path + ": property " + name + " is not float");
      props.push_back(name);
    }
  }
  if (!binary_le) return Status::Error(path + ": only binary_little_endian is read");
  if (count < 0 || props != std::vector<std::string>{"x", "y", "z", "u", "v"}) {
    return Status::Error(path + ": expected vertex properties x y z u v");
  }
  if (static_cast<uint64_t>(count) > BytesLeft(f) / sizeof(PlyPoint)) {
    return Status::Error(path + ": truncated: the header declares " + std::to_string(count) +
                         " vertices, the file holds " +
                         std::to_string(BytesLeft(f) / sizeof(PlyPoint)));
  }
  points->resize(static_cast<size_t>(count));
  f.read(reinterpret_cast<char*>(points->data()),
         static_cast<std::streamsize>(count * sizeof(PlyPoint)));
  if (f.gcount() != static_cast<std::streamsize>(count * sizeof(PlyPoint))) {
    return Status::Error(path + ": truncated: fewer vertices than the header's " +
                         std::to_string(count));
  }
  return Status::Ok();
}

Status WriteQuadMeshPly(const std::string& path, const std::vector<cv::Vec3f>& vertices,
                        const std::vector<cv::Vec4i>& quads, const std::string& comment) {
  return WriteWhole(path, [&](const std::string& part) {
    return WriteQuadMeshPlyTo(part, vertices, quads, comment);
  });
}

namespace {

Status WriteQuadMeshPlyTo(const std::string& path, const std::vector<cv::Vec3f>& vertices,
                          const std::vector<cv::Vec4i>& quads, const std::string& comment) {
  std::ofstream f(path, std::ios::binary);
  if (!f) return Status::Error(path + ": cannot open for writing");
  f << "ply\nformat binary_little_endian 1.0\ncomment " << comment << "\n"
    << "element vertex " << vertices.size() << "\n"
    << "property float x\nproperty float y\nproperty float z\n"
    << "element face " << quads.size() << "\n"
    << "property list uchar int vertex_indices\nend_header\n";
  f.write(reinterpret_cast<const char*>(vertices.data()),
          static_cast<std::streamsize>(vertices.size() * sizeof(cv::Vec3f)));
  for (const cv::Vec4i& q : quads) {
    const uint8_t four = 4;
    f.write(reinterpret_cast<const char*>(&four), 1);
    f.write(reinterpret_cast<const char*>(q.val), 4 * sizeof(int));
  }
  f.close();
  if (!f) return Status::Error(path + ": write failed (" + std::strerror(errno) + ")");
  return Status::Ok();
}

}  // namespace

Status ReadQuadMeshPly(const std::string& path, std::vector<cv::Vec3f>* vertices,
                       std::vector<cv::Vec4i>* quads) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return Status::Error(path + ": cannot open");
  std::string line;
  long nv = -1, nf = -1;
  while (std::getline(f, line) && line != "end_header") {
    std::istringstream is(line);
    std::string word, name;
    is >> word;
    if (word == "element") {
      long count;
      is >> name >> count;
      (name == "vertex" ? nv : nf) = count;
    }
  }
  if (nv < 0 || nf < 0) return Status::Error(path + ": expected vertex and face elements");
  // 12 bytes per vertex, 17 per quad: a header declaring more than the file holds is refused
  // before anything is allocated.
  const uint64_t left = BytesLeft(f);
  if (static_cast<uint64_t>(nv) > left / 12 ||
      static_cast<uint64_t>(nf) > (left - 12 * static_cast<uint64_t>(nv)) / 17) {
    return Status::Error(path + ": truncated: the header declares " + std::to_string(nv) +
                         " vertices and " + std::to_string(nf) + " faces, the file holds " +
                         std::to_string(left) + " bytes of data");
  }
  vertices->resize(static_cast<size_t>(nv));
  f.read(reinterpret_cast<char*>(vertices->data()),
         static_cast<std::streamsize>(nv * sizeof(cv::Vec3f)));
  quads->resize(static_cast<size_t>(nf));
  for (long k = 0; k < nf; ++k) {
    uint8_t count = 0;
    f.read(reinterpret_cast<char*>(&count), 1);
    if (count != 4) return Status::Error(path + ": face " + std::to_string(k) + " is not a quad");
    f.read(reinterpret_cast<char*>((*quads)[k].val), 4 * sizeof(int));
    for (int i = 0; f && i < 4; ++i) {
      if ((*quads)[k][i] < 0 || (*quads)[k][i] >= nv) {
        return Status::Error(path + ": face " + std::to_string(k) + " names vertex " +
                             std::to_string((*quads)[k][i]) + " of " + std::to_string(nv));
      }
    }
  }
  if (!f) return Status::Error(path + ": truncated");
  return Status::Ok();
}

}  // namespace vellum
