#include "io/products.h"

#include <cctype>
#include <filesystem>
#include <future>
#include <map>
#include <opencv2/imgproc.hpp>

#include "io/image_file.h"
#include "io/json.h"
#include "io/ply.h"
#include "io/scan_io.h"
#include "io/version.h"
#include "io/xmp.h"

namespace vellum {
namespace fs = std::filesystem;

Status WriteSheets(const std::string& dir, const Mesh& mesh, const std::vector<cv::Point2d>& flat) {
  std::vector<int> index(mesh.kind.size(), -1);
  std::vector<cv::Vec3f> before, after;
  for (size_t k = 0; k < mesh.kind.size(); ++k) {
    if (!mesh.Active(static_cast<int>(k))) continue;
    index[k] = static_cast<int>(before.size());
    before.push_back(cv::Vec3f(mesh.point[k]));
    after.emplace_back(static_cast<float>(flat[k].x), static_cast<float>(flat[k].y), 0.0f);
  }
  std::vector<cv::Vec4i> quads;
  for (const cv::Vec4i& q : mesh.quads)
    quads.emplace_back(index[q[0]], index[q[1]], index[q[2]], index[q[3]]);
  Status s = WriteQuadMeshPly((fs::path(dir) / "mesh.ply").string(), before, quads,
                              "vellum sheet before flattening: world frame, mm");
  if (!s.ok()) return s;
  return WriteQuadMeshPly(
      (fs::path(dir) / "flat.ply").string(), after, quads,
      "vellum sheet after flattening: page plane, mm (same vertices as mesh.ply)");
}

namespace {

// A restored image's dpi for its TIFF's resolution tags: in orthographic view; none (0) in
// camera view.
double TiffDpi(const RestoreResult& restored) {
  return restored.view == RestoreView::kOrthographic ? std::round(restored.dpi) : 0;
}

// Writes `image` as the TIFF `tif` (resolution tags when dpi > 0), then its XMP and, with
// `profile`, its ICC profile: the identity, vellum's name and version, `figures`, and `icc` (sRGB
// when it is empty).
Status WriteTiffMaster(const std::string& tif, const cv::Mat& image, double dpi,
                       const ScanIdentity& identity, std::map<std::string, std::string> figures,
                       const IccProfile& icc, bool profile = true) {
  const Status written = WriteTiff(tif, image, dpi);
  if (!written.ok()) return written;
  XmpFields xmp;
  xmp.identity = identity;
  xmp.creator_tool = std::string("vellum ") + VellumVersion();
  xmp.figures = std::move(figures);
  xmp.icc_channels = profile ? image.channels() : 0;
  xmp.icc_profile = icc;
  return WriteXmp(tif, xmp);
}

}  // namespace

Status WriteRestoredAlbedo(const std::string& dir, const RestoreResult& albedo,
                           const ScanIdentity& identity,
                           const std::map<std::string, std::string>& figures,
                           const std::string& file) {
  std::map<std::string, std::string> with_encoding = figures;
  with_encoding["encoding"] = "linear reflectance: 65535 = albedo 1; 0 = not measured";
  return WriteTiffMaster((fs::path(dir) / file).string(), albedo.image, TiffDpi(albedo), identity,
                         with_encoding, IccProfile(),
                         /*profile=*/false);
}

Status WriteRestoredLight(const std::string& dir, const std::string& name, const cv::Mat& image,
                          const RestoreResult& restored, const ScanIdentity& identity,
                          const std::map<std::string, std::string>& figures,
                          const IccProfile& icc) {
  const fs::path folder = fs::path(dir) / "lights";
  const Status s = MakeDirectories(folder.string());
  if (!s.ok()) return s;
  std::map<std::string, std::string> with_light = figures;
  with_light["light"] = name;
  return WriteTiffMaster((folder / (name + ".tif")).string(), image, TiffDpi(restored), identity,
                         with_light, icc);
}

Status WriteNormalMap(const std::string& dir, const cv::Mat& normal_map,
                      const RestoreResult& restored, const ScanIdentity& identity,
                      const std::map<std::string, std::string>& figures) {
  std::map<std::string, std::string> with_encoding = figures;
  with_encoding["encoding"] =
      "normal map: red, green, blue = x (right), y (up), z (out of the page), each (c + 1) / 2 "
      "of 65535; 0 = not measured";
  return WriteTiffMaster((fs::path(dir) / "normals.tif").string(), normal_map, TiffDpi(restored),
                         identity, with_encoding, IccProfile(),
                         /*profile=*/false);
}

Status WriteArchivalMaster(const std::string& dir, const cv::Mat& texture,
                           const ScanIdentity& identity, const IccProfile& icc) {
  return WriteTiffMaster(
      (fs::path(dir) / "archival.tif").string(), texture, 0, identity,
      {{"view", "camera"}, {"master", "archival: the texture as captured, not flattened"}}, icc);
}

Status WriteRestored(const std::string& dir, const RestoreResult& restored,
                     const ScanIdentity& identity,
                     const std::map<std::string, std::string>& provenance, const IccProfile& icc) {
  const std::string tif = (fs::path(dir) / "restored.tif").string();
  // The mask and the sampling map on a second thread while this one writes the master: each
  // write is mostly one compressor's work, and they share nothing.
  std::future<Status> beside = std::async(std::launch::async, [&] {
    if (!restored.mask.empty()) {
      const Status s = WriteImage((fs::path(dir) / "restored_mask.png").string(), restored.mask);
      if (!s.ok()) return s;
    }
    if (!restored.sampling.empty()) {
      return WriteImage((fs::path(dir) / "sampling_ppi.tif").string(), restored.sampling);
    }
    return Status::Ok();
  });
  // XMP names are camelCase (rotationDeg), restored.json's snake_case (rotation_deg).
  std::map<std::string, std::string> figures;
  for (const auto& [key, value] : provenance) {
    std::string name;
    for (size_t k = 0; k < key.size(); ++k) {
      if (key[k] == '_' && k + 1 < key.size()) {
        name += static_cast<char>(std::toupper(static_cast<unsigned char>(key[++k])));
      } else {
        name += key[k];
      }
    }
    figures[name] = value;
  }
  figures["view"] = ToString(restored.view);
  if (restored.view == RestoreView::kOrthographic) {
    figures["dpi"] = JsonNumber(restored.dpi).dump();
    figures["rotationDeg"] = JsonNumber(restored.rotation_deg).dump();
  }
  const Status written =
      WriteTiffMaster(tif, restored.image, TiffDpi(restored), identity, figures, icc);
  const Status written_beside = beside.get();
  if (!written_beside.ok()) return written_beside;
  if (!written.ok()) return written;
  Json r;
  Json id = Json::object();
  ForEachIdentityField(identity, [&](const char* key, const std::string& value) {
    if (!value.empty()) id[key] = value;
  });
  if (!id.empty()) r["identity"] = id;
  r["view"] = ToString(restored.view);
  r["image"] = "restored.tif";
  if (!restored.mask.empty()) r["mask"] = "restored_mask.png";
  r["width"] = restored.image.cols;
  r["height"] = restored.image.rows;
  if (restored.view == RestoreView::kOrthographic) {
    const cv::Matx23d& a = restored.pixel_from_flat;
    r["dpi"] = JsonNumber(restored.dpi);
    r["flat_frame"] = "the x, y of flat.ply, mm";
    r["rotation_deg"] = JsonNumber(restored.rotation_deg);
    Json rows = Json::array();
    for (int row = 0; row < 2; ++row) {
      Json cols = Json::array();
      for (int col = 0; col < 3; ++col) cols.push_back(JsonNumber(a(row, col)));
      rows.push_back(cols);
    }
    r["pixel_from_flat_mm"] = rows;
    r["pixel_convention"] =
        "pixel centres at integer coordinates; the flat page turned counter-clockwise by "
        "rotation_deg, then column = x, row = -y, cropped to the leaf plus a margin";
  } else {
    r["flat_frame"] = "the x, y of flat.ply, mm, on the table plane z = 0";
    r["pixel_from_flat_mm"] = "the calibrated camera's projection of (x, y, 0)";
  }
  if (!restored.sampling.empty()) r["sampling"] = "sampling_ppi.tif";
  if (!provenance.empty()) r["provenance"] = provenance;
  return WriteJsonFile((fs::path(dir) / "restored.json").string(), r);
}

}  // namespace vellum
