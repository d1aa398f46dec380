// The steps of finding the leaf (steps.h), each on small synthetic maps whose answer is known:
// heights in mm on a grid of 0.25 mm pixels (the default rig's), a texture of known brightness.
#include "core/outline/steps.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>
#include <utility>
#include <vector>

#include "core/sim/gantry.h"

namespace vellum::outline {
namespace {

constexpr double kPixelMm = 0.25;

// A point map of `size` pixels whose height at pixel (u, v) is height(u, v) (NaN: no point), x
// and y the pixel's place in mm, with Gaussian noise of `noise_mm` in z.
cv::Mat Points(cv::Size size, const std::function<double(int, int)>& height, double noise_mm = 0,
               uint64_t seed = 1) {
  cv::Mat points(size, CV_32FC3);
  cv::RNG rng(seed);
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      const double z = height(u, v);
      points.at<cv::Vec3f>(v, u) =
          std::isnan(z)
              ? cv::Vec3f(NAN, NAN, NAN)
              : cv::Vec3f(static_cast<float>(u * kPixelMm), static_cast<float>(v * kPixelMm),
                          static_cast<float>(z + rng.gaussian(noise_mm)));
    }
  }
  return points;
}

// A gray texture of `size` whose level at (u, v) is level(u, v), with 1.5 DN of noise.
cv::Mat Texture(cv::Size size, const std::function<double(int, int)>& level) {
  cv::Mat texture(size, CV_8U);
  cv::RNG rng(2);
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      texture.at<uint8_t>(v, u) = cv::saturate_cast<uint8_t>(level(u, v) + rng.gaussian(1.5));
    }
  }
  return texture;
}

// Everything the cut needs from `points` and `texture`, at the default options.
struct Scene {
  Cues cues;
  Blocks blocks;
  std::vector<Plane> planes;
  cv::Mat above;
};

Scene Prepare(const cv::Mat& points, const cv::Mat& texture) {
  Scene s;
  const OutlineOptions options;
  s.cues = MeasureCues(points, texture, options);
  s.blocks = MakeBlocks(s.cues, points, BlockSize(points.size(), options.blocks_across));
  s.planes = FitSurround(s.blocks, options.surround);
  s.above = AboveSurround(s.blocks, s.planes);
  return s;
}

// The blocks of `blocks` whose centre's pixel `inside` holds.
cv::Mat BlocksWhere(const Blocks& blocks, const std::function<bool(int, int)>& inside) {
  cv::Mat out(blocks.grid, CV_8U, cv::Scalar(0));
  for (int by = 0; by < blocks.grid.height; ++by) {
    for (int bx = 0; bx < blocks.grid.width; ++bx) {
      const int u = bx * blocks.size + blocks.size / 2, v = by * blocks.size + blocks.size / 2;
      out.at<uint8_t>(by, bx) = inside(u, v) ? 255 : 0;
    }
  }
  return out;
}

double IoU(const cv::Mat& a, const cv::Mat& b) {
  const double both = cv::countNonZero(a & b), either = cv::countNonZero(a | b);
  return either > 0 ? both / either : 0;
}

// A step in the surface is a rim; a crease, where the surface bends sharply but goes on, and a
// plane are not. The step is 0.2 mm (a leaf's thickness): strength over 1 (the rim threshold)
// on it; the crease turns 60 degrees (30 each way, a sharp fold): well under it.
TEST(RimStrength, AStepIsARimAndACreaseIsNot) {
  const cv::Size size(120, 40);
  const int step_at = 60;
  const cv::Mat texture(size, CV_8U, cv::Scalar(200));
  const OutlineOptions options;
  auto strongest_near = [&](const cv::Mat& points) {
    const Cues cues = MeasureCues(points, texture, options);
    double strongest = 0;
    cv::minMaxLoc(cues.rim(cv::Rect(step_at - 4, 10, 8, 20)), nullptr, &strongest);
    double elsewhere = 0;
    cv::minMaxLoc(cues.rim(cv::Rect(10, 10, 30, 20)), nullptr, &elsewhere);
    return std::make_pair(strongest, elsewhere);
  };
  const auto step =
      strongest_near(Points(size, [&](int u, int) { return u >= step_at ? 0.2 : 0.0; }));
  EXPECT_GT(step.first, 1.5);
  EXPECT_LT(step.second, 0.1);
  const double slope = std::tan(30 * M_PI / 180) * kPixelMm;  // mm per pixel.
  const auto crease =
      strongest_near(Points(size, [&](int u, int) { return 10 + std::fabs(u - step_at) * slope; }));
  EXPECT_LT(crease.first, 0.5);
  const auto plane =
      strongest_near(Points(size, [&](int u, int v) { return 0.01 * u + 0.02 * v; }));
  EXPECT_LT(plane.first, 0.1);
}

// The surround's planes from the view's outermost measured blocks: a table at z = 0 around a
// board 5 mm high that reaches the view's left and right edges, a leaf 0.2 mm thick in the
// middle (which is not sampled).
TEST(FitSurround, FindsTheTableAndASupportReachingTheViewsEdge) {
  const cv::Size size(400, 300);
  const cv::Mat points = Points(
      size,
      [&](int u, int v) {
        const bool board = v >= 60 && v < 240;
        const bool leaf = board && u >= 150 && u < 250 && v >= 100 && v < 200;
        return leaf ? 5.2 : board ? 5.0 : 0.0;
      },
      0.005);
  const Scene s = Prepare(points, cv::Mat(size, CV_8U, cv::Scalar(120)));
  ASSERT_EQ(s.planes.size(), 2u);
  std::vector<double> heights{s.planes[0].c, s.planes[1].c};
  std::sort(heights.begin(), heights.end());
  EXPECT_NEAR(heights[0], 0.0, 0.01);
  EXPECT_NEAR(heights[1], 5.0, 0.01);
  for (const Plane& p : s.planes) EXPECT_LT(std::hypot(p.a, p.b), 1e-4);
  // Above the nearest: the leaf stands 0.2 mm off the board, the board and the table on theirs.
  const int b = s.blocks.size;
  EXPECT_NEAR(s.above.at<float>(150 / b, 200 / b), 0.2f, 0.01f);
  EXPECT_NEAR(s.above.at<float>(80 / b, 50 / b), 0.0f, 0.01f);
  EXPECT_NEAR(s.above.at<float>(20 / b, 200 / b), 0.0f, 0.01f);
}

// A leaf folded across its middle, turned 45 degrees (a diamond, its fold along the view's
// middle row), on a dark support that gives no heights, the table beyond it in the view's
// corners: the outermost measured blocks of the rows and columns between the corners lie along
// the leaf's edges on its two flat halves, each tilted 6 degrees the other way, and each holds a
// plane's share of the samples. Neither is the surround: table, support and frame lie on one
// another, parallel.
TEST(FitSurround, TakesNoFoldedLeafsHalvesForTheSurround) {
  const cv::Size size(400, 300);
  const double slope = std::tan(6 * M_PI / 180) * kPixelMm;  // mm per pixel.
  const cv::Mat points = Points(
      size,
      [&](int u, int v) {
        const double across = std::abs(u - 200) / 175.0 + std::abs(v - 150) / 145.0;
        if (across <= 1) return 0.2 + (145 - std::abs(v - 150)) * slope;  // The leaf.
        if ((u < 70 || u >= 330) && (v < 70 || v >= 230)) return 0.0;     // The table.
        return std::numeric_limits<double>::quiet_NaN();                  // The support.
      },
      0.005);
  const Scene s = Prepare(points, cv::Mat(size, CV_8U, cv::Scalar(120)));
  ASSERT_EQ(s.planes.size(), 1u);
  EXPECT_NEAR(s.planes[0].c, 0.0, 0.01);
  EXPECT_LT(std::hypot(s.planes[0].a, s.planes[0].b), 1e-4);
  // The angle between planes, by which they were told apart.
  Plane left, right;
  left.a = std::tan(6 * M_PI / 180);
  right.a = -left.a;
  EXPECT_NEAR(TiltBetweenDeg(left, right), 12.0, 1e-9);
  EXPECT_NEAR(TiltBetweenDeg(s.planes[0], left), 6.0, 0.01);
}

// Fitted again over all the surround in view, a plane tilted by its first fit (0.3 mm per metre:
// 0.06 mm across a 200 mm support, which the cut reads as a thin leaf) comes level, and the leaf
// 0.2 mm above it, with the blocks beside it, stays out of the fit.
TEST(RefitSurround, LevelsAPlaneOverAllTheSurroundLeftOfTheLeaf) {
  const cv::Size size(400, 300);
  auto inside = [](int u, int v) { return u >= 150 && u < 250 && v >= 100 && v < 200; };
  const cv::Mat points = Points(
      size, [&](int u, int v) { return 5.0 + (inside(u, v) ? 0.2 : 0.0); }, 0.005);
  const Scene s = Prepare(points, cv::Mat(size, CV_8U, cv::Scalar(120)));
  const cv::Mat leaf = BlocksWhere(s.blocks, inside);
  Plane tilted;
  tilted.b = 3e-4;
  tilted.c = 5.0 - 3e-4 * 37.5;  // Right at the view's middle row (37.5 mm).
  tilted.inliers = 10;
  std::vector<Plane> planes{tilted};
  RefitSurround(s.blocks, leaf, OutlineOptions().surround, &planes);
  ASSERT_EQ(planes.size(), 1u);
  EXPECT_LT(std::hypot(planes[0].a, planes[0].b), 2e-5);
  EXPECT_NEAR(planes[0].c, 5.0, 0.003);
  EXPECT_GT(planes[0].inliers, 10);
  // A plane with fewer blocks on it than it had keeps its fit.
  std::vector<Plane> many{tilted};
  many[0].inliers = 1000000;
  RefitSurround(s.blocks, leaf, OutlineOptions().surround, &many);
  EXPECT_EQ(many[0].b, tilted.b);
}

// A frame taken with the leaf in its window: the plane along what was found is the frame's face,
// judged along its outer outline. The leaf's dark squares, cut out of what was found, lie flush
// on the table; along their edges (more blocks than along the frame's outline) lies the table,
// not the frame, and counted with them the frame's face is not most of the outline.
TEST(PlaneAlongOutline, FindsAFramesFaceAlongItsOuterOutlineNotAlongItsHoles) {
  const cv::Size size(400, 300);
  auto frame = [](int u, int v) {
    const bool outer = u >= 40 && u < 360 && v >= 30 && v < 270;
    return outer && !(u >= 80 && u < 320 && v >= 60 && v < 240);
  };
  auto square = [](int u, int v) {  // The leaf's dark squares, 16 px, 8 px apart.
    return u >= 80 && u < 320 && v >= 60 && v < 240 && (u - 80) % 24 >= 8 && (v - 60) % 24 >= 8;
  };
  const cv::Mat points = Points(
      size, [&](int u, int v) { return frame(u, v) ? 1.0 : 0.0; }, 0.005);
  const Scene s = Prepare(points, cv::Mat(size, CV_8U, cv::Scalar(120)));
  ASSERT_EQ(s.planes.size(), 1u);
  EXPECT_NEAR(s.planes[0].c, 0.0, 0.01);
  const cv::Mat found = BlocksWhere(s.blocks, [&](int u, int v) {
    return u >= 40 && u < 360 && v >= 30 && v < 270 && !square(u, v);
  });
  Plane plane;
  cv::Mat ring;
  int known = 0;
  ASSERT_TRUE(PlaneAlongOutline(s.blocks, found, s.planes, OutlineOptions().surround, &plane, &ring,
                                &known));
  // The face within 0.15 mm of the frame's 1 mm: the outermost blocks straddle the frame's edge
  // (part frame, part table) and draw the fit a little toward the table; the table is 1 mm off.
  EXPECT_NEAR(plane.At(50, 37.5), 1.0, 0.15) << plane.a << " " << plane.b << " " << plane.c;
  EXPECT_LT(std::hypot(plane.a, plane.b), 1e-4);
  EXPECT_EQ(known, -1);  // A new plane.
  // The ring is the frame's outer edge, none of it on the leaf.
  EXPECT_GT(cv::countNonZero(ring), 0);
  EXPECT_EQ(
      cv::countNonZero(ring & BlocksWhere(s.blocks, [&](int u, int v) { return !frame(u, v); })),
      0);

  // The frame known already, fitted from a few blocks and tilted (0.8 mm per metre: 0.03 mm
  // off at the frame's ends, which the cut reads as a thin leaf): the plane along the outline is
  // that one, fitted again level at the frame's face without the outermost blocks, which
  // straddle its edge (within 0.01 mm: twice the blocks' noise, where the first fit was 0.08 mm
  // off).
  Plane tilted;
  tilted.b = 8e-4;
  tilted.c = 1.0 - 8e-4 * 37.5;
  const std::vector<Plane> with_frame{s.planes[0], tilted};
  ASSERT_TRUE(PlaneAlongOutline(s.blocks, found, with_frame, OutlineOptions().surround, &plane,
                                &ring, &known));
  EXPECT_EQ(known, 1);
  EXPECT_NEAR(plane.At(50, 37.5), 1.0, 0.01) << plane.a << " " << plane.b << " " << plane.c;
  EXPECT_LT(std::hypot(plane.a, plane.b), 1e-4);
  // What lies on the table (the lowest known plane) along its outline is no support or frame.
  const cv::Mat on_table = BlocksWhere(
      s.blocks, [&](int u, int v) { return u >= 100 && u < 300 && v >= 80 && v < 220; });
  EXPECT_FALSE(PlaneAlongOutline(s.blocks, on_table, with_frame, OutlineOptions().surround, &plane,
                                 &ring, &known));
}

// One energy over every cue: a leaf is found by its height off the table where it looks like the
// table (0.1 mm, ten times the table's noise), by its look where it lies flush (0 mm: a bright
// leaf on a dark table), and not at all where neither sets it apart (flush and looking alike: the
// cut has nothing to go on, and finds no leaf rather than the table).
TEST(CutLeaf, EachCueAloneFindsTheLeafWhereItSuffices) {
  const cv::Size size(400, 300);
  const cv::Rect leaf(120, 80, 160, 140);
  auto in_leaf = [&](int u, int v) { return leaf.contains(cv::Point(u, v)); };
  struct Case {
    const char* name;
    double rim_mm, leaf_level, table_level;
    bool found;
  } cases[] = {{"raised, alike", 0.1, 150, 150, true},
               {"flush, bright on dark", 0.0, 200, 60, true},
               {"flush, alike", 0.0, 150, 150, false}};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const cv::Mat points = Points(
        size, [&](int u, int v) { return in_leaf(u, v) ? c.rim_mm : 0.0; }, 0.01);
    const cv::Mat texture =
        Texture(size, [&](int u, int v) { return in_leaf(u, v) ? c.leaf_level : c.table_level; });
    const Scene s = Prepare(points, texture);
    const cv::Mat seed = BlocksWhere(
        s.blocks, [&](int u, int v) { return u >= 160 && u < 240 && v >= 120 && v < 180; });
    const Cut cut =
        CutLeaf(s.blocks, s.above, seed, OuterSurround(s.blocks, s.above), cv::Mat(), CutOptions());
    const cv::Mat truth = BlocksWhere(s.blocks, in_leaf);
    if (c.found) {
      EXPECT_GE(IoU(cut.leaf, truth), 0.95);
    } else {
      EXPECT_LT(cv::countNonZero(cut.leaf), cv::countNonZero(truth) / 4);
    }
  }
}

// The cut's outline, a block off, is brought onto the crest of the rims and edges: a leaf whose
// edge is a texture edge and a 0.2 mm step, from a cut 3 pixels too big all round.
TEST(RefineRim, BringsTheCutsOutlineToThePixel) {
  const cv::Size size(200, 160);
  const cv::Rect leaf(51, 41, 98, 78);
  auto in_leaf = [&](int u, int v) { return leaf.contains(cv::Point(u, v)); };
  const cv::Mat points = Points(size, [&](int u, int v) { return in_leaf(u, v) ? 0.2 : 0.0; });
  const cv::Mat texture = Texture(size, [&](int u, int v) { return in_leaf(u, v) ? 200.0 : 80.0; });
  const OutlineOptions options;
  const Cues cues = MeasureCues(points, texture, options);
  const int block = 4;
  cv::Mat cut(size.height / block, size.width / block, CV_8U, cv::Scalar(0));
  cut(cv::Rect(12, 9, 26, 21)).setTo(255);  // Pixels 48..151 x 36..119: 3 to 5 pixels too big.
  const cv::Mat refined =
      RefineRim(BlocksToPixels(cut, block, size), cues, points, {}, Look(), Look(), block, options);
  cv::Mat truth(size, CV_8U, cv::Scalar(0));
  truth(leaf).setTo(255);
  // Within a pixel all round: 98 x 78 px, a pixel more each side is 352 pixels.
  EXPECT_LE(cv::countNonZero(refined ^ truth), 360);
  EXPECT_GE(IoU(refined, truth), 0.95);
}

// Where the cut strays past the leaf's rim by more than a block and the band (a stretch of table
// beside a low rim taken with the leaf), its seeds reach the rim itself; the leaf keeps to its rim
// and does not flood the table beyond it. A 0.15 mm leaf on a table nearly as light as itself
// (its texture edge a tenth of a full one at most; a basin of the table's pattern beside the
// rim), the cut 14 pixels too far out along its whole left side.
TEST(RefineRim, KeepsToTheRimWhereTheCutStraysFarPastIt) {
  const cv::Size size(200, 160);
  const cv::Rect leaf(62, 41, 87, 78);
  auto in_leaf = [&](int u, int v) { return leaf.contains(cv::Point(u, v)); };
  const cv::Mat points = Points(
      size, [&](int u, int v) { return in_leaf(u, v) ? 0.15 : 0.0; }, 0.01);
  const cv::Mat texture = Texture(size, [&](int u, int v) {
    // The table's texture closes a basin beside the rim, as a table's pattern may.
    const bool across = (v == 36 || v == 37 || v == 122 || v == 123) && u >= 50 && u <= 62;
    const bool along = (u == 50 || u == 51) && v >= 36 && v <= 123;
    return in_leaf(u, v) ? 200.0 : across || along ? 166.0 : 196.0;
  });
  const OutlineOptions options;
  const Cues cues = MeasureCues(points, texture, options);
  const int block = 4;
  cv::Mat cut(size.height / block, size.width / block, CV_8U, cv::Scalar(0));
  cut(cv::Rect(12, 10, 26, 20)).setTo(255);  // Pixels 48..151 x 40..119.
  const cv::Mat refined =
      RefineRim(BlocksToPixels(cut, block, size), cues, points, {}, Look(), Look(), block, options);
  cv::Mat truth(size, CV_8U, cv::Scalar(0));
  truth(leaf).setTo(255);
  // Off the leaf: a pixel all round at most (the rim's mixed pixels), where the seeds on the rim
  // took 917; the stray part alone is 1,120.
  EXPECT_LE(cv::countNonZero(refined & ~truth), 340);
  cv::Mat beyond(size, CV_8U, cv::Scalar(0));
  beyond(cv::Rect(48, 40, 12, 80)).setTo(255);  // More than two pixels out from the rim.
  EXPECT_EQ(cv::countNonZero(refined & beyond), 0);
}

// On a dark table the decoder gives heights only here and there: islands of them beside the
// leaf, cut off from the surround's seeds by pixels with no height, stay the table's. A leaf at
// level 200 on a table at 15 of which one pixel in three has a height, the cut's outline a block
// off the leaf's (the islands beyond it).
TEST(RefineRim, LeavesADarkTablesIslandsOfHeightsOut) {
  const cv::Size size(200, 160);
  const cv::Rect leaf(51, 41, 98, 78);
  auto in_leaf = [&](int u, int v) { return leaf.contains(cv::Point(u, v)); };
  cv::RNG rng(7);
  const cv::Mat points = Points(size, [&](int u, int v) {
    return in_leaf(u, v) ? 0.1 : rng.uniform(0.0, 1.0) < 0.33 ? 0.0 : NAN;
  });
  const cv::Mat texture = Texture(size, [&](int u, int v) { return in_leaf(u, v) ? 200.0 : 15.0; });
  const OutlineOptions options;
  const Cues cues = MeasureCues(points, texture, options);
  const int block = 4;
  cv::Mat cut(size.height / block, size.width / block, CV_8U, cv::Scalar(0));
  cut(cv::Rect(13, 10, 25, 20)).setTo(255);  // Pixels 52..151 x 40..119: -1 to 3 pixels out.
  const cv::Mat full = BlocksToPixels(cut, block, size);
  const cv::Mat refined = RefineRim(full, cues, points, {}, Look(), Look(), block, options);
  cv::Mat truth(size, CV_8U, cv::Scalar(0));
  truth(leaf).setTo(255);
  // Nothing more than 5 pixels (1.25 mm) out, under the family's 1.5 mm bar for the restored
  // mask: an island on the texture edge's slope (the edge measured over 2 x 3 pixels) is the
  // crest's, and either flood may take it. The islands beyond reach 121 pixels without the
  // surround's seeds over the table's pixels without a height.
  cv::Mat near_rim;
  cv::dilate(truth, near_rim, cv::Mat::ones(11, 11, CV_8U));
  EXPECT_EQ(cv::countNonZero(refined & ~near_rim), 0);
  EXPECT_GE(IoU(refined, truth), 0.97);
}

// A raised edge's mixed pixels (half leaf, half table) are not the leaf: a plateau 20 mm up
// whose outermost ring of pixels stands at 10 mm loses that ring and no more.
TEST(TrimRim, TakesTheRaisedEdgesMixedPixelsOut) {
  const cv::Size size(100, 100);
  const cv::Rect plateau(20, 20, 60, 60);
  cv::Mat z(size, CV_32F, cv::Scalar(0));
  z(plateau).setTo(20.0f);
  cv::Mat leaf(size, CV_8U, cv::Scalar(0));
  leaf(plateau).setTo(255);
  // Its outermost ring mixed.
  cv::Mat ring = leaf.clone();
  ring(cv::Rect(21, 21, 58, 58)).setTo(0);
  z.setTo(10.0f, ring);
  TrimRim(z, 0.8, &leaf);
  EXPECT_EQ(cv::countNonZero(leaf), 58 * 58);
  EXPECT_EQ(cv::countNonZero(leaf & ring), 0);
}

// A hole that shows the table under the leaf (its heights 0.3 mm below the leaf's) is kept; a
// hole without heights that looks like the leaf (its points lost to ink or a shadow) is filled.
TEST(FillHoles, KeepsAHoleShowingWhatIsUnderAndFillsOneThatShowsNothing) {
  const cv::Size size(200, 200);
  const cv::Point2f real(60, 100), lost(140, 100);
  auto in = [](int u, int v, cv::Point2f c) { return std::hypot(u - c.x, v - c.y) < 15; };
  cv::Mat z(size, CV_32F, cv::Scalar(0.3));
  cv::Mat gray(size, CV_8U, cv::Scalar(200));
  cv::Mat leaf(size, CV_8U, cv::Scalar(255));
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      if (in(u, v, real)) z.at<float>(v, u) = 0.0f, gray.at<uint8_t>(v, u) = 60;
      if (in(u, v, lost)) z.at<float>(v, u) = kNoData;
      if (in(u, v, real) || in(u, v, lost)) leaf.at<uint8_t>(v, u) = 0;
    }
  }
  const OutlineOptions options;
  const cv::Mat threshold = StepThreshold(gray, 200, options.step_mm, options.scale_px, true);
  EXPECT_EQ(FillHoles(z, gray, threshold, 200, &leaf), 1);
  EXPECT_EQ(leaf.at<uint8_t>(cv::Point(real)), 0);
  EXPECT_EQ(leaf.at<uint8_t>(cv::Point(lost)), 255);
}

// Over dark ink one point's rim threshold is several times a leaf's thickness (the decoder's
// noise goes as 1 / brightness), yet the hole's many points show their offset: a burnt hole over
// a dark square showing the table 0.2 mm below is kept, a patch of the same ink whose heights lie
// on the leaf (cut out by its look) is filled, both under the same noise (0.06 mm per point).
TEST(FillHoles, OverDarkInkAHolesOffsetShowsThroughItsPointsNoise) {
  const cv::Size size(200, 200);
  const cv::Point2f real(60, 100), island(140, 100);
  auto in = [](int u, int v, cv::Point2f c) { return std::hypot(u - c.x, v - c.y) < 15; };
  cv::Mat z(size, CV_32F), noise(size, CV_32F);
  cv::RNG rng(7);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, 0.06);
  cv::Mat gray(size, CV_8U, cv::Scalar(230));
  gray(cv::Rect(30, 70, 140, 60)).setTo(20);  // The dark squares both lie in.
  cv::Mat leaf(size, CV_8U, cv::Scalar(255));
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      const bool hole = in(u, v, real);
      z.at<float>(v, u) = (hole ? 0.0f : 0.2f) + noise.at<float>(v, u);
      if (hole || in(u, v, island)) leaf.at<uint8_t>(v, u) = 0;
    }
  }
  const OutlineOptions options;
  const cv::Mat threshold = StepThreshold(gray, 230, options.step_mm, options.scale_px, true);
  ASSERT_GT(threshold.at<float>(cv::Point(real)), 0.4f);  // Over the ink: twice the step and more.
  EXPECT_EQ(FillHoles(z, gray, threshold, 230, &leaf), 1);
  EXPECT_EQ(leaf.at<uint8_t>(cv::Point(real)), 0);
  EXPECT_EQ(leaf.at<uint8_t>(cv::Point(island)), 255);
}

// A leaf flush with the table (no thickness to see): a hole and a mark on the page both lie on
// the table's plane, and the heights cannot tell them. The look does: a hole showing the table
// (its look and brightness) is kept; a patch of the page's own ink, cut out, is filled.
TEST(FillHoles, OnAFlushLeafTheLookTellsAHoleFromTheInk) {
  const cv::Size size(240, 200);
  const cv::Point2f hole(70, 100), mark(170, 100);
  auto in = [](int u, int v, cv::Point2f c) { return std::hypot(u - c.x, v - c.y) < 15; };
  const cv::Rect page(30, 30, 180, 140);
  cv::Mat points(size, CV_32FC3), colour(size, CV_8UC3, cv::Scalar(100, 100, 100));
  cv::Mat z(size, CV_32F, cv::Scalar(0)), leaf(size, CV_8U, cv::Scalar(0));
  cv::RNG rng(3);
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      const float h = static_cast<float>(rng.gaussian(0.02));
      points.at<cv::Vec3f>(v, u) = cv::Vec3f(0.25f * u, 0.25f * v, h);
      z.at<float>(v, u) = h;
      if (!page.contains({u, v})) continue;
      // Paper with lines of ink (gray 40) every 10 rows: the leaf's look has both.
      const uint8_t g = (v % 10 < 3 || in(u, v, mark)) ? 40 : 200;
      colour.at<cv::Vec3b>(v, u) = cv::Vec3b(g, g, g);
      if (in(u, v, hole)) colour.at<cv::Vec3b>(v, u) = cv::Vec3b(100, 100, 100);
      leaf.at<uint8_t>(v, u) = in(u, v, hole) || in(u, v, mark) ? 0 : 255;
    }
  }
  Look leaf_look;
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      if (leaf.at<uint8_t>(v, u)) leaf_look.Add(Look::Bin(colour.at<cv::Vec3b>(v, u)), 1);
    }
  }
  leaf_look.Finish();
  cv::Mat gray;
  cv::cvtColor(colour, gray, cv::COLOR_BGR2GRAY);
  const OutlineOptions options;
  const cv::Mat threshold = StepThreshold(gray, 200, options.step_mm, options.scale_px, true);
  const SurroundLook surround(points, colour, leaf, {Plane()}, leaf_look, options.well_plane_mm,
                              options.well_look);
  cv::Mat without = leaf.clone();
  FillHoles(z, gray, threshold, 200, &without);
  EXPECT_EQ(without.at<uint8_t>(cv::Point(hole)), 255);  // The heights alone fill both.
  EXPECT_EQ(FillHoles(z, gray, threshold, 200, &leaf, &surround), 1);
  EXPECT_EQ(leaf.at<uint8_t>(cv::Point(hole)), 0);
  EXPECT_EQ(leaf.at<uint8_t>(cv::Point(mark)), 255);
}

// Beside a leaf (bright, on a dark table), a strip the camera saw but the scan did not measure
// (a curled edge turned from the projector): counted when it looks like the leaf, four pixels
// or more from it; a strip without heights that looks like the table (a projector's shadow) is
// not, nor is one that does not reach the leaf.
TEST(UnseenBeside, CountsWhatLooksLikeTheLeafBesideItWithoutHeights) {
  const cv::Size size(200, 200);
  cv::Mat colour(size, CV_8UC3, cv::Scalar(40, 40, 40));
  cv::Mat leaf(size, CV_8U, cv::Scalar(0)), measured(size, CV_8U, cv::Scalar(255));
  leaf(cv::Rect(60, 40, 80, 120)).setTo(255);
  colour(cv::Rect(60, 40, 80, 120)).setTo(cv::Scalar(210, 210, 210));
  const cv::Rect wall(40, 40, 20, 120), shadow(140, 40, 16, 120), apart(10, 40, 10, 120);
  colour(wall).setTo(cv::Scalar(200, 200, 200));
  measured(wall).setTo(0);
  measured(shadow).setTo(0);
  measured(apart).setTo(0);
  colour(apart).setTo(cv::Scalar(200, 200, 200));
  Look leaf_look, surround_look;
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      if (!measured.at<uint8_t>(v, u)) continue;
      (leaf.at<uint8_t>(v, u) ? leaf_look : surround_look)
          .Add(Look::Bin(colour.at<cv::Vec3b>(v, u)), 1);
    }
  }
  leaf_look.Finish();
  surround_look.Finish();
  const int counted = UnseenBeside(leaf, measured, colour, leaf_look, surround_look, 64, 1.0);
  // The wall's 20 columns less the 3 nearest the leaf (the rim's mixed pixels), and a pixel of
  // blur around its far side and ends; nothing of the shadow or the strip apart.
  EXPECT_GE(counted, 14 * 120);
  EXPECT_LE(counted, 17 * 120);
}

// On a table of the leaf's own shade the look cannot tell the leaf unmeasured from a shadow; the
// projector's sight can. A slab 25 mm high (x within 20 mm of the table's centre, across the view)
// on the quick rig (about 1 mm per pixel, the projector 225 mm to the left): its shadow on the
// table to its right is unmeasured, and so is its own left end (x below -12 mm, as a curl's edge
// turned from the projector would be). The left end's table points lie in the projector's light
// (had the pixels shown the table, it would have been measured): counted. The shadow's lie behind
// the slab: not counted.
TEST(UnseenBeside, TellsTheLeafUnmeasuredFromItsShadowByTheProjectorsSight) {
  const Calibration rig = QuickRig();
  const cv::Size size = rig.camera.size;
  const cv::Vec3d eye = rig.camera.Center(), projector = rig.projector.Center();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cv::Mat points(size, CV_32FC3, cv::Scalar::all(nan));
  cv::Mat leaf(size, CV_8U, cv::Scalar(0)), measured(size, CV_8U, cv::Scalar(0));
  cv::Mat band(size, CV_8U, cv::Scalar(0)), shadow(size, CV_8U, cv::Scalar(0));
  cv::Mat wall(size, CV_8U, cv::Scalar(0));  // The slab's walls the camera sees, edge-on.
  const cv::Mat colour(size, CV_8UC3, cv::Scalar(150, 150, 150));
  constexpr double kHigh = 25, kHalfX = 20, kHalfY = 1000, kBandTo = -12;
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      const cv::Vec3d ray = rig.camera.RayDirection(cv::Point2d(u, v));
      const cv::Vec3d top = eye + ((kHigh - eye[2]) / ray[2]) * ray;
      const cv::Vec3d table = eye + (-eye[2] / ray[2]) * ray;
      if (std::fabs(top[0]) <= kHalfX && std::fabs(top[1]) <= kHalfY) {
        if (top[0] < kBandTo) {
          band.at<uint8_t>(v, u) = 255;
          continue;
        }
        points.at<cv::Vec3f>(v, u) = cv::Vec3f(top);
        leaf.at<uint8_t>(v, u) = measured.at<uint8_t>(v, u) = 255;
        continue;
      }
      if (std::fabs(table[0]) <= kHalfX && std::fabs(table[1]) <= kHalfY) {  // A wall.
        wall.at<uint8_t>(v, u) = 255;
        continue;
      }
      // In the slab's shadow: the line to the projector meets its right wall below its top.
      const cv::Vec3d to = projector - table;
      const double at = (kHalfX - table[0]) / to[0];
      const cv::Vec3d wall = table + at * to;
      if (table[0] > kHalfX && at > 0 && wall[2] < kHigh && std::fabs(wall[1]) <= kHalfY) {
        shadow.at<uint8_t>(v, u) = 255;
        continue;
      }
      points.at<cv::Vec3f>(v, u) = cv::Vec3f(table);
      measured.at<uint8_t>(v, u) = 255;
    }
  }
  ASSERT_GT(cv::countNonZero(band), 300);
  ASSERT_GT(cv::countNonZero(shadow), 300);
  Look look;  // The leaf's and the table's: one shade.
  look.Add(Look::Bin(cv::Vec3b(150, 150, 150)), 1000);
  look.Finish();
  const std::vector<Plane> planes = {Plane{0, 0, 0}};
  const ProjectorSight sight(rig, points, planes, 0.5);
  EXPECT_EQ(UnseenBeside(leaf, measured, colour, look, look, 40, 1.0), 0);
  const int counted = UnseenBeside(leaf, measured, colour, look, look, 40, 1.0, &sight);
  // The band's pixels four or more from the leaf (its columns but the three nearest), and at most
  // the slab's walls beside it (the slab too), none of the shadow's.
  cv::Mat apart;
  cv::distanceTransform(~leaf, apart, cv::DIST_L1, 3, CV_8U);
  const int far_in_band = cv::countNonZero(band & (apart > 3));
  EXPECT_GE(counted, far_in_band * 9 / 10);
  EXPECT_LE(counted, cv::countNonZero((band | wall) & (apart > 3)));
}

// A leaf lying flat under the camera whose right side rises as a ramp `rise_mm` high at `deg`
// degrees from the table (a curled edge, straightened), on a table at z = 0; points by casting
// the camera's rays. `leaf` gets the leaf's pixels.
cv::Mat RampLeaf(const Calibration& rig, double deg, double rise_mm, cv::Mat* leaf) {
  const cv::Size size = rig.camera.size;
  const cv::Vec3d eye = rig.camera.Center();
  const cv::Vec3d below = rig.camera.RayDirection(cv::Point2d(size.width / 2.0, size.height / 2.0));
  const cv::Vec3d middle = eye + (-eye[2] / below[2]) * below;  // On the table.
  const double slope = std::tan(deg * CV_PI / 180), lies = 0.2;
  const double left = middle[0] - 60, foot = middle[0] + 10, top = foot + rise_mm / slope;
  const double half_y = 50;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cv::Mat points(size, CV_32FC3, cv::Scalar::all(nan));
  *leaf = cv::Mat(size, CV_8U, cv::Scalar(0));
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      const cv::Vec3d ray = rig.camera.RayDirection(cv::Point2d(u, v));
      double nearest = std::numeric_limits<double>::infinity();
      bool on_leaf = false;
      auto hit = [&](double t, bool part_of_leaf, double from_x, double to_x) {
        const cv::Vec3d x = eye + t * ray;
        if (t <= 0 || t >= nearest || x[0] < from_x || x[0] > to_x) return;
        if (part_of_leaf && std::fabs(x[1] - middle[1]) > half_y) return;
        nearest = t;
        on_leaf = part_of_leaf;
      };
      hit((lies - eye[2]) / ray[2], true, left, foot);
      hit((lies - eye[2] + (eye[0] - foot) * slope) / (ray[2] - ray[0] * slope), true, foot, top);
      hit(-eye[2] / ray[2], false, -1e9, 1e9);
      points.at<cv::Vec3f>(v, u) = cv::Vec3f(eye + nearest * ray);
      leaf->at<uint8_t>(v, u) = on_leaf ? 255 : 0;
    }
  }
  return points;
}

// A leaf whose side rises 30 mm at 80 degrees is seen edge-on along that side (a third of its
// outline: the side is 100 mm of about 300); one rising as high at 45 degrees is not, and an edge
// lower than the height asked for is not counted however steep.
TEST(EdgeOnShare, FindsTheSideRisingSteeplyOffTheTable) {
  const Calibration rig = QuickRig();
  const std::vector<Plane> table = {Plane{0, 0, 0}};
  cv::Mat leaf;
  const cv::Mat steep = RampLeaf(rig, 80, 30, &leaf);
  ASSERT_GT(cv::countNonZero(leaf), 5000);
  const double share = EdgeOnShare(leaf, steep, table, rig.camera, 5, 73, 6);
  EXPECT_GT(share, 0.2);
  EXPECT_LT(share, 0.45);
  EXPECT_LT(EdgeOnShare(leaf, steep, table, rig.camera, 40, 73, 6), 0.01);
  const cv::Mat gentle = RampLeaf(rig, 45, 30, &leaf);
  EXPECT_LT(EdgeOnShare(leaf, gentle, table, rig.camera, 5, 73, 6), 0.01);
}

// A text page (paper 200 DN, lines of ink 60 DN) on a table a shade darker (184 DN, 8% of the
// paper). The outline of the page itself is set apart by its look all round; an outline drawn
// through the page (its lower half taken for the table, as a flush leaf's curl alone would be)
// is not, along the cut through the text, though the text's ink gives texture edges there.
TEST(LookApart, TellsTheLeafsEdgeFromACutThroughItsText) {
  const cv::Size size(240, 240);
  const cv::Rect page(40, 40, 160, 160);
  const cv::Mat gray = Texture(size, [&](int u, int v) {
    if (!page.contains({u, v})) return 184.0;
    const bool line = (v - 48) % 12 < 5 && (u * 7 + v * 3) % 11 < 6;  // Words of ink.
    return line && v > 46 && v < 192 && u > 48 && u < 192 ? 60.0 : 200.0;
  });
  cv::Mat whole(size, CV_8U, cv::Scalar(0));
  whole(page).setTo(255);
  const OutlineOptions options;
  const double bright = 200;
  auto share = [&](const cv::Mat& leaf, const cv::Rect& part) {
    cv::Mat eroded;
    cv::erode(leaf, eroded, cv::Mat());
    const cv::Mat rim = (leaf & ~eroded)(part);
    const cv::Mat apart =
        LookApart(leaf, gray, bright, options.rim_look_px, options.rim_look_contrast)(part);
    return static_cast<double>(cv::countNonZero(rim & apart)) / std::max(1, cv::countNonZero(rim));
  };
  EXPECT_GE(share(whole, cv::Rect(0, 0, 240, 240)), 0.98);
  // The upper half only: its three sides on the table are apart, its lower side through the text
  // (rows 119 and 120 of the page, inside the lines of ink) is not.
  cv::Mat half(size, CV_8U, cv::Scalar(0));
  half(cv::Rect(40, 40, 160, 80)).setTo(255);
  EXPECT_GE(share(half, cv::Rect(0, 0, 240, 110)), 0.98);
  EXPECT_LE(share(half, cv::Rect(50, 110, 140, 20)), 0.05);
  // Yet the texture's edges lie along the cut: the cue the rim's confidence took before.
  cv::Mat gx;
  cv::Sobel(gray, gx, CV_32F, 0, 1);
  EXPECT_GT(cv::countNonZero(cv::abs(gx(cv::Rect(50, 116, 140, 8))) > 200), 100);
}

TEST(SplitAtGutter, FindsAValleyAndWhatSaysItIsABooksGutter) {
  const cv::Size size(800, 300);  // 200 x 75 mm.
  const int middle = 400;
  const double slope = std::tan(30 * M_PI / 180) * kPixelMm;
  const OutlineOptions options;
  cv::Mat leaf(size, CV_8U, cv::Scalar(0));
  leaf(cv::Rect(40, 30, 720, 240)).setTo(255);
  struct Case {
    const char* name;
    std::function<double(int, int)> height;
    int gap_px;
    bool split, parted, bound;
  } cases[] = {
      {"gap", [&](int u, int) { return std::fabs(u - middle) * slope; }, 8, true, true, false},
      {"meeting", [&](int u, int) { return std::fabs(u - middle) * slope; }, 0, true, false, false},
      // A gap of 4 mm whose walls' feet stand level to 0.05 mm, one higher in a row and the other
      // in the next: the rows' lowest points fall on either wall, and the valley runs between.
      {"wide gap",
       [&](int u, int v) {
         return std::fabs(u - middle) * slope + (((v / 4) % 2 == 0) == (u > middle) ? 0.05 : 0.0);
       },
       16, true, true, false},
      {"bound",  // Rising 62 degrees out of the gutter, level 15 mm above it by 30 mm out.
       [&](int u, int) { return 15 * (1 - std::exp(-std::fabs(u - middle) * kPixelMm / 8)); }, 0,
       true, false, true},
      {"trough",
       [&](int u, int) {
         const double x = (u - middle) * kPixelMm;
         return 100 - std::sqrt(100.0 * 100 - x * x);
       },
       0, false, false, false}};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    cv::Mat mask = leaf.clone();
    if (c.gap_px > 0) mask.colRange(middle - c.gap_px / 2, middle + c.gap_px / 2).setTo(0);
    const cv::Mat points = Points(size, c.height);
    cv::Mat zn;
    const cv::Mat z = SmoothHeights(points, &zn);
    cv::Vec4f line;
    cv::Mat left, right;
    GutterSigns signs;
    const bool split = SplitAtGutter(points, z, mask, options, &line, &left, &right, &signs);
    EXPECT_EQ(split, c.split);
    if (!split) continue;
    EXPECT_EQ(signs.parted, c.parted);
    EXPECT_EQ(signs.bound, c.bound);
    EXPECT_NEAR(line[2] + (150 - line[3]) * line[0] / line[1], middle, 6);  // The gutter's column.
    EXPECT_EQ(cv::countNonZero(left & right), 0);
    // The pages cover the leaf but for the pixels that belong to both, left out of both: the
    // column either side of a gap (seen at a grazing angle down the gutter, those pixels' points
    // mix both walls), or, where the pages meet, the pixels within 1.5 px of the gutter's line.
    EXPECT_EQ(cv::countNonZero((left | right) & ~mask), 0);
    const cv::Mat left_out = mask & ~(left | right);
    cv::Mat both(size, CV_8U, cv::Scalar(0));
    if (c.gap_px > 0) {
      both(cv::Rect(middle - c.gap_px / 2 - 1, 30, 1, 240)).setTo(255);
      both(cv::Rect(middle + c.gap_px / 2, 30, 1, 240)).setTo(255);
      EXPECT_EQ(cv::countNonZero(left_out ^ both), 0);
    } else {
      both(cv::Rect(middle - 3, 30, 6, 240)).setTo(255);
      EXPECT_EQ(cv::countNonZero(left_out & ~both), 0);
      EXPECT_GE(cv::countNonZero(left_out), 2 * 240);
      EXPECT_LE(cv::countNonZero(left_out), 3 * 240);
    }
  }
}

}  // namespace
}  // namespace vellum::outline

namespace vellum {
namespace {

// Every threshold of finding the leaf is an option with its unit, and Check() refuses a value
// out of its range (FindLeaf then fails with the reason instead of finding a wrong leaf).
// A leaf (light, with dark lines of text) on a dark table, its outline stopping 20 px short of
// the right edge of a 300 x 200 view. Where the leaf runs on to the edge (its look there, the
// text too), the rows it runs on along are counted; where the table lies between (a 20 px
// gap), or a light mount of its own, grey look that lies beside the leaf on its other sides
// too, nothing is. Asymmetric on purpose: only the right side is near the leaf.
TEST(MeanColour3x3, IsMean3x3AtEveryPixelOfTheBoxEdgesAndCornersToo) {
  cv::RNG rng(7);
  for (const cv::Size size :
       {cv::Size(1, 1), cv::Size(1, 5), cv::Size(6, 1), cv::Size(2, 2), cv::Size(37, 23)}) {
    cv::Mat colour(size, CV_8UC3);
    rng.fill(colour, cv::RNG::UNIFORM, 0, 256);
    const cv::Rect whole(0, 0, size.width, size.height);
    // The whole image, an inner box, a box hanging over the image's corner (clipped to it).
    for (const cv::Rect box :
         {whole, cv::Rect(1, 1, size.width - 2, size.height - 2),
          cv::Rect(size.width / 2, size.height / 2, size.width, size.height)}) {
      const cv::Rect in = box & whole;
      const cv::Mat mean = outline::MeanColour3x3(colour, box);
      ASSERT_EQ(mean.size(), in.size());
      for (int v = 0; v < in.height; ++v) {
        for (int u = 0; u < in.width; ++u) {
          ASSERT_EQ(mean.at<cv::Vec3b>(v, u), outline::Mean3x3(colour, in.x + u, in.y + v))
              << size << " box " << box << " at " << u << "," << v;
        }
      }
    }
  }
}

TEST(LookRunsOff, CountsTheLeafsLookRunningOnToTheEdgeAndNotATableOrAMount) {
  const cv::Size size(300, 200);
  const cv::Scalar paper(200, 215, 225), table(50, 50, 50), mount(170, 170, 170);
  auto scene = [&](const cv::Scalar& beyond) {
    cv::Mat colour(size, CV_8UC3, table);
    colour(cv::Rect(100, 40, 200, 120)).setTo(paper);  // The leaf, to the right edge...
    colour(cv::Rect(280, 40, 20, 120)).setTo(beyond);  // ...or what lies past its outline.
    for (int v = 50; v < 150; v += 12) colour(cv::Rect(110, v, 190, 3)).setTo(table);  // Text.
    // The mount on the leaf's other sides too, when there is one (what lies beside it).
    if (beyond == mount) {
      colour(cv::Rect(60, 10, 240, 30)).setTo(mount);
      colour(cv::Rect(60, 160, 240, 30)).setTo(mount);
      colour(cv::Rect(60, 40, 40, 120)).setTo(mount);
    }
    return colour;
  };
  cv::Mat leaf(size, CV_8U, cv::Scalar(0));
  leaf(cv::Rect(100, 40, 180, 120)).setTo(255);  // The outline, 20 px short of the edge.
  // reach 60 px, min_look 1 nat.
  const int runs_on = outline::LookRunsOff(leaf, scene(paper), 2, 60, 1.0);
  // The leaf's 120 rows (the text's bridged by the paper beside it), and up to two more at
  // either end, where the 3 x 3 mean and a bridged gap of one reach past it.
  EXPECT_GE(runs_on, 110);
  EXPECT_LE(runs_on, 124);
  EXPECT_EQ(outline::LookRunsOff(leaf, scene(table), 2, 60, 1.0), 0);
  EXPECT_EQ(outline::LookRunsOff(leaf, scene(mount), 2, 60, 1.0), 0);
  // Far from every edge (reach 10 px): not looked at.
  EXPECT_EQ(outline::LookRunsOff(leaf, scene(paper), 2, 10, 1.0), 0);
}

TEST(OutlineOptions, CheckRefusesEachThresholdOutOfItsRange) {
  std::string why;
  ASSERT_TRUE(OutlineOptions().Check(&why)) << why;
  const std::vector<std::pair<const char*, std::function<void(OutlineOptions*)>>> bad = {
      {"step_mm", [](OutlineOptions* o) { o->step_mm = 0; }},
      {"band_px", [](OutlineOptions* o) { o->band_px = -1; }},
      {"well_plane_mm", [](OutlineOptions* o) { o->well_plane_mm = 0; }},
      {"well_depth_mm", [](OutlineOptions* o) { o->well_depth_mm = -1; }},
      {"well_look", [](OutlineOptions* o) { o->well_look = NAN; }},
      {"trim_off_mm", [](OutlineOptions* o) { o->trim_off_mm = 0; }},
      {"lies_on_mm", [](OutlineOptions* o) { o->lies_on_mm = -0.01; }},
      {"lies_on_apart", [](OutlineOptions* o) { o->lies_on_apart = 1.5; }},
      {"raised_plane_mm", [](OutlineOptions* o) { o->raised_plane_mm = 0; }},
      {"wider_support_share", [](OutlineOptions* o) { o->wider_support_share = 1.5; }},
      {"unseen_reach_px", [](OutlineOptions* o) { o->unseen_reach_px = 0; }},
      {"off_view_reach_share", [](OutlineOptions* o) { o->off_view_reach_share = 0; }},
      {"off_view_share", [](OutlineOptions* o) { o->off_view_share = 2; }},
      {"unseen_look", [](OutlineOptions* o) { o->unseen_look = -1; }},
      {"max_unseen_share", [](OutlineOptions* o) { o->max_unseen_share = 2; }},
      {"max_lost_share", [](OutlineOptions* o) { o->max_lost_share = -0.1; }},
      {"edge_on_height_mm", [](OutlineOptions* o) { o->edge_on_height_mm = -1; }},
      {"edge_on_deg", [](OutlineOptions* o) { o->edge_on_deg = 90; }},
      {"edge_on_band_px", [](OutlineOptions* o) { o->edge_on_band_px = 3; }},
      {"max_edge_on_share", [](OutlineOptions* o) { o->max_edge_on_share = 1.5; }},
      {"gutter_apart_px", [](OutlineOptions* o) { o->gutter_apart_px = 0; }},
      {"gutter_borrow_rows", [](OutlineOptions* o) { o->gutter_borrow_rows = 0; }},
      {"gutter_meet_px", [](OutlineOptions* o) { o->gutter_meet_px = -1; }},
      {"surround", [](OutlineOptions* o) { o->surround.tolerance_mm = 0; }},
      {"cut", [](OutlineOptions* o) { o->cut.thickness_mm = 0; }},
  };
  const cv::Mat points(64, 64, CV_32FC3, cv::Scalar(0, 0, 0));
  const cv::Mat texture(64, 64, CV_8U, cv::Scalar(128));
  for (const auto& [name, spoil] : bad) {
    OutlineOptions options;
    spoil(&options);
    why.clear();
    EXPECT_FALSE(options.Check(&why)) << name;
    const Outline found = FindLeaf(points, texture, options);
    EXPECT_FALSE(found.status.ok()) << name;
    EXPECT_NE(found.status.message().find("outline options"), std::string::npos)
        << name << ": " << found.status.message();
  }
}

}  // namespace
}  // namespace vellum

namespace vellum {
namespace {

// A leaf hint is a box inside the view covering at most max_view_share of it; FindLeaf refuses
// any other, naming it, whatever path it came by.
TEST(LeafHintFits, ABoxInsideTheLeafFitsAndTheWholeViewOrOffItDoesNot) {
  const cv::Size view(640, 480);
  std::string why;
  EXPECT_TRUE(LeafHintFits(cv::Rect(200, 150, 240, 180), view, 0.85, &why)) << why;
  EXPECT_FALSE(LeafHintFits(cv::Rect(0, 0, 640, 480), view, 0.85, &why));
  EXPECT_NE(why.find("covers 100%"), std::string::npos) << why;
  for (const cv::Rect& off : {cv::Rect(700, 10, 20, 20), cv::Rect(-1, 0, 20, 20),
                              cv::Rect(630, 0, 20, 20), cv::Rect(0, 0, 2000000000, 2000000000)}) {
    EXPECT_FALSE(LeafHintFits(off, view, 0.85, &why)) << off;
    EXPECT_NE(why.find("not a box inside the 640x480"), std::string::npos) << why;
  }
  OutlineOptions options;
  options.hint = cv::Rect(0, 0, 64, 64);
  const Outline found = FindLeaf(cv::Mat(64, 64, CV_32FC3, cv::Scalar(0, 0, 0)),
                                 cv::Mat(64, 64, CV_8U, cv::Scalar(128)), options);
  ASSERT_FALSE(found.status.ok());
  EXPECT_NE(found.status.message().find("leaf hint 0,0,64,64"), std::string::npos)
      << found.status.message();
}

}  // namespace
}  // namespace vellum
