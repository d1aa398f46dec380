// Reflectance from the projector's light on the virtual gantry, with the projector's
// fall-off (inverse square, vignetting 0.3 at the image's corners) and two studio lamps that
// shade the texture as real ones do. The flat field is measured once on a white target lying
// on the table; each page's albedo is then compared with the truth the gantry put on it.
#include "core/shading/albedo.h"

#include <gtest/gtest.h>

#include <cstdio>

#include "core/decode/decode.h"
#include "core/geometry/triangulate.h"
#include "core/outline/outline.h"
#include "core/sim/evaluate.h"

namespace vellum {
namespace {

LightOptions RealLight() {
  LightOptions light;
  light.projector_falloff = true;
  light.studio_lamps = {cv::Vec3d(-450, -250, 500), cv::Vec3d(450, -250, 500)};
  return light;
}

struct Measured {
  SimulatedScan scan;
  DecodeResult decoded;
  cv::Mat points;
};

Measured Scan(const PageOptions& page, const TextureOptions& texture, uint64_t seed) {
  Measured m;
  m.scan = SimulateScan(DefaultRig(), page, texture, SceneOptions(), seed, RealLight());
  m.decoded = Decode(m.scan.sequence, m.scan.frames);
  m.points = Triangulator(DefaultRig()).Triangulate(m.decoded).points;
  return m;
}

// The albedo of the scan's leaf (found by its shape, as the pipeline finds it).
AlbedoResult AlbedoOfLeaf(const Measured& m, const FlatField& field) {
  const Outline leaf = FindLeaf(m.points, m.scan.texture);
  if (!leaf.status.ok()) {
    AlbedoResult failed;
    failed.status = leaf.status;
    return failed;
  }
  return EstimateAlbedo(m.decoded.amplitude, m.points, leaf.mask, DefaultRig(), field);
}

// The white target: a plain sheet of albedo 0.85 larger than the camera's view, on the table.
const FlatField& TableFlatField() {
  static const FlatField field = [] {
    PageOptions page;
    page.size_mm = {420, 320};
    TextureOptions texture;
    texture.kind = TextureKind::kPlain;
    texture.paper_albedo = 0.85;
    const Measured m = Scan(page, texture, 41);
    FlatFieldOptions options;
    options.target_albedo = 0.85;
    Status s = Status::Ok();
    FlatField f = MeasureFlatField(m.decoded.amplitude, m.points, DefaultRig(), options, &s);
    EXPECT_TRUE(s.ok()) << s.message();
    return f;
  }();
  return field;
}

struct Uniformity {
  double mean = 0, spread = 0;  // Mean and standard deviation / mean.
  int pixels = 0;
};

// Sums values into a Uniformity.
class Moments {
 public:
  void Add(double a) {
    sum_ += a;
    sum2_ += a * a;
    ++n_;
  }
  Uniformity Result() const {
    Uniformity out;
    out.pixels = n_;
    if (n_ == 0) return out;
    out.mean = sum_ / n_;
    out.spread = std::sqrt(std::max(0.0, sum2_ / n_ - out.mean * out.mean)) / out.mean;
    return out;
  }

 private:
  double sum_ = 0, sum2_ = 0;
  int n_ = 0;
};

// Over the pixels in `where` (CV_8U) of `values` (CV_32F).
Uniformity Measure(const cv::Mat& values, const cv::Mat& where) {
  Moments m;
  for (int v = 0; v < values.rows; ++v) {
    for (int u = 0; u < values.cols; ++u) {
      if (where.at<uint8_t>(v, u)) m.Add(values.at<float>(v, u));
    }
  }
  return m.Result();
}

// The same over blocks of `block` x `block` pixels wholly in `where`, each its mean: the light's
// unevenness without the camera's pixel noise.
Uniformity MeasureBlocks(const cv::Mat& values, const cv::Mat& where, int block) {
  Moments m;
  for (int v = 0; v + block <= values.rows; v += block) {
    for (int u = 0; u + block <= values.cols; u += block) {
      const cv::Rect r(u, v, block, block);
      if (cv::countNonZero(where(r)) == r.area()) m.Add(cv::mean(values(r))[0]);
    }
  }
  return m.Result();
}

// A plain white leaf (albedo 0.85) flat, curled, folded and rolled: its albedo in the camera's
// pixels, against its texture shaded by the lamps, over the leaf's pixels that are not marked.
TEST(Albedo, APlainCurledLeafIsEvenWhereItsTextureIsShaded) {
  const FlatField& field = TableFlatField();
  ASSERT_FALSE(field.empty());
  for (PageShape shape : {PageShape::kFlat, PageShape::kCurl, PageShape::kFold, PageShape::kCone}) {
    SCOPED_TRACE(ToString(shape));
    PageOptions page;
    page.shape = shape;
    TextureOptions texture;
    texture.kind = TextureKind::kPlain;
    const Measured m = Scan(page, texture, 7);
    const AlbedoResult a = AlbedoOfLeaf(m, field);
    ASSERT_TRUE(a.status.ok()) << a.status.message();
    const GroundTruth& truth = m.scan.gantry->truth();
    cv::Mat on_page = truth.on_page & a.valid;
    cv::Mat texture_f;
    m.scan.texture.convertTo(texture_f, CV_32F);
    const Uniformity albedo = Measure(a.albedo, on_page), shaded = Measure(texture_f, on_page);
    const Uniformity albedo4 = MeasureBlocks(a.albedo, on_page, 4),
                     shaded4 = MeasureBlocks(texture_f, on_page, 4);
    std::printf("[albedo] %-5s 4x4 blocks: albedo %.2f%%, texture %.2f%%\n", ToString(shape),
                100 * albedo4.spread, 100 * shaded4.spread);
    std::printf(
        "[albedo] %-5s: albedo mean %.4f (true %.2f), non-uniformity %.2f%% over %d px; "
        "texture %.2f%%; marked: %d shadowed, %d rim, %d grazing, %d outside the flat "
        "field\n",
        ToString(shape), albedo.mean, texture.paper_albedo, 100 * albedo.spread, albedo.pixels,
        100 * shaded.spread, a.shadowed, a.rim, a.grazing, a.outside_flat_field);
    // Per camera pixel the sensor's noise (1.5 DN on each of white and black, 1.3% of paper's
    // ~160 DN) sets a floor; over 1 mm blocks (4 x 4 pixels) what is left is the model's.
    EXPECT_LE(albedo.spread, 0.02);
    EXPECT_LE(albedo4.spread, 0.01);
    EXPECT_GT(shaded4.spread, 5 * albedo4.spread) << "the lamps should shade the texture";
    EXPECT_NEAR(albedo.mean / texture.paper_albedo, 1.0, 0.01);
  }
}

// White and black squares of a checkerboard leaf, flat and curled: each square's interior (the
// pixels whose true albedo, averaged over the pixel, is the square's) has a mean albedo within
// 2% of the truth (paper 0.85, ink 0.08). Ink returns a tenth of paper's light, so its pixels
// are ten times noisier; their mean over a whole leaf's squares is not.
TEST(Albedo, CheckerboardSquaresHaveTheirTrueAlbedo) {
  const FlatField& field = TableFlatField();
  ASSERT_FALSE(field.empty());
  for (PageShape shape : {PageShape::kFlat, PageShape::kCurl}) {
    SCOPED_TRACE(ToString(shape));
    PageOptions page;
    page.shape = shape;
    const TextureOptions texture;  // The checkerboard.
    const Measured m = Scan(page, texture, 9);
    const AlbedoResult a = AlbedoOfLeaf(m, field);
    ASSERT_TRUE(a.status.ok()) << a.status.message();
    const cv::Mat& truth = m.scan.gantry->albedo();
    const cv::Mat on_page = m.scan.gantry->truth().on_page & a.valid;
    for (const double want : {texture.paper_albedo, texture.ink_albedo}) {
      const cv::Mat exact = (cv::abs(truth - want) < 1e-4) & on_page;
      const Uniformity got = Measure(a.albedo, exact);
      std::printf("[albedo] %-5s %s: %.4f (true %.2f) over %d px\n", ToString(shape),
                  want == texture.ink_albedo ? "ink  " : "paper", got.mean, want, got.pixels);
      ASSERT_GT(got.pixels, 10000);
      EXPECT_NEAR(got.mean / want, 1.0, 0.02);
    }
  }
}

// The studio lamps' shading taken out of the texture: the studio field from the
// texture of a white target (albedo 0.85) on the table under the same two lamps, then a plain
// curled and a folded leaf's texture corrected by their measured shape. Over 8 x 8 blocks (the
// light's unevenness without the camera's pixel noise, 1.5 DN on ~190) the corrected texture is
// even within 1%, where the texture itself is shaded by 10-20%; its mean is the leaf's albedo.
TEST(StudioField, TheLampsShadingIsTakenOutOfTheTexture) {
  const LightOptions light = RealLight();
  TextureOptions plain;
  plain.kind = TextureKind::kPlain;
  PageOptions target;
  target.size_mm = {420, 320};
  const VirtualGantry white(DefaultRig(), target, plain, light);
  Status s = Status::Ok();
  const StudioField field = MeasureStudioField(white.RenderTexture(3), DefaultRig().camera,
                                               light.studio_lamps, plain.paper_albedo, &s);
  ASSERT_TRUE(s.ok()) << s.message();
  for (PageShape shape : {PageShape::kCurl, PageShape::kFold}) {
    SCOPED_TRACE(ToString(shape));
    PageOptions page;
    page.shape = shape;
    const Measured m = Scan(page, plain, 21);
    const Outline leaf = FindLeaf(m.points, m.scan.texture);
    ASSERT_TRUE(leaf.status.ok());
    const AlbedoResult a = CorrectTexture(m.scan.texture, m.points, leaf.mask, DefaultRig(), field);
    ASSERT_TRUE(a.status.ok()) << a.status.message();
    cv::Mat texture;
    m.scan.texture.convertTo(texture, CV_32F, 1.0 / 255);
    const Uniformity got = MeasureBlocks(a.albedo, a.valid, 8);
    const Uniformity raw = MeasureBlocks(texture, a.valid, 8);
    std::printf(
        "[studio] %-5s corrected %.4f (true %.2f), non-uniformity %.2f%%; texture "
        "%.2f%%; %.1f%% of the leaf corrected\n",
        ToString(shape), got.mean, plain.paper_albedo, 100 * got.spread, 100 * raw.spread,
        100.0 * a.estimated / cv::countNonZero(leaf.mask));
    EXPECT_NEAR(got.mean / plain.paper_albedo, 1.0, 0.01);
    EXPECT_LE(got.spread, 0.01);
    EXPECT_GT(raw.spread, 5 * got.spread);
    EXPECT_GT(a.estimated, 0.9 * cv::countNonZero(leaf.mask));
  }
}

// Options no shading model can use are refused with their reason, not run.
TEST(ShadingOptions, NonsenseIsRefusedByName) {
  FlatFieldOptions field;
  field.target_albedo = 0;  // A target that reflects nothing.
  Status s = Status::Ok();
  MeasureFlatField(cv::Mat::zeros(4, 4, CV_32F), cv::Mat(4, 4, CV_32FC3, cv::Scalar::all(0)),
                   DefaultRig(), field, &s);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("target_albedo"), std::string::npos) << s.message();
  AlbedoOptions albedo;
  albedo.normal_window_px = 0;
  const AlbedoResult r =
      EstimateAlbedo(cv::Mat::zeros(4, 4, CV_32F), cv::Mat(4, 4, CV_32FC3, cv::Scalar::all(0)),
                     cv::Mat(), DefaultRig(), FlatField(), albedo);
  ASSERT_FALSE(r.status.ok());
  EXPECT_NE(r.status.message().find("normal_window_px"), std::string::npos);
  std::string why;
  EXPECT_TRUE(FlatFieldOptions().Check(&why)) << why;
  EXPECT_TRUE(AlbedoOptions().Check(&why)) << why;
}

}  // namespace
}  // namespace vellum
