// vellum calibrate: capture (cmd_station.cc) and solve.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "calib/calibrate.h"
#include "cli/commands.h"
#include "io/calibration_io.h"
#include "io/scan_io.h"

namespace vellum {
namespace {

int RunCalibrateSolve(const std::vector<std::string>& args) {
  Flags flags(
      "vellum calibrate solve DIR...",
      "Calibrates the camera, the (virtual, unmirrored) projector and the table from\n"
      "board poses, each DIR one pose's scan directory (from `vellum calibrate capture`,\n"
      "or rendered or recorded by any tool in that form). Writes the calibration YAML\n"
      "of DESIGN.md to --out and a report (per-pose and overall reprojection errors,\n"
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
  if (s.ok()) {
    std::ofstream f(out + ".report.txt");
    f << report;
    if (!f) s = Status::Error(out + ".report.txt: cannot write");
  }
  if (!s.ok()) {
    std::fprintf(stderr, "vellum calibrate solve: %s\n", s.message().c_str());
    return 1;
  }
  std::printf("calibration written to %s (report: %s.report.txt)\n", out.c_str(), out.c_str());
  return 0;
}

}  // namespace

int RunCalibrate(const std::vector<std::string>& args) {
  const std::string usage =
      "usage: vellum calibrate capture --out DIR [--url URL]   record one board pose\n"
      "       vellum calibrate solve --board COLSxROWS --square MM --table DIR --out FILE DIR...\n"
      "Run 'vellum calibrate capture --help' or 'vellum calibrate solve --help' for details.\n";
  if (args.empty() || args[0] == "--help") {
    std::fputs(usage.c_str(), args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  const std::vector<std::string> rest(args.begin() + 1, args.end());
  if (args[0] == "capture") return RunCalibrateCapture(rest);
  if (args[0] == "solve") return RunCalibrateSolve(rest);
  std::fprintf(stderr, "vellum calibrate: unknown step '%s'\n%s", args[0].c_str(), usage.c_str());
  return 2;
}

}  // namespace vellum
