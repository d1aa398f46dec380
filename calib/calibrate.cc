#include "calib/calibrate.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace vellum {
namespace {

std::string Px(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3f px", v);
  return buf;
}

// The board's corners in its own frame, mm, in the detector's row-major order.
std::vector<cv::Point3f> BoardPoints(const BoardSpec& board) {
  std::vector<cv::Point3f> points;
  for (int j = 0; j < board.inner_corners.height; ++j) {
    for (int i = 0; i < board.inner_corners.width; ++i) {
      points.emplace_back(static_cast<float>(i * board.square_mm),
                          static_cast<float>(j * board.square_mm), 0.0f);
    }
  }
  return points;
}

// Sign of the board's handedness as an image sees it: +1 or -1 (the turn from the board's
// first row to its first column).
int Handedness(const std::vector<cv::Point2f>& c, const BoardSpec& board) {
  const cv::Point2f a = c[0], b = c[board.inner_corners.width - 1],
                    d = c[static_cast<size_t>(board.inner_corners.height - 1) *
                          board.inner_corners.width];
  const double cross = (b.x - a.x) * (d.y - a.y) - (b.y - a.y) * (d.x - a.x);
  return cross >= 0 ? 1 : -1;
}

// RMS distance between image points and the board projected through a device's model.
double ReprojectionRms(const std::vector<cv::Point3f>& object,
                       const std::vector<cv::Point2f>& image, const cv::Mat& k, const cv::Mat& d,
                       const cv::Mat& rvec, const cv::Mat& tvec) {
  std::vector<cv::Point2f> projected;
  cv::projectPoints(object, rvec, tvec, k, d, projected);
  double sum = 0;
  for (size_t i = 0; i < image.size(); ++i) {
    const cv::Point2f e = projected[i] - image[i];
    sum += e.dot(e);
  }
  return image.empty() ? 0 : std::sqrt(sum / image.size());
}

// The grid's corners renumbered as the grid turned by `turns` quarter turns: a W x H grid,
// row-major, becomes H x W for odd turns. A turn keeps the board's handedness.
std::vector<cv::Point2f> TurnGrid(const std::vector<cv::Point2f>& c, cv::Size size, int turns,
                                  cv::Size* turned) {
  const int w = size.width, h = size.height;
  *turned = turns % 2 ? cv::Size(h, w) : size;
  std::vector<cv::Point2f> out;
  out.reserve(c.size());
  for (int jn = 0; jn < turned->height; ++jn) {
    for (int in = 0; in < turned->width; ++in) {
      int i = in, j = jn;  // The corner's place in the grid as detected.
      if (turns == 1) i = jn, j = h - 1 - in;
      if (turns == 2) i = w - 1 - in, j = h - 1 - jn;
      if (turns == 3) i = w - 1 - jn, j = in;
      out.push_back(c[static_cast<size_t>(j) * w + i]);
    }
  }
  return out;
}

// The quarter turns (of those with the parity `parity`, or any for -1) that make the grid's
// first row run most nearly along the image's +x.
int TurnsAlongImageX(const std::vector<cv::Point2f>& c, cv::Size size, int parity) {
  int best = 0;
  double best_cos = -2;
  for (int turns = 0; turns < 4; ++turns) {
    if (parity >= 0 && turns % 2 != parity) continue;
    cv::Size turned;
    const std::vector<cv::Point2f> t = TurnGrid(c, size, turns, &turned);
    const cv::Point2f row = t[turned.width - 1] - t[0];
    const double cos = row.x / std::max(1e-9, std::hypot(double{row.x}, double{row.y}));
    if (cos > best_cos) best_cos = cos, best = turns;
  }
  return best;
}

CameraModel ToModel(cv::Size size, const cv::Mat& k, const cv::Mat& d, const cv::Matx33d& r,
                    const cv::Vec3d& t) {
  CameraModel m;
  m.size = size;
  m.matrix = cv::Matx33d(k);
  for (int i = 0; i < 5; ++i) {
    m.distortion[i] = static_cast<size_t>(i) < d.total() ? d.at<double>(i) : 0.0;
  }
  m.rotation = r;
  m.translation = t;
  return m;
}

}  // namespace

bool CalibrateOptions::Check(std::string* why) const {
  if (!(window_squares > 0) || min_window_points < 6 || min_views < 2 ||
      !(warn_reprojection_px > 0) || !(max_reprojection_px >= warn_reprojection_px) ||
      !(same_pose_px >= 0) || !(outlier_factor > 1) || !(outlier_floor_px >= 0)) {
    *why =
        "calibrate: window_squares and warn_reprojection_px must be > 0, min_window_points >= 6, "
        "min_views >= 2, max_reprojection_px >= warn_reprojection_px, same_pose_px and "
        "outlier_floor_px >= 0, outlier_factor > 1";
    return false;
  }
  return decode.Check(why);
}

BoardView DetectBoard(const Scan& scan, const BoardSpec& board, const std::string& name,
                      const CalibrateOptions& options) {
  BoardView view;
  view.name = name;
  view.camera_size = scan.texture.size();
  view.projector_size = scan.sequence.projector_size;
  const std::string where = name + ": ";
  if (std::string why; !options.Check(&why)) {
    view.status = Status::Error(where + why);
    return view;
  }
  cv::Mat gray = scan.texture;
  if (gray.channels() == 3) cv::cvtColor(gray, gray, cv::COLOR_BGR2GRAY);
  std::vector<cv::Point2f> corners;
  const bool found = cv::findChessboardCornersSB(gray, board.inner_corners, corners,
                                                 cv::CALIB_CB_EXHAUSTIVE | cv::CALIB_CB_ACCURACY);
  if (!found || corners.size() != static_cast<size_t>(board.inner_corners.area())) {
    view.status = Status::Error(where + "no board of " + std::to_string(board.inner_corners.width) +
                                "x" + std::to_string(board.inner_corners.height) +
                                " inner corners found in the texture");
    return view;
  }
  Decoder decoder(options.decode);
  DecodeResult decoded;
  decoder.Decode(scan.sequence, scan.frames, &decoded);
  if (!decoded.status.ok()) {
    view.status = Status::Error(where + decoded.status.message());
    return view;
  }
  if (!decoded.has_columns || !decoded.has_rows) {
    view.status = Status::Error(where +
                                "the pattern sequence must encode projector columns and "
                                "rows (a projector calibration needs both)");
    return view;
  }
  // The window: about half a square around each corner, from the corners' own spacing.
  double spacing = 0;
  for (int j = 0; j < board.inner_corners.height; ++j) {
    for (int i = 0; i + 1 < board.inner_corners.width; ++i) {
      const size_t k = static_cast<size_t>(j) * board.inner_corners.width + i;
      spacing += cv::norm(corners[k + 1] - corners[k]);
    }
  }
  spacing /= (board.inner_corners.width - 1) * board.inner_corners.height;
  const int half = std::max(3, static_cast<int>(std::lround(options.window_squares * spacing)));
  int unlit = 0;
  std::vector<cv::Point2f> projector(corners.size());
  std::vector<cv::Point2f> from, to;
  for (size_t k = 0; k < corners.size(); ++k) {
    from.clear();
    to.clear();
    const int cx = static_cast<int>(std::lround(corners[k].x)),
              cy = static_cast<int>(std::lround(corners[k].y));
    for (int v = std::max(0, cy - half); v <= std::min(gray.rows - 1, cy + half); ++v) {
      const float* px = decoded.projector_x.ptr<float>(v);
      const float* py = decoded.projector_y.ptr<float>(v);
      for (int u = std::max(0, cx - half); u <= std::min(gray.cols - 1, cx + half); ++u) {
        if (std::isnan(px[u]) || std::isnan(py[u])) continue;
        from.emplace_back(static_cast<float>(u), static_cast<float>(v));
        to.emplace_back(px[u], py[u]);
      }
    }
    if (static_cast<int>(from.size()) < options.min_window_points) {
      ++unlit;
      continue;
    }
    const cv::Mat h = cv::findHomography(from, to, 0);
    if (h.empty()) {
      ++unlit;
      continue;
    }
    std::vector<cv::Point2f> mapped;
    cv::perspectiveTransform(std::vector<cv::Point2f>{corners[k]}, mapped, h);
    projector[k] = mapped[0];
  }
  if (unlit > 0) {
    view.status = Status::Error(
        where + "the projector lights only " + std::to_string(corners.size() - unlit) + " of " +
        std::to_string(corners.size()) + " board corners (each needs " +
        std::to_string(options.min_window_points) +
        " decoded pixels around it): move the board into the projector's light");
    return view;
  }
  view.camera_corners = std::move(corners);
  view.projector_corners = std::move(projector);
  view.status = Status::Ok();
  return view;
}

namespace {

// One solve from a set of poses: both devices' intrinsics, their relative pose, the world frame
// from the table pose, and each pose's errors.
struct PoseSolve {
  Calibration calibration;
  double camera_rms_px = 0, projector_rms_px = 0, stereo_rms_px = 0;
  std::vector<double> camera_px, projector_px;  // Per pose, in the order given.
};

Status SolvePoses(const std::vector<cv::Point3f>& object,
                  const std::vector<std::vector<cv::Point2f>>& cam,
                  const std::vector<std::vector<cv::Point2f>>& proj, size_t table,
                  cv::Size camera_size, cv::Size projector_size, PoseSolve* out) {
  const std::vector<std::vector<cv::Point3f>> objects(cam.size(), object);
  const int flags = cv::CALIB_FIX_K3;
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12);
  cv::Mat kc, dc, kp, dp, std_in, std_ex, errors_c, errors_p;
  std::vector<cv::Mat> rc, tc, rp, tp;
  try {
    out->camera_rms_px = cv::calibrateCamera(objects, cam, camera_size, kc, dc, rc, tc, std_in,
                                             std_ex, errors_c, flags, criteria);
    out->projector_rms_px = cv::calibrateCamera(objects, proj, projector_size, kp, dp, rp, tp,
                                                std_in, std_ex, errors_p, flags, criteria);
    cv::Mat r, t, e, f;
    out->stereo_rms_px = cv::stereoCalibrate(objects, cam, proj, kc, dc, kp, dp, camera_size, r, t,
                                             e, f, cv::CALIB_FIX_INTRINSIC, criteria);
    // World frame from the table pose: the board's frame turned over (x kept, y and z
    // reversed) when its z axis points away from the camera, so that +z is up.
    cv::Matx33d rb;
    cv::Rodrigues(rc[table], rb);
    const cv::Vec3d tb(tc[table]);
    const cv::Vec3d camera_in_board = -(rb.t() * tb);
    const cv::Matx33d flip =
        camera_in_board[2] < 0 ? cv::Matx33d(1, 0, 0, 0, -1, 0, 0, 0, -1) : cv::Matx33d::eye();
    const cv::Matx33d r_cw = rb * flip;
    const cv::Matx33d r_pc(r);
    const cv::Vec3d t_pc(t);
    out->calibration.camera = ToModel(camera_size, kc, dc, r_cw, tb);
    out->calibration.projector = ToModel(projector_size, kp, dp, r_pc * r_cw, r_pc * tb + t_pc);
    out->camera_px.clear();
    out->projector_px.clear();
    for (size_t n = 0; n < cam.size(); ++n) {
      out->camera_px.push_back(ReprojectionRms(object, cam[n], kc, dc, rc[n], tc[n]));
      out->projector_px.push_back(ReprojectionRms(object, proj[n], kp, dp, rp[n], tp[n]));
    }
  } catch (const cv::Exception& e) {
    return Status::Error(std::string("calibration failed in OpenCV: ") + e.what());
  }
  return Status::Ok();
}

// The projector's pose relative to the camera: how far two calibrations differ, in degrees and
// mm (independent of the world frame's gauge).
void RelativePoseChange(const Calibration& a, const Calibration& b, double* deg, double* mm) {
  const cv::Matx33d ra = a.projector.rotation * a.camera.rotation.t();
  const cv::Matx33d rb = b.projector.rotation * b.camera.rotation.t();
  const cv::Vec3d ta = a.projector.translation - ra * a.camera.translation;
  const cv::Vec3d tb = b.projector.translation - rb * b.camera.translation;
  const cv::Matx33d d = ra * rb.t();
  *deg = std::acos(std::clamp((cv::trace(d) - 1) / 2, -1.0, 1.0)) * 180.0 / M_PI;
  *mm = cv::norm(ta - tb);
}

// How well a solve without a pose predicts it: the board's pose from the pose's camera corners
// (the solve's camera), carried to the projector by the solve's camera-to-projector motion,
// against the pose's projector corners (RMS px). A pose that moved between its texture and its
// patterns, or whose projector corners are off, is predicted badly even when each device alone
// fits it (a uniform offset is absorbed by that pose's own extrinsics).
double HeldOutError(const Calibration& without, const std::vector<cv::Point3f>& object,
                    const std::vector<cv::Point2f>& cam, const std::vector<cv::Point2f>& proj) {
  const cv::Mat kc(without.camera.matrix), dc(without.camera.distortion);
  const cv::Mat kp(without.projector.matrix), dp(without.projector.distortion);
  cv::Mat rvec, tvec;
  if (!cv::solvePnP(object, cam, kc, dc.t(), rvec, tvec)) return 1e9;
  cv::Matx33d rb;
  cv::Rodrigues(rvec, rb);
  const cv::Matx33d r_pc = without.projector.rotation * without.camera.rotation.t();
  const cv::Vec3d t_pc = without.projector.translation - r_pc * without.camera.translation;
  cv::Mat rp;
  cv::Rodrigues(cv::Mat(r_pc * rb), rp);
  const cv::Vec3d tp = r_pc * cv::Vec3d(tvec) + t_pc;
  return ReprojectionRms(object, proj, kp, dp.t(), rp, cv::Mat(tp).clone());
}

// The scale at which `c` measures one pose's board: its corners triangulated (the camera's ray
// against the projector's, the midpoint where they pass closest), and the ratio of their spread
// about their centroid to the board layout's (the scale of the best similarity between them): 1
// when the calibration measures lengths truly. NaN when fewer than 3 corners triangulate.
double MeasuredScale(const Calibration& c, const std::vector<cv::Point3f>& object,
                     const std::vector<cv::Point2f>& cam, const std::vector<cv::Point2f>& proj) {
  const cv::Vec3d oc = c.camera.Center(), op = c.projector.Center(), w = oc - op;
  std::vector<cv::Vec3d> points, board;
  for (size_t k = 0; k < cam.size() && k < proj.size() && k < object.size(); ++k) {
    const cv::Vec3d a = c.camera.RayDirection(cam[k]), b = c.projector.RayDirection(proj[k]);
    const double aa = a.dot(a), ab = a.dot(b), bb = b.dot(b), aw = a.dot(w), bw = b.dot(w);
    const double den = aa * bb - ab * ab;
    if (!(std::fabs(den) > 1e-12)) continue;  // Parallel rays (or NaN): no point.
    const double s = (ab * bw - bb * aw) / den, t = (aa * bw - ab * aw) / den;
    points.push_back(0.5 * ((oc + s * a) + (op + t * b)));
    board.emplace_back(object[k].x, object[k].y, object[k].z);
  }
  if (points.size() < 3) return std::nan("");
  cv::Vec3d pc(0, 0, 0), bc(0, 0, 0);
  for (size_t k = 0; k < points.size(); ++k) {
    pc += points[k] / static_cast<double>(points.size());
    bc += board[k] / static_cast<double>(points.size());
  }
  double ps = 0, bs = 0;
  for (size_t k = 0; k < points.size(); ++k) {
    ps += (points[k] - pc).dot(points[k] - pc);
    bs += (board[k] - bc).dot(board[k] - bc);
  }
  return bs > 0 ? std::sqrt(ps / bs) : std::nan("");
}

double Median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

double BoardScale(const Calibration& calibration, const BoardSpec& board, const BoardView& view) {
  return MeasuredScale(calibration, BoardPoints(board), view.camera_corners,
                       view.projector_corners);
}

namespace {

// The board poses a solve uses: each pose's camera and projector corners (in the board's
// order), which of `views` each is, and the table pose's index among them.
struct Poses {
  std::vector<cv::Point3f> object;  // The board's corners, mm.
  std::vector<std::vector<cv::Point2f>> cam, proj;
  std::vector<size_t> used;  // Index into the views of each.
  size_t table = 0;          // Of cam, proj, used.
  cv::Size camera_size, projector_size;
  int mirrored = 0;  // Poses whose projector corners run the other way round from the camera's.
};

// The usable poses of `views` (each pose's status in sol->views): the board's size, one camera
// and projector size, not the same pose twice.
Poses GatherPoses(const std::vector<BoardView>& views, const BoardSpec& board,
                  const CalibrateOptions& options, CalibrationSolution* sol) {
  Poses p;
  p.object = BoardPoints(board);
  const std::vector<cv::Point3f>& object = p.object;
  sol->views.resize(views.size());
  for (size_t i = 0; i < views.size(); ++i) {
    const BoardView& v = views[i];
    ViewReport& r = sol->views[i];
    r.name = v.name;
    r.status = v.status;
    if (!v.status.ok()) continue;
    if (v.camera_corners.size() != object.size() || v.projector_corners.size() != object.size()) {
      r.status = Status::Error(v.name + ": corners do not match the board size");
      continue;
    }
    if (p.used.empty()) {
      p.camera_size = v.camera_size;
      p.projector_size = v.projector_size;
    } else if (v.camera_size != p.camera_size || v.projector_size != p.projector_size) {
      r.status = Status::Error(v.name + ": camera or projector size differs from the first pose's");
      continue;
    }
    // The same pose twice (one folder given twice, or a board not moved between captures)
    // adds no constraint and biases the solve towards it: refused, naming the first.
    const auto same = std::find_if(p.used.begin(), p.used.end(), [&](size_t u) {
      double sum = 0;
      for (size_t k = 0; k < object.size(); ++k) {
        const cv::Point2f d = views[u].camera_corners[k] - v.camera_corners[k];
        sum += d.dot(d);
      }
      return std::sqrt(sum / object.size()) < options.same_pose_px;
    });
    if (same != p.used.end()) {
      r.status = Status::Error(v.name + ": the same pose as " + views[*same].name +
                               " (its corners within " + Px(options.same_pose_px) +
                               "); refused: move the board between poses");
      continue;
    }
    p.mirrored += Handedness(v.camera_corners, board) != Handedness(v.projector_corners, board);
    r.corners = static_cast<int>(object.size());
    p.cam.push_back(v.camera_corners);
    p.proj.push_back(v.projector_corners);
    p.used.push_back(i);
  }
  return p;
}

// Whether the poses can be solved: enough of them, the table pose among them, the projector's
// image not mirrored. Sets p->table.
Status CheckPoses(const std::vector<BoardView>& views, size_t table,
                  const CalibrateOptions& options, const CalibrationSolution& sol, Poses* p) {
  std::string reasons;
  for (const ViewReport& r : sol.views) {
    if (!r.status.ok()) reasons += "\n  " + r.status.message();
  }
  const std::vector<size_t>& used = p->used;
  if (static_cast<int>(used.size()) < options.min_views) {
    return Status::Error("only " + std::to_string(used.size()) + " usable board poses of " +
                         std::to_string(views.size()) + " (at least " +
                         std::to_string(options.min_views) + " are needed)" + reasons);
  }
  const auto table_at = std::find(used.begin(), used.end(), table);
  if (table >= views.size() || table_at == used.end()) {
    return Status::Error("the table pose is not usable: " + (table < views.size()
                                                                 ? sol.views[table].status.message()
                                                                 : std::string("no such pose")));
  }
  if (2 * p->mirrored > static_cast<int>(used.size())) {
    return Status::Error(
        "the projector's image reaches the board mirrored (" + std::to_string(p->mirrored) +
        " of " + std::to_string(used.size()) +
        " poses): the projector daemon's --flip does not match the mirror; the calibration "
        "describes the virtual, unmirrored projector, so fix --flip and capture again");
  }
  p->table = static_cast<size_t>(table_at - used.begin());
  return Status::Ok();
}

// The world's x runs along the camera's image rows on the table pose (as the rig's world
// does, and the restored page with it). Each pose's corners are renumbered by the quarter
// turns that make it so: a board size given transposed (COLSxROWS for ROWSxCOLS) solves just
// as well, but with the world, and every restored page, turned a quarter turn; so does a board
// laid on the table turned round. Then the board is taken at its size as it lies, and named.
void TurnToTheTable(const BoardSpec& board, Poses* p, CalibrationSolution* sol) {
  const int table_turns = TurnsAlongImageX(p->cam[p->table], board.inner_corners, -1);
  cv::Size size = board.inner_corners;
  for (size_t n = 0; n < p->cam.size(); ++n) {
    const int turns = n == p->table
                          ? table_turns
                          : TurnsAlongImageX(p->cam[n], board.inner_corners, table_turns % 2);
    p->cam[n] = TurnGrid(p->cam[n], board.inner_corners, turns, &size);
    cv::Size same;
    p->proj[n] = TurnGrid(p->proj[n], board.inner_corners, turns, &same);
  }
  if (size != board.inner_corners) {
    const auto wxh = [](cv::Size s) {
      return std::to_string(s.width) + "x" + std::to_string(s.height);
    };
    sol->warnings.push_back("the board was given as " + wxh(board.inner_corners) +
                            " inner corners, but on the table "
                            "pose its rows run down the camera's image: it lies " +
                            wxh(size) +
                            " (the size given transposed, or the board turned a quarter turn on "
                            "the table); solved as " +
                            wxh(size) + ", so that the world's x runs along the camera's rows");
    BoardSpec turned = board;
    turned.inner_corners = size;
    p->object = BoardPoints(turned);
  }
  sol->board = size;
}

Status Solve(const Poses& p, PoseSolve* solved) {
  return SolvePoses(p.object, p.cam, p.proj, p.table, p.camera_size, p.projector_size, solved);
}

// A pose left out: predicted by the solve without it (HeldOutError), and the projector's pose
// without it against the whole solve's.
struct LeftOut {
  size_t n;
  double error_px, deg, mm;
  double scale;  // MeasuredScale of the pose by the solve without it.
};

// Leave one pose out: each pose (but the table pose, which defines the world), when the
// options ask it and there are poses to spare. A solve that fails leaves its pose out of it.
std::vector<LeftOut> LeaveOneOut(const Poses& p, const PoseSolve& all,
                                 const CalibrateOptions& options) {
  std::vector<LeftOut> out;
  if (!options.leave_one_out || static_cast<int>(p.used.size()) <= options.min_views) return out;
  for (size_t n = 0; n < p.used.size(); ++n) {
    if (n == p.table) continue;
    Poses without_n = p;
    without_n.cam.clear();
    without_n.proj.clear();
    for (size_t m = 0; m < p.used.size(); ++m) {
      if (m == n) continue;
      without_n.cam.push_back(p.cam[m]);
      without_n.proj.push_back(p.proj[m]);
    }
    without_n.table = p.table < n ? p.table : p.table - 1;
    PoseSolve without;
    if (!Solve(without_n, &without).ok()) continue;
    LeftOut l{n, HeldOutError(without.calibration, p.object, p.cam[n], p.proj[n]), 0, 0,
              MeasuredScale(without.calibration, p.object, p.cam[n], p.proj[n])};
    RelativePoseChange(without.calibration, all.calibration, &l.deg, &l.mm);
    out.push_back(l);
  }
  return out;
}

// Outlier poses: predicted far worse than the others (a board that moved or bent, corners
// that are off), or fitted far worse by one device alone (corners that are noisy). Named in
// sol->warnings; returned to be dropped when enough poses remain (the table pose, which
// defines the world frame, is never dropped).
std::vector<size_t> Outliers(const std::vector<BoardView>& views, const Poses& p,
                             const PoseSolve& solved, const std::vector<LeftOut>& left_out,
                             const CalibrateOptions& options, CalibrationSolution* sol) {
  std::vector<double> held;
  for (const LeftOut& l : left_out) held.push_back(l.error_px);
  std::vector<size_t> drop;
  std::vector<std::string> named;
  const double mc = Median(solved.camera_px), mp = Median(solved.projector_px);
  for (size_t n = 0; n < p.used.size(); ++n) {
    const double c = solved.camera_px[n], pr = solved.projector_px[n];
    if ((c > options.outlier_factor * mc && c > options.outlier_floor_px) ||
        (pr > options.outlier_factor * mp && pr > options.outlier_floor_px)) {
      drop.push_back(n);
      named.push_back(views[p.used[n]].name + ": an outlier (camera " + Px(c) + ", projector " +
                      Px(pr) + " against medians " + Px(mc) + ", " + Px(mp) +
                      "): did the board move or bend?");
    }
  }
  if (!held.empty()) {
    const double median = Median(held);
    for (const LeftOut& l : left_out) {
      if (l.error_px > options.outlier_factor * median && l.error_px > options.outlier_floor_px &&
          std::find(drop.begin(), drop.end(), l.n) == drop.end()) {
        drop.push_back(l.n);
        named.push_back(views[p.used[l.n]].name +
                        ": an outlier (the other poses predict its projector corners to " +
                        Px(l.error_px) + ", the median pose to " + Px(median) +
                        "): did the board move or bend?");
      }
    }
  }
  for (size_t k = 0; k < drop.size(); ++k) {
    if (drop[k] != p.table) continue;
    sol->warnings.push_back(named[k] + " It is the table pose, so it is kept: capture it again");
    drop.erase(drop.begin() + static_cast<long>(k));
    named.erase(named.begin() + static_cast<long>(k));
    break;
  }
  const bool can_drop = static_cast<int>(p.used.size() - drop.size()) >= options.min_views;
  for (const std::string& w : named) {
    sol->warnings.push_back(w + (can_drop ? " Dropped from the solve; capture it again"
                                          : " Kept: too few poses to solve without it; "
                                            "capture it again or add poses"));
  }
  if (!can_drop) drop.clear();
  return drop;
}

// The poses without those in `drop` (each marked dropped in sol->views, with its errors).
void DropPoses(const std::vector<BoardView>& views, const std::vector<size_t>& drop,
               const PoseSolve& solved, Poses* p, CalibrationSolution* sol) {
  Poses kept = *p;
  kept.used.clear();
  kept.cam.clear();
  kept.proj.clear();
  for (size_t n = 0; n < p->used.size(); ++n) {
    if (std::find(drop.begin(), drop.end(), n) != drop.end()) {
      ViewReport& r = sol->views[p->used[n]];
      r.status = Status::Error(views[p->used[n]].name + ": dropped, an outlier");
      r.camera_rms_px = solved.camera_px[n];
      r.projector_rms_px = solved.projector_px[n];
      continue;
    }
    if (n == p->table) kept.table = kept.used.size();
    kept.used.push_back(p->used[n]);
    kept.cam.push_back(p->cam[n]);
    kept.proj.push_back(p->proj[n]);
  }
  *p = std::move(kept);
}

// The scale error: each pose's measured scale by the solve without it where there is one, else
// by the whole; their RMS, and the worst pose.
void ScaleError(const std::vector<BoardView>& views, const Poses& p, const PoseSolve& solved,
                const std::vector<LeftOut>& left_out, CalibrationSolution* sol) {
  double sum_squares = 0;
  int scaled = 0;
  for (size_t n = 0; n < p.used.size(); ++n) {
    double scale = MeasuredScale(solved.calibration, p.object, p.cam[n], p.proj[n]);
    for (const LeftOut& l : left_out)
      if (l.n == n) scale = l.scale;
    if (std::isnan(scale)) continue;
    const double error = 100 * (scale - 1);
    sum_squares += error * error;
    ++scaled;
    if (std::fabs(error) >= std::fabs(sol->worst_scale_error_percent)) {
      sol->worst_scale_error_percent = error;
      sol->worst_scale_pose = views[p.used[n]].name;
    }
  }
  if (scaled > 0) {
    sol->scale_error_percent = std::sqrt(sum_squares / scaled);
    sol->calibration.scale_error_percent = sol->scale_error_percent;
  }
}

// The reprojection errors above the warning level, each named, and the first above the limit
// past which the calibration is not written (unless forced).
void JudgeReprojection(const std::vector<BoardView>& views, const Poses& p,
                       const CalibrateOptions& options, CalibrationSolution* sol) {
  const double warn = options.warn_reprojection_px;
  auto check = [&](const std::string& what, double rms) {
    if (rms > warn)
      sol->warnings.push_back(what + " reprojection error " + Px(rms) + " (above " + Px(warn) +
                              ")");
  };
  check("camera", sol->camera_rms_px);
  check("projector", sol->projector_rms_px);
  check("camera-projector stereo", sol->stereo_rms_px);
  for (size_t n : p.used) {
    check(views[n].name + ": camera", sol->views[n].camera_rms_px);
    check(views[n].name + ": projector", sol->views[n].projector_rms_px);
  }
  for (const auto& [what, rms] : {std::pair<const char*, double>{"camera", sol->camera_rms_px},
                                  {"projector", sol->projector_rms_px},
                                  {"stereo", sol->stereo_rms_px}}) {
    if (rms > options.max_reprojection_px && sol->over_limits.empty()) {
      sol->over_limits = std::string(what) + " reprojection error " + Px(rms) +
                         " is above the limit of " + Px(options.max_reprojection_px);
    }
  }
}

}  // namespace

CalibrationSolution SolveCalibration(const std::vector<BoardView>& views, size_t table,
                                     const BoardSpec& board, const CalibrateOptions& options) {
  CalibrationSolution sol;
  if (std::string why; !options.Check(&why)) {
    sol.status = Status::Error(why);
    return sol;
  }
  Poses p = GatherPoses(views, board, options, &sol);
  sol.status = CheckPoses(views, table, options, sol, &p);
  if (!sol.status.ok()) return sol;
  TurnToTheTable(board, &p, &sol);
  PoseSolve solved;
  sol.status = Solve(p, &solved);
  if (!sol.status.ok()) return sol;
  std::vector<LeftOut> left_out = LeaveOneOut(p, solved, options);
  const std::vector<size_t> drop = Outliers(views, p, solved, left_out, options, &sol);
  if (!drop.empty()) {
    DropPoses(views, drop, solved, &p, &sol);
    sol.status = Solve(p, &solved);
    if (!sol.status.ok()) return sol;
    left_out = LeaveOneOut(p, solved, options);
  }
  for (const LeftOut& l : left_out) {
    sol.leave_one_out_deg = std::max(sol.leave_one_out_deg, l.deg);
    if (l.mm >= sol.leave_one_out_mm) {
      sol.leave_one_out_mm = l.mm;
      sol.leave_one_out_pose = views[p.used[l.n]].name;
    }
  }
  sol.calibration = solved.calibration;
  ScaleError(views, p, solved, left_out, &sol);
  sol.camera_rms_px = solved.camera_rms_px;
  sol.projector_rms_px = solved.projector_rms_px;
  sol.stereo_rms_px = solved.stereo_rms_px;
  for (size_t n = 0; n < p.used.size(); ++n) {
    sol.views[p.used[n]].camera_rms_px = solved.camera_px[n];
    sol.views[p.used[n]].projector_rms_px = solved.projector_px[n];
  }
  std::string why;
  if (!sol.calibration.Check(&why)) {
    sol.status = Status::Error("the solved calibration is not valid: " + why);
    return sol;
  }
  sol.views_used = static_cast<int>(p.used.size());
  sol.corners_used = static_cast<int>(p.used.size() * p.object.size());
  JudgeReprojection(views, p, options, &sol);
  sol.status = Status::Ok();
  return sol;
}

std::string FormatCalibrationReport(const CalibrationSolution& s) {
  std::string out;
  char line[512];
  for (const ViewReport& v : s.views) {
    if (v.status.ok()) {
      std::snprintf(line, sizeof(line), "pose %s: %d corners, camera %.3f px, projector %.3f px\n",
                    v.name.c_str(), v.corners, v.camera_rms_px, v.projector_rms_px);
    } else {
      std::snprintf(line, sizeof(line), "pose %s: not used: %s\n", v.name.c_str(),
                    v.status.message().c_str());
    }
    out += line;
  }
  if (s.status.ok()) {
    std::snprintf(line, sizeof(line),
                  "overall: %d poses, %d corners; reprojection RMS camera %.3f px, projector "
                  "%.3f px, stereo %.3f px\n",
                  s.views_used, s.corners_used, s.camera_rms_px, s.projector_rms_px,
                  s.stereo_rms_px);
    out += line;
    const CameraModel& c = s.calibration.camera;
    const CameraModel& p = s.calibration.projector;
    std::snprintf(line, sizeof(line),
                  "camera f = %.2f, %.2f px, centre %.2f, %.2f px, %.1f mm above the table\n"
                  "projector f = %.2f, %.2f px, centre %.2f, %.2f px, at (%.1f, %.1f, %.1f) mm\n",
                  c.matrix(0, 0), c.matrix(1, 1), c.matrix(0, 2), c.matrix(1, 2), c.Center()[2],
                  p.matrix(0, 0), p.matrix(1, 1), p.matrix(0, 2), p.matrix(1, 2), p.Center()[0],
                  p.Center()[1], p.Center()[2]);
    out += line;
    if (!s.leave_one_out_pose.empty()) {
      std::snprintf(line, sizeof(line),
                    "leave one pose out: the projector's pose moves by at most %.3f deg, %.3f mm "
                    "(most without %s)\n",
                    s.leave_one_out_deg, s.leave_one_out_mm, s.leave_one_out_pose.c_str());
      out += line;
    }
    if (!s.worst_scale_pose.empty()) {
      std::snprintf(line, sizeof(line),
                    "scale: lengths on the board measured within %.3f%% RMS over the poses "
                    "(worst %+.3f%%, %s)\n",
                    s.scale_error_percent, s.worst_scale_error_percent, s.worst_scale_pose.c_str());
      out += line;
    }
    if (!s.over_limits.empty()) out += "over the limits: " + s.over_limits + "\n";
  } else {
    out += "not solved: " + s.status.message() + "\n";
  }
  for (const std::string& w : s.warnings) out += "warning: " + w + "\n";
  return out;
}

}  // namespace vellum
