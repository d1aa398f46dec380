#include "pipeline/stages.h"

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <future>
#include <limits>
#include <map>
#include <opencv2/imgproc.hpp>

#include "core/common/depth.h"
#include "core/common/text.h"
#include "core/report/pictures.h"
#include "io/calibration_io.h"
#include "io/iiif.h"
#include "io/image_file.h"
#include "io/json.h"
#include "io/ply.h"
#include "io/products.h"
#include "io/ptm.h"
#include "io/scan_io.h"
#include "io/version.h"

namespace vellum {
namespace fs = std::filesystem;
namespace {

// An image as the report shows it: 8-bit, at most 1400 pixels across.
cv::Mat ReportSized(const cv::Mat& image) {
  cv::Mat out = EightBit(image);
  if (out.cols > 1400) {
    const double scale = 1400.0 / out.cols;
    cv::resize(out, out, cv::Size(), scale, scale, cv::INTER_AREA);
  }
  return out;
}

// Starts the clock of a stage's report; Finish sets the status and the wall time.
class Stage {
 public:
  Stage(const char* name, const std::string& page = "") : start_(std::chrono::steady_clock::now()) {
    report_.stage = name;
    report_.page = page;
  }
  StageReport& report() { return report_; }
  StageReport Finish(const Status& status) {
    report_.status = status;
    report_.seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    rusage usage{};
    if (getrusage(RUSAGE_SELF, &usage) == 0) report_.peak_memory_mb = usage.ru_maxrss / 1024.0;
    return report_;
  }
  // Records one of the stage's files (relative to the results folder) when it was written.
  Status Output(const std::string& name, const Status& written) {
    if (written.ok()) report_.outputs.push_back(name);
    return written;
  }
  // Writes one of the stage's files (`name`, relative to the results folder) with `write`,
  // given its path: on the run's writes' threads while the steps go on when the pipeline runs
  // the stage (its failure then fails the run where the writes are waited for), else at once.
  // `write` holds what it writes by value: it may run after the stage has returned.
  Status File(const std::string& results, const std::string& name,
              std::function<Status(const std::string& path)> write) {
    const std::string path = (fs::path(results) / name).string();
    if (FileWrites* writes = CurrentFileWrites()) {
      writes->AddFile(path, std::move(write));
      return Output(name, Status::Ok());
    }
    return Output(name, write(path));
  }
  // A picture for report.html in <results>/report/ (<stem>-<page>.png for a page of a
  // spread): at most 1400 pixels across, 8-bit.
  Status Picture(const std::string& results, const std::string& stem, const cv::Mat& image) {
    cv::Mat out = ReportSized(image);
    // Written from a copy of its own (the image may change meanwhile).
    if (out.data == image.data) out = out.clone();
    return PictureDrawn(results, stem, [out] { return out; });
  }
  // The same, drawn by `draw` where it is written (File): what it draws from, it holds by value.
  Status PictureDrawn(const std::string& results, const std::string& stem,
                      std::function<cv::Mat()> draw) {
    Status s = MakeDirectories((fs::path(results) / "report").string());
    if (!s.ok()) return s;
    const std::string file =
        "report/" + stem + (report_.page.empty() ? "" : "-" + report_.page) + ".png";
    return File(results, file, [draw = std::move(draw)](const std::string& path) {
      return WriteImage(path, ReportSized(draw()));
    });
  }

 private:
  std::chrono::steady_clock::time_point start_;
  StageReport report_;
};

// A page's file name relative to the results folder.
std::string PageFile(const std::string& page, const std::string& name) {
  return page.empty() ? name : "pages/" + page + "/" + name;
}

}  // namespace

bool PipelineOptions::Check(std::string* why) const {
  if (!(max_warp_error_px > 0)) {
    *why = "max_warp_error_px must be > 0";
    return false;
  }
  return decode.Check(why) && triangulate.Check(why) && outline.Check(why) && mesh.Check(why) &&
         flatten.Check(why) && restore.Check(why) && target.Check(why);
}

std::string PageName(const Outline& outline, size_t page) {
  if (outline.pages.size() <= 1) return "";
  return page == 0 ? "left" : "right";
}

std::string PageDir(const std::string& results, const std::string& page) {
  return page.empty() ? results : (fs::path(results) / "pages" / page).string();
}

namespace {

// The scan's redundancy: each Gray frame and its inverse add up to white + black. A pair far
// off the scan's usual names its frames (frame_contradicts).
void JudgeFramePairs(const Scan& scan, const std::vector<FramePairCheck>& pairs,
                     const WarningLimits& limits, StageReport* r) {
  if (pairs.empty()) return;
  std::vector<double> shares;
  for (const FramePairCheck& p : pairs) shares.push_back(p.Share());
  std::vector<double> sorted = shares;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double usual = sorted[sorted.size() / 2];
  r->Number("frames", "pairs_judged", static_cast<double>(pairs.size()));
  r->Number("frames", "pair_disagreement_median", usual);
  r->Number("frames", "pair_disagreement_max", *std::max_element(shares.begin(), shares.end()));
  const double bar = std::max(limits.max_pair_disagreement,
                              std::min(limits.pair_over_usual * usual, limits.pair_always_named));
  std::string named, left_out;
  int count = 0, mended = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    const FramePairCheck& p = pairs[k];
    if (p.left_out >= 0) {
      left_out += (left_out.empty() ? "" : ",") + std::to_string(p.left_out);
    }
    if (shares[k] <= bar) continue;
    mended += p.left_out >= 0;
    if (count++ < 4) {
      named += std::string(named.empty() ? "" : "; ") + "frames " + std::to_string(p.pattern) +
               " and " + std::to_string(p.inverse) + " ('" +
               Describe(scan.sequence.patterns[p.pattern]) + "' and its inverse) at " +
               Fixed(100.0 * shares[k], 1) + "%";
      if (p.left_out >= 0) {
        const int kept = p.left_out == p.pattern ? p.inverse : p.pattern;
        named += ", frame " + std::to_string(p.left_out) +
                 (p.shows_pair ? " showing its pair's pattern" : " off the scan's light") +
                 " left out, the bit decoded from frame " + std::to_string(kept) + " alone";
      }
    }
  }
  if (!left_out.empty()) r->Text("frames", "left_out", left_out);
  if (count == 0) return;
  r->Number("frames", "pairs_contradicting", count);
  r->Number("frames", "pairs_mended", mended);
  r->Warn("frame_contradicts",
          std::to_string(count) +
              " Gray frame pair(s) do not add up to the white and black frames at " +
              "many of the lit pixels (" + named + (count > 4 ? "; ..." : "") +
              "; the scan's usual pair: " + Fixed(100.0 * usual, 2) +
              "%): a frame of another scan or leaf, a pattern shown in another's place, or a "
              "frame taken before the projector changed; " +
              (mended == count ? "decoded without it, but the captures hold a wrong frame: "
                                 "scan again for the archive"
                               : "scan again"));
}

}  // namespace

StageReport DecodeStage(const Scan& scan, Decoder* decoder, const WarningLimits& limits,
                        DecodeResult* decoded, const std::string& frames_dir) {
  Stage stage("decode");
  StageReport& r = stage.report();
  const DecodeOptions& o = decoder->options();
  r.Text("options", "decoder", o.use_phase ? "phase" : "gray");
  r.Number("options", "smooth_radius_px", o.smooth_radius_px);
  r.Number("options", "min_contrast_dn", o.min_contrast_dn);
  r.Number("options", "min_modulation_dn", o.min_modulation_dn);
  r.Number("options", "max_unwrap_error", o.max_unwrap_error);
  // What the object is (scan.yaml, or SCAN_STARTED at the station), for the report.
  ForEachIdentityField(scan.identity, [&](const char* key, const std::string& value) {
    if (!value.empty()) r.Text("identity", key, value);
  });
  // Where the operator said the leaf is (scan.yaml, or SCAN_STARTED at the station).
  if (!scan.leaf_hint.empty()) r.Text("operator", "leaf_hint", LeafHintText(scan.leaf_hint));
  if (scan.object != ObjectKind::kAuto) r.Text("operator", "object", ToString(scan.object));
  if (scan.live_off_view != 0) {
    r.Text("operator", "live_off_view", ViewSidesText(scan.live_off_view));
  }
  r.Text("sizes", "camera", SizeText(scan.camera_size));
  r.Text("sizes", "projector", SizeText(scan.sequence.projector_size));
  r.Number("sizes", "patterns", static_cast<double>(scan.sequence.patterns.size()));
  r.Text("sizes", "gray_inverses",
         scan.sequence.GrayInverses(Axis::kColumn) || scan.sequence.GrayInverses(Axis::kRow)
             ? "yes"
             : "no");
  if (!scan.frames.empty()) {
    decoder->Decode(scan.sequence, scan.frames, decoded);
  } else if (frames_dir.empty()) {
    decoder->Finish(decoded);  // Its frames were added as they came.
  } else {
    // Each frame is decoded as it is read: the scan's frames are never all in memory.
    Status read = decoder->Begin(scan.sequence, scan.camera_size);
    if (read.ok()) {
      read = ReadFrames(frames_dir, scan,
                        [&](int k, cv::Mat frame) { return decoder->Add(k, frame); });
    }
    if (!read.ok()) return stage.Finish(read);
    decoder->Finish(decoded);
  }
  if (!decoded->status.ok()) return stage.Finish(decoded->status);
  const DecodeStats& d = decoded->stats;
  r.Number("pixels", "camera", d.pixels);
  r.Number("pixels", "lit", d.lit);
  r.Number("pixels", "decoded", d.valid);
  r.Number("pixels", "rejected_saturated", d.rejected_saturated);
  r.Number("pixels", "rejected_gray_bits", d.rejected_bits);
  r.Number("pixels", "rejected_modulation", d.rejected_modulation);
  r.Number("pixels", "rejected_unwrap", d.rejected_unwrap);
  r.Number("pixels", "fit_fallbacks", d.fit_fallbacks);
  r.Number("sizes", "gray_stripe_px", d.gray_stripe_px);
  JudgeFramePairs(scan, d.pairs, limits, &r);
  return stage.Finish(Status::Ok());
}

StageReport TriangulateStage(const DecodeResult& decoded, const Triangulator& triangulator,
                             const TriangulateOptions& options, const WarningLimits& limits,
                             const std::string& results, PointMap* map) {
  Stage stage("triangulate");
  StageReport& r = stage.report();
  r.Number("options", "max_epipolar_error_px", options.max_epipolar_error_px);
  r.Number("options", "max_flying_mm", options.max_flying_mm);
  const Calibration& c = triangulator.calibration();
  r.Text("provenance", "calibration_sha256", CalibrationSha256(c));
  r.Text("provenance", "vellum_version", VellumVersion());
  if (std::isfinite(c.scale_error_percent))
    r.Number("provenance", "calibration_scale_error_percent", c.scale_error_percent);
  r.Number("options", "volume_low_mm",
           std::isnan(options.min_z_mm) ? c.min_z_mm : options.min_z_mm);
  r.Number("options", "volume_high_mm",
           std::isnan(options.max_z_mm) ? c.max_z_mm : options.max_z_mm);
  triangulator.Triangulate(decoded, options, map);
  if (!map->status.ok()) return stage.Finish(map->status);
  r.Number("pixels", "valid", map->valid);
  r.Number("pixels", "rejected_epipolar", map->rejected_epipolar);
  r.Number("pixels", "rejected_volume", map->rejected_volume);
  r.Number("pixels", "rejected_flying", map->rejected_flying);
  // Points cannot come without lit pixels: a count of 0 beside points is a count not known (a
  // decode whose stats did not reach here), not judged.
  const int lit = decoded.stats.lit;
  if (lit == 0 && map->valid == 0) {
    r.Number("pixels", "points_of_lit", 0);
    r.Warn("decode_low",
           "no pixel was lit by the projector (its white frame no brighter than its black): the "
           "frames are not in the pattern's order, or the projector was off; scan again");
  } else if (lit > 0) {
    const double of_lit = static_cast<double>(map->valid) / lit;
    r.Number("pixels", "points_of_lit", of_lit);
    if (of_lit < limits.min_points_of_lit) {
      const DecodeStats& d = decoded.stats;
      auto share = [&](int n) { return Fixed(100.0 * n / lit, 1) + "%"; };
      r.Warn("decode_low",
             "only " + share(map->valid) + " of the " + std::to_string(lit) +
                 " pixels the projector lit gave a 3D point (the code unreadable at " +
                 share(d.rejected_bits + d.rejected_modulation + d.rejected_unwrap) +
                 ", off the projector's rays at " + share(map->rejected_epipolar) + ", flying at " +
                 share(map->rejected_flying) +
                 "; a sound scan gives nearly all): frames of another scan, patterns out of "
                 "order, or a camera or projector that moved during the scan; scan again");
    }
  }
  // The heights' range for the report here; the files on the writes' threads (File), while the
  // points go on.
  double z_min = 0, z_max = 0;
  const cv::Mat depth = DepthPicture(map->points, &z_min, &z_max);
  const cv::Mat points = map->points;
  Status s = stage.PictureDrawn(results, "valid", [points] { return ValidMask(points); });
  if (s.ok()) {
    s = stage.PictureDrawn(results, "depth",
                           [depth, z_min, z_max] { return WithHeightBar(depth, z_min, z_max); });
  }
  if (s.ok()) {
    s = stage.File(results, "points.ply",
                   [points](const std::string& path) { return WritePointsPly(path, points); });
  }
  if (s.ok()) {
    s = stage.File(results, "depth.png",
                   [depth](const std::string& path) { return WriteImage(path, depth); });
  }
  if (!s.ok()) return stage.Finish(s);
  r.Number("height_mm", "min", z_min);
  r.Number("height_mm", "max", z_max);
  return stage.Finish(s);
}

namespace {

// How much of the leaf (`leaf` pixels of outline.mask) was measured in 3D, and how much of its
// texture is clipped: the figures, and the warnings when below or above the limits.
void JudgeMeasuredAndExposure(const cv::Mat& points, const cv::Mat& texture, const Outline& outline,
                              int leaf, const WarningLimits& limits, StageReport* report) {
  StageReport& r = *report;
  int measured = 0, high = 0, low = 0;
  const double top = texture.depth() == CV_16U ? 65535 : 255;
  for (int v = 0; v < outline.mask.rows; ++v) {
    const uint8_t* in = outline.mask.ptr<uint8_t>(v);
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    for (int u = 0; u < outline.mask.cols; ++u) {
      if (!in[u]) continue;
      measured += !std::isnan(p[u][0]);
      double hi = 0, lo = top;
      for (int c = 0; c < texture.channels(); ++c) {
        const double value = texture.depth() == CV_16U
                                 ? texture.ptr<uint16_t>(v)[u * texture.channels() + c]
                                 : texture.ptr<uint8_t>(v)[u * texture.channels() + c];
        hi = std::max(hi, value);
        lo = std::min(lo, value);
      }
      high += hi >= top;
      low += lo <= 0;
    }
  }
  // Measured: of the leaf found by every cue, the share with a point (FindLeaf's), which counts
  // what the mask leaves out for want of points (a shadow at the rim, a side seen edge-on).
  const double share_measured =
      std::min(leaf > 0 ? static_cast<double>(measured) / leaf : 0.0, outline.measured_share);
  const double share_high = leaf > 0 ? static_cast<double>(high) / leaf : 0;
  const double share_low = leaf > 0 ? static_cast<double>(low) / leaf : 0;
  r.Number("outline", "valid_in_leaf", share_measured);
  r.Number("exposure", "clipped_highlights", share_high);
  r.Number("exposure", "clipped_shadows", share_low);
  if (share_measured < limits.min_valid_in_leaf) {
    r.Warn("valid_low", "only " + Fixed(100 * share_measured, 1) +
                            "% of the leaf was measured in 3D (glare, the projector's light not "
                            "reaching, or ink too dark to decode); the rest of the sheet is "
                            "filled in");
  }
  if (std::max(share_high, share_low) > limits.max_clipped) {
    r.Warn("exposure_clipped",
           Fixed(100 * share_high, 1) + "% of the leaf's pixels are at the camera's maximum and " +
               Fixed(100 * share_low, 1) +
               "% at 0: detail is lost there; shorten or lengthen the exposure, or move the "
               "lights (glare)");
  }
}

// On a spread: how much page the gutter keeps from view (UnseenAtGutter), and the warning
// when it is more than the limit.
void JudgeGutter(const cv::Mat& points, const Outline& outline, const WarningLimits& limits,
                 StageReport* report) {
  StageReport& r = *report;
  const GutterGap gap = UnseenAtGutter(points, outline);
  if (gap.rows > 0) {
    r.Number("outline", "gutter_unseen_mm", gap.median_mm);
    r.Number("outline", "gutter_unseen_p95_mm", gap.p95_mm);
    r.Number("outline", "gutter_unseen_bound_mm", gap.bound_mm);
    // The line between the pages' last points is the least that is missing; where their
    // slopes meet farther down, as much as the valley between can hold.
    const double most_mm = std::max(gap.median_mm, gap.bound_mm);
    if (most_mm > limits.max_gutter_unseen_mm) {
      const std::string how_much =
          most_mm > gap.median_mm + 0.05
              ? Fixed(gap.median_mm, 1) + " to " + Fixed(most_mm, 1) + " mm"
              : "at least " + Fixed(gap.median_mm, 1) + " mm (" + Fixed(gap.p95_mm, 1) +
                    " mm in places)";
      r.Warn("gutter_hidden",
             "the restored pages leave out " + how_much +
                 " of page at the gutter: the camera or the projector did not reach it, or it "
                 "was not "
                 "measured or not taken as the page (see the outline in the report); open "
                 "the book wider, or turn the cradle towards the projector");
    }
  }
}

// A surface standing above the leaf inside it, in a hole of the leaf: the leaf itself, more
// likely, on a support (HighestRaisedHole); the warning when the hole is large enough.
void JudgeRaisedHole(const cv::Mat& points, const Outline& outline, int leaf, double step_mm,
                     const WarningLimits& limits, StageReport* report) {
  StageReport& r = *report;
  const RaisedHole raised = HighestRaisedHole(points, outline.mask, step_mm);
  if (raised.area_px > 0) {
    r.Number("outline", "raised_hole_pixels", raised.area_px);
    r.Number("outline", "raised_hole_rise_mm", raised.rise_mm);
  }
  if (leaf > 0 && raised.area_px >= limits.min_raised_hole * leaf) {
    const cv::Rect& b = raised.box;
    r.Warn("leaf_ambiguous",
           "a surface " + Fixed(raised.rise_mm, 2) +
               " mm above the leaf found lies inside it, in " + "a hole of " +
               Fixed(100.0 * raised.area_px / leaf, 0) + "% of its area (camera pixels " +
               LeafHintText(b) +
               "); through a hole one sees what is under the leaf, so that surface is likely "
               "the leaf itself, on a support taken for the leaf: draw a leaf hint over it in "
               "the viewer (or give --leaf-hint) and scan again");
  }
}

// The live view saw the leaf run off the view (`seen`, ViewSide bits) when the scan was asked, and
// the scan's outline does not: it may have taken less than the leaf for it. Where the outline comes
// within reach of a side so seen, the two disagree and the scan cannot pass; an outline far from
// every such side means the live view, which goes by the look alone, took a support or a table
// for the leaf: recorded, not warned of.
void JudgeLiveOffView(const Outline& outline, int seen, const OutlineOptions& options,
                      StageReport* r) {
  const cv::Size view = outline.mask.size();
  const cv::Rect box = cv::boundingRect(outline.mask);
  const int gap[kViewSideCount] = {box.x, view.width - box.br().x, box.y, view.height - box.br().y};
  const double reach = options.off_view_reach_share * std::max(view.width, view.height);
  int near = 0, nearest = std::numeric_limits<int>::max();
  for (int k = 0; k < kViewSideCount; ++k) {
    if (!(seen & (1 << k)) || gap[k] > reach) continue;
    near |= 1 << k;
    nearest = std::min(nearest, gap[k]);
  }
  r->Text("outline", "live_off_view", ViewSidesText(seen));
  r->Text("outline", "live_off_view_near", near ? ViewSidesText(near) : "none");
  if (near == 0) return;
  r->Warn("seen_off_view",
          "the live view saw the leaf run off the view (" + ViewSidesText(near, ", ") +
              ") when the scan was asked, but the scan's outline stops " + std::to_string(nearest) +
              " camera pixels inside it: check the outline in the report; if the leaf runs off, "
              "move it into the view and scan again");
}

}  // namespace

Status WriteTexturePicture(const std::string& results, const cv::Mat& texture) {
  const Status s = MakeDirectories((fs::path(results) / "report").string());
  if (!s.ok()) return s;
  return WriteImage((fs::path(results) / kTexturePicture).string(), ReportSized(texture));
}

StageReport OutlineStage(const cv::Mat& points, const cv::Mat& texture, const Calibration& rig,
                         const ScanContext& context, const OutlineOptions& options,
                         const WarningLimits& limits, const std::string& results,
                         bool texture_pictured, Outline* outline) {
  Stage stage("outline");
  StageReport& r = stage.report();
  r.Number("options", "outline_step_mm", options.step_mm);
  // The scan's own hint (drawn for it) outranks the options' (the station's configuration).
  OutlineOptions o = options;
  const cv::Rect scan_hint = context.leaf_hint;
  if (!scan_hint.empty()) o.hint = scan_hint;
  if (!o.hint.empty()) {
    r.Text("outline", "hint", LeafHintText(o.hint));
    r.Text("outline", "hint_from", scan_hint.empty() ? "options" : "scan");
  }
  const ObjectKind said = context.object;
  if (said != ObjectKind::kAuto) o.object = said;
  r.Text("outline", "object", ToString(o.object));
  *outline = FindLeaf(points, texture, o, &rig);
  if (!outline->status.ok()) return stage.Finish(outline->status);
  r.Text("outline", "method", outline->method);
  r.Number("outline", "confidence", outline->confidence);
  const int leaf = cv::countNonZero(outline->mask);
  r.Number("outline", "leaf_pixels", leaf);
  r.Number("outline", "holes", outline->holes);
  r.Number("outline", "unseen_beside_share", outline->unseen_share);
  r.Number("outline", "edge_on_share", outline->edge_on_share);
  r.Number("outline", "pages", static_cast<double>(outline->pages.size()));
  r.Number("outline", "touches_border", outline->touches_border ? 1 : 0);
  JudgeMeasuredAndExposure(points, texture, *outline, leaf, limits, &r);
  if (outline->touches_border) {
    r.Warn("page_cut_off",
           "the leaf runs off the camera's view: what lies outside it is missing from the "
           "restored page; move the leaf into the view and scan again");
  } else if (context.live_off_view != 0) {
    JudgeLiveOffView(*outline, context.live_off_view, options, &r);
  }
  if (outline->pages.size() == 2) JudgeGutter(points, *outline, limits, &r);
  JudgeRaisedHole(points, *outline, leaf, options.step_mm, limits, &r);
  if (outline->confidence < limits.min_outline_confidence) {
    r.Warn("outline_uncertain",
           "only " + Fixed(100 * outline->confidence, 0) +
               "% of the leaf's rim is set apart from what surrounds it (found by " +
               outline->method + "); check the outline in the report, or give a hint");
  }
  for (const OutlineDoubt& doubt : outline->doubts) r.Warn(doubt.code, doubt.message);
  // The one writer of the texture's picture, here or in a daemon as the texture came.
  Status s = texture_pictured
                 ? stage.Output(kTexturePicture, Status::Ok())
                 : stage.File(results, kTexturePicture, [results, texture](const std::string&) {
                     return WriteTexturePicture(results, texture);
                   });
  if (s.ok()) {
    // Drawn where it is written, from its own copy of the pages.
    Outline drawn;
    for (const cv::Mat& page : outline->pages) drawn.pages.push_back(page.clone());
    s = stage.PictureDrawn(results, "outline",
                           [texture, drawn] { return DrawOutline(texture, drawn); });
  }
  return stage.Finish(s);
}

StageReport MeshStage(const ScanWork& work, const PipelineOptions& options, PageResult* p) {
  const cv::Mat& points = work.map.points;
  const cv::Mat& page_mask = p->mask;
  const CameraModel& camera = work.calibration.camera;
  const std::string& page = p->name;
  Mesh* mesh = &p->mesh;
  Stage stage("mesh", page);
  StageReport& r = stage.report();
  const auto project = [&](const cv::Vec3d& x) { return camera.Project(x); };
  r.Text("options", "grid", options.auto_grid ? "auto" : SizeText(options.mesh.grid));
  if (options.auto_grid) r.Number("options", "max_warp_error_px", options.max_warp_error_px);
  MeshOptions mesh_options = options.mesh;
  *mesh = BuildMesh(points, page_mask, mesh_options, project);
  if (mesh->status.ok() && options.auto_grid) {
    // The sheet's density from the page's shape: finer until the warp's error is small.
    const cv::Size grid = GridForError(*mesh, options.max_warp_error_px);
    if (grid != mesh_options.grid) {
      mesh_options.grid = grid;
      *mesh = BuildMesh(points, page_mask, mesh_options, project);
    }
  }
  if (!mesh->status.ok()) return stage.Finish(mesh->status);
  r.Text("sheet", "grid", SizeText(mesh_options.grid));
  r.Number("sheet", "warp_error_px", WarpError(*mesh));
  r.Number("sheet", "measured_nodes", mesh->measured);
  r.Number("sheet", "filled_nodes", mesh->filled);
  r.Number("sheet", "skirt_nodes", mesh->skirt);
  r.Number("sheet", "springs", static_cast<double>(mesh->springs.size()));
  r.Number("sheet", "quads", static_cast<double>(mesh->quads.size()));
  return stage.Finish(Status::Ok());
}

StageReport FlattenStage(const ScanWork& work, const PipelineOptions& o, PageResult* p) {
  const Mesh& mesh = p->mesh;
  const FlattenOptions& options = o.flatten;
  const WarningLimits& limits = o.limits;
  const std::string& results = work.results;
  const std::string& page = p->name;
  FlattenResult* flat = &p->flat;
  Stage stage("flatten", page);
  StageReport& r = stage.report();
  r.Text("options", "solver", ToString(options.solver));
  *flat = Flatten(mesh, options);
  if (!flat->status.ok()) return stage.Finish(flat->status);
  r.Text("flattening", "solver", ToString(options.solver));
  r.Number("flattening", "iterations", flat->iterations);
  r.Number("flattening", "mean_strain", flat->mean_strain);
  r.Number("flattening", "max_strain", flat->max_strain);
  r.Number("flattening", "widespread_strain", flat->widespread_strain);
  r.Number("flattening", "folded_quads", flat->folded_quads);
  if (flat->mean_strain > limits.max_mean_strain) {
    r.Warn("strain_high", "the flattened sheet keeps a strain of " +
                              Fixed(100 * flat->mean_strain, 2) + "% on average and " +
                              Fixed(100 * flat->max_strain, 2) +
                              "% at most: the sheet may hold more than the leaf (a support or "
                              "frame), or the leaf was stretched or creased");
  } else if (flat->widespread_strain > limits.max_strain) {
    r.Warn("strain_high", "the flattened sheet keeps a strain of " +
                              Fixed(100 * flat->widespread_strain, 2) + "% or more in " +
                              std::to_string(kWidespreadSprings) + " places (" +
                              Fixed(100 * flat->mean_strain, 2) +
                              "% on average): most likely a crease sharper than the scanner "
                              "resolves, across which the restored page comes out short by "
                              "tenths of a millimetre; see where in the report's strain "
                              "picture, and measure across it on the leaf if it matters");
  }
  if (flat->folded_quads > 0) {
    r.Warn("fold_over", std::to_string(flat->folded_quads) +
                            " cells of the sheet folded over as it flattened: the restored page "
                            "is wrong there");
  }
  const std::string dir = PageDir(results, page);
  Status s = MakeDirectories(dir);
  if (s.ok()) s = WriteSheets(dir, mesh, flat->flat);
  if (s.ok()) r.outputs = {PageFile(page, "mesh.ply"), PageFile(page, "flat.ply")};
  return stage.Finish(s);
}

namespace {

// The restored page's figures, worked out once: the report records them and the page's files
// carry them (Provenance).
struct RestoreFigures {
  bool sampled = false;      // The camera's true sampling of the page was measured:
  SamplingSummary sampling;  // what it is.
  double scale_error_percent = std::numeric_limits<double>::quiet_NaN();  // NaN: not a scale.
  std::string icc_profile;  // The colour profile the page is written in.
};

// The restored page's figures (true sampling, scale error, colour profile), recorded in its
// report `r` (with dpi_above_sampling when it is written finer than it was sampled), for its
// files' provenance.
RestoreFigures MeasureFigures(const RestoreResult& restored, int channels,
                              const IccProfile& camera_icc, const FlattenResult& flattened,
                              const ScanContext& context, const WarningLimits& limits,
                              StageReport* r) {
  RestoreFigures figures;
  figures.icc_profile = camera_icc.empty()
                            ? std::string(channels == 3 ? "sRGB" : "gray, sRGB tone curve") +
                                  " (no camera profile configured)"
                            : camera_icc.description;
  r->Text("restored", "icc_profile", figures.icc_profile);
  if (restored.view == RestoreView::kOrthographic) {
    // The reproduction scale error: the flat page's lengths against the measured surface's
    // (the flattening's mean strain) plus the calibration's measured error of every length
    // (`vellum calibrate`), when its file carries one. They add: the one is a bias of every
    // length, the other a mean departure from it.
    const double flattening = 100 * flattened.mean_strain;
    const double calibration = context.scale_error_percent;
    const bool measured = std::isfinite(calibration);
    r->Number("restored", "scale_error_flattening_percent", flattening);
    if (measured) r->Number("restored", "scale_error_calibration_percent", calibration);
    figures.scale_error_percent = flattening + (measured ? calibration : 0);
    r->Number("restored", "scale_error_percent", figures.scale_error_percent);
  }
  if (!restored.sampling.empty()) {
    // What the camera truly saw of the page, beside the dpi it is written at.
    figures.sampled = true;
    figures.sampling = SummarizeSampling(restored.sampling);
    const SamplingSummary& sampling = figures.sampling;
    r->Number("sampling", "median_ppi", sampling.median_ppi);
    r->Number("sampling", "p5_ppi", sampling.p5_ppi);
    r->Number("sampling", "p95_ppi", sampling.p95_ppi);
    r->Number("sampling", "share_400", sampling.share_400);
    r->Number("sampling", "share_300", sampling.share_300);
    r->Number("sampling", "share_200", sampling.share_200);
    if (sampling.p95_ppi > 0 && restored.dpi > (1 + limits.max_upsampling) * sampling.p95_ppi) {
      r->Warn("dpi_above_sampling",
              "the page is written at " + Fixed(restored.dpi, 0) +
                  " dpi, but the camera truly sampled it at " + Fixed(sampling.p95_ppi, 0) +
                  " ppi at the finest (median " + Fixed(sampling.median_ppi, 0) +
                  "): it is upsampled " + Fixed(restored.dpi / sampling.p95_ppi, 1) +
                  " times and holds no finer detail than that; leave the dpi unset (0) to write "
                  "the true sampling");
    }
  }
  return figures;
}

// What the restored page's files say of how it was made (restored.json's `provenance` and the
// TIFF's XMP): its scale, measured error, true sampling and colour profile (`figures`), its
// flattening's strain (`flat`), the calibration's checksum (`context`), all typed; and the
// options as run, as every stage recorded them in its report's "options" section (`earlier`,
// the scan's stages so far, which travel with the products, and the restore stage's own,
// `own`): a whole section, never a value looked up by its key.
std::map<std::string, std::string> Provenance(const RestoreResult& restored,
                                              const FlattenResult& flat, const ScanContext& context,
                                              const RestoreFigures& figures,
                                              const std::vector<StageReport>& earlier,
                                              const StageReport& own, const std::string& page) {
  std::map<std::string, std::string> out;
  if (restored.view == RestoreView::kOrthographic && restored.dpi > 0) {
    out["scale_mm_per_pixel"] = JsonNumber(25.4 / restored.dpi).dump();
  }
  out["flattening_mean_strain"] = JsonNumber(flat.mean_strain).dump();
  out["flattening_max_strain"] = JsonNumber(flat.max_strain).dump();
  if (figures.sampled) {
    out["true_median_ppi"] = JsonNumber(figures.sampling.median_ppi).dump();
    out["true_p5_ppi"] = JsonNumber(figures.sampling.p5_ppi).dump();
  }
  if (std::isfinite(figures.scale_error_percent)) {
    out["scale_error_percent"] = JsonNumber(figures.scale_error_percent).dump();
  }
  out["icc_profile"] = figures.icc_profile;
  if (!context.calibration_sha256.empty()) {
    out["calibration_sha256"] = context.calibration_sha256;
  }
  Json options = Json::object();
  auto add_options = [&](const StageReport& stage) {
    if (!stage.page.empty() && stage.page != page) return;
    for (const ReportValue& v : stage.values) {
      if (v.section == "options") options[v.key] = v.is_text ? Json(v.text) : JsonNumber(v.number);
    }
  };
  for (const StageReport& stage : earlier) add_options(stage);
  add_options(own);
  out["options"] = options.dump();
  return out;
}

}  // namespace

StageReport ArchiveStage(const cv::Mat& texture, const ScanIdentity& identity,
                         const IccProfile& camera_icc, const std::string& results) {
  Stage stage("archive");
  return stage.Finish(
      stage.Output("archival.tif", WriteArchivalMaster(results, texture, identity, camera_icc)));
}

StageReport RestoreStage(const ScanWork& work, const PipelineOptions& o, PageResult* p) {
  const cv::Mat& texture = work.scan.texture;
  const cv::Mat& page_mask = p->mask;
  const Mesh& mesh = p->mesh;
  const FlattenResult& flattened = p->flat;
  const CameraModel& camera = work.calibration.camera;
  const RestoreOptions& options = o.restore;
  const WarningLimits& limits = o.limits;
  const IccProfile& camera_icc = o.camera_icc;
  const ScanContext& context = work.context;
  const std::vector<StageReport>& earlier = work.stages;
  const std::string& results = work.results;
  const std::string& page = p->name;
  RestoreResult* restored = &p->restored;
  Stage stage("restore", page);
  StageReport& r = stage.report();
  const std::vector<cv::Point2d>& flat = flattened.flat;
  r.Text("options", "view", ToString(options.view));
  *restored = Restore(texture, mesh, flat, camera, options, page_mask);
  if (!restored->status.ok()) return stage.Finish(restored->status);
  if (page.empty()) r.Number("options", "dpi", restored->dpi);
  r.Number("restored", "width", restored->image.cols);
  r.Number("restored", "height", restored->image.rows);
  r.Number("restored", "dpi", restored->dpi);
  r.Number("restored", "rotation_deg", restored->rotation_deg);
  r.Number("restored", "bits_per_channel", texture.depth() == CV_16U ? 16 : 8);
  const RestoreFigures figures =
      MeasureFigures(*restored, texture.channels(), camera_icc, flattened, context, limits, &r);
  const std::map<std::string, std::string> provenance =
      Provenance(*restored, flattened, context, figures, earlier, r, page);
  if (restored->view == RestoreView::kOrthographic && !restored->mask.empty()) {
    const cv::Rect leaf = cv::boundingRect(restored->mask);
    const double mm = 25.4 / restored->dpi;
    const cv::Size2d size(leaf.width * mm, leaf.height * mm);
    r.Number("restored", "leaf_width_mm", size.width);
    r.Number("restored", "leaf_height_mm", size.height);
    const cv::Size2d& want = limits.expected_leaf_mm;
    if (want.width > 0 && want.height > 0) {
      // Either way round: the operator may not know how the leaf lies.
      auto off = [&](double a, double b) { return std::fabs(a / b - 1); };
      const double as_is = std::max(off(size.width, want.width), off(size.height, want.height));
      const double turned = std::max(off(size.width, want.height), off(size.height, want.width));
      if (std::min(as_is, turned) > limits.size_tolerance) {
        r.Warn("size_unexpected", "the leaf measures " + Fixed(size.width, 0) + " x " +
                                      Fixed(size.height, 0) + " mm flat, not the " +
                                      Fixed(want.width, 0) + " x " + Fixed(want.height, 0) +
                                      " mm expected");
      }
    }
  }
  const std::string dir = PageDir(results, page);
  Status s = MakeDirectories(dir);
  const ScanIdentity& identity = context.identity;
  if (s.ok()) {
    s = WriteRestored(dir, *restored, page.empty() ? identity : PageIdentity(identity, page),
                      provenance, camera_icc);
  }
  if (!s.ok()) return stage.Finish(s);
  r.outputs.push_back(PageFile(page, "restored.tif"));
  if (!restored->mask.empty()) r.outputs.push_back(PageFile(page, "restored_mask.png"));
  if (!restored->sampling.empty()) r.outputs.push_back(PageFile(page, "sampling_ppi.tif"));
  r.outputs.push_back(PageFile(page, "restored.json"));
  // The production master as a pyramid of tiles, for an IIIF image server (io/iiif.h), written
  // on a second thread while this one makes the report's pictures: each is mostly one
  // compressor's work, and neither needs the other.
  std::future<Status> pyramid = std::async(std::launch::async, [&dir] {
    return WritePyramidalTiff((fs::path(dir) / "restored.tif").string(),
                              (fs::path(dir) / kPyramidName).string());
  });
  // The whole restored page for the report (1400 px wide at most), with its scale bar.
  double bar_mm = 0;
  s = stage.Picture(results, "restored", RestoredWithScaleBar(*restored, 1400, &bar_mm));
  r.Number("restored", "scale_bar_mm", bar_mm);
  // The others drawn where they are written, from copies (the sheet is small; the images'
  // pixels are shared, and nothing changes them).
  auto drawn = [&](const char* stem, auto draw) {
    if (s.ok()) {
      s = stage.PictureDrawn(results, stem, [draw, mesh, flat, restored = *restored, camera] {
        return draw(mesh, flat, restored, camera);
      });
    }
  };
  drawn("grid", [](const Mesh& m, const std::vector<cv::Point2d>& f, const RestoreResult& r,
                   const CameraModel& c) { return GridOverPage(m, f, r, c); });
  drawn("strain", StrainPicture);
  drawn("before_after",
        [texture](const Mesh& m, const std::vector<cv::Point2d>& f, const RestoreResult& r,
                  const CameraModel& c) { return BeforeAfter(texture, m, f, r, c); });
  if (!restored->sampling.empty()) {
    drawn("sampling", [](const Mesh&, const std::vector<cv::Point2d>&, const RestoreResult& r,
                         const CameraModel&) { return SamplingPicture(r.sampling); });
  }
  const Status pyramid_written = stage.Output(PageFile(page, kPyramidName), pyramid.get());
  return stage.Finish(pyramid_written.ok() ? s : pyramid_written);
}

namespace {

// A page's reflectance per camera pixel (`a`, from the projector's light or the studio's)
// restored through the page's own warp (RestoreMore of `restored`), with its shares in the
// report under `stage`'s name, written as `file` (16-bit, linear).
StageReport RestoreReflectance(const char* stage_name, const AlbedoResult& a,
                               const cv::Mat& page_mask, const RestoreResult& restored,
                               const ScanContext& context, const std::string& results,
                               const std::string& page, const std::string& file,
                               const std::string& model, const char* dim_key, RestoreResult* out) {
  Stage stage(stage_name, page);
  StageReport& r = stage.report();
  if (!a.status.ok()) return stage.Finish(a.status);
  const double page_px = std::max(1, cv::countNonZero(page_mask));
  r.Number(stage_name, "estimated_share", a.estimated / page_px);
  r.Number(stage_name, "marked_unmeasured_share", a.shadowed / page_px);
  r.Number(stage_name, "marked_rim_share", a.rim / page_px);
  r.Number(stage_name, dim_key, a.grazing / page_px);
  r.Number(stage_name, "marked_outside_flat_field_share", a.outside_flat_field / page_px);
  cv::Mat above = a.albedo > 1.0f;  // In any channel.
  if (above.channels() == 3) {
    std::vector<cv::Mat> channels;
    cv::split(above, channels);
    above = channels[0] | channels[1] | channels[2];
  }
  r.Number(stage_name, "above_one_share", cv::countNonZero(above & a.valid) / page_px);
  // The reflectance through the page's own warp, its marked pixels NaN: a restored pixel that
  // drew on any marked camera pixel comes out NaN, marked too, as does one off the sheet (one
  // pass, not a second one for where it holds).
  std::vector<cv::Mat> through;
  const Status warped = RestoreMore(restored, {MarkedAsNaN(a)}, &through, std::nan(""));
  if (!warped.ok()) return stage.Finish(warped);
  *out = restored;  // Its view, dpi, map, mask and sampling.
  out->extras.clear();
  cv::Mat measured = through[0] == through[0];  // Not NaN, in every channel.
  if (measured.channels() == 3) {
    std::vector<cv::Mat> channels;
    cv::split(measured, channels);
    measured = channels[0] & channels[1] & channels[2];
  }
  through[0].setTo(cv::Scalar::all(0), measured == 0);
  // 16-bit, linear; saturates above 1 (gloss, fluorescence).
  through[0].convertTo(out->image, CV_16U, 65535.0);
  const cv::Scalar mean = cv::mean(out->image, measured);  // Over the channels, too.
  const int channels = out->image.channels();
  r.Number(stage_name, "mean",
           (channels == 3 ? (mean[0] + mean[1] + mean[2]) / 3 : mean[0]) / 65535.0);
  const std::string dir = PageDir(results, page);
  Status s = MakeDirectories(dir);
  if (s.ok()) {
    const ScanIdentity& identity = context.identity;
    std::map<std::string, std::string> figures;
    figures["view"] = ToString(out->view);
    if (out->view == RestoreView::kOrthographic) figures["dpi"] = JsonNumber(out->dpi).dump();
    figures["model"] = model;
    s = stage.Output(
        PageFile(page, file),
        WriteRestoredAlbedo(dir, *out, page.empty() ? identity : PageIdentity(identity, page),
                            figures, file));
  }
  return stage.Finish(s);
}

}  // namespace

StageReport AlbedoStage(const ScanWork& work, const PipelineOptions& o, PageResult* p) {
  return RestoreReflectance(
      "albedo",
      EstimateAlbedo(work.amplitude, work.map.points, p->mask, work.calibration, o.flat_field),
      p->mask, p->restored, work.context, work.results, p->name, "restored_albedo.tif",
      "Lambertian, lit by the projector alone (white less black), its flat field from a white "
      "target on the table; interreflection and gloss not modelled",
      "marked_grazing_share", &p->albedo);
}

StageReport ReflectanceStage(const ScanWork& work, const PipelineOptions& o, PageResult* p) {
  return RestoreReflectance(
      "reflectance",
      CorrectTexture(work.scan.texture, work.map.points, p->mask, work.calibration, o.studio_field),
      p->mask, p->restored, work.context, work.results, p->name, "restored_reflectance.tif",
      "Lambertian, lit by the described studio lamps (point sources of equal strength), their "
      "field from a white target on the table; shadows the page casts on itself, "
      "interreflection and gloss not modelled",
      "marked_dim_share", &p->reflectance);
}

StageReport LightsStage(const ScanWork& work, const PipelineOptions& o, PageResult* p) {
  const std::vector<ScanLight>& lights = work.scan.lights;
  const cv::Mat& page_mask = p->mask;
  const Mesh& mesh = p->mesh;
  const std::vector<cv::Point2d>& flat = p->flat.flat;
  const IccProfile& camera_icc = o.camera_icc;
  const RestoreResult& restored = p->restored;
  const ScanContext& context = work.context;
  const std::string& results = work.results;
  const std::string& page = p->name;
  LightsResult* out = &p->lights;
  Stage stage("lights", page);
  StageReport& r = stage.report();
  *out = LightsResult();
  // The lights of known direction give the normals, in the camera's pixels.
  std::vector<cv::Mat> directed;
  std::vector<cv::Vec3d> directions;
  for (const ScanLight& light : lights) {
    if (light.directed()) directed.push_back(light.image), directions.push_back(light.direction);
  }
  const bool photometric = directed.size() >= 3 && restored.view == RestoreView::kOrthographic;
  std::vector<cv::Mat> extras;
  for (const ScanLight& light : lights) extras.push_back(light.image);
  const double page_px = std::max(1, cv::countNonZero(page_mask));
  if (photometric) {
    const PhotometricResult normals = PhotometricNormals(directed, directions, page_mask);
    if (!normals.status.ok()) return stage.Finish(normals.status);
    r.Number("normals", "solved_share", normals.solved / page_px);
    r.Number("normals", "lights", static_cast<double>(directed.size()));
    extras.push_back(normals.normals);
  }
  // Through the page's own warp.
  std::vector<cv::Mat> images;
  const Status warped = RestoreMore(restored, extras, &images);
  if (!warped.ok()) return stage.Finish(warped);
  const std::string dir = PageDir(results, page);
  Status s = MakeDirectories(dir);
  const ScanIdentity& identity = context.identity;
  const ScanIdentity page_identity = page.empty() ? identity : PageIdentity(identity, page);
  std::map<std::string, std::string> figures;
  figures["view"] = ToString(restored.view);
  if (restored.view == RestoreView::kOrthographic) figures["dpi"] = JsonNumber(restored.dpi).dump();
  for (size_t k = 0; k < lights.size() && s.ok(); ++k) {
    std::map<std::string, std::string> light_figures = figures;
    if (lights[k].directed()) {
      const cv::Vec3d& d = lights[k].direction;
      light_figures["direction"] =
          JsonNumber(d[0]).dump() + " " + JsonNumber(d[1]).dump() + " " + JsonNumber(d[2]).dump();
    }
    if (!restored.mask.empty()) images[k].setTo(0, restored.mask == 0);
    // The camera's profile where it fits the light's image (a colour UV shot of a gray
    // camera's scan takes sRGB).
    const bool fits = camera_icc.empty() || camera_icc.channels == images[k].channels();
    s = stage.Output(PageFile(page, "lights/" + lights[k].name + ".tif"),
                     WriteRestoredLight(dir, lights[k].name, images[k], restored, page_identity,
                                        light_figures, fits ? camera_icc : IccProfile()));
    out->names.push_back(lights[k].name);
    out->images.push_back(images[k]);
  }
  const SheetFrame frame = photometric ? RestoredSheetFrame(mesh, flat, restored) : SheetFrame();
  if (s.ok() && directed.size() >= 6 && photometric) {
    // The page relit at will in an RTI viewer: a PTM of the flat page from the directed lights.
    std::vector<cv::Mat> lit;
    for (size_t k = 0; k < lights.size(); ++k) {
      if (lights[k].directed()) lit.push_back(images[k]);
    }
    out->ptm = FitPtm(lit, directions, frame.right, frame.up);
    if (out->ptm.status.ok()) {
      if (!restored.mask.empty()) out->ptm.valid.setTo(0, restored.mask == 0);
      const double leaf_px = restored.mask.empty() ? static_cast<double>(restored.image.total())
                                                   : std::max(1, cv::countNonZero(restored.mask));
      r.Number("ptm", "solved_share", cv::countNonZero(out->ptm.valid) / leaf_px);
      r.Number("ptm", "lights", static_cast<double>(lit.size()));
      s = stage.Output(PageFile(page, "lights.ptm"),
                       WritePtm((fs::path(dir) / "lights.ptm").string(), out->ptm));
    } else {
      r.Text("ptm", "not_written", out->ptm.status.message());
    }
  }
  if (s.ok() && photometric) {
    out->normals = NormalsOnPage(images.back(), frame.right, frame.up, frame.normal);
    out->normals.setTo(0, restored.mask.empty() ? cv::Mat() : restored.mask == 0);
    figures["model"] =
        "photometric stereo: Lambertian, distant lights of equal strength, a linear camera; "
        "normals in the flat page's frame";
    s = stage.Output(
        PageFile(page, "normals.tif"),
        WriteNormalMap(dir, NormalMapImage(out->normals), restored, page_identity, figures));
    if (s.ok()) s = stage.Picture(results, "relief", ReliefPicture(out->normals));
  }
  return stage.Finish(s);
}

}  // namespace vellum
