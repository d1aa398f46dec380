// The `vellum` tool as a user runs it: help, the pattern/render/process chain on a small rig,
// and bad input (missing frame, mixed sizes, non-image, wrong calibration) giving one clear
// error that names the file and the problem, a non-zero exit, and never a crash.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/sim/gantry.h"
#include "io/calibration_io.h"
#include "io/ply.h"
#include "io/scan_io.h"
#include "io/xmp.h"
#include "tests/icc_profile.h"
#include "tests/shell.h"

namespace vellum {
namespace {

namespace fs = std::filesystem;

using Result = ShellResult;

Result RunVellum(const std::string& args) { return Shell(std::string(VELLUM_BIN) + " " + args); }

class CliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = fs::temp_directory_path() / ("vellum_cli_test_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    fs::create_directories(root_);
    ASSERT_TRUE(WriteCalibration((root_ / "rig.yaml").string(), QuickRig()).ok());
    const Result r = RunVellum("render --page curl --calibration " + (root_ / "rig.yaml").string() +
                               " --out " + (root_ / "scan").string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  static void TearDownTestSuite() { fs::remove_all(root_); }

  // A copy of the good scan to break.
  static std::string CopyScan(const std::string& name) {
    const fs::path dst = root_ / name;
    fs::remove_all(dst);
    fs::copy(root_ / "scan", dst, fs::copy_options::recursive);
    return dst.string();
  }
  static std::string Process(const std::string& scan, const std::string& calib) {
    return "process --scan " + scan + " --calibration " + calib + " --out " +
           (root_ / "out").string();
  }
  static std::string Rig() { return (root_ / "rig.yaml").string(); }
  static fs::path root_;
};
fs::path CliTest::root_;

TEST_F(CliTest, EveryCommandHasHelp) {
  for (const char* cmd :
       {"--help", "patterns --help", "render --help", "process --help", "manifest --help",
        "iiif --help", "collection --help", "calibrate flatfield --help", "calibrate studio --help",
        "calibrate solve --help"}) {
    const Result r = RunVellum(cmd);
    EXPECT_EQ(r.exit_code, 0) << cmd;
    EXPECT_NE(r.output.find("usage: vellum"), std::string::npos) << r.output;
  }
  const Result r = RunVellum("process --bogus 1");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("unknown flag --bogus"), std::string::npos) << r.output;
}

TEST_F(CliTest, PatternsWritesImagesAndScanYaml) {
  const std::string dir = (root_ / "patterns").string();
  const Result r = RunVellum("patterns --projector 854x480 --out " + dir);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  Scan header;
  ASSERT_TRUE(ReadScanYaml(dir, &header).ok());
  const PatternSequence& seq = header.sequence;
  EXPECT_EQ(seq.projector_size, cv::Size(854, 480));
  EXPECT_EQ(seq.GrayBits(Axis::kColumn), 10);
  EXPECT_EQ(seq.GrayBits(Axis::kRow), 9);
  for (size_t k = 0; k < seq.patterns.size(); ++k) {
    const cv::Mat img = cv::imread((fs::path(dir) / PatternName(static_cast<int>(k))).string(),
                                   cv::IMREAD_UNCHANGED);
    ASSERT_EQ(img.size(), cv::Size(854, 480)) << k;
    EXPECT_EQ(cv::norm(img, RenderPattern(seq.patterns[k], seq.projector_size), cv::NORM_INF), 0);
  }
  EXPECT_FALSE(fs::exists(fs::path(dir) / PatternName(static_cast<int>(seq.patterns.size()))));
}

TEST_F(CliTest, ProcessWritesPointsAndReport) {
  const Result r = RunVellum(Process((root_ / "scan").string(), Rig()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::vector<PlyPoint> points;
  ASSERT_TRUE(ReadPointsPly((root_ / "out" / "points.ply").string(), &points).ok());
  // Most of the 400x300 camera sees lit table or page.
  EXPECT_GT(points.size(), 60000u);
  std::ifstream report(root_ / "out" / "report.json");
  const std::string text((std::istreambuf_iterator<char>(report)),
                         std::istreambuf_iterator<char>());
  for (const char* key : {"\"decode\"", "\"triangulate\"", "\"valid\"", "\"options\""}) {
    EXPECT_NE(text.find(key), std::string::npos) << key << " in " << text;
  }
}

// A doubtful result is written, printed as a warning, recorded in report.json, and exits 3; a
// clean one prints no warning and exits 0.
TEST_F(CliTest, ADoubtfulResultExitsThreeWithItsWarning) {
  const Result clean = RunVellum(Process((root_ / "scan").string(), Rig()));
  ASSERT_EQ(clean.exit_code, 0) << clean.output;
  EXPECT_EQ(clean.output.find("warning"), std::string::npos) << clean.output;
  EXPECT_NE(clean.output.find("quality: pass"), std::string::npos) << clean.output;
  const Result r = RunVellum(Process((root_ / "scan").string(), Rig()) + " --leaf-size 100x100");
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("warning size_unexpected: the leaf measures"), std::string::npos)
      << r.output;
  EXPECT_TRUE(fs::exists(root_ / "out" / "restored.tif"));
  std::ifstream report(root_ / "out" / "report.json");
  const std::string text((std::istreambuf_iterator<char>(report)),
                         std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("\"size_unexpected\""), std::string::npos) << text;
  // Quality control: a warning on scale, printed and in report.json.
  EXPECT_NE(r.output.find("quality: warn"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("scale: warn: leaf"), std::string::npos) << r.output;
  const nlohmann::json j = nlohmann::json::parse(text);
  EXPECT_EQ(j["qc"]["verdict"], "warn") << j["qc"].dump();
  std::ifstream html(root_ / "out" / "report.html");
  const std::string page((std::istreambuf_iterator<char>(html)), std::istreambuf_iterator<char>());
  EXPECT_NE(page.find("<div class=\"qc qc-warn\"><h2>Quality: warn</h2>"), std::string::npos);
}

// The collection's target: a scan short of it fails quality control on the figure that falls
// short, named with what the target asks, and exits 3 (doubtful); one that meets it passes.
// The test rig samples the table at about 25 ppi.
TEST_F(CliTest, ACollectionTargetFailsAScanShortOfItOnTheFigureNamed) {
  const std::string base = Process((root_ / "scan").string(), Rig());
  const Result met = RunVellum(base + " --target-ppi 10");
  EXPECT_EQ(met.exit_code, 0) << met.output;
  EXPECT_NE(met.output.find("quality: pass"), std::string::npos) << met.output;
  const Result short_of = RunVellum(base + " --target-ppi 300");
  EXPECT_EQ(short_of.exit_code, 3) << short_of.output;
  EXPECT_NE(short_of.output.find("quality: fail"), std::string::npos) << short_of.output;
  EXPECT_NE(short_of.output.find("sampling: fail:"), std::string::npos) << short_of.output;
  EXPECT_NE(short_of.output.find("the target (300 ppi) asks 300"), std::string::npos)
      << short_of.output;
  std::ifstream report(root_ / "out" / "report.json");
  const nlohmann::json j = nlohmann::json::parse(report);
  EXPECT_EQ(j["qc"]["target"], "300 ppi");
  bool named = false;
  for (const auto& c : j["qc"]["checks"])
    named |= c["name"] == "sampling" && c["verdict"] == "fail";
  EXPECT_TRUE(named) << j["qc"].dump();
  const Result bits = RunVellum(base + " --target-bits 16");
  EXPECT_EQ(bits.exit_code, 3) << bits.output;
  EXPECT_NE(bits.output.find("bit depth: fail: 8 bits per channel; the target (16 bits) asks 16"),
            std::string::npos)
      << bits.output;
  const Result odd = RunVellum(base + " --target-bits 12");
  EXPECT_EQ(odd.exit_code, 2) << odd.output;
  EXPECT_NE(odd.output.find("--target-bits must be 0 (none), 8 or 16"), std::string::npos)
      << odd.output;
}

// An object that is not a page: --until points writes the point cloud and the report, and no
// sheet or restored page.
TEST_F(CliTest, UntilPointsStopsAfterThePointCloud) {
  const std::string out = (root_ / "points_only").string();
  const Result r = RunVellum("process --scan " + (root_ / "scan").string() + " --calibration " +
                             Rig() + " --out " + out + " --until points");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("stopped after the point cloud"), std::string::npos) << r.output;
  std::vector<PlyPoint> points;
  ASSERT_TRUE(ReadPointsPly(out + "/points.ply", &points).ok());
  EXPECT_GT(points.size(), 60000u);
  EXPECT_TRUE(fs::exists(out + "/report.json"));
  EXPECT_TRUE(fs::exists(out + "/report.html"));
  for (const char* absent : {"mesh.ply", "flat.ply", "restored.tif", "restored.json"}) {
    EXPECT_FALSE(fs::exists(out + "/" + absent)) << absent;
  }
  EXPECT_EQ(RunVellum("process --scan " + (root_ / "scan").string() + " --calibration " + Rig() +
                      " --out " + out + " --until mesh")
                .exit_code,
            2);
}

// Frames that do not belong together (here the scan's frames in reverse order, as a pattern
// list shuffled against them gives) are flagged where the points are written, `--until points`
// too: decode_low names it, the quality check "points" warns, and the run exits 3.
TEST_F(CliTest, FramesOutOfOrderAreFlaggedWhereThePointsAreWritten) {
  const std::string scan = CopyScan("reversed");
  int frames = 0;
  while (fs::exists(fs::path(scan) / FrameName(frames))) ++frames;
  ASSERT_GT(frames, 4);
  for (int k = 0; k < frames / 2; ++k) {
    const fs::path a = fs::path(scan) / FrameName(k),
                   b = fs::path(scan) / FrameName(frames - 1 - k);
    const fs::path t = fs::path(scan) / "swap.png";
    fs::rename(a, t);
    fs::rename(b, a);
    fs::rename(t, b);
  }
  const std::string out = (root_ / "reversed_points").string();
  const Result r = RunVellum("process --scan " + scan + " --calibration " + Rig() + " --out " +
                             out + " --until points");
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("warning decode_low: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("quality: warn"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("points: warn: "), std::string::npos) << r.output;
  // The scan as it was: nearly every lit pixel gives a point, no such warning.
  const Result clean = RunVellum("process --scan " + (root_ / "scan").string() + " --calibration " +
                                 Rig() + " --out " + out + " --until points");
  EXPECT_EQ(clean.exit_code, 0) << clean.output;
  EXPECT_EQ(clean.output.find("decode_low"), std::string::npos) << clean.output;
}

// Points of two runs matched by their camera pixel: how many of `a`'s the other lacks, and how
// many it has more than `mm` away.
struct PointsApart {
  size_t missing = 0, moved = 0;
};
PointsApart ComparePoints(const std::string& a_ply, const std::string& b_ply, double mm) {
  std::vector<PlyPoint> a, b;
  EXPECT_TRUE(ReadPointsPly(a_ply, &a).ok()) << a_ply;
  EXPECT_TRUE(ReadPointsPly(b_ply, &b).ok()) << b_ply;
  std::map<std::pair<int, int>, const PlyPoint*> by_pixel;
  for (const PlyPoint& p : b) by_pixel[{std::lround(p.u), std::lround(p.v)}] = &p;
  PointsApart apart;
  for (const PlyPoint& p : a) {
    const auto it = by_pixel.find({std::lround(p.u), std::lround(p.v)});
    if (it == by_pixel.end()) {
      ++apart.missing;
      continue;
    }
    const PlyPoint& q = *it->second;
    apart.moved += std::hypot(p.x - q.x, p.y - q.y, p.z - q.z) > mm;
  }
  return apart;
}

// A frame that contradicts the others is named (frame_contradicts), `--until points` too, and
// where the scan's redundancy tells which frame of its pair is wrong, the bit is decoded without
// it. Each Gray frame and its inverse add up to the white and black frames (light is additive);
// the sound scan's pairs do at all but a few of the lit pixels.
// - The same pattern's frame of another leaf in one's place (a coarse row bit; before, a few
//   hundred points 1 mm off with every other check passed): it lies off the two levels this
//   scan's light allows where its pair lies on them, so it is left out: the points are the sound
//   scan's (a Gray bit decides a whole stripe; decided from one frame against white + black, a
//   pixel may change only where the frame is as dim as noise).
// - The inverse taken before the projector changed (it shows its pair's pattern): the later of
//   the two is left out, as above.
// - A frame of another pattern lies on the levels as the right one does: named, not mended.
TEST_F(CliTest, AFrameThatContradictsTheOthersIsNamedAndLeftOutWhereTheScanTells) {
  const std::string other = (root_ / "other_leaf").string();
  ASSERT_EQ(RunVellum("render --page fold --calibration " + Rig() + " --out " + other).exit_code,
            0);
  Scan header;
  ASSERT_TRUE(ReadScanHeader((root_ / "scan").string(), &header).ok());
  const int coarse = header.sequence.Find(PatternKind::kGray, Axis::kRow, 7, false);
  const int inverse = header.sequence.Find(PatternKind::kGray, Axis::kRow, 7, true);
  const int finer = header.sequence.Find(PatternKind::kGray, Axis::kRow, 6, false);
  ASSERT_GE(coarse, 0);
  ASSERT_EQ(inverse, coarse + 1);
  ASSERT_GE(finer, 0);
  const std::string named = "frames " + std::to_string(coarse) + " and " + std::to_string(inverse) +
                            " ('gray row bit 7' and its inverse)";
  const std::string clean_out = (root_ / "clean_out").string();
  const Result clean = RunVellum("process --scan " + (root_ / "scan").string() + " --calibration " +
                                 Rig() + " --out " + clean_out + " --until points");
  EXPECT_EQ(clean.exit_code, 0) << clean.output;
  EXPECT_EQ(clean.output.find("frame_contradicts"), std::string::npos) << clean.output;
  std::vector<PlyPoint> sound;
  ASSERT_TRUE(ReadPointsPly(clean_out + "/points.ply", &sound).ok());
  const size_t clean_points = sound.size();
  ASSERT_GT(clean_points, 60000u);
  struct {
    const char* name;
    int frame;     // Replaced,
    fs::path by;   // by this one.
    int left_out;  // The frame the bit is decoded without, -1 none.
    const char* why;
  } cases[] = {
      {"another_leaf", coarse, fs::path(other) / FrameName(coarse), coarse, "off the scan's light"},
      {"before_the_change", inverse, root_ / "scan" / FrameName(coarse), inverse,
       "showing its pair's pattern"},
      {"another_pattern", coarse, root_ / "scan" / FrameName(finer), -1, ""}};
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string scan = CopyScan(c.name);
    fs::copy_file(c.by, fs::path(scan) / FrameName(c.frame), fs::copy_options::overwrite_existing);
    const std::string out = (root_ / (std::string(c.name) + "_out")).string();
    const Result r = RunVellum("process --scan " + scan + " --calibration " + Rig() + " --out " +
                               out + " --until points");
    EXPECT_EQ(r.exit_code, 3) << r.output;
    EXPECT_NE(r.output.find("warning frame_contradicts: 1 Gray frame pair"), std::string::npos)
        << r.output;
    EXPECT_NE(r.output.find(named), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("points: warn: "), std::string::npos) << r.output;
    const PointsApart apart = ComparePoints(clean_out + "/points.ply", out + "/points.ply", 0.1);
    if (c.left_out >= 0) {
      const int kept = c.left_out == coarse ? inverse : coarse;
      EXPECT_NE(
          r.output.find("frame " + std::to_string(c.left_out) + " " + c.why +
                        " left out, the bit decoded from frame " + std::to_string(kept) + " alone"),
          std::string::npos)
          << r.output;
      EXPECT_NE(r.output.find("decoded without it"), std::string::npos) << r.output;
      // At most 1 in 10,000 of the sound scan's points lost or moved 0.1 mm (a tenth of the
      // millimetre the wrong frame moved them by).
      EXPECT_LE(apart.missing + apart.moved, 1 + clean_points / 10000)
          << apart.missing << " missing, " << apart.moved << " moved";
    } else {
      // Not mended: the wrong bit costs a good part of the points (it is flagged, above).
      EXPECT_GT(apart.missing + apart.moved, clean_points / 100);
      EXPECT_EQ(r.output.find("left out"), std::string::npos) << r.output;
      EXPECT_NE(r.output.find("; scan again"), std::string::npos) << r.output;
    }
  }
  // Frames of two scans mixed in one folder (every other frame the other leaf's): every pair is
  // off, so none is far off the scan's usual; each is named all the same (over 5%).
  const std::string mixed = CopyScan("two_scans_mixed");
  for (int k = 3; k < static_cast<int>(header.sequence.patterns.size()); k += 2) {
    fs::copy_file(fs::path(other) / FrameName(k), fs::path(mixed) / FrameName(k),
                  fs::copy_options::overwrite_existing);
  }
  const Result r = RunVellum("process --scan " + mixed + " --calibration " + Rig() + " --out " +
                             (root_ / "two_scans_mixed_out").string() + " --until points");
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("warning frame_contradicts: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("points: warn: "), std::string::npos) << r.output;
}

std::string FileBytes(const fs::path& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

// Rendering and processing are deterministic: the same seed gives the same frames and the
// same scan gives the same points.ply, byte for byte (parallel loops included).
TEST_F(CliTest, RenderAndProcessAreByteForByteRepeatable) {
  const std::string again = (root_ / "scan_again").string();
  ASSERT_EQ(RunVellum("render --page curl --calibration " + Rig() + " --out " + again).exit_code,
            0);
  for (const char* name : {"texture.png", "frame_000.png", "frame_020.png", "frame_057.png"}) {
    EXPECT_EQ(FileBytes(root_ / "scan" / name), FileBytes(fs::path(again) / name)) << name;
  }
  const std::string out1 = (root_ / "det1").string(), out2 = (root_ / "det2").string();
  ASSERT_EQ(RunVellum("process --scan " + (root_ / "scan").string() + " --calibration " + Rig() +
                      " --out " + out1)
                .exit_code,
            0);
  ASSERT_EQ(
      RunVellum("process --scan " + again + " --calibration " + Rig() + " --out " + out2).exit_code,
      0);
  const std::string a = FileBytes(fs::path(out1) / "points.ply");
  EXPECT_GT(a.size(), 100000u);
  EXPECT_EQ(a, FileBytes(fs::path(out2) / "points.ply"));
}

// XResolution (282) of a little-endian TIFF, as a rational in the first IFD.
double TiffXResolution(const std::string& bytes) {
  auto u16 = [&](size_t o) {
    return static_cast<uint16_t>(uint8_t(bytes[o]) | uint8_t(bytes[o + 1]) << 8);
  };
  auto u32 = [&](size_t o) {
    return static_cast<uint32_t>(u16(o)) | static_cast<uint32_t>(u16(o + 2)) << 16;
  };
  if (bytes.size() < 8 || bytes[0] != 'I') return -1;
  const size_t ifd = u32(4);
  const int entries = u16(ifd);
  for (int e = 0; e < entries; ++e) {
    const size_t at = ifd + 2 + 12 * e;
    if (u16(at) == 282) {
      const size_t off = u32(at + 8);
      return static_cast<double>(u32(off)) / u32(off + 4);
    }
  }
  return -1;
}

TEST_F(CliTest, ProcessWritesTheSheetAndARestoredPageAtItsDpi) {
  const std::string out = (root_ / "full").string();
  const Result r = RunVellum("process --scan " + (root_ / "scan").string() + " --calibration " +
                             Rig() + " --out " + out + " --grid 20x16 --dpi 150");
  // The small rig samples the page at about 25 ppi: 150 dpi is written, and flagged (exit 3).
  ASSERT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("warning dpi_above_sampling: the page is written at 150 dpi, but the "
                          "camera truly sampled it at "),
            std::string::npos)
      << r.output;
  std::vector<cv::Vec3f> before, after;
  std::vector<cv::Vec4i> q1, q2;
  ASSERT_TRUE(ReadQuadMeshPly(out + "/mesh.ply", &before, &q1).ok());
  ASSERT_TRUE(ReadQuadMeshPly(out + "/flat.ply", &after, &q2).ok());
  EXPECT_EQ(before.size(), after.size());
  EXPECT_EQ(q1, q2);
  EXPECT_GT(q1.size(), 100u);
  for (const cv::Vec3f& v : after) EXPECT_EQ(v[2], 0.0f);
  EXPECT_NEAR(TiffXResolution(FileBytes(fs::path(out) / "restored.tif")), 150.0, 1e-9);
  const cv::Mat restored = cv::imread(out + "/restored.tif", cv::IMREAD_UNCHANGED);
  EXPECT_FALSE(restored.empty());
  const std::string json = FileBytes(fs::path(out) / "restored.json");
  EXPECT_NE(json.find("\"dpi\": 150"), std::string::npos) << json;
  EXPECT_NE(json.find("pixel_from_flat_mm"), std::string::npos) << json;
  const std::string report = FileBytes(fs::path(out) / "report.json");
  for (const char* key :
       {"\"mean_strain\"", "\"max_strain\"", "\"iterations\"", "\"grid\": \"20x16\""}) {
    EXPECT_NE(report.find(key), std::string::npos) << key;
  }
  // Camera view: the camera's image size, no dpi.
  const Result c = RunVellum("process --scan " + (root_ / "scan").string() + " --calibration " +
                             Rig() + " --out " + out + "_cam --view camera --solver euler");
  ASSERT_EQ(c.exit_code, 0) << c.output;
  EXPECT_EQ(cv::imread(out + "_cam/restored.tif", cv::IMREAD_UNCHANGED).size(), cv::Size(400, 300));
}

// A leaf laid turned on the table is restored upright. It is turned 12 degrees about
// the vertical; the restoration turns it back (restored.json's rotation_deg), so that its
// edges run along the image's rows and columns and its width and height are the right way
// round, flat or curled. On the small rig (0.625 mm per pixel; the quick rig's 1 mm leaves a
// turned curl's silhouette too coarse, and flags its strain). The tolerance, 0.5 degrees: the
// edges are found on the restored mask, whose pixel is 0.62 mm; over a 150 mm edge, 0.24
// degrees, and the outline's own error as much again.
TEST_F(CliTest, ALeafLaidTurnedIsRestoredUpright) {
  // A text page is found by its shape; a flat checkerboard turned so by the brightness rule
  // (its outline's edges are rougher: within 1 degree, 0.62 measured).
  for (const auto& [shape, texture, tolerance] :
       {std::tuple<std::string, std::string, double>{"flat", "text", 0.5},
        {"curl", "text", 0.5},
        {"flat", "checkerboard", 1.0}}) {
    const std::string scan = (root_ / ("turned_" + shape + "_" + texture)).string();
    const std::string rig = std::string(VELLUM_SOURCE_DIR) + "/config/small_rig.yaml";
    const Result render = RunVellum("render --out " + scan + " --calibration " + rig + " --page " +
                                    shape + " --page-size 150x200 --pose 0,0,12,0,0,0 --texture " +
                                    texture + " --truth false");
    ASSERT_EQ(render.exit_code, 0) << render.output;
    const std::string out = scan + "_out";
    const Result r =
        RunVellum("process --scan " + scan + " --calibration " + rig + " --out " + out);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const nlohmann::json restored =
        nlohmann::json::parse(FileBytes(fs::path(out) / "restored.json"));
    EXPECT_NEAR(restored["rotation_deg"].get<double>(), -12, tolerance) << shape << " " << texture;
    const cv::Mat mask = cv::imread(out + "/restored_mask.png", cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(mask.empty()) << shape;
    std::vector<cv::Point> leaf;
    cv::findNonZero(mask, leaf);
    const cv::RotatedRect box = cv::minAreaRect(leaf);
    const double angle = std::fmod(std::fabs(box.angle), 90.0);
    EXPECT_LT(std::min(angle, 90 - angle), tolerance)
        << shape << " " << texture << ": the leaf's edges lean " << box.angle;
    const double mm = 25.4 / restored["dpi"].get<double>();
    const cv::Rect upright = cv::boundingRect(leaf);
    // The right way round (turned a quarter, it would be 50 mm off). The curled leaf's
    // restored extent runs over by its silhouette's width: 2.6 mm laid square, 5 mm turned
    // (measured; the curl's edge crosses the sheet's cells diagonally).
    EXPECT_NEAR(upright.width * mm, 150, 8) << shape;
    EXPECT_NEAR(upright.height * mm, 200, 8) << shape;
  }
}

// vellum manifest writes a folder's SHA-256 manifest and checks it: a changed file is named
// and fails the check.
// vellum iiif: a manifest per scan, with the page's canvas at its size and true scale; a folder
// that is not a scan's results, or one outside the served folder, is named and refused.
TEST_F(CliTest, IiifWritesAManifestAndNamesWhatItCannotServe) {
  const fs::path served = root_ / "served";
  const fs::path leaf = served / "leaf";
  Result r = RunVellum("process --scan " + (root_ / "scan").string() + " --calibration " + Rig() +
                       " --out " + leaf.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunVellum("iiif --root " + served.string() + " --base http://127.0.0.1:8080/ " +
                leaf.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream in(leaf / "iiif-manifest.json");
  const nlohmann::json manifest = nlohmann::json::parse(in);
  EXPECT_EQ(manifest["id"], "http://127.0.0.1:8080/leaf/iiif-manifest.json");
  std::ifstream page_in(leaf / "restored.json");
  const nlohmann::json page = nlohmann::json::parse(page_in);
  const nlohmann::json& canvas = manifest["items"][0];
  EXPECT_EQ(canvas["width"], page["width"]);
  EXPECT_EQ(canvas["height"], page["height"]);
  EXPECT_DOUBLE_EQ(canvas["service"][0]["physicalScale"].get<double>(),
                   25.4 / page["dpi"].get<double>());
  EXPECT_EQ(canvas["items"][0]["items"][0]["body"]["service"][0]["@id"],
            "http://127.0.0.1:8080/iiif/leaf%2Frestored_pyramid.tif");
  // Not a results folder: the file it looked for is named.
  fs::create_directories(served / "empty");
  r = RunVellum("iiif --root " + served.string() + " --base http://h " +
                (served / "empty").string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("no restored page"), std::string::npos) << r.output;
  // Outside the served folder: the server could not reach it.
  r = RunVellum("iiif --root " + (served / "empty").string() + " --base http://h " + leaf.string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("not under the served folder"), std::string::npos) << r.output;
  // No --root: a usage error.
  r = RunVellum("iiif --base http://h " + leaf.string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
}

TEST_F(CliTest, ManifestWritesAndChecksAFolder) {
  const std::string dir = CopyScan("manifest");
  const Result w = RunVellum("manifest write " + dir);
  ASSERT_EQ(w.exit_code, 0) << w.output;
  EXPECT_TRUE(fs::exists(fs::path(dir) / "manifest-sha256.txt"));
  const Result ok = RunVellum("manifest check " + dir);
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  std::ofstream(fs::path(dir) / "scan.yaml", std::ios::app) << "# edited\n";
  const Result bad = RunVellum("manifest check " + dir);
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("scan.yaml: changed"), std::string::npos) << bad.output;
}

void ExpectCleanError(const Result& r, const std::string& file, const std::string& problem) {
  EXPECT_EQ(r.exit_code, 1) << "expected a clean failure, got: " << r.output;
  EXPECT_NE(r.output.find(file), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(problem), std::string::npos) << r.output;
  // One clear line, not a stack of messages.
  EXPECT_LE(std::count(r.output.begin(), r.output.end(), '\n'), 2) << r.output;
}

// The camera's own ICC profile (--camera-icc) goes as is into the production and the
// archival master in place of sRGB, and is named in report.json; exiftool (a reader vellum did
// not write) reads its name. A profile for colour images on a gray camera's scan, and a file
// that is not a profile, are refused before any work, naming the file.
TEST_F(CliTest, TheCamerasIccProfileGoesIntoBothMasters) {
  const fs::path gray = root_ / "camera_gray.icc", rgb = root_ / "camera_rgb.icc";
  WriteCameraProfile(gray, false, "Gantry camera 7, gray, gamma 2.2");
  WriteCameraProfile(rgb, true, "Gantry camera 7, Adobe RGB primaries");
  const std::string out = (root_ / "out_icc").string();
  const Result r =
      RunVellum(Process((root_ / "scan").string(), Rig()) + "_icc --camera-icc " + gray.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string made = FileBytes(gray);
  for (const char* master : {"restored.tif", "archival.tif"}) {
    std::string embedded;
    ASSERT_TRUE(ReadIccProfile((fs::path(out) / master).string(), &embedded).ok()) << master;
    EXPECT_EQ(embedded, made) << master << ": not the camera's profile as given";
    const Result exif = Shell("exiftool -s3 -ProfileDescription " + out + "/" + master);
    ASSERT_EQ(exif.exit_code, 0) << exif.output;
    EXPECT_EQ(exif.output, "Gantry camera 7, gray, gamma 2.2\n") << master;
  }
  const std::string report = FileBytes(fs::path(out) / "report.json");
  EXPECT_NE(report.find("\"icc_profile\": \"Gantry camera 7, gray, gamma 2.2\""), std::string::npos)
      << report;

  ExpectCleanError(RunVellum(Process((root_ / "scan").string(), Rig()) + "_icc_rgb --camera-icc " +
                             rgb.string()),
                   rgb.string(), "describes colour images, but");
  EXPECT_FALSE(fs::exists(root_ / "out_icc_rgb" / "points.ply")) << "work done before the check";
  std::ofstream(root_ / "junk.icc") << "not a colour profile";
  const Result junk = RunVellum(Process((root_ / "scan").string(), Rig()) +
                                "_icc_junk --camera-icc " + (root_ / "junk.icc").string());
  EXPECT_EQ(junk.exit_code, 2) << junk.output;
  EXPECT_NE(junk.output.find("junk.icc: not an ICC profile"), std::string::npos) << junk.output;
}

// A camera that gives more than 8 bits (the virtual gantry's texture at 16) gives
// 16-bit masters: restored.tif and archival.tif at 16 bits a sample (as exiftool reads them),
// the report's bit depth 16 (FADGI's 4-star figure). The structured-light frames are the same
// 8-bit frames, so the geometry is the same as the 8-bit scan's: the 16-bit restored page,
// scaled to 8 bits, is the 8-bit one within its rounding (under 1 DN; the noise is the same
// draw).
TEST_F(CliTest, ASixteenBitTextureGivesSixteenBitMasters) {
  const std::string scan16 = (root_ / "scan16").string();
  Result r =
      RunVellum("render --page curl --texture-bits 16 --calibration " + Rig() + " --out " + scan16);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string out8 = (root_ / "out_8bit").string(), out16 = (root_ / "out_16bit").string();
  r = RunVellum("process --scan " + (root_ / "scan").string() + " --calibration " + Rig() +
                " --out " + out8);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunVellum("process --scan " + scan16 + " --calibration " + Rig() + " --out " + out16);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* master : {"restored.tif", "archival.tif"}) {
    const Result exif = Shell("exiftool -s3 -BitsPerSample " + out16 + "/" + master);
    ASSERT_EQ(exif.exit_code, 0) << exif.output;
    EXPECT_EQ(exif.output, "16\n") << master;
  }
  const nlohmann::json report = nlohmann::json::parse(FileBytes(fs::path(out16) / "report.json"));
  EXPECT_EQ(report.at("restored").at("bits_per_channel"), 16);
  bool four_star_depth = false;
  for (const auto& figure : report.at("fadgi").at(0).at("figures")) {
    if (figure.at("name") == "bit depth") four_star_depth = figure.at("stars") == 4;
  }
  EXPECT_TRUE(four_star_depth) << report.at("fadgi").dump();
  const cv::Mat a = cv::imread(out8 + "/restored.tif", cv::IMREAD_UNCHANGED);
  const cv::Mat b = cv::imread(out16 + "/restored.tif", cv::IMREAD_UNCHANGED);
  ASSERT_EQ(a.type(), CV_8U);
  ASSERT_EQ(b.type(), CV_16U);
  ASSERT_EQ(a.size(), b.size());
  cv::Mat a16, scaled;
  a.convertTo(a16, CV_32F);
  b.convertTo(scaled, CV_32F, 1.0 / 257);
  EXPECT_LT(cv::norm(a16, scaled, cv::NORM_INF), 1.0);
  EXPECT_GT(cv::norm(a16, scaled, cv::NORM_L1) / a16.total(), 0.05) << "no finer samples at all";
  // On the bus the texture keeps its 16 bits (Y16 / BGR6): imported and exported back, it is
  // the same image, sample for sample, and the frames the same 8-bit frames.
  const std::string log16 = (root_ / "scan16.lcmlog").string(),
                    back = (root_ / "scan16_back").string();
  r = RunVellum("import " + scan16 + " " + log16);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunVellum("export " + log16 + " " + back);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  Scan original, exported;
  ASSERT_TRUE(ReadScan(scan16, &original).ok());
  ASSERT_TRUE(ReadScan(back, &exported).ok());
  ASSERT_EQ(exported.texture.type(), original.texture.type());
  ASSERT_EQ(original.texture.depth(), CV_16U);
  EXPECT_EQ(cv::norm(exported.texture, original.texture, cv::NORM_INF), 0);
  ASSERT_EQ(exported.frames.size(), original.frames.size());
  for (size_t k = 0; k < original.frames.size(); ++k) {
    ASSERT_EQ(exported.frames[k].depth(), CV_8U) << k;
    EXPECT_EQ(cv::norm(exported.frames[k], original.frames[k], cv::NORM_INF), 0) << k;
  }
}

// The albedo as a user gets it. A white target (albedo 0.85) lying on the table is
// scanned and measured (`vellum calibrate flatfield`); a plain white curled leaf of the same
// paper processed with the flat field gets restored_albedo.tif beside restored.tif: 16-bit,
// the same size, its mean the paper's 0.85 within 2% (the projector's light falls off with
// distance here, as a real one's does). A flat field that is not one is refused, named.
TEST_F(CliTest, AFlatFieldGivesEachPageItsAlbedo) {
  const std::string target = (root_ / "white").string(), leaf = (root_ / "plain").string();
  const std::string field = (root_ / "flatfield.yaml").string();
  Result r = RunVellum(
      "render --page flat --texture plain --page-size 420x320 "
      "--projector-falloff true --calibration " +
      Rig() + " --out " + target);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunVellum("calibrate flatfield --scan " + target + " --calibration " + Rig() +
                " --albedo 0.85 --out " + field);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("projector cells"), std::string::npos) << r.output;
  r = RunVellum(
      "render --page curl --texture plain --seed 5 --projector-falloff true "
      "--calibration " +
      Rig() + " --out " + leaf);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string out = (root_ / "out_albedo").string();
  r = RunVellum("process --scan " + leaf + " --calibration " + Rig() + " --out " + out +
                " --flatfield " + field);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const cv::Mat albedo = cv::imread(out + "/restored_albedo.tif", cv::IMREAD_UNCHANGED);
  const cv::Mat restored = cv::imread(out + "/restored.tif", cv::IMREAD_UNCHANGED);
  ASSERT_EQ(albedo.type(), CV_16U);
  ASSERT_EQ(albedo.size(), restored.size());
  const double mean = cv::mean(albedo, albedo > 0)[0] / 65535;
  EXPECT_NEAR(mean / 0.85, 1.0, 0.02) << mean;
  const nlohmann::json report = nlohmann::json::parse(FileBytes(fs::path(out) / "report.json"));
  EXPECT_NEAR(report.at("albedo").at("mean").get<double>(), mean, 1e-3);
  EXPECT_GT(report.at("albedo").at("estimated_share").get<double>(), 0.9);
  std::ofstream(root_ / "junk_field.yaml") << "%YAML:1.0\n---\ncell_px: 8\n";
  r = RunVellum("process --scan " + leaf + " --calibration " + Rig() + " --out " + out +
                "_junk --flatfield " + (root_ / "junk_field.yaml").string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("junk_field.yaml: key 'projector_size' is missing"), std::string::npos)
      << r.output;
}

// A scan with raking lights and UV (vellum render --raking 3 --uv true) gives each light
// restored beside the page, of its size, with its dpi (as exiftool reads it), and the normals;
// vellum import puts the lights in the log (their captures after the patterns), and vellum
// export gives them back as they were.
TEST_F(CliTest, ExtraLightsAreRestoredBesideThePage) {
  const std::string scan = (root_ / "lit").string(), out = (root_ / "out_lit").string();
  Result r = RunVellum("render --raking 3 --uv true --ridge 0.2,120 --truth false --calibration " +
                       Rig() + " --out " + scan);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(fs::path(scan) / "light_raking-120.png"));
  r = RunVellum("process --scan " + scan + " --calibration " + Rig() + " --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const cv::Mat restored = cv::imread(out + "/restored.tif", cv::IMREAD_UNCHANGED);
  const nlohmann::json report = nlohmann::json::parse(FileBytes(fs::path(out) / "report.json"));
  const std::string dpi = std::to_string(report.at("restored").at("dpi").get<int>());
  for (const char* name : {"raking-000", "raking-120", "raking-240", "uv"}) {
    const std::string file = out + "/lights/" + name + ".tif";
    const cv::Mat light = cv::imread(file, cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(light.empty()) << file;
    EXPECT_EQ(light.size(), restored.size()) << file;
    const Result exif = Shell("exiftool -s3 -XResolution " + file);
    EXPECT_EQ(exif.output, dpi + "\n") << file;
  }
  const cv::Mat normals = cv::imread(out + "/normals.tif", cv::IMREAD_UNCHANGED);
  ASSERT_EQ(normals.type(), CV_16UC3);
  EXPECT_EQ(normals.size(), restored.size());
  // Where solved (the checkerboard's ink is too dark under a raking light: marked, 0), nearly
  // straight out of the page (z, blue, near full scale), in the page's own frame.
  cv::Mat z;
  cv::extractChannel(normals, z, 0);
  ASSERT_GT(cv::countNonZero(z), restored.total() / 4);
  EXPECT_GT(cv::mean(z, z > 0)[0], 0.98 * 65535);
  EXPECT_GT(report.at("normals").at("solved_share").get<double>(), 0.5);
  const std::string outputs = report.at("outputs").dump();
  EXPECT_NE(outputs.find("lights/uv.tif"), std::string::npos) << outputs;
  EXPECT_NE(outputs.find("report/relief.png"), std::string::npos) << outputs;
  EXPECT_NE(FileBytes(fs::path(out) / "report.html").find("<img src=\"report/relief.png\""),
            std::string::npos);
  r = RunVellum("import " + scan + " " + (root_ / "lit.lcm").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string back = (root_ / "lit_back").string();
  r = RunVellum("export " + (root_ / "lit.lcm").string() + " " + back);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("4 extra lights"), std::string::npos) << r.output;
  Scan original, exported;
  ASSERT_TRUE(ReadScan(scan, &original).ok());
  ASSERT_TRUE(ReadScan(back, &exported).ok());
  ASSERT_EQ(exported.lights.size(), original.lights.size());
  for (size_t k = 0; k < original.lights.size(); ++k) {
    EXPECT_EQ(exported.lights[k].name, original.lights[k].name);
    EXPECT_EQ(exported.lights[k].direction, original.lights[k].direction) << k;
    EXPECT_EQ(cv::norm(exported.lights[k].image, original.lights[k].image, cv::NORM_INF), 0) << k;
  }
}

// The studio lamps' field from a white target's texture (vellum calibrate studio), then
// a curled plain leaf lit by the same lamps: restored_reflectance.tif is its albedo, even where
// its texture is shaded; a bad lamp is refused naming the flag.
TEST_F(CliTest, AStudioFieldTakesTheLampsShadingOutOfTheTexture) {
  const std::string target = (root_ / "studio_white").string();
  const std::string leaf = (root_ / "studio_leaf").string();
  const std::string field = (root_ / "studio.yaml").string();
  const std::string lamps = "\"-450,-250,500;450,-250,500\"";
  Result r = RunVellum(
      "render --page flat --texture plain --page-size 420x320 --truth false "
      "--studio-lamps " +
      lamps + " --calibration " + Rig() + " --out " + target);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunVellum("calibrate studio --scan " + target + " --calibration " + Rig() + " --lamps " +
                lamps + " --albedo 0.85 --out " + field);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("under 2 lamps"), std::string::npos) << r.output;
  r = RunVellum("render --page curl --texture plain --seed 6 --truth false --studio-lamps " +
                lamps + " --calibration " + Rig() + " --out " + leaf);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string out = (root_ / "out_studio").string();
  r = RunVellum("process --scan " + leaf + " --calibration " + Rig() + " --out " + out +
                " --studio-field " + field);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const cv::Mat reflectance = cv::imread(out + "/restored_reflectance.tif", cv::IMREAD_UNCHANGED);
  const cv::Mat restored = cv::imread(out + "/restored.tif", cv::IMREAD_UNCHANGED);
  ASSERT_EQ(reflectance.type(), CV_16U);
  ASSERT_EQ(reflectance.size(), restored.size());
  const cv::Mat corrected = reflectance > 0;
  cv::Scalar mean, sd, t_mean, t_sd;
  cv::meanStdDev(reflectance, mean, sd, corrected);
  cv::meanStdDev(restored, t_mean, t_sd, corrected);
  // The quick rig's pixels are 1 mm: fewer, and the rim's marked band is wider, but the same
  // physics: within 0.02 of 0.85, and far more even than the texture.
  EXPECT_NEAR(mean[0] / 65535 / 0.85, 1.0, 0.02);
  EXPECT_LT(sd[0] / mean[0], 0.3 * t_sd[0] / t_mean[0]);
  const nlohmann::json report = nlohmann::json::parse(FileBytes(fs::path(out) / "report.json"));
  EXPECT_GT(report.at("reflectance").at("estimated_share").get<double>(), 0.8);
  r = RunVellum("calibrate studio --scan " + target + " --calibration " + Rig() +
                " --lamps 1,2 --out " + field + "_bad");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--lamps: each lamp is X,Y,Z"), std::string::npos) << r.output;
}

TEST_F(CliTest, MissingFrame) {
  const std::string scan = CopyScan("missing");
  fs::remove(fs::path(scan) / FrameName(9));
  ExpectCleanError(RunVellum(Process(scan, Rig())), "frame_009.png", "file is missing");
}

TEST_F(CliTest, FramesOfMixedSizes) {
  const std::string scan = CopyScan("mixed");
  cv::imwrite((fs::path(scan) / FrameName(4)).string(), cv::Mat(300, 200, CV_8U, cv::Scalar(9)));
  ExpectCleanError(RunVellum(Process(scan, Rig())), "frame_004.png", "image is 200x300");
}

TEST_F(CliTest, NonImageFile) {
  const std::string scan = CopyScan("junk");
  std::ofstream(fs::path(scan) / FrameName(12)) << "GIF89a? no, just text";
  ExpectCleanError(RunVellum(Process(scan, Rig())), "frame_012.png", "not a readable image");
  const std::string scan2 = CopyScan("junk_texture");
  std::ofstream(fs::path(scan2) / "texture.png", std::ios::trunc) << "";
  ExpectCleanError(RunVellum(Process(scan2, Rig())), "texture.png", "not a readable image");
}

TEST_F(CliTest, CalibrationWithWrongKeys) {
  std::ifstream in(Rig());
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  text.replace(text.find("camera_rotation"), 15, "camera_rotat1on");
  const std::string bad = (root_ / "bad_key.yaml").string();
  std::ofstream(bad) << text;
  ExpectCleanError(RunVellum(Process((root_ / "scan").string(), bad)), "bad_key.yaml",
                   "'camera_rotation' is missing");
}

TEST_F(CliTest, CalibrationOfTheWrongSize) {
  const std::string big = (root_ / "default_rig.yaml").string();
  ASSERT_TRUE(WriteCalibration(big, DefaultRig()).ok());
  ExpectCleanError(RunVellum(Process((root_ / "scan").string(), big)), "default_rig.yaml",
                   "1600x1200 camera");
}

TEST_F(CliTest, CalibrationWithAWildFocalLength) {
  Calibration rig = QuickRig();
  rig.camera.matrix(0, 0) = 1e300;
  const std::string wild = (root_ / "wild_fx.yaml").string();
  ASSERT_TRUE(WriteCalibration(wild, rig).ok());
  ExpectCleanError(RunVellum(Process((root_ / "scan").string(), wild)), "wild_fx.yaml",
                   "camera: fx = 1e+300 px gives a field of view");
}

TEST_F(CliTest, MissingScanDirectory) {
  ExpectCleanError(RunVellum(Process((root_ / "nowhere").string(), Rig())), "nowhere",
                   "not a directory");
}

// A leaf hint is checked as a hint from scan.yaml, the bus or the viewer is (LeafHintFits): one
// over the whole view (which would seed the table as the leaf) or off it is refused, named.
TEST_F(CliTest, ALeafHintOverTheWholeViewOrOffItIsRefused) {
  const std::string scan = (root_ / "scan").string();
  ExpectCleanError(RunVellum(Process(scan, Rig()) + " --leaf-hint 0,0,400,300"),
                   "leaf hint 0,0,400,300", "covers 100% of the camera's view");
  ExpectCleanError(RunVellum(Process(scan, Rig()) + " --leaf-hint 500,10,20,20"),
                   "leaf hint 500,10,20,20", "not a box inside the 400x300 camera's view");
  ExpectCleanError(RunVellum(Process(scan, Rig()) + " --leaf-hint 0,0,2000000000,2000000000"),
                   "leaf hint 0,0,2000000000,2000000000", "not a box inside");
  // The station's own path (`vellum scan`, as the viewer's drawn box: fractions of the view)
  // meets the same rule, before anything is asked of the bus (memq: this process alone).
  const Result station = RunVellum("scan --url memq:// --leaf-hint 0,0,1,1");
  EXPECT_EQ(station.exit_code, 2) << station.output;
  EXPECT_NE(station.output.find("--leaf-hint '0,0,1,1' covers 100% of the camera's view, more "
                                "than 85%: a hint is a box inside the leaf"),
            std::string::npos)
      << station.output;
}

// The files under `dir` (relative names), each with a hash of its bytes.
std::map<std::string, size_t> FolderPrint(const fs::path& dir) {
  std::map<std::string, size_t> print;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    std::ifstream f(e.path(), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    print[fs::relative(e.path(), dir).string()] = std::hash<std::string>()(bytes);
  }
  return print;
}

// A run writes its results whole or not at all: into a hidden folder beside --out that takes its
// place when every stage succeeded. A run that fails part way (here at the outline, after the
// point cloud and its pictures were written; a full disk fails the same way, at any file) leaves
// an earlier run's results as they were, byte for byte, and nothing beside them; into a new
// folder, it leaves nothing. A folder that is not an earlier run's results (no report.json) is
// refused before any work, its files untouched: the run would replace it.
TEST_F(CliTest, AFailedRunLeavesTheEarlierResultsAsTheyWere) {
  const std::string scan = (root_ / "scan").string();
  const fs::path out = root_ / "whole_out";
  const std::string to_out = "process --scan " + scan + " --calibration " + Rig() + " --out ";
  const Result first = RunVellum(to_out + out.string());
  ASSERT_EQ(first.exit_code, 0) << first.output;
  const std::map<std::string, size_t> before = FolderPrint(out);
  ASSERT_TRUE(before.count("report.json") && before.count("restored.tif") &&
              before.count("points.ply"));
  auto beside = [&] {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(root_)) {
      const std::string name = e.path().filename().string();
      if (name.find("whole_out") != std::string::npos) names.push_back(name);
    }
    std::sort(names.begin(), names.end());
    return names;
  };
  ASSERT_EQ(beside(), std::vector<std::string>{"whole_out"});
  const Result failed = RunVellum(to_out + out.string() + " --leaf-hint 0,0,400,300");
  EXPECT_EQ(failed.exit_code, 1) << failed.output;
  EXPECT_NE(failed.output.find("leaf hint 0,0,400,300"), std::string::npos) << failed.output;
  EXPECT_EQ(failed.output.find(".part-"), std::string::npos) << failed.output;
  EXPECT_EQ(FolderPrint(out), before) << "a failed run changed the earlier results";
  EXPECT_EQ(beside(), std::vector<std::string>{"whole_out"});
  // Into a new folder: nothing.
  const fs::path fresh = root_ / "whole_out_new";
  EXPECT_EQ(RunVellum(to_out + fresh.string() + " --leaf-hint 0,0,400,300").exit_code, 1);
  EXPECT_FALSE(fs::exists(fresh));
  EXPECT_EQ(beside(), std::vector<std::string>{"whole_out"});
  // A second good run replaces the first whole (a trailing slash names the same folder).
  const Result again = RunVellum(to_out + out.string() + "/");
  EXPECT_EQ(again.exit_code, 0) << again.output;
  EXPECT_EQ(FolderPrint(out).size(), before.size());
  EXPECT_EQ(beside(), std::vector<std::string>{"whole_out"});
  // Not a results folder: refused, untouched.
  const fs::path other = root_ / "whole_out_notes";
  fs::create_directories(other);
  std::ofstream(other / "notes.txt") << "the curator's notes\n";
  ExpectCleanError(RunVellum(to_out + other.string()), other.string(),
                   "holds files but no report.json");
  EXPECT_EQ(FolderPrint(other).size(), 1u);
  EXPECT_FALSE(fs::exists(other / "points.ply"));
  fs::remove_all(other);
}

// Calibration from board poses rendered by `vellum render --pose` (a 640x480 camera and a
// 512x384 projector: 0.6 mm per camera pixel), solved by `vellum calibrate solve`: the
// calibration YAML and its report are written and the focal lengths are the rig's; bad poses
// are named and the rest used; too few poses fail.
TEST_F(CliTest, CalibrateSolveRecoversTheRigFromRenderedPoses) {
  Calibration rig = DefaultRig();
  rig.camera.size = {640, 480};
  rig.camera.matrix = cv::Matx33d(960, 0, 319.5, 0, 960, 239.5, 0, 0, 1);
  rig.projector.size = {512, 384};
  rig.projector.matrix = cv::Matx33d(900, 0, 255.5, 0, 900, 191.5, 0, 0, 1);
  const std::string rig_file = (root_ / "calib_rig.yaml").string();
  ASSERT_TRUE(WriteCalibration(rig_file, rig).ok());
  const char* poses[] = {"0,0,0,0,0,0",    "18,0,4,0,0,60",   "-18,0,-4,0,0,60",  "0,20,0,0,0,55",
                         "0,-20,3,5,0,55", "12,14,6,-8,6,70", "-12,-14,8,0,-5,45"};
  std::string dirs;
  for (int i = 0; i < 7; ++i) {
    const std::string dir = (root_ / ("pose" + std::to_string(i))).string();
    const Result r =
        RunVellum("render --page flat --truth false --calibration " + rig_file + " --seed " +
                  std::to_string(i + 3) + " --pose " + poses[i] + " --out " + dir);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    if (i > 0) dirs += " " + dir;
  }
  const std::string out = (root_ / "solved.yaml").string();
  const std::string missing = (root_ / "no_such_pose").string();
  const Result r = RunVellum("calibrate solve --board 16x21 --square 10 --table " +
                             (root_ / "pose0").string() + " --out " + out + dirs + " " + missing);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("overall: 7 poses, 2352 corners"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("no_such_pose: not used"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(out + ".report.txt"));
  Calibration solved;
  ASSERT_TRUE(ReadCalibration(out, &solved).ok());
  EXPECT_NEAR(solved.camera.matrix(0, 0), 960, 960 * 0.003);
  EXPECT_NEAR(solved.projector.matrix(0, 0), 900, 900 * 0.003);
  EXPECT_NEAR(solved.camera.Center()[2], rig.camera.Center()[2], 1.0);

  const Result few = RunVellum("calibrate solve --table " + (root_ / "pose0").string() + " --out " +
                               out + " " + (root_ / "pose1").string());
  EXPECT_EQ(few.exit_code, 1) << few.output;
  EXPECT_NE(few.output.find("only 2 usable board poses"), std::string::npos) << few.output;
  EXPECT_EQ(RunVellum("calibrate solve --board 2x9 --table x --out y").exit_code, 2);
  EXPECT_EQ(RunVellum("calibrate").exit_code, 2);
}

}  // namespace
}  // namespace vellum
