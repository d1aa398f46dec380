#include "core/patterns/patterns.h"

#include <gtest/gtest.h>

#include <limits>
#include <set>

#include "core/patterns/display_lag.h"
#include "core/patterns/scan.h"

namespace vellum {
namespace {

// The scan's folder is named after what is scanned, safely on any file system.
TEST(ScanIdentity, SlugIsReadableAndSafe) {
  ScanIdentity id;
  EXPECT_EQ(IdentitySlug(id), "");
  id.label = "from vellum-viewer";
  EXPECT_EQ(IdentitySlug(id), "from-vellum-viewer");  // The label only without the others.
  id.shelfmark = "MS 12";
  id.folio = "3";
  id.side = "recto";
  EXPECT_EQ(IdentitySlug(id), "MS-12_3_recto");
  EXPECT_EQ(IdentityTitle(id), "MS 12, 3 recto");
  id.shelfmark = "Cotton MS Otho A. VI, f. 12";
  id.folio = "12";
  id.side = "";
  EXPECT_EQ(IdentitySlug(id), "Cotton-MS-Otho-A.-VI-f.-12_12");
  // No path, no hidden file, no control or non-ASCII character, bounded.
  id = ScanIdentity();
  id.shelfmark = "../../etc/passwd";
  id.folio = "..";
  id.side = "\x01verso\n";
  EXPECT_EQ(IdentitySlug(id), "etc-passwd_verso");
  id.shelfmark = "\xce\x9c\xce\xa3 5 /\\ :*?\"<>|";  // Greek letters and Windows' forbidden set.
  id.folio = id.side = "";
  EXPECT_EQ(IdentitySlug(id), "5");
  id.shelfmark = std::string(300, 'a');
  EXPECT_EQ(IdentitySlug(id).size(), kMaxSlug);
  id.shelfmark = std::string(kMaxSlug - 1, 'a') + " b";
  EXPECT_EQ(IdentitySlug(id), std::string(kMaxSlug - 1, 'a'));  // Never ends in '-'.
}

// A sequence of scans: recto, verso, next recto...; pages (no side) count up; the folio's last
// number is the one that counts ("f. 12a" has none after its letter: "12" is it).
TEST(ScanIdentity, NextFolioRunsRectoVersoThenTheNextFolio) {
  ScanIdentity id;
  id.shelfmark = "MS 12";
  id.folio = "3";
  id.side = "recto";
  id = NextFolio(id);
  EXPECT_EQ(id.folio, "3");
  EXPECT_EQ(id.side, "verso");
  id = NextFolio(id);
  EXPECT_EQ(id.folio, "4");
  EXPECT_EQ(id.side, "recto");
  EXPECT_EQ(id.shelfmark, "MS 12");
  id.folio = "f. 99";
  id.side = "verso";
  EXPECT_EQ(NextFolio(id).folio, "f. 100");
  id.folio = "12a";
  EXPECT_EQ(NextFolio(id).folio, "13a");
  id.side = "";  // Pages of a printed book, or the openings of a spread.
  id.folio = "p. 109";
  EXPECT_EQ(NextFolio(id).folio, "p. 110");
  EXPECT_EQ(NextFolio(id).side, "");
  id.folio = "flyleaf";
  EXPECT_EQ(NextFolio(id).folio, "flyleaf");
}

// A spread names its opening: "2v-3r" (foliated) turns to "3v-4r", "14-15" (paginated) to
// "16-17", across a carry; each page gets its own folio and side. A folio that is not an
// opening keeps its text, with the page as its side.
TEST(ScanIdentity, ASpreadTurnsToTheNextOpeningAndEachPageHasItsOwnFolio) {
  ScanIdentity id;
  id.shelfmark = "MS 12";
  id.folio = "2v-3r";
  EXPECT_EQ(NextFolio(id).folio, "3v-4r");
  EXPECT_EQ(NextFolio(id).side, "");
  EXPECT_EQ(PageIdentity(id, "left").folio, "2");
  EXPECT_EQ(PageIdentity(id, "left").side, "verso");
  EXPECT_EQ(PageIdentity(id, "right").folio, "3");
  EXPECT_EQ(PageIdentity(id, "right").side, "recto");
  EXPECT_EQ(PageIdentity(id, "right").shelfmark, "MS 12");
  id.folio = "9v-10r";
  EXPECT_EQ(NextFolio(id).folio, "10v-11r");
  id.folio = "14-15";
  EXPECT_EQ(NextFolio(id).folio, "16-17");
  EXPECT_EQ(PageIdentity(id, "left").folio, "14");
  EXPECT_EQ(PageIdentity(id, "left").side, "left");
  EXPECT_EQ(PageIdentity(id, "right").folio, "15");
  id.folio = "p. 98-p. 99";
  EXPECT_EQ(NextFolio(id).folio, "p. 100-p. 101");
  id.folio = "frontispiece";
  EXPECT_EQ(NextFolio(id).folio, "frontispiece");
  EXPECT_EQ(PageIdentity(id, "right").folio, "frontispiece");
  EXPECT_EQ(PageIdentity(id, "right").side, "right");
}

TEST(Patterns, SequenceLayoutFor1024x768) {
  const PatternSequence seq = MakePatternSequence(PatternOptions());
  std::string why;
  ASSERT_TRUE(seq.Check(&why)) << why;
  EXPECT_EQ(seq.GrayBits(Axis::kColumn), 10);
  EXPECT_EQ(seq.GrayBits(Axis::kRow), 10);
  // White, black, 2 x 10 x 2 Gray, 2 x 8 phase.
  EXPECT_EQ(seq.patterns.size(), 2u + 40u + 16u);
  EXPECT_EQ(seq.patterns[0].kind, PatternKind::kWhite);
  EXPECT_EQ(seq.patterns[1].kind, PatternKind::kBlack);
}

TEST(Patterns, GrayBitsForNonPowersOfTwo) {
  EXPECT_EQ(GrayBitsFor(1024), 10);
  EXPECT_EQ(GrayBitsFor(1025), 11);
  EXPECT_EQ(GrayBitsFor(854), 10);
  EXPECT_EQ(GrayBitsFor(480), 9);
  EXPECT_EQ(GrayBitsFor(800), 10);
  EXPECT_EQ(GrayBitsFor(1280), 11);
}

// Every projector column and row of odd sizes gets its own code, and neighbours differ in
// exactly one bit (the Gray property that bounds boundary errors to one pixel).
TEST(Patterns, EveryColumnAndRowHasAUniqueGrayCode) {
  for (cv::Size size : {cv::Size(1280, 800), cv::Size(854, 480), cv::Size(37, 5)}) {
    PatternOptions o;
    o.projector_size = size;
    const PatternSequence seq = MakePatternSequence(o);
    for (Axis axis : {Axis::kColumn, Axis::kRow}) {
      const int extent = axis == Axis::kColumn ? size.width : size.height;
      std::vector<int> code(extent, 0);
      for (int bit = 0; bit < seq.GrayBits(axis); ++bit) {
        const cv::Mat on =
            RenderPattern(seq.patterns[seq.Find(PatternKind::kGray, axis, bit, false)], size);
        const cv::Mat off =
            RenderPattern(seq.patterns[seq.Find(PatternKind::kGray, axis, bit, true)], size);
        for (int c = 0; c < extent; ++c) {
          const cv::Point p =
              axis == Axis::kColumn ? cv::Point(c, size.height / 2) : cv::Point(size.width / 2, c);
          ASSERT_NE(on.at<uint8_t>(p), off.at<uint8_t>(p)) << "inverse must differ";
          code[c] |= (on.at<uint8_t>(p) > 0) << bit;
        }
      }
      std::set<int> unique(code.begin(), code.end());
      EXPECT_EQ(static_cast<int>(unique.size()), extent) << size << " " << ToString(axis);
      for (int c = 1; c < extent; ++c) {
        EXPECT_EQ(__builtin_popcount(code[c] ^ code[c - 1]), 1);
      }
    }
  }
}

TEST(Patterns, PhaseSinusoidHasTheStatedPeriodAndShift) {
  PatternSpec s;
  s.kind = PatternKind::kPhase;
  s.axis = Axis::kColumn;
  s.steps = 8;
  s.step = 2;
  s.period_px = 16;
  const cv::Mat img = RenderPattern(s, {64, 4});
  // 2 pi c / 16 - 2 pi 2 / 8 = 0 at c = 4: the maximum.
  EXPECT_EQ(img.at<uint8_t>(0, 4), 255);
  EXPECT_EQ(img.at<uint8_t>(0, 4 + 16), 255);
  EXPECT_EQ(img.at<uint8_t>(0, 12), 0);
}

TEST(Patterns, OptionsCheckRejectsBadValues) {
  std::string why;
  PatternOptions o;
  o.phase_steps = 2;
  EXPECT_FALSE(o.Check(&why));
  o = PatternOptions();
  o.phase_period_px = 3;
  EXPECT_FALSE(o.Check(&why));
  o = PatternOptions();
  o.columns = o.rows = false;
  EXPECT_FALSE(o.Check(&why));
}

TEST(Patterns, SequenceCheckFindsAMissingInverse) {
  PatternSequence seq = MakePatternSequence(PatternOptions());
  seq.patterns.erase(seq.patterns.begin() + seq.Find(PatternKind::kGray, Axis::kRow, 3, true));
  std::string why;
  EXPECT_FALSE(seq.Check(&why));
  EXPECT_NE(why.find("bit 3"), std::string::npos) << why;
}

// Other rigs' sequences: without inverses, without the finest bits; what cannot decode is
// refused with the reason.
TEST(Patterns, SequencesWithoutInversesOrFinestBitsAreValid) {
  PatternOptions o;
  o.gray_inverses = false;
  o.gray_skip_bits = 2;
  std::string why;
  ASSERT_TRUE(o.Check(&why)) << why;
  const PatternSequence seq = MakePatternSequence(o);
  ASSERT_TRUE(seq.Check(&why)) << why;
  EXPECT_EQ(seq.GrayBits(Axis::kColumn), 10);
  EXPECT_EQ(seq.FirstGrayBit(Axis::kColumn), 2);
  EXPECT_FALSE(seq.GrayInverses(Axis::kColumn));
  EXPECT_EQ(seq.Find(PatternKind::kGray, Axis::kColumn, 1, false), -1);
  // White, black, 2 x 8 Gray bits, 2 x 8 phase.
  EXPECT_EQ(seq.patterns.size(), 2u + 2 * 8 + 2 * 8);
  // Stripes of 8 px cannot unwrap a 16 px period (the Gray code must place the phase within
  // 0.4 of a period).
  o.gray_skip_bits = 3;
  EXPECT_FALSE(o.Check(&why));
  PatternSequence coarse = MakePatternSequence(PatternOptions());
  for (int bit : {0, 1, 2}) {
    for (bool inverted : {false, true}) {
      coarse.patterns.erase(coarse.patterns.begin() +
                            coarse.Find(PatternKind::kGray, Axis::kColumn, bit, inverted));
    }
  }
  EXPECT_FALSE(coarse.Check(&why));
  EXPECT_NE(why.find("cannot unwrap"), std::string::npos) << why;
}

// A scan.yaml claiming an absurd projector is refused at once (GrayBitsFor and Check never loop
// over it).
TEST(Patterns, AnAbsurdProjectorIsRefusedAtOnce) {
  EXPECT_EQ(GrayBitsFor(1 << 30), 30);
  EXPECT_EQ(GrayBitsFor(std::numeric_limits<int>::max()), 31);
  PatternSequence seq = MakePatternSequence(PatternOptions());
  seq.projector_size = cv::Size(1 << 30, 768);
  std::string why;
  EXPECT_FALSE(seq.Check(&why));
  EXPECT_NE(why.find("above 65536"), std::string::npos) << why;
  seq.projector_size = cv::Size(std::numeric_limits<int>::max(), 768);
  EXPECT_FALSE(seq.Check(&why));
  seq = MakePatternSequence(PatternOptions());
  seq.patterns[5].bit = 40;
  EXPECT_FALSE(seq.Check(&why));
  EXPECT_NE(why.find("out of range"), std::string::npos) << why;
  // A phase period whose double overflowed an int (found by fuzz/fuzz_files).
  seq = MakePatternSequence(PatternOptions());
  for (PatternSpec& s : seq.patterns) {
    if (s.kind == PatternKind::kPhase) s.period_px = 2000000000;
  }
  EXPECT_FALSE(seq.Check(&why));
  EXPECT_NE(why.find("period of 2000000000 px is out of range"), std::string::npos) << why;
}

// Flashes on a display whose image reaches the page `lag_ms` after vsync, seen by a linear
// camera exposing `exposure_ms` of each 33.3 ms frame, its frames' phase against the flashes
// drifting from flash to flash (as two free-running clocks do): white 200, black 20.
std::vector<FlashFrames> Flashes(double lag_ms, double exposure_ms, int count) {
  std::vector<FlashFrames> flashes;
  const double period = 1000.0 / 30;
  for (int i = 0; i < count; ++i) {
    FlashFrames f;
    f.handed_us = 1000000LL * (i + 1);
    f.white = i % 2 == 0;
    f.exposure_us = static_cast<int64_t>(1000 * exposure_ms);
    const double phase = period * ((i * 5) % 12) / 12;
    for (double t = -phase; t < 150; t += period) {
      // The share of the exposure after the change, as the camera integrates it.
      const double share = exposure_ms > 0
                               ? std::clamp((t + exposure_ms - lag_ms) / exposure_ms, 0.0, 1.0)
                               : (t >= lag_ms ? 1.0 : 0.0);
      const double seen = f.white ? share : 1 - share;
      f.start_us.push_back(f.handed_us + static_cast<int64_t>(1000 * t));
      f.level.push_back(20 + 180 * seen);
    }
    flashes.push_back(f);
  }
  return flashes;
}

TEST(DisplayLag, IsReadOffTheFramesTheChangeFellWithinInMillisecondsAndRefreshes) {
  for (double lag : {0.0, 16.7, 33.3, 50.0}) {
    const DisplayLag d = EstimateDisplayLag(Flashes(lag, 10, 12), 60);
    ASSERT_TRUE(d.status.ok()) << d.status.message();
    EXPECT_NEAR(d.median_ms, lag, 0.01) << d.Describe();
    EXPECT_NEAR(d.refreshes(), lag * 60 / 1000, 0.001);
    EXPECT_GE(d.exact, 3) << d.Describe();  // The change falls within 10 ms of each 33.3.
    EXPECT_NEAR(d.wait_ms, lag + 1, 0.01);  // The slowest flash and a millisecond.
    EXPECT_EQ(d.seen, 12);
  }
  // Without the exposure's length, frames before and after the change bound it: the wait
  // covers the lag.
  const DisplayLag bounds = EstimateDisplayLag(Flashes(33.3, 0, 8), 60);
  ASSERT_TRUE(bounds.status.ok()) << bounds.status.message();
  EXPECT_EQ(bounds.exact, 0);
  EXPECT_GE(bounds.wait_ms, 33.3);
  EXPECT_LE(bounds.wait_ms, 33.3 + 1000.0 / 30 + 1);
  EXPECT_NE(bounds.Describe().find("at most"), std::string::npos) << bounds.Describe();
  // A camera that does not see the projector: refused, saying so.
  std::vector<FlashFrames> dark = Flashes(33.3, 10, 8);
  for (FlashFrames& f : dark) std::fill(f.level.begin(), f.level.end(), 21.0);
  const DisplayLag none = EstimateDisplayLag(dark, 60);
  ASSERT_FALSE(none.status.ok());
  EXPECT_NE(none.status.message().find("the camera saw no flash"), std::string::npos);
}

}  // namespace
}  // namespace vellum
