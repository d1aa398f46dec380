#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <tiffio.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/sim/gantry.h"
#include "io/calibration_io.h"
#include "io/image_file.h"
#include "io/json.h"
#include "io/manifest.h"
#include "io/ply.h"
#include "io/products.h"
#include "io/ptm.h"
#include "io/scan_io.h"
#include "io/write_whole.h"
#include "io/xmp.h"

namespace vellum {
namespace {

namespace fs = std::filesystem;

class IoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("vellum_io_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  // The text of scan.yaml in `dir`.
  static std::string ScanYaml(const std::string& dir) {
    std::ifstream in(dir + "/scan.yaml");
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  // `key`'s line of scan.yaml in `dir` (which must have it) given each of `values` in turn: every
  // one refused by ReadScanHeader, naming the file and the key. scan.yaml is left at the last.
  static void ExpectEachRefused(const std::string& dir, const std::string& key,
                                const std::vector<std::string>& values) {
    const std::string yaml = ScanYaml(dir);
    const size_t at = yaml.find(key + ":");
    ASSERT_NE(at, std::string::npos) << yaml;
    const size_t end = yaml.find('\n', at);
    for (const std::string& bad : values) {
      std::string edited = yaml;
      edited.replace(at, end - at, key + ": " + bad);
      std::ofstream(dir + "/scan.yaml") << edited;
      Scan r;
      const Status s = ReadScanHeader(dir, &r);
      ASSERT_FALSE(s.ok()) << bad;
      EXPECT_NE(s.message().find("scan.yaml: key '" + key + "'"), std::string::npos) << s.message();
    }
  }
  fs::path dir_;
};

TEST_F(IoTest, CalibrationRoundTrip) {
  Calibration c = DefaultRig();
  c.projector.distortion = cv::Vec<double, 5>(0.01, -0.02, 0.001, 0.002, 0.003);
  ASSERT_TRUE(WriteCalibration(Path("c.yaml"), c).ok());
  Calibration r;
  const Status s = ReadCalibration(Path("c.yaml"), &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(r.camera.size, c.camera.size);
  EXPECT_LT(cv::norm(r.projector.distortion - c.projector.distortion), 1e-12);
  EXPECT_LT(cv::norm(r.projector.rotation - c.projector.rotation), 1e-12);
  EXPECT_LT(cv::norm(r.camera.translation - c.camera.translation), 1e-9);
  EXPECT_EQ(r.min_z_mm, c.min_z_mm);
  EXPECT_EQ(r.max_z_mm, c.max_z_mm);
}

// The optional measured scale error (`vellum calibrate` writes it): kept through a round trip
// and in the checksum; absent, unknown (NaN) and the checksum the file always had; wrong, named.
TEST_F(IoTest, CalibrationScaleError) {
  Calibration c = DefaultRig();
  ASSERT_TRUE(std::isnan(c.scale_error_percent));
  const std::string plain = CalibrationSha256(c);
  c.scale_error_percent = 0.0125;
  ASSERT_TRUE(WriteCalibration(Path("scaled.yaml"), c).ok());
  Calibration r;
  Status s = ReadCalibration(Path("scaled.yaml"), &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(r.scale_error_percent, 0.0125);
  EXPECT_NE(CalibrationSha256(r), plain);
  ASSERT_TRUE(WriteCalibration(Path("plain.yaml"), DefaultRig()).ok());
  ASSERT_TRUE(ReadCalibration(Path("plain.yaml"), &r).ok());
  EXPECT_TRUE(std::isnan(r.scale_error_percent));
  EXPECT_EQ(CalibrationSha256(r), plain);
  std::ofstream(Path("plain.yaml"), std::ios::app) << "scale_error_percent: -1\n";
  s = ReadCalibration(Path("plain.yaml"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("plain.yaml: scale_error_percent"), std::string::npos) << s.message();
}

// The optional working volume: a sequence or a 1x2 matrix; absent, the default; wrong, named.
TEST_F(IoTest, CalibrationWorkingVolume) {
  ASSERT_TRUE(WriteCalibration(Path("c.yaml"), DefaultRig()).ok());
  std::ifstream in(Path("c.yaml"));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t at = text.find("working_volume_z");
  ASSERT_NE(at, std::string::npos);
  const std::string without = text.substr(0, at);
  Calibration r;
  std::ofstream(Path("none.yaml")) << without;
  ASSERT_TRUE(ReadCalibration(Path("none.yaml"), &r).ok());
  EXPECT_EQ(r.min_z_mm, Calibration().min_z_mm);
  std::ofstream(Path("seq.yaml")) << without << "working_volume_z: [ -5, 120.5 ]\n";
  Status s = ReadCalibration(Path("seq.yaml"), &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(r.min_z_mm, -5);
  EXPECT_EQ(r.max_z_mm, 120.5);
  std::ofstream(Path("upside.yaml")) << without << "working_volume_z: [ 50, 10 ]\n";
  s = ReadCalibration(Path("upside.yaml"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("upside.yaml"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("working_volume_z"), std::string::npos) << s.message();
  std::ofstream(Path("word.yaml")) << without << "working_volume_z: [ low, 10 ]\n";
  s = ReadCalibration(Path("word.yaml"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("working_volume_z"), std::string::npos) << s.message();
}

// What Python's cv2.FileStorage writes: sizes as 1x2 integer matrices, float matrices, and a
// translation as 1x3.
// The shipped example calibration is the virtual gantry's default rig.
TEST_F(IoTest, ShippedDefaultCalibrationIsTheDefaultRig) {
  Calibration shipped;
  const Status s = ReadCalibration(VELLUM_SOURCE_DIR "/config/default_calibration.yaml", &shipped);
  ASSERT_TRUE(s.ok()) << s.message();
  const Calibration rig = DefaultRig();
  for (const auto& [a, b] :
       {std::pair{&shipped.camera, &rig.camera}, std::pair{&shipped.projector, &rig.projector}}) {
    EXPECT_EQ(a->size, b->size);
    EXPECT_LT(cv::norm(a->matrix - b->matrix), 1e-9);
    EXPECT_LT(cv::norm(a->distortion - b->distortion), 1e-12);
    EXPECT_LT(cv::norm(a->rotation - b->rotation), 1e-12);
    EXPECT_LT(cv::norm(a->translation - b->translation), 1e-9);
  }
}

TEST_F(IoTest, ReadsPythonStyleSizesAndRowTranslations) {
  const Calibration c = DefaultRig();
  std::ofstream f(Path("py.yaml"));
  f << "%YAML:1.0\n---\n";
  for (const char* dev : {"camera", "projector"}) {
    const CameraModel& m = std::string(dev) == "camera" ? c.camera : c.projector;
    f << dev << "_size: !!opencv-matrix\n   rows: 1\n   cols: 2\n   dt: i\n   data: [ "
      << m.size.width << ", " << m.size.height << " ]\n";
    auto mat = [&](const std::string& key, const double* v, int rows, int cols) {
      f << dev << "_" << key << ": !!opencv-matrix\n   rows: " << rows << "\n   cols: " << cols
        << "\n   dt: f\n   data: [ ";
      for (int i = 0; i < rows * cols; ++i) f << (i ? ", " : "") << v[i];
      f << " ]\n";
    };
    mat("matrix", m.matrix.val, 3, 3);
    mat("distortion", m.distortion.val, 1, 5);
    mat("rotation", m.rotation.val, 3, 3);
    mat("translation", m.translation.val, 1, 3);
  }
  f.close();
  Calibration r;
  const Status s = ReadCalibration(Path("py.yaml"), &r);
  // float storage of the rotation rounds it at 1e-7; Check() allows 1e-6.
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(r.projector.size, cv::Size(1024, 768));
  EXPECT_NEAR(r.camera.translation[2], 600, 1e-3);
}

TEST_F(IoTest, CalibrationErrorsNameTheFileAndKey) {
  ASSERT_TRUE(WriteCalibration(Path("c.yaml"), DefaultRig()).ok());
  std::ifstream in(Path("c.yaml"));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // Rename a key.
  std::string bad = text;
  bad.replace(bad.find("projector_matrix"), 16, "projector_matrx");
  std::ofstream(Path("bad_key.yaml")) << bad;
  Calibration r;
  Status s = ReadCalibration(Path("bad_key.yaml"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("bad_key.yaml"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("projector_matrix"), std::string::npos) << s.message();
  // A 3x3 where 1x5 belongs.
  cv::FileStorage fs(Path("bad_size.yaml"), cv::FileStorage::WRITE);
  const Calibration c = DefaultRig();
  fs << "camera_size" << c.camera.size << "camera_matrix" << cv::Mat(c.camera.matrix)
     << "camera_distortion" << cv::Mat(c.camera.matrix);
  fs.release();
  s = ReadCalibration(Path("bad_size.yaml"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("camera_distortion"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("1x5"), std::string::npos) << s.message();
  // Not YAML at all.
  std::ofstream(Path("junk.yaml")) << "\x01\x02 not yaml {{{";
  s = ReadCalibration(Path("junk.yaml"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("junk.yaml"), std::string::npos) << s.message();
}

Scan SmallScan() {
  Scan scan;
  PatternOptions o;
  o.projector_size = {40, 30};
  scan.sequence = MakePatternSequence(o);
  scan.camera_size = {32, 24};
  scan.texture = cv::Mat(24, 32, CV_8U, cv::Scalar(100));
  for (size_t k = 0; k < scan.sequence.patterns.size(); ++k) {
    scan.frames.push_back(cv::Mat(24, 32, CV_8U, cv::Scalar(static_cast<double>(k))));
  }
  return scan;
}

TEST_F(IoTest, ScanRoundTrip) {
  const Scan scan = SmallScan();
  ASSERT_TRUE(WriteScan(Path("scan"), scan).ok());
  Scan r;
  const Status s = ReadScan(Path("scan"), &r);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(r.sequence.patterns.size(), scan.sequence.patterns.size());
  for (size_t k = 0; k < r.frames.size(); ++k) {
    EXPECT_TRUE(r.sequence.patterns[k] == scan.sequence.patterns[k]);
    EXPECT_EQ(cv::norm(r.frames[k], scan.frames[k], cv::NORM_INF), 0);
  }
}

// A scan's extra lights (scan.yaml `lights`, light_<name>.png) round trip, a 16-bit
// light stays 16-bit, and a bad entry or a missing file is an error naming the light.
// The station's lights file (what vellum-projector and vellum-lights read): the
// shipped example reads, with its channels; a bad one is refused with the file and the problem.
TEST_F(IoTest, TheStationsLightsFileReadsAndABadOneIsNamed) {
  StationLights lights;
  const std::string shipped = std::string(VELLUM_SOURCE_DIR) + "/config/lights.yaml";
  ASSERT_TRUE(ReadLightsFile(shipped, &lights).ok()) << ReadLightsFile(shipped, &lights).message();
  ASSERT_EQ(lights.lights.size(), 4u);
  EXPECT_EQ(lights.channels, (std::vector<int>{1, 2, 3, 4}));
  EXPECT_EQ(lights.studio_channel, 0);
  for (int k = 0; k < 3; ++k) {
    EXPECT_TRUE(lights.lights[k].directed()) << k;
    EXPECT_NEAR(cv::norm(lights.lights[k].direction), 1.0, 1e-9);
  }
  EXPECT_EQ(lights.lights[3].name, "uv");
  EXPECT_FALSE(lights.lights[3].directed());
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"lights: []", "key 'lights' must be a non-empty sequence"},
      {"lights:\n  - { name: UV }", "light 0: 'name' must be 1 to 32"},
      {"lights:\n  - { name: uv, channel: 300 }", "light 0 ('uv'): 'channel' must be"},
      {"lights:\n  - { name: low, direction: [ 1, 0, -0.1 ] }", "must point up from the table"},
      {"studio_channel: x\nlights:\n  - { name: uv }", "'studio_channel' must be"},
  };
  for (const auto& [text, message] : bad) {
    const std::string path = Path("bad_lights.yaml");
    std::ofstream(path) << "%YAML:1.0\n---\n" << text << "\n";
    const Status s = ReadLightsFile(path, &lights);
    EXPECT_FALSE(s.ok()) << text;
    EXPECT_NE(s.message().find(path), std::string::npos) << s.message();
    EXPECT_NE(s.message().find(message), std::string::npos) << text << ": " << s.message();
  }
}

TEST_F(IoTest, ScanLightsRoundTripAndBadOnesAreNamed) {
  Scan scan = SmallScan();
  ScanLight raking;
  raking.name = "raking-090";
  raking.direction = cv::normalize(cv::Vec3d(0, 1, 1));
  raking.image = cv::Mat(scan.texture.size(), CV_8U, cv::Scalar(90));
  ScanLight uv;
  uv.name = "uv";
  uv.image = cv::Mat(scan.texture.size(), CV_16U, cv::Scalar(40000));
  scan.lights = {raking, uv};
  ASSERT_TRUE(WriteScan(Path("scan"), scan).ok());
  ASSERT_TRUE(std::filesystem::exists(Path("scan") + "/light_uv.png"));
  Scan r;
  ASSERT_TRUE(ReadScan(Path("scan"), &r).ok());
  ASSERT_EQ(r.lights.size(), 2u);
  EXPECT_EQ(r.lights[0].name, "raking-090");
  EXPECT_LT(cv::norm(r.lights[0].direction - raking.direction), 1e-12);
  EXPECT_EQ(cv::norm(r.lights[0].image, raking.image, cv::NORM_INF), 0);
  EXPECT_FALSE(r.lights[1].directed());
  EXPECT_EQ(r.lights[1].image.type(), CV_16U);
  EXPECT_EQ(cv::norm(r.lights[1].image, uv.image, cv::NORM_INF), 0);

  std::string yaml = ScanYaml(Path("scan"));
  const size_t at = yaml.find("lights:"), end = yaml.find("patterns:");
  ASSERT_NE(at, std::string::npos) << yaml;
  const struct {
    std::string lights, problem;
  } cases[] = {
      {"lights:\n  - { name: \"Raking/N\" }\n", "light 0: 'name'"},
      {"lights:\n  - { name: uv }\n  - { name: uv }\n", "given twice"},
      {"lights:\n  - { name: low, direction: [ 1, 0, -0.2 ] }\n", "point up"},
      {"lights:\n  - { name: ir, direction: [ 1, 0 ] }\n", "[ x, y, z ]"},
      {"lights: 3\n", "must be a sequence"},
  };
  for (const auto& c : cases) {
    std::string bad = yaml;
    bad.replace(at, end - at, c.lights);
    std::ofstream(Path("scan") + "/scan.yaml") << bad;
    Scan b;
    const Status s = ReadScanHeader(Path("scan"), &b);
    ASSERT_FALSE(s.ok()) << c.lights;
    EXPECT_NE(s.message().find(c.problem), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("scan.yaml"), std::string::npos) << s.message();
  }
  std::ofstream(Path("scan") + "/scan.yaml") << yaml;
  std::filesystem::remove(Path("scan") + "/light_uv.png");
  Scan b;
  const Status s = ReadScanHeader(Path("scan"), &b);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("light_uv.png: file is missing (light 'uv'"), std::string::npos)
      << s.message();
}

// The studio lamps' field round trips (gray and colour), and a file without lamps is
// an error naming the file and the key.
TEST_F(IoTest, StudioFieldRoundTripsAndABadOneIsNamed) {
  for (int channels : {1, 3}) {
    StudioField field;
    field.camera_size = cv::Size(40, 30);
    field.cell_px = 8;
    field.gain = cv::Mat(4, 5, CV_32FC(channels), cv::Scalar(200, 210, 190));
    field.gain.at<float>(0, 0) = std::nanf("");
    field.lamps = {cv::Vec3d(-450, -250, 500), cv::Vec3d(450, -250, 500)};
    ASSERT_TRUE(WriteStudioField(Path("studio.yaml"), field).ok());
    StudioField back;
    const Status s = ReadStudioField(Path("studio.yaml"), &back);
    ASSERT_TRUE(s.ok()) << s.message();
    EXPECT_EQ(back.camera_size, field.camera_size);
    EXPECT_EQ(back.gain.channels(), channels);
    ASSERT_EQ(back.lamps.size(), 2u);
    EXPECT_EQ(back.lamps[1], field.lamps[1]);
    EXPECT_TRUE(std::isnan(back.gain.at<float>(0, 0)));
    EXPECT_NEAR(back.At(cv::Point2d(20, 15))[0], 200, 1e-3);
  }
  std::ofstream(Path("no_lamps.yaml")) << "%YAML:1.0\n---\ncamera_size: [ 40, 30 ]\ncell_px: 8\n";
  StudioField back;
  const Status s = ReadStudioField(Path("no_lamps.yaml"), &back);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no_lamps.yaml: lamps must be"), std::string::npos) << s.message();
}

// A texture or light whose header claims another size than the camera's is refused by its
// header, before a pixel is decoded (a 783 KB PNG can claim 16384 x 16384 and take 818 MB and
// seconds to decode). The header here claims 16384 x 16384 over 32 x 24 pixels of data: decoding
// it would fail as "not a readable image", so the size's error shows the header was judged first.
TEST_F(IoTest, ATextureClaimingAnotherSizeIsRefusedByItsHeaderBeforeDecoding) {
  const Scan scan = SmallScan();
  ASSERT_TRUE(WriteScan(Path("huge"), scan).ok());
  const std::string texture = Path("huge") + "/texture.png";
  std::string bytes;
  {
    std::ifstream in(texture, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  ASSERT_GT(bytes.size(), 24u);
  ASSERT_EQ(bytes.substr(12, 4), "IHDR");
  const unsigned char side[4] = {0, 0, 0x40, 0};  // 16384, big-endian.
  bytes.replace(16, 4, reinterpret_cast<const char*>(side), 4);
  bytes.replace(20, 4, reinterpret_cast<const char*>(side), 4);
  std::ofstream(texture, std::ios::binary | std::ios::trunc) << bytes;
  Scan back;
  const Status s = ReadScanHeader(Path("huge"), &back);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("texture.png: image is 16384x16384 but camera_size in scan.yaml says "
                             "32x24"),
            std::string::npos)
      << s.message();
}

// The operator's leaf hint in scan.yaml: kept through a round trip in camera pixels, absent when
// not given, and a hint that is not a region of the camera's view refused naming the file and
// the key.
TEST_F(IoTest, ScanLeafHintRoundTripsAndABadOneIsRefused) {
  Scan scan = SmallScan();
  const cv::Size camera = scan.camera_size;
  scan.leaf_hint =
      cv::Rect(camera.width / 4, camera.height / 5, camera.width / 3, camera.height / 2);
  ASSERT_TRUE(WriteScan(Path("hinted"), scan).ok());
  Scan r;
  const Status read = ReadScan(Path("hinted"), &r);
  ASSERT_TRUE(read.ok()) << read.message();
  EXPECT_EQ(r.leaf_hint, scan.leaf_hint);
  ASSERT_TRUE(WriteScan(Path("plain"), SmallScan()).ok());
  ASSERT_TRUE(ReadScan(Path("plain"), &r).ok());
  EXPECT_TRUE(r.leaf_hint.empty());
  ExpectEachRefused(Path("hinted"), "leaf_hint",
                    {"[ 10, 7, 31 ]", "[ 10, 7, -1, 19 ]", "[ a, 7, 31, 19 ]",
                     "[ 2147483000, 7, 2000, 19 ]",  // Wraps an int.
                     "[ " + std::to_string(camera.width - 5) + ", 7, 31, 19 ]"});
}

// What the live view saw at the view's edge, in scan.yaml: the sides kept through a round trip
// (written by name), none when absent, and a list that is not of sides refused naming the key.
TEST_F(IoTest, ScanLiveOffViewRoundTripsAndABadOneIsRefused) {
  Scan scan = SmallScan();
  scan.live_off_view = kViewRight | kViewBottom;
  ASSERT_TRUE(WriteScan(Path("seen"), scan).ok());
  Scan r;
  ASSERT_TRUE(ReadScan(Path("seen"), &r).ok());
  EXPECT_EQ(r.live_off_view, kViewRight | kViewBottom);
  EXPECT_NE(ScanYaml(Path("seen")).find("live_off_view: [ right, bottom ]"), std::string::npos)
      << ScanYaml(Path("seen"));
  ASSERT_TRUE(WriteScan(Path("unseen"), SmallScan()).ok());
  ASSERT_TRUE(ReadScan(Path("unseen"), &r).ok());
  EXPECT_EQ(r.live_off_view, 0);
  ExpectEachRefused(Path("seen"), "live_off_view",
                    {"[ rigth ]", "[ left, left ]", "right", "[ 1 ]"});
}

// The catalogue identity in scan.yaml (docs/formats.md, "Identity"), kept through a round
// trip, read as hand-written (a folio as a number), and made safe: control characters removed,
// a field cut to 200 bytes, an unknown side dropped.
TEST_F(IoTest, ScanIdentityRoundTripsAndIsSanitised) {
  Scan scan = SmallScan();
  scan.identity.shelfmark = "MS 12";
  scan.identity.folio = "3";
  scan.identity.side = "recto";
  scan.identity.operator_name = "A. Scribe";
  scan.identity.note = "burnt edge, Cotton fire 1731";
  ASSERT_TRUE(WriteScan(Path("scan"), scan).ok());
  Scan r;
  ASSERT_TRUE(ReadScan(Path("scan"), &r).ok());
  EXPECT_TRUE(r.identity == scan.identity);
  Scan header;
  ASSERT_TRUE(ReadScanYaml(Path("scan"), &header).ok());
  ScanIdentity id = header.identity;
  EXPECT_EQ(id.shelfmark, "MS 12");
  // By hand: a folio written as a number, a side in capitals, a shelfmark with a control
  // character and a note far too long.
  std::string yaml = ScanYaml(Path("scan"));
  const size_t at = yaml.find("shelfmark:");
  ASSERT_NE(at, std::string::npos) << yaml;
  const size_t end = yaml.find("texture:");
  yaml.replace(
      at, end - at,
      "shelfmark: \"MS\\t12\"\nfolio: 3\nside: Verso\nnote: \"" + std::string(300, 'x') + "\"\n");
  std::ofstream(Path("scan") + "/scan.yaml") << yaml;
  ASSERT_TRUE(ReadScanYaml(Path("scan"), &header).ok());
  id = header.identity;
  EXPECT_EQ(id.shelfmark, "MS12");
  EXPECT_EQ(id.folio, "3");
  EXPECT_EQ(id.side, "verso");
  EXPECT_EQ(id.note.size(), kMaxIdentityField);
  EXPECT_TRUE(id.operator_name.empty());
  std::string why;
  ScanIdentity odd;
  odd.side = "sideways";
  odd.folio = "../../etc";
  EXPECT_TRUE(SanitizedIdentity(odd, &why).side.empty());
  EXPECT_NE(why.find("side 'sideways' is not recto, verso, left or right"), std::string::npos)
      << why;
}

TEST_F(IoTest, ScanErrorsNameTheFileAndProblem) {
  const Scan scan = SmallScan();
  Scan r;
  // Missing frame.
  ASSERT_TRUE(WriteScan(Path("missing"), scan).ok());
  fs::remove(Path("missing/" + FrameName(5)));
  Status s = ReadScan(Path("missing"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame_005.png: file is missing"), std::string::npos) << s.message();
  // Mixed sizes.
  ASSERT_TRUE(WriteScan(Path("mixed"), scan).ok());
  cv::imwrite(Path("mixed/" + FrameName(7)), cv::Mat(20, 20, CV_8U, cv::Scalar(0)));
  s = ReadScan(Path("mixed"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame_007.png: image is 20x20"), std::string::npos) << s.message();
  // Not an image.
  ASSERT_TRUE(WriteScan(Path("junk"), scan).ok());
  std::ofstream(Path("junk/" + FrameName(2))) << "this is not a PNG";
  s = ReadScan(Path("junk"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame_002.png: not a readable image"), std::string::npos)
      << s.message();
  // Corrupt scan.yaml.
  ASSERT_TRUE(WriteScan(Path("yaml"), scan).ok());
  std::ofstream(Path("yaml/scan.yaml"))
      << "%YAML:1.0\n---\nprojector_size: [ 40, 30 ]\npatterns: 7\n";
  s = ReadScan(Path("yaml"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("scan.yaml"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("patterns"), std::string::npos) << s.message();
}

// A PNG whose header claims 32768 x 32768 16-bit RGBA (8 GiB decoded) is refused from its
// header, before anything is allocated; so is a 16-bit frame of a sane size.
TEST_F(IoTest, AnImageHeaderClaimingGigabytesIsRefusedBeforeDecoding) {
  const Scan scan = SmallScan();
  ASSERT_TRUE(WriteScan(Path("huge"), scan).ok());
  // Signature, then the IHDR chunk: length 13, "IHDR", width, height, depth 16, colour type 6
  // (RGBA), compression, filter, interlace, and a CRC (not checked by the header read).
  const unsigned char header[] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 0, 0, 0,
                                  13,   'I', 'H', 'D', 'R',  0,    0,    0x80, 0, 0, 0,
                                  0x80, 0,   16,  6,   0,    0,    0,    0,    0, 0, 0};
  {
    std::ofstream out(Path("huge/" + FrameName(3)), std::ios::binary);
    out.write(reinterpret_cast<const char*>(header), sizeof header);
  }
  Scan r;
  Status s = ReadScan(Path("huge"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame_003.png: its header claims 32768x32768 pixels"),
            std::string::npos)
      << s.message();
  ASSERT_TRUE(WriteScan(Path("deep"), scan).ok());
  cv::imwrite(Path("deep/" + FrameName(4)), cv::Mat(24, 32, CV_16U, cv::Scalar(1000)));
  s = ReadScan(Path("deep"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame_004.png: must be an 8-bit image (its header says 16-bit)"),
            std::string::npos)
      << s.message();
}

// A scan.yaml claiming a projector 2^30 pixels wide is refused at once, naming the file (it
// once sent the pattern check into an endless loop).
TEST_F(IoTest, AScanClaimingAnAbsurdProjectorIsRefusedAtOnce) {
  ASSERT_TRUE(WriteScan(Path("wide"), SmallScan()).ok());
  std::ifstream in(Path("wide/scan.yaml"));
  std::string yaml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string from = "projector_size: [ 40, 30 ]";
  const size_t at = yaml.find(from);
  ASSERT_NE(at, std::string::npos) << yaml;
  yaml.replace(at, from.size(), "projector_size: [ 1073741824, 30 ]");
  std::ofstream(Path("wide/scan.yaml")) << yaml;
  Scan r;
  const Status s = ReadScan(Path("wide"), &r);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("scan.yaml"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("key 'projector_size' must be 1 to 16384 pixels each way"),
            std::string::npos)
      << s.message();
}

TEST_F(IoTest, PlyRoundTrip) {
  cv::Mat points(3, 4, CV_32FC3, cv::Scalar::all(NAN));
  points.at<cv::Vec3f>(1, 2) = cv::Vec3f(1.5f, -2.0f, 3.25f);
  points.at<cv::Vec3f>(2, 3) = cv::Vec3f(4, 5, 6);
  ASSERT_TRUE(WritePointsPly(Path("p.ply"), points).ok());
  std::vector<PlyPoint> r;
  ASSERT_TRUE(ReadPointsPly(Path("p.ply"), &r).ok());
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].x, 1.5f);
  EXPECT_EQ(r[0].u, 2.0f);
  EXPECT_EQ(r[0].v, 1.0f);
  EXPECT_EQ(r[1].z, 6.0f);
  // Larger than the writer's buffer (32 rows): every third point, in order, across its flushes.
  cv::Mat many(200, 40, CV_32FC3, cv::Scalar::all(NAN));
  for (int v = 0; v < many.rows; ++v) {
    for (int u = 0; u < many.cols; ++u) {
      if ((v * many.cols + u) % 3 == 0) many.at<cv::Vec3f>(v, u) = cv::Vec3f(u, v, u + v);
    }
  }
  ASSERT_TRUE(WritePointsPly(Path("many.ply"), many).ok());
  ASSERT_TRUE(ReadPointsPly(Path("many.ply"), &r).ok());
  ASSERT_EQ(r.size(), 200u * 40u / 3 + 1);
  for (size_t i = 0; i < r.size(); ++i) {
    const int at = static_cast<int>(3 * i);
    ASSERT_EQ(r[i].u, at % 40) << i;
    ASSERT_EQ(r[i].v, at / 40) << i;
    ASSERT_EQ(r[i].z, r[i].x + r[i].y) << i;
  }
}

// A scan's manifest lists every file of its raw/ and results/ (not what lies beside them), in
// the format sha256sum reads (checked by sha256sum itself), and names each file missing,
// changed or added since.
// Image files without OpenCV's imgcodecs, read back by OpenCV as an outside reader: colour
// stays in its order (a picture that is not symmetric in its channels: blue, green and red
// differ everywhere), 16 bits stay 16, the TIFF's resolution tags hold the dpi, a float map's
// channels are written in their own order, other formats are read by libvips, and a broken
// file is an error naming it.
TEST_F(IoTest, ImagesRoundTripWithoutOpenCvsCodecsAndOpenCvReadsThem) {
  cv::Mat colour(37, 53, CV_8UC3), gray(37, 53, CV_8U), deep(37, 53, CV_16UC3);
  for (int y = 0; y < colour.rows; ++y) {
    for (int x = 0; x < colour.cols; ++x) {
      colour.at<cv::Vec3b>(y, x) = cv::Vec3b(x, 100 + y, 200 + (x + y) % 50);
      gray.at<uint8_t>(y, x) = static_cast<uint8_t>(3 * x + y);
      deep.at<cv::Vec3w>(y, x) = cv::Vec3w(1000 * x + 7, 300 * y + 1, 65535 - x * y);
    }
  }
  for (const cv::Mat& image : {colour, gray, deep}) {
    for (const char* name : {"i.png", "i.tif"}) {
      ASSERT_TRUE(WriteImage(Path(name), image).ok()) << name;
      cv::Mat back;
      ASSERT_TRUE(ReadImage(Path(name), &back).ok()) << name;
      EXPECT_EQ(back.type(), image.type()) << name;
      EXPECT_EQ(cv::norm(back, image, cv::NORM_INF), 0) << name << " " << image.type();
      const cv::Mat theirs = cv::imread(Path(name), cv::IMREAD_UNCHANGED);
      EXPECT_EQ(cv::norm(theirs, image, cv::NORM_INF), 0) << "OpenCV reads " << name;
    }
  }
  // For showing or as a texture: gray widened to colour; 16 bits refused.
  cv::Mat shown;
  ASSERT_TRUE(WriteImage(Path("g.png"), gray).ok());
  ASSERT_TRUE(ReadColourImage(Path("g.png"), &shown).ok());
  ASSERT_EQ(shown.type(), CV_8UC3);
  EXPECT_EQ(shown.at<cv::Vec3b>(5, 7), cv::Vec3b::all(gray.at<uint8_t>(5, 7)));
  ASSERT_TRUE(WriteImage(Path("deep.png"), deep).ok());
  EXPECT_FALSE(ReadColourImage(Path("deep.png"), &shown).ok());
  // Stored, unfiltered (a frame's way) reads the same.
  ASSERT_TRUE(WritePng(Path("stored.png"), gray, PngWriting{0, false}).ok());
  cv::Mat back;
  ASSERT_TRUE(ReadImage(Path("stored.png"), &back).ok());
  EXPECT_EQ(cv::norm(back, gray, cv::NORM_INF), 0);
  // The dpi in the TIFF's tags, and a float map of x y z written x first.
  ASSERT_TRUE(WriteTiff(Path("dpi.tif"), colour, 400).ok());
  TIFF* tif = TIFFOpen(Path("dpi.tif").c_str(), "r");
  ASSERT_NE(tif, nullptr);
  float xres = 0;
  uint16_t unit = 0;
  EXPECT_EQ(TIFFGetField(tif, TIFFTAG_XRESOLUTION, &xres), 1);
  EXPECT_EQ(TIFFGetField(tif, TIFFTAG_RESOLUTIONUNIT, &unit), 1);
  EXPECT_FLOAT_EQ(xres, 400);
  EXPECT_EQ(unit, RESUNIT_INCH);
  TIFFClose(tif);
  cv::Mat points(5, 6, CV_32FC3, cv::Scalar(1.5f, -2.0f, 30.25f));
  ASSERT_TRUE(WriteImage(Path("points.tiff"), points).ok());
  tif = TIFFOpen(Path("points.tiff").c_str(), "r");
  ASSERT_NE(tif, nullptr);
  std::vector<float> row(TIFFScanlineSize(tif) / sizeof(float));
  ASSERT_EQ(TIFFReadScanline(tif, row.data(), 0), 1);
  EXPECT_EQ(row[0], 1.5f);
  EXPECT_EQ(row[2], 30.25f);
  TIFFClose(tif);
  // JPEG, by libvips; a bilevel PNG widened to 8 bits.
  ASSERT_TRUE(cv::imwrite(Path("i.jpg"), colour));
  ASSERT_TRUE(ReadImage(Path("i.jpg"), &back).ok());
  EXPECT_EQ(back.type(), CV_8UC3);
  EXPECT_LT(cv::norm(back, cv::imread(Path("i.jpg")), cv::NORM_INF), 3);
  // One row of pixels as a TIFF, written by libtiff: `samples` a pixel of `bits` each.
  auto write_row_tiff = [&](const std::string& name, int width, int samples, int bits, int format,
                            int photometric, const void* row) {
    TIFF* t = TIFFOpen(Path(name).c_str(), "w");
    ASSERT_NE(t, nullptr);
    TIFFSetField(t, TIFFTAG_IMAGEWIDTH, width);
    TIFFSetField(t, TIFFTAG_IMAGELENGTH, 1);
    TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, samples);
    TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, bits);
    TIFFSetField(t, TIFFTAG_SAMPLEFORMAT, format);
    TIFFSetField(t, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
    TIFFSetField(t, TIFFTAG_PHOTOMETRIC, photometric);
    if (photometric == PHOTOMETRIC_SEPARATED) TIFFSetField(t, TIFFTAG_INKSET, INKSET_CMYK);
    ASSERT_EQ(TIFFWriteScanline(t, const_cast<void*>(row), 0), 1);
    TIFFClose(t);
  };
  // A CMYK TIFF (a printer's or a scanning bureau's file) is read as colour, not as its first
  // three inks: cyan, yellow, black and paper, in that order, each where it should be.
  const uint8_t inks[16] = {255, 0, 0, 0, 0, 0, 255, 0, 0, 0, 0, 255, 0, 0, 0, 0};
  write_row_tiff("cmyk.tif", 4, 4, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_SEPARATED, inks);
  ASSERT_TRUE(ReadImage(Path("cmyk.tif"), &back).ok());
  ASSERT_EQ(back.type(), CV_8UC3);
  ASSERT_EQ(back.cols, 4);
  const cv::Vec3b cyan = back.at<cv::Vec3b>(0, 0), yellow = back.at<cv::Vec3b>(0, 1),
                  black = back.at<cv::Vec3b>(0, 2), paper = back.at<cv::Vec3b>(0, 3);
  // BGR. The profile decides the exact values; which channels are high and low it does not.
  EXPECT_LT(cyan[2], 100) << cyan;
  EXPECT_GT(cyan[0], 150) << cyan;
  EXPECT_GT(yellow[2], 150) << yellow;
  EXPECT_GT(yellow[1], 150) << yellow;
  EXPECT_LT(yellow[0], 100) << yellow;
  EXPECT_LT(cv::norm(black, cv::NORM_INF), 100) << black;
  EXPECT_GT(paper[0], 200) << paper;
  EXPECT_GT(paper[1], 200) << paper;
  EXPECT_GT(paper[2], 200) << paper;
  // Samples of 32-bit integers are refused by name, not clipped to 8 bits.
  const uint32_t wide[2] = {70000, 5};
  write_row_tiff("wide.tif", 2, 1, 32, SAMPLEFORMAT_UINT, PHOTOMETRIC_MINISBLACK, wide);
  const Status wide_read = ReadImage(Path("wide.tif"), &back);
  EXPECT_FALSE(wide_read.ok());
  EXPECT_NE(wide_read.message().find("wide.tif: its samples are uint"), std::string::npos)
      << wide_read.message();
  cv::Mat bits = gray > 100;
  ASSERT_TRUE(cv::imwrite(Path("bits.png"), bits, {cv::IMWRITE_PNG_BILEVEL, 1}));
  ASSERT_TRUE(ReadImage(Path("bits.png"), &back).ok());
  EXPECT_EQ(cv::norm(back, bits, cv::NORM_INF), 0);
  // A PNG cut short, and no file at all.
  std::ifstream whole(Path("i.png"), std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(whole)), {});
  std::ofstream(Path("cut.png"), std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  Status s = ReadImage(Path("cut.png"), &back);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("cut.png: not a readable image"), std::string::npos) << s.message();
  s = ReadImage(Path("none.png"), &back);
  EXPECT_NE(s.message().find("none.png: file is missing"), std::string::npos) << s.message();
}

TEST_F(IoTest, TheManifestProvesAScanWholeAndNamesWhatChanged) {
  fs::create_directories(dir_ / "raw");
  fs::create_directories(dir_ / "results" / "report");
  auto write = [&](const std::string& rel, const std::string& text) {
    std::ofstream(dir_ / rel, std::ios::binary) << text;
  };
  write("raw/scan.yaml", "format: vellum-scan\n");
  write("results/restored.tif", std::string(3 << 20, 'x'));  // Several read buffers.
  write("results/report/strain.png", "png");
  write("pending", "the supervisor's ledger");
  int files = 0;
  ASSERT_TRUE(WriteManifest(dir_.string(), {"raw", "results"}, &files).ok());
  EXPECT_EQ(files, 3);
  std::string hex;
  ASSERT_TRUE(Sha256OfFile(Path("raw/scan.yaml"), &hex).ok());
  EXPECT_EQ(hex.size(), 64u);
  std::vector<std::string> problems;
  ASSERT_TRUE(CheckManifest(dir_.string(), &problems).ok());
  EXPECT_TRUE(problems.empty()) << problems.front();
  // The same verdict from coreutils.
  const std::string cmd = "cd '" + dir_.string() + "' && sha256sum --quiet -c " + kManifestName;
  EXPECT_EQ(std::system(cmd.c_str()), 0);
  // A byte changed, a file gone, a file added.
  write("results/report/strain.png", "pnG");
  fs::remove(dir_ / "raw" / "scan.yaml");
  write("results/extra.txt", "added");
  ASSERT_TRUE(CheckManifest(dir_.string(), &problems).ok());
  ASSERT_EQ(problems.size(), 3u);
  std::string all;
  for (const std::string& p : problems) all += p + "\n";
  EXPECT_NE(all.find("raw/scan.yaml: missing"), std::string::npos) << all;
  EXPECT_NE(all.find("results/report/strain.png: changed"), std::string::npos) << all;
  EXPECT_NE(all.find("results/extra.txt: not in the manifest"), std::string::npos) << all;
  EXPECT_NE(std::system(cmd.c_str()), 0);
  // No manifest, or a damaged one: an error naming it.
  write(kManifestName, "not a manifest\n");
  const Status bad = CheckManifest(dir_.string(), &problems);
  EXPECT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("manifest-sha256.txt: line 1"), std::string::npos) << bad.message();
  // An empty or blank manifest proves nothing: an error, never "whole and unchanged".
  for (const std::string& text : {std::string(), std::string("\n\n  \n")}) {
    write(kManifestName, text);
    const Status empty = CheckManifest(dir_.string(), &problems);
    EXPECT_FALSE(empty.ok()) << "manifest '" << text << "'";
    EXPECT_NE(empty.message().find("lists no file"), std::string::npos) << empty.message();
  }
}

// A symbolic link under a scan's folder is reported wherever it lies and whatever it points to
// (a file, a folder, nothing): the manifest cannot vouch for what it points to.
// Hashes recorded as the files were written spare the manifest reading them again, and give the
// same manifest as hashing at the end: a log hashed in pieces as it grew (and once after it was
// cut), files written whole. A file changed after it was recorded (rewritten, or appended to) is
// hashed again, never vouched for with its old hash.
TEST_F(IoTest, HashesRecordedAsFilesAreWrittenMakeTheSameManifestAndChangesAreHashedAgain) {
  fs::create_directories(dir_ / "raw");
  fs::create_directories(dir_ / "results");
  const auto append = [&](const std::string& rel, const std::string& text) {
    std::ofstream(dir_ / rel, std::ios::binary | std::ios::app) << text;
  };
  HashRecord record(dir_.string());
  std::string log;
  for (int k = 0; k < 5; ++k) {
    // Pieces across the hasher's 1 MB reads.
    const std::string piece(700000 + 13 * k, static_cast<char>('a' + k));
    append("raw/captures.lcmlog", piece);
    log += piece;
    ASSERT_TRUE(record.Grow("raw/captures.lcmlog").ok()) << k;
    const std::string frame = "raw/frame_00" + std::to_string(k) + ".png";
    append(frame, std::string(1000 + k, static_cast<char>('A' + k)));
    ASSERT_TRUE(record.Add(frame).ok()) << frame;
    if (k == 2) {  // Cut (a torn tail trimmed) and written again: hashed afresh.
      fs::resize_file(dir_ / "raw" / "captures.lcmlog", 10);
      log.resize(10);
      ASSERT_TRUE(record.Grow("raw/captures.lcmlog").ok());
    }
  }
  append("raw/frame_009.png", "later");  // Written after the record: not in it.
  ASSERT_TRUE(record.Save().ok());
  std::ifstream saved(dir_ / kRecordedHashesName);
  std::string line;
  int lines = 0;
  while (std::getline(saved, line)) ++lines;
  EXPECT_EQ(lines, 6);  // The log and five frames.
  append("results/restored.tif", "tiff");
  ASSERT_TRUE(WriteManifest(dir_.string(), {"raw", "results"}).ok());
  const auto manifest = [&] {
    std::ifstream in(dir_ / kManifestName);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string with_record = manifest();
  EXPECT_NE(with_record.find(Sha256OfBytes(log) + "  raw/captures.lcmlog"), std::string::npos)
      << with_record;
  EXPECT_EQ(with_record.find(kRecordedHashesName), std::string::npos) << with_record;
  std::vector<std::string> problems;
  ASSERT_TRUE(CheckManifest(dir_.string(), &problems).ok());
  EXPECT_TRUE(problems.empty()) << problems.front();
  fs::rename(dir_ / kRecordedHashesName, dir_ / "aside.txt");
  ASSERT_TRUE(WriteManifest(dir_.string(), {"raw", "results"}).ok());
  EXPECT_EQ(manifest(), with_record);  // The same, every file read.
  // The record is used: a hash put in it by hand for a file of that size and time is taken.
  std::ifstream in(dir_ / "aside.txt");
  std::string text(std::istreambuf_iterator<char>(in), {});
  const std::string real = Sha256OfBytes(std::string(1000, 'A'));
  const std::string fake(64, '0');
  ASSERT_NE(text.find(real), std::string::npos) << text;
  text.replace(text.find(real), 64, fake);
  std::ofstream(dir_ / kRecordedHashesName, std::ios::binary | std::ios::trunc) << text;
  ASSERT_TRUE(WriteManifest(dir_.string(), {"raw", "results"}).ok());
  EXPECT_NE(manifest().find(fake + "  raw/frame_000.png"), std::string::npos) << manifest();
  // Changed since (same size, later time; or appended to): hashed again.
  const fs::path frame = dir_ / "raw" / "frame_000.png";
  const auto recorded_time = fs::last_write_time(frame);
  std::ofstream(frame, std::ios::binary | std::ios::trunc) << std::string(1000, 'Z');
  fs::last_write_time(frame, recorded_time + std::chrono::seconds(1));  // Whatever the clock.
  append("raw/captures.lcmlog", "more");
  ASSERT_TRUE(WriteManifest(dir_.string(), {"raw", "results"}).ok());
  EXPECT_EQ(manifest().find(fake), std::string::npos) << manifest();
  ASSERT_TRUE(CheckManifest(dir_.string(), &problems).ok());
  EXPECT_TRUE(problems.empty()) << problems.front();
}

// A daemon's own record (recorded-sha256-<name>.txt) is taken as the decoder's is; records, and
// records being written, are never in the manifest, but a file named like one inside raw/ or
// results/ is.
TEST_F(IoTest, EachWritersRecordIsTakenAndNoRecordIsInTheManifest) {
  fs::create_directories(dir_ / "raw");
  fs::create_directories(dir_ / "results" / "report");
  auto write = [&](const std::string& rel, const std::string& text) {
    std::ofstream(dir_ / rel, std::ios::binary | std::ios::trunc) << text;
  };
  write("raw/scan.yaml", "format: vellum-scan\n");
  HashRecord mine(dir_.string(), RecordedHashesName("triangulator"));
  std::vector<std::string> files;
  for (int k = 0; k < 8; ++k) {
    files.push_back("results/report/picture_" + std::to_string(k) + ".png");
    write(files.back(), std::string(5000 + k, static_cast<char>('a' + k)));
  }
  write("results/recorded-sha256-not-a-record.txt", "a result like any other");
  for (const std::string& rel : files) ASSERT_TRUE(mine.Add(rel).ok()) << rel;
  ASSERT_TRUE(mine.Save().ok());
  write(".part-recorded-sha256-flattener.txt", "a record being written when the manifest is");
  // The record's hash of one picture replaced by another: the manifest takes the record's.
  std::ifstream in(dir_ / RecordedHashesName("triangulator"));
  std::string text(std::istreambuf_iterator<char>(in), {});
  in.close();
  const std::string real = Sha256OfBytes(std::string(5003, 'd'));
  const std::string fake(64, 'f');
  ASSERT_NE(text.find(real), std::string::npos) << text;
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 8) << text;
  text.replace(text.find(real), 64, fake);
  write(RecordedHashesName("triangulator"), text);
  int listed = 0;
  ASSERT_TRUE(WriteManifest(dir_.string(), {}, &listed).ok());
  std::ifstream m(dir_ / kManifestName);
  const std::string manifest(std::istreambuf_iterator<char>(m), {});
  EXPECT_EQ(listed, 10) << manifest;  // scan.yaml, 8 pictures, the result named like a record.
  EXPECT_NE(manifest.find(fake + "  results/report/picture_3.png"), std::string::npos) << manifest;
  EXPECT_NE(manifest.find("results/recorded-sha256-not-a-record.txt"), std::string::npos);
  EXPECT_EQ(manifest.find("  recorded-sha256"), std::string::npos) << manifest;
  EXPECT_EQ(manifest.find(".part-"), std::string::npos) << manifest;
}

TEST_F(IoTest, TheManifestCheckReportsEverySymbolicLink) {
  fs::create_directories(dir_ / "raw");
  fs::create_directories(dir_ / "results");
  std::ofstream(dir_ / "raw" / "scan.yaml") << "format: vellum-scan\n";
  std::ofstream(dir_ / "results" / "restored.tif") << "tiff";
  ASSERT_TRUE(WriteManifest(dir_.string(), {"raw", "results"}).ok());
  fs::create_symlink(dir_ / "raw" / "scan.yaml", dir_ / "results" / "to_file");
  fs::create_directory_symlink(dir_ / "raw", dir_ / "results" / "to_folder");
  fs::create_symlink(dir_ / "nowhere", dir_ / "results" / "dangling");
  std::vector<std::string> problems;
  ASSERT_TRUE(CheckManifest(dir_.string(), &problems).ok());
  std::string all;
  for (const std::string& p : problems) all += p + "\n";
  for (const char* link : {"results/to_file", "results/to_folder", "results/dangling"}) {
    EXPECT_NE(all.find(std::string(link) + ": a symbolic link"), std::string::npos) << all;
  }
  EXPECT_EQ(problems.size(), 3u) << all;  // Each once; a link to a file is not also "not listed".
}

// A file the process may not read is reported as what it is, not as a bad image: permission
// denied, a folder, missing. As root (who may read anything), the check runs in a child that
// has become nobody.
TEST_F(IoTest, AFileThatCannotBeReadIsReportedAsWhatItIs) {
  const std::string image = Path("frame_003.png");
  ASSERT_TRUE(WritePng(image, cv::Mat(8, 8, CV_8U, cv::Scalar(7))).ok());
  fs::permissions(image, fs::perms::none);
  fs::permissions(dir_, fs::perms::owner_all | fs::perms::others_exec | fs::perms::group_exec);
  auto denied = [&] {
    cv::Mat read;
    const Status s = ReadImage(image, &read);
    return !s.ok() &&
           s.message() == image + ": permission denied (this process may not read it; " +
                              "ls -l shows who may)" &&
           !CheckReadable(image).ok();
  };
  if (::geteuid() == 0) {
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      const bool ok = ::setgid(65534) == 0 && ::setuid(65534) == 0 && denied();
      ::_exit(ok ? 0 : 1);
    }
    int status = 0;
    ASSERT_EQ(::waitpid(child, &status, 0), child);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
        << "as nobody: not 'permission denied'";
  } else {
    EXPECT_TRUE(denied());
  }
  fs::permissions(image, fs::perms::owner_read | fs::perms::owner_write);
  cv::Mat read;
  EXPECT_TRUE(ReadImage(image, &read).ok());
  fs::create_directories(dir_ / "folder.png");
  Status s = ReadImage(Path("folder.png"), &read);
  EXPECT_NE(s.message().find("folder.png: is a folder, not a file"), std::string::npos)
      << s.message();
  s = ReadImage(Path("gone.png"), &read);
  EXPECT_NE(s.message().find("gone.png: file is missing"), std::string::npos) << s.message();
}

// A write cut short (here by a file-size limit, as a full disk would: the write fails part way)
// leaves nothing that looks like the product: no file, or the earlier whole one unchanged, and no
// temporary part. The writers of points, sheets, images and text all go through WriteWhole.
TEST_F(IoTest, AWriteCutShortLeavesNoHalfProduct) {
  cv::Mat points(400, 400, CV_32FC3, cv::Scalar(1, 2, 3));  // 3.2 MB of PLY.
  cv::Mat image(800, 800, CV_8UC3);
  cv::randu(image, 0, 256);  // Noise: LZW cannot bring it under the limit.
  const std::string old_ply = Path("old.ply");
  ASSERT_TRUE(WritePointsPly(old_ply, cv::Mat(2, 2, CV_32FC3, cv::Scalar(4, 5, 6))).ok());
  std::string before;
  {
    std::ifstream in(old_ply, std::ios::binary);
    before.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  // In this process (a forked child would deadlock in libvips' threads): the soft limit lowered
  // for the writes, then raised back.
  rlimit saved{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &saved), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);  // A write past it fails (EFBIG).
  rlimit limit = saved;
  limit.rlim_cur = 64 << 10;
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &limit), 0);
  const Status ply = WritePointsPly(Path("points.ply"), points);
  const Status again = WritePointsPly(old_ply, points);
  const Status tif = WriteTiff(Path("restored.tif"), image);
  const Status text = WriteTextFile(Path("report.json"), std::string(200 << 10, ' '));
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &saved), 0);
  std::signal(SIGXFSZ, old_handler);
  EXPECT_FALSE(ply.ok());
  EXPECT_EQ(ply.message().find(Path("points.ply") + ": write failed"), 0u) << ply.message();
  EXPECT_EQ(ply.message().find(".part-"), std::string::npos) << ply.message();
  EXPECT_FALSE(again.ok());
  EXPECT_FALSE(tif.ok());
  EXPECT_FALSE(text.ok());
  for (const char* name : {"points.ply", "restored.tif", "report.json"}) {
    EXPECT_FALSE(fs::exists(Path(name))) << name << ": half a product left";
    EXPECT_FALSE(fs::exists(PartName(Path(name)))) << name << ": its part left";
  }
  std::string after;
  {
    std::ifstream in(old_ply, std::ios::binary);
    after.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  EXPECT_EQ(after, before) << "the earlier whole product was overwritten by half of a new one";
  // Without the limit, each is written whole.
  EXPECT_TRUE(WritePointsPly(Path("points.ply"), points).ok());
  EXPECT_TRUE(WriteTiff(Path("restored.tif"), image).ok());
  EXPECT_FALSE(fs::exists(PartName(Path("points.ply"))));
}

// The restored page carries its catalogue identity in an XMP packet that any XMP reader finds
// (Dublin Core, and vellum's own namespace), beside unchanged pixels and resolution tags.
TEST_F(IoTest, TheRestoredTiffCarriesItsIdentityInXmpBesideItsPixelsAndDpi) {
  RestoreResult restored;
  restored.status = Status::Ok();
  restored.image = cv::Mat(40, 30, CV_8UC3);
  cv::randu(restored.image, 0, 255);
  restored.view = RestoreView::kOrthographic;
  restored.dpi = 400;
  restored.rotation_deg = -2.5;
  ScanIdentity id;
  id.shelfmark = "Cotton MS Otho B <x> & \"y\"";  // Markup characters must survive.
  id.folio = "12";
  id.side = "verso";
  id.operator_name = "Ann Example";
  id.note = "burnt edge, lower left";
  ASSERT_TRUE(WriteRestored(dir_.string(), restored, id).ok());

  std::map<std::string, std::string> xmp;
  const Status s = ReadXmp(Path("restored.tif"), &xmp);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(xmp["dc:identifier"], id.shelfmark);
  EXPECT_EQ(xmp["dc:title"], IdentityTitle(id));
  EXPECT_EQ(xmp["dc:description"], id.note);
  EXPECT_EQ(xmp["dc:contributor"], id.operator_name);
  EXPECT_EQ(xmp["vellum:folio"], "12");
  EXPECT_EQ(xmp["vellum:side"], "verso");
  EXPECT_EQ(xmp["vellum:dpi"], "400");
  EXPECT_EQ(xmp["vellum:rotationDeg"], "-2.5");
  EXPECT_EQ(xmp.count("vellum:label"), 0u) << "empty fields are left out";
  EXPECT_EQ(xmp["xmp:CreatorTool"].rfind("vellum ", 0), 0u) << xmp["xmp:CreatorTool"];

  const cv::Mat back = cv::imread(Path("restored.tif"), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(back.size(), restored.image.size());
  EXPECT_EQ(cv::norm(back, restored.image, cv::NORM_INF), 0);
  TIFF* tif = TIFFOpen(Path("restored.tif").c_str(), "r");
  ASSERT_NE(tif, nullptr);
  float xres = 0, yres = 0;
  uint16_t unit = 0;
  EXPECT_EQ(TIFFGetField(tif, TIFFTAG_XRESOLUTION, &xres), 1);
  EXPECT_EQ(TIFFGetField(tif, TIFFTAG_YRESOLUTION, &yres), 1);
  EXPECT_EQ(TIFFGetField(tif, TIFFTAG_RESOLUTIONUNIT, &unit), 1);
  TIFFClose(tif);
  EXPECT_EQ(xres, 400.0f);
  EXPECT_EQ(yres, 400.0f);
  EXPECT_EQ(unit, RESUNIT_INCH);

  // The colour profile: sRGB, embedded where TIFF keeps it (tag 34675), and a gray page gets a
  // gray one (an RGB profile on a gray image is refused by colour-managed readers).
  auto icc_space = [&](const std::string& file) {
    std::string icc;
    EXPECT_TRUE(ReadIccProfile(file, &icc).ok()) << file;
    EXPECT_GT(icc.size(), 128u) << file;
    EXPECT_EQ(icc.substr(36, 4), "acsp") << file;  // The ICC header's signature.
    return icc.size() > 128 ? icc.substr(16, 4) : std::string();
  };
  EXPECT_EQ(icc_space(Path("restored.tif")), "RGB ");
  TIFF* tagged = TIFFOpen(Path("restored.tif").c_str(), "r");
  ASSERT_NE(tagged, nullptr);
  uint32_t icc_size = 0;
  void* icc_data = nullptr;
  EXPECT_EQ(TIFFGetField(tagged, TIFFTAG_ICCPROFILE, &icc_size, &icc_data), 1);
  TIFFClose(tagged);
  EXPECT_GT(icc_size, 128u);
  cv::cvtColor(restored.image, restored.image, cv::COLOR_BGR2GRAY);
  fs::create_directories(dir_ / "gray");
  ASSERT_TRUE(WriteRestored((dir_ / "gray").string(), restored, id).ok());
  EXPECT_EQ(icc_space(Path("gray/restored.tif")), "GRAY");
  // A camera's own profile goes in as given; one for the other kind of image, or bytes that are
  // no profile, are refused, named.
  IccProfile camera;
  ASSERT_TRUE(ParseIccProfile(MakeSrgbProfile(1), "camera.icc", &camera).ok());
  EXPECT_EQ(camera.channels, 1);
  fs::create_directories(dir_ / "camera");
  ASSERT_TRUE(WriteRestored((dir_ / "camera").string(), restored, id, {}, camera).ok());
  std::string embedded;
  ASSERT_TRUE(ReadIccProfile(Path("camera/restored.tif"), &embedded).ok());
  EXPECT_EQ(embedded, camera.bytes);
  cv::cvtColor(restored.image, restored.image, cv::COLOR_GRAY2BGR);
  const Status mismatched = WriteRestored((dir_ / "camera").string(), restored, id, {}, camera);
  EXPECT_FALSE(mismatched.ok());
  EXPECT_NE(mismatched.message().find("describes gray images, this one is colour"),
            std::string::npos)
      << mismatched.message();
  IccProfile junk;
  const Status not_icc = ParseIccProfile("no profile here", "junk.icc", &junk);
  EXPECT_FALSE(not_icc.ok());
  EXPECT_NE(not_icc.message().find("junk.icc: not an ICC profile"), std::string::npos)
      << not_icc.message();

  const Status missing = ReadXmp(Path("none.tif"), &xmp);
  EXPECT_FALSE(missing.ok());
  EXPECT_NE(missing.message().find("none.tif"), std::string::npos) << missing.message();
}

}  // namespace
}  // namespace vellum

namespace vellum {
namespace {

// A scratch path of this process in the temporary directory: vellum_NAME_PID.
std::filesystem::path Scratch(const std::string& name) {
  return std::filesystem::temp_directory_path() /
         ("vellum_" + name + "_" + std::to_string(getpid()));
}

// A seed of fuzz/fuzz_files (tests/fuzz_corpus/fuzz_files/NAME) as the file the fuzzer wrote: its
// bytes after the first, which picks the reader; empty if the seed cannot be read.
std::string FuzzFileSeed(const std::string& name) {
  std::ifstream in(VELLUM_SOURCE_DIR "/tests/fuzz_corpus/fuzz_files/" + name, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return bytes.empty() ? bytes : bytes.substr(1);
}

// A fuzz_files seed read as a station's lights file, `dir`/lights.yaml (an empty seed, as a
// missing one reads, fails the test).
Status ReadLightsSeed(const std::string& name, const std::filesystem::path& dir) {
  const std::string lights = FuzzFileSeed(name);
  EXPECT_FALSE(lights.empty()) << name;
  std::ofstream(dir / "lights.yaml", std::ios::binary) << lights;
  StationLights station;
  return ReadLightsFile((dir / "lights.yaml").string(), &station);
}

// Inputs the fuzzers found that made OpenCV's YAML reader throw std::length_error (not a
// cv::Exception), which ended the reading process; now they are errors naming the file.
TEST(IoFuzzRegressions, YamlThatMakesOpenCvThrowIsAnError) {
  const std::string bytes = FuzzFileSeed("regression-yaml-length-error");
  ASSERT_FALSE(bytes.empty());
  const std::filesystem::path dir = Scratch("io_regress");
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "scan.yaml", std::ios::binary) << bytes;
  std::ofstream(dir / "calibration.yaml", std::ios::binary) << bytes;
  Scan header;
  EXPECT_FALSE(ReadScanYaml(dir.string(), &header).ok());
  Calibration calibration;
  EXPECT_FALSE(ReadCalibration((dir / "calibration.yaml").string(), &calibration).ok());
  // The same throw from the station's lights file ended the process (its reader caught only
  // cv::Exception; found once fuzz_files read lights files).
  const Status s = ReadLightsSeed("regression-lights-yaml-length-error", dir);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("lights.yaml: cannot parse"), std::string::npos) << s.message();
  std::filesystem::remove_all(dir);
}

// Texts on which OpenCV 4.6's YAML parser never returns (found by fuzz/fuzz_files): each is
// refused, naming the problem, before OpenCV sees it. (A regression shows as a hang, which the
// test's timeout turns into a failure.)
TEST(IoFuzzRegressions, YamlThatHangsOpenCvIsRefusedFirst) {
  const std::filesystem::path dir = Scratch("io_hang");
  std::filesystem::create_directories(dir);
  const struct {
    std::string text, problem;
  } cases[] = {
      {std::string("%YAML:1.0\ncamera_size: [ 4, 3 ]\0\n", 33), "NUL"},
      {"%YAML:1.0\n   rows: 3\n* v-m\n", "indented"},
      {"%YAML:1.0\na: 1\n...\n-x\n", "\"...\""},
      {"%YAML:1.0\n---  rows: 3\n* v-m\n", "an entry on a \"---\" line"},
      {"%YAML:1.0\n---\n %YAML:1.0\n-x--\n", "\"%\" directive"},
  };
  for (const auto& c : cases) {
    const std::string path = (dir / "calibration.yaml").string();
    std::ofstream(path, std::ios::binary) << c.text;
    Calibration calibration;
    const Status s = ReadCalibration(path, &calibration);
    EXPECT_FALSE(s.ok());
    EXPECT_NE(s.message().find(c.problem), std::string::npos) << s.message();
    std::ofstream(dir / "scan.yaml", std::ios::binary) << c.text;
    Scan header;
    EXPECT_FALSE(ReadScanYaml(dir.string(), &header).ok());
  }
  // The same in a station's lights file, as the fuzzer found it (its first byte picks the file).
  const Status refused = ReadLightsSeed("regression-opencv-yaml-indented-directive-hang", dir);
  EXPECT_FALSE(refused.ok());
  EXPECT_NE(refused.message().find("directive"), std::string::npos) << refused.message();
  // The header OpenCV writes, comments and blank lines before the first entry are fine.
  Calibration calibration;
  ASSERT_TRUE(WriteCalibration((dir / "ok.yaml").string(), DefaultRig()).ok());
  std::ifstream in(dir / "ok.yaml");
  const std::string written((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t header = written.find('\n') + 1;  // After "%YAML:1.0".
  std::ofstream(dir / "commented.yaml") << written.substr(0, header) << "# hand-edited\n\n"
                                        << written.substr(header);
  const Status s = ReadCalibration((dir / "commented.yaml").string(), &calibration);
  EXPECT_TRUE(s.ok()) << s.message();
  std::filesystem::remove_all(dir);
}

// Sizes and cells whose arithmetic overflowed an int (found by fuzz/fuzz_files: a 70000 x 70000
// projector in a flat field, whose area is 4.9e9; a cell of 2^31 - 1 pixels, whose sum with the
// width wrapped): each is refused naming the file and the key, in every YAML reader of sizes,
// and a size within the bound still reads, as a sequence or as a matrix.
TEST(IoFuzzRegressions, SizesBeyondTheBoundAreRefusedNamingTheKey) {
  const std::filesystem::path dir = Scratch("io_sizes");
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "field.yaml").string();
  auto write = [&](const std::string& text) {
    std::ofstream(path, std::ios::binary) << "%YAML:1.0\n---\n" << text;
  };
  const std::string tail = "cell_px: 8\nreference_mm: 500\n";
  FlatField flat;
  StudioField studio;
  for (const std::string& bad : {std::string("[ 70000, 70000 ]"), std::string("[ 0, 30 ]"),
                                 std::string("[ 40.5, 30 ]"), std::string("[ 40 ]")}) {
    write("projector_size: " + bad + "\n" + tail);
    Status s = ReadFlatField(path, &flat);
    ASSERT_FALSE(s.ok()) << bad;
    EXPECT_NE(s.message().find("field.yaml: key 'projector_size' must be"), std::string::npos)
        << s.message();
    write("camera_size: " + bad + "\n" + tail);
    s = ReadStudioField(path, &studio);
    ASSERT_FALSE(s.ok()) << bad;
    EXPECT_NE(s.message().find("field.yaml: key 'camera_size' must be"), std::string::npos)
        << s.message();
  }
  write("projector_size: [ 100, 100 ]\ncell_px: 2147483647\nreference_mm: 500\n");
  Status s = ReadFlatField(path, &flat);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("cell_px must be an integer from 1 to 16384"), std::string::npos)
      << s.message();
  // A size written as a matrix (as other tools may) reads; its gain is then what is missing.
  write("projector_size: !!opencv-matrix\n  rows: 1\n  cols: 2\n  dt: d\n  data: [ 16, 8 ]\n" +
        tail);
  s = ReadFlatField(path, &flat);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("gain must be a 2x1 matrix"), std::string::npos) << s.message();
  // The calibration's devices and scan.yaml's sizes share the reader.
  Calibration calibration = DefaultRig();
  calibration.camera.size = cv::Size(40000, 3);
  ASSERT_TRUE(WriteCalibration(path, calibration).ok());
  s = ReadCalibration(path, &calibration);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("camera_size' must be 1 to 16384"), std::string::npos) << s.message();
  std::ofstream(dir / "scan.yaml") << "%YAML:1.0\n---\nprojector_size: [ 40, 30 ]\n"
                                      "camera_size: [ 3, 70000 ]\npatterns: [ x ]\n";
  Scan header;
  s = ReadScanYaml(dir.string(), &header);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("scan.yaml: key 'camera_size' must be 1 to 16384"), std::string::npos)
      << s.message();
  std::filesystem::remove_all(dir);
}

// A PTM's header is believed only as far as the file bears it out: a header claiming 65536 x
// 65536 pixels (38 GB) over a few bytes, or a bias no byte can be offset by, is refused naming
// the file; the seed the fuzzer starts from reads.
TEST(IoFuzzRegressions, APtmClaimingMoreThanItHoldsIsRefusedBeforeAllocating) {
  const std::string bytes = FuzzFileSeed("ptm_2x1");
  ASSERT_FALSE(bytes.empty());
  const std::string path = Scratch("ptm").string() + "_page.ptm";
  std::ofstream(path, std::ios::binary) << bytes;
  PtmResult ptm;
  Status s = ReadPtm(path, &ptm);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(ptm.coefficients.size(), cv::Size(2, 1));
  EXPECT_EQ(ptm.solved, 1);  // The first pixel's colour is black: not solved.
  const struct {
    std::string header, problem;
  } cases[] = {
      {"PTM_1.2\nPTM_FORMAT_LRGB\n65536 65536\n1 1 1 1 1 1\n0 0 0 0 0 0\n",
       "page.ptm: shorter than its size says (65536x65536 pixels need 38654705664 bytes"},
      {"PTM_1.2\nPTM_FORMAT_LRGB\n2 1\n1 1 1 1 1 1\n0 0 -2147483648 0 0 0\n",
       "page.ptm: coefficient 2's scale"},
      {"PTM_1.2\nPTM_FORMAT_LRGB\n2 1\n1 1 1 1e300 1 1\n0 0 0 0 0 0\n",
       "page.ptm: coefficient 3's scale"},
  };
  for (const auto& c : cases) {
    std::ofstream(path, std::ios::binary) << c.header << std::string(18 + 6, '\x01');
    s = ReadPtm(path, &ptm);
    EXPECT_FALSE(s.ok()) << c.header;
    EXPECT_NE(s.message().find(c.problem), std::string::npos) << s.message();
  }
  std::remove(path.c_str());
}

// Formats libvips knows but vellum does not read are refused naming the loader, before libvips'
// loader runs: a malformed OpenEXR file, read as a scan's texture, leaked inside libvips 8.14
// (found by fuzz/fuzz_files; under the fuzzer's LeakSanitizer a failure).
TEST(IoFuzzRegressions, AFormatVellumDoesNotReadIsRefusedNamingIt) {
  const std::string bytes = FuzzFileSeed("regression-vips-openexr-leak");
  ASSERT_FALSE(bytes.empty());
  const std::filesystem::path dir = Scratch("io_exr");
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "texture.png", std::ios::binary) << bytes;
  cv::Mat image;
  Status s = ReadTexture(dir.string(), &image);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("texture.png: not a readable image (by its first bytes, one for "
                             "libvips' Openexr loader; vellum reads PNG, TIFF, JPEG, JPEG 2000, "
                             "WebP)"),
            std::string::npos)
      << s.message();
  s = ReadImage((dir / "texture.png").string(), &image);
  EXPECT_FALSE(s.ok());
  std::filesystem::remove_all(dir);
}

// A PLY header declaring more data than the file holds is refused before anything is allocated
// (a fuzzed mesh asked for 10^100 vertices), and a face naming a vertex beyond them is refused.
TEST(IoFuzzRegressions, PlyCountsBeyondTheFileAreRefused) {
  const std::string bytes = FuzzFileSeed("regression-ply-huge-vertex-count");
  ASSERT_FALSE(bytes.empty());
  const std::string path = Scratch("ply").string() + ".ply";
  std::ofstream(path, std::ios::binary) << "ply\nformat binary_little_endian 1.0\n"
                                        << "element vertex 1000000\nelement face 0\nend_header\n";
  std::vector<cv::Vec3f> vertices;
  std::vector<cv::Vec4i> quads;
  const Status s = ReadQuadMeshPly(path, &vertices, &quads);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("declares 1000000 vertices"), std::string::npos) << s.message();
  std::ofstream(path, std::ios::binary) << bytes;
  EXPECT_FALSE(ReadQuadMeshPly(path, &vertices, &quads).ok());
  // A face naming a vertex the file does not hold is refused, not handed on to be indexed.
  ASSERT_TRUE(WriteQuadMeshPly(path, std::vector<cv::Vec3f>(4), {cv::Vec4i(0, 1, 4, 3)}, "").ok());
  const Status beyond = ReadQuadMeshPly(path, &vertices, &quads);
  EXPECT_FALSE(beyond.ok());
  EXPECT_NE(beyond.message().find("face 0 names vertex 4 of 4"), std::string::npos)
      << beyond.message();
  ASSERT_TRUE(WriteQuadMeshPly(path, std::vector<cv::Vec3f>(4), {cv::Vec4i(0, 1, 2, 3)}, "").ok());
  EXPECT_TRUE(ReadQuadMeshPly(path, &vertices, &quads).ok());
  std::remove(path.c_str());
}

}  // namespace
}  // namespace vellum
