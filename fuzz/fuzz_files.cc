// libFuzzer: the files outside tools write. The first byte picks the reader: scan.yaml of a
// scan directory, a calibration YAML (and the flat and studio fields), points.ply, a quad-mesh
// PLY, a scan's texture.png (the image header checked before decoding), the station's lights
// file, a PTM, a scan directory's header (scan.yaml with its leaf hint, then its images), or a
// daemon's `flag: value` config file. The input is written to a scratch file and read back; bad
// files must give an error Status (or the flags' UsageError), never a crash.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "flags/flags.h"
#include "io/calibration_io.h"
#include "io/ply.h"
#include "io/ptm.h"
#include "io/scan_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vellum;
  namespace fs = std::filesystem;
  if (size < 1 || size > (1u << 20)) return 0;
  static const fs::path dir =
      fs::temp_directory_path() / ("vellum_fuzz_files_" + std::to_string(getpid()));
  static const bool made = fs::create_directories(dir) || fs::exists(dir);
  (void)made;
  const uint8_t kind = data[0] % 9;
  const char* names[] = {"scan.yaml", "calibration.yaml", "points.ply",
                         "mesh.ply",  "texture.png",      "lights.yaml",
                         "page.ptm",  "scan.yaml",        "vellum-decoder.yaml"};
  const fs::path path = dir / names[kind];
  {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
  }
  switch (kind) {
    case 0: {
      Scan header;  // Every key: identity, lights, hint, object, what the live view saw.
      (void)ReadScanYaml(dir.string(), &header);
      break;
    }
    case 1: {
      // The other YAML files a station reads beside its calibration: the flat fields.
      Calibration c;
      (void)ReadCalibration(path.string(), &c);
      FlatField flat_field;
      (void)ReadFlatField(path.string(), &flat_field);
      StudioField studio_field;
      (void)ReadStudioField(path.string(), &studio_field);
      break;
    }
    case 2: {
      std::vector<PlyPoint> points;
      (void)ReadPointsPly(path.string(), &points);
      break;
    }
    case 3: {
      std::vector<cv::Vec3f> vertices;
      std::vector<cv::Vec4i> quads;
      (void)ReadQuadMeshPly(path.string(), &vertices, &quads);
      break;
    }
    case 4: {
      cv::Mat texture;
      (void)ReadTexture(dir.string(), &texture);
      break;
    }
    case 5: {
      StationLights lights;
      (void)ReadLightsFile(path.string(), &lights);
      break;
    }
    case 6: {
      PtmResult ptm;
      (void)ReadPtm(path.string(), &ptm);
      break;
    }
    case 7: {
      // No texture.png beside it (one an earlier input left would make the run depend on
      // it): the header's keys, the leaf hint among them, are read before images are sought.
      fs::remove(dir / "texture.png");
      Scan scan;
      (void)ReadScanHeader(dir.string(), &scan);
      break;
    }
    case 8: {
      Flags flags("fuzz", "a daemon's flags",
                  {{"config", "FILE", "config", ""},
                   {"bus", "URL", "bus", "udpm://"},
                   {"size", "WxH", "size", "4x3"},
                   {"count", "N", "count", "1"},
                   {"gain", "X", "gain", "1.5"},
                   {"flag", "", "a switch", ""}});
      auto quietly = [](auto read) {
        try {
          read();
        } catch (const UsageError&) {
        }
      };
      quietly([&] { (void)flags.Parse({"--config", path.string()}); });
      quietly([&] { (void)flags.GetSize("size"); });
      quietly([&] { (void)flags.GetInt("count", 0, 100); });
      quietly([&] { (void)flags.GetDouble("gain", 0, 10); });
      quietly([&] { (void)flags.GetBool("flag"); });
      break;
    }
  }
  return 0;
}
