// vellum calibrate: capture (cmd_station.cc), solve and flatfield.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "calib/calibrate.h"
#include "cli/commands.h"
#include "core/common/text.h"
#include "core/decode/decode.h"
#include "core/geometry/triangulate.h"
#include "core/shading/albedo.h"
#include "flags/options.h"
#include "io/calibration_io.h"
#include "io/json.h"
#include "io/scan_io.h"

namespace vellum {
namespace {

int RunCalibrateSolve(const std::vector<std::string>& args) {
  Flags flags(
      "vellum calibrate solve DIR...",
      "Calibrates the camera, the (virtual, unmirrored) projector and the table from\n"
      "board poses, each DIR one pose's scan directory (from `vellum calibrate capture`,\n"
      "or rendered or recorded by any tool in that form). Writes the calibration YAML\n"
      "of docs/formats.md to --out and a report (per-pose and overall reprojection errors,\n"
      "corners used, warnings above 0.5 px, a leave-one-pose-out check) beside it as\n"
      "FILE.report.txt. A pose that cannot be used is named with the reason, and the\n"
      "others are used; the same pose given twice is refused; an outlier pose (errors\n"
      "over 3x the poses' median) is dropped from the solve and named. A calibration\n"
      "whose overall error is above 1 px is not written (exit status 1) unless --force.",
      {
          {"board", "COLSxROWS", "the board's inner corners, across x down", "16x21"},
          {"square", "MM", "the board's square side, mm", "10"},
          {"table", "DIR", "the pose lying flat on the table (defines z = 0)", ""},
          {"out", "FILE", "the calibration YAML to write", ""},
          {"force", "", "write the calibration even when its errors are over the limits", "false"},
      });
  std::vector<std::string> dirs, rest;
  SplitPositional(args, &dirs, &rest, {"--force"});
  if (!flags.Parse(rest)) return 0;
  BoardSpec board;
  board.inner_corners = flags.GetSize("board");
  board.square_mm = flags.GetDouble("square", 0.01, 1000);
  if (board.inner_corners.width < 3 || board.inner_corners.height < 3) {
    throw UsageError("--board needs at least 3x3 inner corners");
  }
  const std::string table = flags.Require("table"), out = flags.Require("out");
  namespace fs = std::filesystem;
  auto same = [](const std::string& a, const std::string& b) {
    std::error_code ec;
    return fs::equivalent(a, b, ec) || a == b;
  };
  if (std::none_of(dirs.begin(), dirs.end(), [&](const std::string& d) { return same(d, table); }))
    dirs.insert(dirs.begin(), table);
  size_t table_index = 0;
  std::vector<BoardView> views;
  for (size_t i = 0; i < dirs.size(); ++i) {
    if (same(dirs[i], table)) table_index = i;
    std::fprintf(stderr, "pose %zu of %zu: %s\n", i + 1, dirs.size(), dirs[i].c_str());
    Scan scan;
    const Status read = ReadScan(dirs[i], &scan);
    if (!read.ok()) {
      BoardView bad;
      bad.name = dirs[i];
      bad.status = Status::Error(read.message());
      views.push_back(bad);
    } else {
      views.push_back(DetectBoard(scan, board, dirs[i]));
    }
    if (!views.back().status.ok())
      std::fprintf(stderr, "  not usable: %s\n", views.back().status.message().c_str());
  }
  const CalibrationSolution solution = SolveCalibration(views, table_index, board);
  const std::string report = FormatCalibrationReport(solution);
  std::fputs(report.c_str(), stdout);
  if (!solution.status.ok()) {
    std::fprintf(stderr, "vellum calibrate solve: %s\n", solution.status.message().c_str());
    return 1;
  }
  if (!solution.over_limits.empty() && !flags.GetBool("force")) {
    std::fprintf(stderr,
                 "vellum calibrate solve: not written: %s (check the board size, --board COLSxROWS,"
                 " and the poses; --force writes it anyway)\n",
                 solution.over_limits.c_str());
    return 1;
  }
  Status s = WriteCalibration(out, solution.calibration);
  if (s.ok()) s = WriteTextFile(out + ".report.txt", report);
  if (!s.ok()) {
    std::fprintf(stderr, "vellum calibrate solve: %s\n", s.message().c_str());
    return 1;
  }
  std::printf("calibration written to %s (report: %s.report.txt)\n", out.c_str(), out.c_str());
  return 0;
}

int RunCalibrateFlatField(const std::vector<std::string>& args) {
  Flags flags(
      "vellum calibrate flatfield",
      "Measures the projector's own light (its fall-off, vignetting and response, as the\n"
      "camera sees it) from a scan of a white target lying flat on the table and covering\n"
      "the camera's view (white card, or a reflectance standard for the best figures), for\n"
      "the page's albedo: `vellum process --flatfield FILE` then writes restored_albedo.tif.\n"
      "Writes the flat field YAML to --out. Scan the target again whenever the projector,\n"
      "its lamp or the camera's exposure changes.",
      {
          {"scan", "DIR", "the white target's scan directory", ""},
          {"calibration", "FILE", "the station's calibration", ""},
          {"albedo", "A", "the target's reflectance, 0..1 (its maker's figure)", "0.9"},
          {"out", "FILE", "the flat field YAML to write", ""},
      });
  if (!flags.Parse(args)) return 0;
  const std::string dir = flags.Require("scan"), out = flags.Require("out");
  FlatFieldOptions options;
  options.target_albedo = flags.GetDouble("albedo", 0.01, 1);
  Calibration calibration;
  Scan scan;
  Status s = ReadCalibration(flags.Require("calibration"), &calibration);
  if (s.ok()) s = ReadScan(dir, &scan);
  if (s.ok() && scan.camera_size != calibration.camera.size) {
    s = Status::Error(dir + ": camera images are " + SizeText(scan.camera_size) +
                      " but the calibration's camera is " + SizeText(calibration.camera.size));
  }
  FlatField field;
  if (s.ok()) {
    const DecodeResult decoded = Decode(scan.sequence, scan.frames);
    s = decoded.status;
    if (s.ok()) {
      const PointMap map = Triangulator(calibration).Triangulate(decoded);
      s = map.status;
      if (s.ok()) field = MeasureFlatField(decoded.amplitude, map.points, calibration, options, &s);
    }
  }
  if (s.ok()) s = WriteFlatField(out, field);
  if (!s.ok()) {
    std::fprintf(stderr, "vellum calibrate flatfield: %s\n", s.message().c_str());
    return 1;
  }
  double low = 0, high = 0;
  cv::minMaxIdx(field.gain, &low, &high, nullptr, nullptr, field.gain == field.gain);
  const int measured = cv::countNonZero(field.gain == field.gain);
  std::printf(
      "flat field: %d of %d projector cells (%d px each) measured; the projector's light there "
      "runs from %.0f%% to 100%% of its brightest; written to %s\n",
      measured, static_cast<int>(field.gain.total()), field.cell_px, 100 * low / high, out.c_str());
  return 0;
}

int RunCalibrateStudio(const std::vector<std::string>& args) {
  Flags flags(
      "vellum calibrate studio",
      "Measures the studio lamps' light (and the camera's gain and vignetting under them) from\n"
      "the texture of a white target lying flat on the table and covering the camera's view,\n"
      "shot under the same lamps and exposure as the pages, for the texture's reflectance:\n"
      "`vellum process --studio-field FILE` then writes restored_reflectance.tif. The lamps\n"
      "are described by where they stand (world mm: the table's frame, z up); they are taken\n"
      "as point sources of equal strength. Writes the studio field YAML to --out.",
      {
          {"scan", "DIR", "the white target's scan directory (its texture.png is used)", ""},
          {"calibration", "FILE", "the station's calibration", ""},
          {"lamps", "X,Y,Z;...", "each lamp's place, world mm, ';' between lamps", ""},
          {"albedo", "A", "the target's reflectance, 0..1 (its maker's figure)", "0.9"},
          {"out", "FILE", "the studio field YAML to write", ""},
      });
  if (!flags.Parse(args)) return 0;
  const std::string dir = flags.Require("scan"), out = flags.Require("out");
  const std::vector<cv::Vec3d> lamps = ParseLamps("lamps", flags.Require("lamps"));
  if (lamps.empty()) throw UsageError("--lamps: give at least one lamp");
  Calibration calibration;
  cv::Mat texture;
  Status s = ReadCalibration(flags.Require("calibration"), &calibration);
  if (s.ok()) s = ReadTexture(dir, &texture);
  StudioField field;
  if (s.ok()) {
    field = MeasureStudioField(texture, calibration.camera, lamps,
                               flags.GetDouble("albedo", 0.01, 1), &s);
    if (!s.ok()) s = Status::Error(dir + "/texture.png: " + s.message());
  }
  if (s.ok()) s = WriteStudioField(out, field);
  if (!s.ok()) {
    std::fprintf(stderr, "vellum calibrate studio: %s\n", s.message().c_str());
    return 1;
  }
  cv::Mat first;
  cv::extractChannel(field.gain, first, 0);
  double low = 0, high = 0;
  cv::minMaxIdx(first, &low, &high, nullptr, nullptr, first == first);
  std::printf(
      "studio field: %d of %d camera cells (%d px each) measured under %zu lamps; the camera's "
      "gain there runs from %.0f%% to 100%% of its highest; written to %s\n",
      cv::countNonZero(first == first), static_cast<int>(first.total()), field.cell_px,
      lamps.size(), 100 * low / high, out.c_str());
  return 0;
}

}  // namespace

int RunCalibrate(const std::vector<std::string>& args) {
  const std::string usage =
      "usage: vellum calibrate capture --out DIR [--url URL]   record one board pose\n"
      "       vellum calibrate solve --board COLSxROWS --square MM --table DIR --out FILE DIR...\n"
      "       vellum calibrate flatfield --scan DIR --calibration FILE --albedo A --out FILE\n"
      "       vellum calibrate studio --scan DIR --calibration FILE --lamps X,Y,Z;... --out FILE\n"
      "       vellum calibrate latency [--url URL]   the display's lag, through the station\n"
      "Run 'vellum calibrate STEP --help' (capture, solve, flatfield, studio, latency) for "
      "details.\n";
  if (args.empty() || args[0] == "--help") {
    std::fputs(usage.c_str(), args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  const std::vector<std::string> rest(args.begin() + 1, args.end());
  if (args[0] == "capture") return RunCalibrateCapture(rest);
  if (args[0] == "solve") return RunCalibrateSolve(rest);
  if (args[0] == "flatfield") return RunCalibrateFlatField(rest);
  if (args[0] == "studio") return RunCalibrateStudio(rest);
  if (args[0] == "latency") return RunCalibrateLatency(rest);
  std::fprintf(stderr, "vellum calibrate: unknown step '%s'\n%s", args[0].c_str(), usage.c_str());
  return 2;
}

}  // namespace vellum
