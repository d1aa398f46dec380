// Library masters served as a library serves them: the demo's recorded scan processed
// by `vellum process`, its manifests written by `vellum iiif`, and the pages served by a real
// IIPImage (iipsrv, FastCGI) behind a real lighttpd (scripts/serve-iiif.sh), started by the test
// in its own network namespace (ctest runs it inside scripts/netns-run.sh). Through the IIIF
// Image API it fetches info.json and a tile, and checks that each manifest's canvas and
// physical scale agree with them and with the dpi. exiftool (Debian libimage-exiftool-perl), a
// reader vellum did not write, reads the production master's dpi, ICC profile and XMP.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <thread>

#include "tests/shell.h"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using vellum::Shell;

// An HTTP GET with curl: the body into `file`, the status code returned (0: no answer).
int Get(const std::string& url, const fs::path& file) {
  int status = 0;
  const std::string code =
      Shell("curl -s -g -o '" + file.string() + "' -w '%{http_code}' '" + url + "'", &status);
  return status == 0 ? std::atoi(code.c_str()) : 0;
}

// A number as exiftool prints it in JSON (a number, or a string for XMP text).
double Number(const json& value) {
  return value.is_number() ? value.get<double>() : std::stod(value.get<std::string>());
}

json ReadJson(const fs::path& file) {
  std::ifstream in(file);
  return json::parse(in);
}

class IiifTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("vellum_iiif_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "served");
  }
  void TearDown() override {
    // lighttpd's pid file: stopping it stops the iipsrv it spawned.
    std::ifstream pid(dir_ / "work" / "lighttpd.pid");
    int p = 0;
    if (pid >> p && p > 0) {
      int status = 0;
      Shell("kill " + std::to_string(p), &status);
    }
    if (!HasFailure()) fs::remove_all(dir_);
  }
  fs::path dir_;
};

TEST_F(IiifTest, PagesAreServedAtTrueScaleByIipImage) {
  const std::string tool = VELLUM_BIN;
  int status = 0;
  std::string out = Shell(tool + " export " + VELLUM_LOG + " " + (dir_ / "scan").string(), &status);
  ASSERT_EQ(status, 0) << out;
  // The leaf at its true sampling (the default), and again at 200 dpi: two canvases of one
  // sequence, of different sizes and scales.
  const fs::path served = dir_ / "served";
  const fs::path folio = served / "folio", coarse = served / "coarse";
  for (const auto& [out_dir, extra] :
       {std::pair{folio, std::string()}, std::pair{coarse, std::string(" --dpi 200")}}) {
    out = Shell(tool + " process --scan " + (dir_ / "scan").string() + " --calibration " +
                    (dir_ / "scan" / "calibration.yaml").string() + " --out " + out_dir.string() +
                    extra,
                &status);
    ASSERT_EQ(status, 0) << out;
    ASSERT_TRUE(fs::exists(out_dir / "restored_pyramid.tif"));
  }
  const int port = 8000 + getpid() % 1000;
  const std::string base = "http://127.0.0.1:" + std::to_string(port);
  out = Shell(tool + " iiif --root " + served.string() + " --base " + base + " --sequence " +
                  (served / "volume.json").string() + " --label 'Demo MS 1' " + folio.string() +
                  " " + coarse.string(),
              &status);
  ASSERT_EQ(status, 0) << out;

  // The production master as exiftool reads it: dpi, ICC profile, identity and scale in XMP.
  out = Shell(
      "exiftool -j -XResolution -ResolutionUnit -ProfileDescription -XMP-dc:Identifier "
      "-XMP-dc:Title -XMP-vellum:all " +
          (folio / "restored.tif").string(),
      &status);
  ASSERT_EQ(status, 0) << out;
  const json exif = json::parse(out).at(0);
  const json restored = ReadJson(folio / "restored.json");
  const double dpi = restored.at("dpi").get<double>();
  EXPECT_EQ(Number(exif.at("XResolution")), dpi);
  EXPECT_EQ(exif.at("ResolutionUnit"), "inches");
  EXPECT_EQ(exif.at("ProfileDescription"), "sRGB built-in");
  EXPECT_EQ(exif.at("Identifier"), "Demo MS 1");
  EXPECT_EQ(exif.at("Title"), "Demo MS 1, 7 recto");
  EXPECT_NEAR(Number(exif.at("ScaleMmPerPixel")), 25.4 / dpi, 1e-9);
  EXPECT_LT(Number(exif.at("ScaleErrorPercent")), 1.0);
  EXPECT_EQ(exif.at("CalibrationSha256").get<std::string>().size(), 64u);
  // The archival master carries the same identity; the scan's checksum manifest verifies.
  out = Shell("exiftool -j -XMP-dc:Identifier " + (folio / "archival.tif").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(json::parse(out).at(0).at("Identifier"), "Demo MS 1");
  out = Shell(tool + " manifest write " + folio.string() + " && " + tool + " manifest check " +
                  folio.string(),
              &status);
  EXPECT_EQ(status, 0) << out;

  // The server, and a wait until it answers (a condition, not a guessed sleep).
  const std::string serve = std::string(VELLUM_SOURCE_DIR) + "/scripts/serve-iiif.sh";
  ASSERT_EQ(std::system(("VELLUM_IIIF_WORK=" + (dir_ / "work").string() + " " + serve + " " +
                         served.string() + " " + std::to_string(port) + " > " +
                         (dir_ / "serve.log").string() + " 2>&1 &")
                            .c_str()),
            0);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (Get(base + "/volume.json", dir_ / "volume.json") != 200) {
    ASSERT_LT(std::chrono::steady_clock::now(), deadline)
        << "the server never answered; " << Shell("cat " + (dir_ / "serve.log").string(), &status);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }

  const json volume = ReadJson(dir_ / "volume.json");
  EXPECT_EQ(volume.at("type"), "Manifest");
  EXPECT_EQ(volume.at("@context"), "http://iiif.io/api/presentation/3/context.json");
  EXPECT_EQ(volume.at("label").at("en").at(0), "Demo MS 1");
  ASSERT_EQ(volume.at("items").size(), 2u);
  int k = 0;
  for (const fs::path& results : {folio, coarse}) {
    SCOPED_TRACE(results.filename().string());
    // The scan's own manifest, fetched over HTTP: the same canvas as the sequence's.
    ASSERT_EQ(Get(base + "/" + results.filename().string() + "/iiif-manifest.json",
                  dir_ / "manifest.json"),
              200);
    const json manifest = ReadJson(dir_ / "manifest.json");
    ASSERT_EQ(manifest.at("items").size(), 1u);
    const json& canvas = manifest.at("items").at(0);
    EXPECT_EQ(canvas.at("width"), volume.at("items").at(k).at("width"));
    EXPECT_EQ(canvas.at("label").at("en").at(0), "Demo MS 1, 7 recto");
    const json page = ReadJson(results / "restored.json");
    const double page_dpi = page.at("dpi").get<double>();
    EXPECT_EQ(canvas.at("width"), page.at("width"));
    EXPECT_EQ(canvas.at("height"), page.at("height"));
    // The physical-dimensions service: mm per canvas pixel, 25.4 / dpi.
    const json& physdim = canvas.at("service").at(0);
    EXPECT_EQ(physdim.at("profile"), "http://iiif.io/api/annex/services/physdim");
    EXPECT_EQ(physdim.at("physicalUnits"), "mm");
    EXPECT_NEAR(physdim.at("physicalScale").get<double>(), 25.4 / page_dpi, 1e-12);
    // The image server's view of the same page: info.json's size is the canvas's.
    const json& body = canvas.at("items").at(0).at("items").at(0).at("body");
    const std::string service = body.at("service").at(0).at("@id");
    ASSERT_EQ(Get(service + "/info.json", dir_ / "info.json"), 200)
        << Shell("cat " + (dir_ / "work" / "iipsrv.log").string() + " | tail -20", &status);
    const json info = ReadJson(dir_ / "info.json");
    EXPECT_EQ(info.at("width"), canvas.at("width"));
    EXPECT_EQ(info.at("height"), canvas.at("height"));
    // A tile through the Image API: the page's own pixels, the right way round. JPEG at quality
    // 90 over dense script costs 2.5-3.7 DN on average (measured); the page mirrored top to
    // bottom differs by about 25 DN.
    ASSERT_EQ(Get(service + "/128,128,256,256/256,/0/default.jpg", dir_ / "tile.jpg"), 200);
    const cv::Mat tile = cv::imread((dir_ / "tile.jpg").string(), cv::IMREAD_COLOR);
    ASSERT_EQ(tile.size(), cv::Size(256, 256));
    cv::Mat master = cv::imread((results / "restored.tif").string(), cv::IMREAD_COLOR);
    ASSERT_GE(std::min(master.cols, master.rows), 384);
    cv::Mat diff;
    cv::absdiff(tile, master(cv::Rect(128, 128, 256, 256)), diff);
    std::printf("tile vs master: mean %.2f DN\n", cv::mean(diff)[0]);
    EXPECT_LT(cv::mean(diff)[0], 6.0);
    cv::Mat flipped;
    cv::flip(master(cv::Rect(128, 128, 256, 256)), flipped, 0);
    cv::absdiff(tile, flipped, diff);
    std::printf("tile vs master mirrored: mean %.2f DN\n", cv::mean(diff)[0]);
    EXPECT_GT(cv::mean(diff)[0], 12.0) << "the tile should not match the page mirrored";
    ++k;
  }
  // The two canvases differ in scale as their dpi do.
  const double a = volume.at("items").at(0).at("service").at(0).at("physicalScale");
  const double b = volume.at("items").at(1).at("service").at(0).at("physicalScale");
  EXPECT_NEAR(b, 25.4 / 200, 1e-12);
  EXPECT_LT(a, b);
}

}  // namespace
