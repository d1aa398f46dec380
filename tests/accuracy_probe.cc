// Temporary probe: prints accuracy for each page shape.
#include <chrono>
#include <cstdio>

#include "core/decode/decode.h"
#include "core/geometry/triangulate.h"
#include "core/sim/evaluate.h"

using namespace vellum;

int main(int argc, char** argv) {
  const char* shape_name = argc > 1 ? argv[1] : "flat";
  PageOptions page;
  ParsePageShape(shape_name, &page.shape);
  TextureOptions tex;
  auto t0 = std::chrono::steady_clock::now();
  VirtualGantry gantry(DefaultRig(), page, tex);
  auto t1 = std::chrono::steady_clock::now();
  PatternOptions po;
  if (argc > 2) po.phase_steps = atoi(argv[2]);
  if (argc > 3) po.phase_period_px = atoi(argv[3]);
  PatternSequence seq = MakePatternSequence(po);
  auto frames = RenderSequence(gantry, seq, 7);
  auto t2 = std::chrono::steady_clock::now();
  Triangulator tri(gantry.rig());
  DecodeOptions dopt;
  if (argc > 4) dopt.smooth_radius_px = atoi(argv[4]);
  for (bool phase : {true, false}) {
    dopt.use_phase = phase;
    auto t3 = std::chrono::steady_clock::now();
    DecodeResult d = Decode(seq, frames, dopt);
    auto t4 = std::chrono::steady_clock::now();
    PointMap pm = tri.Triangulate(d);
    auto t5 = std::chrono::steady_clock::now();
    PointErrorStats st = ComparePoints(gantry.truth(), pm.points);
    printf("%s phase=%d: lit %d valid %.4f median %.4f rms %.4f p99 %.4f max %.3f | decode %.0f ms tri %.0f ms | rej bits %d mod %d unwrap %d fb %d epi %d vol %d\n",
           shape_name, phase, st.page_lit_pixels, st.valid_fraction, st.median_mm, st.rms_mm, st.p99_mm, st.max_mm,
           std::chrono::duration<double, std::milli>(t4 - t3).count(),
           std::chrono::duration<double, std::milli>(t5 - t4).count(), d.stats.rejected_bits,
           d.stats.rejected_modulation, d.stats.rejected_unwrap, d.stats.fit_fallbacks, pm.rejected_epipolar, pm.rejected_volume);
  }
  printf("gantry %.0f ms, render %.0f ms\n", std::chrono::duration<double, std::milli>(t1 - t0).count(),
         std::chrono::duration<double, std::milli>(t2 - t1).count());
}
