// Warped pages for the virtual gantry. Every shape but kBump is an isometric (developable)
// deformation of the flat page, so the true flat page coordinate of every surface point is
// known exactly: generalised cylinders (curl, fold, ripple, a book's page at the gutter) and a
// cone. A leaf has a thickness (it lies that far above what it rests on) and an outline: a
// rectangle, or the irregular edge and holes of a fire-damaged leaf.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace vellum {

enum class PageShape {
  kFlat,    // Lies on the table.
  kCurl,    // Binder curl: flat, then one side rolls up on a circular arc.
  kFold,    // Rounded diagonal fold: a ridge along a diagonal, resting on its edges.
  kCone,    // Rests on one generator of a cone and rises on both sides.
  kBump,    // Flat with a Gaussian bubble (not developable: real vellum).
  kRipple,  // Ripples across the page: arcs of alternating curvature, steep slopes.
  kGutter,  // A page of an open book in a cradle: flat, then bending down into the gutter.
  // Any generalised cylinder: a chain of constant-curvature segments (PageOptions::profile)
  // across the page from its edge, at any angle (random developable sheets, captured shapes).
  kProfile,
};

enum class OutlineKind {
  kRectangle,  // The whole page.
  kBurnt,      // Edges eaten away irregularly (up to burn_depth_mm), and holes.
};

const char* ToString(PageShape shape);
bool ParsePageShape(const std::string& text, PageShape* shape);

struct PageOptions {
  PageShape shape = PageShape::kFlat;
  cv::Size2d size_mm{190.0, 240.0};  // Page width (s) and height (t), mm.
  cv::Vec2d centre_mm{0.0, 0.0};     // World x, y of the flat page's centre, mm.
  double curl_radius_mm = 60.0;      // kCurl: radius of the rolled part, mm.
  double curl_length_mm = 70.0;      // kCurl: arc length of the rolled part, mm.
  double fold_angle_deg = 35.0;      // kFold: fold line direction from the page's s axis.
  double fold_radius_mm = 15.0;      // kFold: radius of the rounded ridge, mm.
  double fold_slope_deg = 12.0;      // kFold: slope of each flank, degrees.
  bool fold_valley = false;  // kFold: the fold is a valley (a V, lowest along it), not a ridge.
  double cone_half_angle_deg = 35.0;     // kCone: cone half-angle, degrees.
  double cone_apex_distance_mm = 250.0;  // kCone: apex distance below the page's t = 0 edge.
  double bump_height_mm = 3.0;           // kBump: peak height, mm.
  double bump_sigma_mm = 25.0;           // kBump: Gaussian sigma, mm.
  double ripple_period_mm = 60.0;        // kRipple: one ripple every this much across, mm.
  double ripple_slope_deg = 50.0;        // kRipple: steepest slope, degrees.
  bool gutter_left = false;              // kGutter: the gutter is at the s = 0 edge (else s = w).
  double gutter_radius_mm = 45.0;        // kGutter: radius of the bend into the gutter, mm.
  double gutter_angle_deg = 70.0;        // kGutter: how far the page turns down, degrees.
  // kProfile: the profile's segments from the page's edge across it, each (length mm,
  // curvature 1/mm; positive turns up), continued straight past the last; the direction across
  // is profile_angle_deg from the page's s axis. The lowest point rests on the base.
  std::vector<cv::Vec2d> profile;
  double profile_angle_deg = 0.0;
  double thickness_mm = 0.2;  // The leaf's thickness: it lies this far above its base.
  double base_mm = 0.0;       // Height of what it rests on (a support's top), mm.
  OutlineKind outline = OutlineKind::kRectangle;
  double burn_depth_mm = 10.0;  // kBurnt: the deepest the edges are eaten, mm.
  int holes = 3;                // kBurnt: holes burnt through the leaf.
  uint64_t outline_seed = 1;    // kBurnt: the same seed gives the same outline.
  // An embossed line (a ruling, a pricking line) across the page at t = ridge_t_mm, along s: a
  // Gaussian ridge of this height and sigma, mm. It is in the page's normal (the shading: what a
  // raking light shows) only, not in its points: its height is below what the structured light
  // resolves. 0: none.
  double ridge_height_mm = 0.0;
  double ridge_t_mm = 0.0;
  double ridge_sigma_mm = 0.5;
  // A rigid motion applied after the shape (a calibration board held in a pose above the
  // table): world = pose_rotation * shaped point + pose_translation.
  cv::Matx33d pose_rotation = cv::Matx33d::eye();
  cv::Vec3d pose_translation{0.0, 0.0, 0.0};

  bool Check(std::string* why) const;
};

// The rotation of a page pose: about x, then y, then z (degrees), R = Rz Ry Rx.
cv::Matx33d PoseRotation(double rx_deg, double ry_deg, double rz_deg);

class Page {
 public:
  // Options that fail their Check() throw std::invalid_argument.
  explicit Page(const PageOptions& options);

  const PageOptions& options() const { return options_; }
  // World point (mm) of flat page coordinate (s, t) in [0, width] x [0, height], mm.
  cv::Vec3d Point(double s, double t) const;
  // Unit surface normal with +z component (towards the camera), by central differences; with
  // the relief (ridge_height_mm) when `relief`.
  cv::Vec3d Normal(double s, double t, bool relief = true) const;
  // Whether (s, t) is leaf: inside the page and its outline, not in a hole.
  bool Contains(double s, double t) const;

 private:
  // The shape's point before the pose.
  cv::Vec3d ShapePoint(double s, double t) const;
  // Generalised cylinder profile: arc-length sigma across the ridge -> (across, z).
  cv::Vec2d Profile(double sigma) const;

  struct Segment {
    double length, curvature;
  };
  PageOptions options_;
  std::vector<Segment> forward_, backward_;  // Profile segments for sigma >= 0 and sigma < 0.
  cv::Vec2d across_dir_{1.0, 0.0};           // Page direction of increasing sigma.
  double sigma_origin_ = 0.0;                // Page sigma of the profile's reference point.
  double z_offset_ = 0.0;                    // Lifts the shape so its lowest point is z = 0.
  // kBurnt: how deep each edge is eaten, as a function of the position along it (sums of
  // sinusoids, >= 0): [0] s = 0, [1] s = w (along t); [2] t = 0, [3] t = h (along s).
  struct Wave {
    double amplitude, frequency, phase;
  };
  std::vector<Wave> burn_[4];
  struct Hole {
    cv::Vec2d centre;
    double radius;
    std::vector<Wave> rim;  // Relative radius as a function of the angle.
  };
  std::vector<Hole> holes_;
};

}  // namespace vellum
