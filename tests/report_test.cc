// The per-scan report as the operator opens it: `vellum process` of the recorded scan writes
// report.html; headless Chromium (Debian's chromium) loads it from disk with no network and
// every picture must load.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <regex>
#include <string>

#include "tests/shell.h"

namespace {

namespace fs = std::filesystem;

TEST(Report, OpensInHeadlessChromiumWithEveryPictureLoaded) {
  const fs::path dir = fs::temp_directory_path() / ("vellum_report_" + std::to_string(getpid()));
  fs::remove_all(dir);
  const std::string tool = VELLUM_BIN;
  int status = 0;
  std::string out =
      vellum::Shell(tool + " export " + VELLUM_LOG + " " + (dir / "scan").string(), &status);
  ASSERT_EQ(status, 0) << out;
  out = vellum::Shell(tool + " process --scan " + (dir / "scan").string() + " --calibration " +
                          (dir / "scan" / "calibration.yaml").string() + " --out " +
                          (dir / "result").string(),
                      &status);
  ASSERT_EQ(status, 0) << out;
  const fs::path html = dir / "result" / "report.html";
  ASSERT_TRUE(fs::exists(html));
  for (const char* picture :
       {"restored.png", "texture.png", "outline.png", "valid.png", "depth.png", "grid.png",
        "strain.png", "before_after.png", "sampling.png"}) {
    const cv::Mat image = cv::imread((dir / "result" / "report" / picture).string());
    EXPECT_FALSE(image.empty()) << picture;
    EXPECT_GT(image.cols, 100) << picture;
  }
  // The page counts the images that loaded into <body data-images="loaded/total">.
  out = vellum::Shell(
      "timeout 120 chromium --headless --no-sandbox --disable-gpu --virtual-time-budget=5000 "
      "--dump-dom file://" +
          html.string(),
      &status);
  ASSERT_EQ(status, 0) << out;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(out, m, std::regex("data-images=\"(\\d+)/(\\d+)\""))) << out;
  EXPECT_EQ(m[1], m[2]) << "only " << m[1] << " of " << m[2] << " pictures loaded";
  // The six of before, the leaf's outline, the whole restored page and
  // the true sampling map.
  EXPECT_EQ(m[2], "9");
  // Nothing in it reaches for the network.
  std::ifstream in(html);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(text.find("http://"), std::string::npos);
  // The quality verdict first, the whole restored page linking to its TIFF, with the
  // leaf's size and the scale bar's length; the report's date.
  EXPECT_NE(text.find("<div class=\"qc qc-pass\"><h2>Quality: pass</h2>"), std::string::npos);
  // The FADGI figures vellum can vouch for, each with its star level.
  EXPECT_TRUE(std::regex_search(
      text, std::regex("<tr><th>sampling</th><td>[0-9]+ ppi at 95% of the page \\(median "
                       "[0-9]+\\)</td><td>(below 1-star|[1-4]-star)</td>")))
      << text.substr(0, 4000);
  EXPECT_NE(text.find("<tr><th>bit depth</th><td>8 bits per channel</td><td>3-star</td>"),
            std::string::npos);
  EXPECT_NE(text.find("<a href=\"restored.tif\"><img src=\"report/restored.png\""),
            std::string::npos);
  EXPECT_TRUE(std::regex_search(text, std::regex("the leaf [0-9.]+ x [0-9.]+ mm, [0-9.]+ ppi; "
                                                 "the scale bar is [0-9]+ mm")))
      << text.substr(0, 3000);
  EXPECT_NE(text.find("Report made 20"), std::string::npos);
  EXPECT_EQ(text.find("https://"), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
