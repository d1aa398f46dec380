// The flattening sheet (Brown & Seales 2004, sections 3.5-3.6 and 4: a 45 x 45 grid of
// particles sampled from the measured surface, structural and shear springs per quad, rest
// lengths from the measured 3D distances; here measured along the surface where it bends).
#pragma once

#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace vellum {

struct MeshOptions {
  cv::Size grid{45, 45};    // Nodes across and down (each >= 2, up to 1000).
  int min_points = 12;      // Valid page points a node's local fit needs.
  double fit_window = 0.6;  // Node fit window half-size, in grid cells (>= 2 px).
  // A node whose window's points scatter about its fit by more than this (RMS) is a hole, filled
  // from the nodes around it: its window straddles the leaf's silhouette and what lies far behind
  // it (a leaf standing 190 mm above the table, seen edge-on at its corner: 20-37 mm), and its fit
  // would stand in mid-air. On the scene family's met scans the worst node scatters 0.63 mm (its
  // window across a sharp crease, which the quadratic rounds).
  double max_fit_rms_mm = 5.0;
  int skirt_rings = 1;        // Rings of extrapolated nodes around the page (covers its edge).
  bool bend_springs = false;  // Also springs two nodes apart (bending resistance).
  // A spring's rest length is the leaf's length between its nodes measured along the surface
  // (the point map between them, halved until each piece is straight), not the chord: a crease
  // between two nodes shortens the chord by up to a fifth of a cell, and the page with it. A
  // spring is measured so when the nodes' own fits put the surface at its middle off its chord
  // by more than a bend of `min_bend_deg` either side would (fainter bends cost under 0.1% of
  // the chord; the point map's small faults, such as a depth bias on dark ink, are not bends);
  // a piece counts as straight when its middle lies within `straight_mm` of its chord, or
  // within five standard errors of the fit that placed it.
  bool rest_along_surface = true;
  double straight_mm = 0.03;  // > 0.
  double min_bend_deg = 3;    // In [0, 45).

  bool Check(std::string* why) const;
};

enum class NodeKind : uint8_t {
  kOff = 0,   // Not part of the sheet.
  kMeasured,  // Fitted from the page's points around it.
  kFilled,    // A page node in a hole of the data (ink, shadow): interpolated.
  kSkirt,     // Just outside the page: the page surface extrapolated, so edge quads exist.
};

enum class SpringKind : uint8_t { kStructural, kShear, kBend };

struct Spring {
  int a = 0, b = 0;
  double rest_mm = 0;
  SpringKind kind = SpringKind::kStructural;
};

struct Mesh {
  Status status = Status::Error("mesh not built");
  int cols = 0, rows = 0;          // Grid size; node (i, j) has index j * cols + i.
  std::vector<NodeKind> kind;      // Per node.
  std::vector<cv::Point2d> pixel;  // Camera pixel of the node (its point's projection).
  std::vector<cv::Vec3d> point;    // 3D position, world frame, mm.
  std::vector<Spring> springs;     // Between active nodes.
  std::vector<cv::Vec4i> quads;    // Active quads, node indices (i,j) (i+1,j) (i+1,j+1) (i,j+1).
  int measured = 0, filled = 0, skirt = 0;

  int Index(int i, int j) const { return j * cols + i; }
  bool Active(int n) const { return kind[n] != NodeKind::kOff; }
};

// The page in the texture image: brighter than `fraction` of the bright level (98th
// percentile), holes (ink) filled, the largest region. A page on a darker table is assumed.
// With largest_only false: every bright region, ink bridged but holes not filled.
cv::Mat SegmentPage(const cv::Mat& texture, double fraction = 0.6, bool largest_only = true);

// Builds the sheet over the page mask's bounding box from an organised point map (CV_32FC3,
// NaN where invalid). `project` maps a world point to its camera pixel.
Mesh BuildMesh(const cv::Mat& points, const cv::Mat& page_mask, const MeshOptions& options,
               const std::function<cv::Point2d(const cv::Vec3d&)>& project);

// How far the sheet's piecewise-linear warp strays from the surface, in camera pixels: nodes
// are evenly spaced in the image but not on the surface, and the interpolation between them
// strays by about an eighth of a cell's pixels times the relative change of the cells' 3D
// lengths from one to the next (along rows and columns); the 90th percentile over the page.
double WarpError(const Mesh& mesh);

// The grid that brings the warp error of `mesh` (built at its grid) to `max_error_px`: the
// error falls as the square of the node spacing. Never coarser than the mesh's grid; at most
// `max_nodes` each way.
cv::Size GridForError(const Mesh& mesh, double max_error_px, int max_nodes = 400);

// The length along the measured surface between two nodes (3D `a`, `b` seen at pixels `pa`, `pb`)
// of a sheet over `points` and `mask`: the chord where the surface between them is straight,
// else the sum over halves (to pieces of two pixels). The chord where the points give out.
double LengthAlongSurface(const cv::Mat& points, const cv::Mat& mask, const cv::Vec3d& a,
                          cv::Point2d pa, const cv::Vec3d& b, cv::Point2d pb, double straight_mm,
                          int depth = 0);

// The sheet's topology from its nodes: given cols, rows, kind and point, sets pixel (the
// projection of each active node), the node counts, the springs (rest lengths from the 3D
// distances) and the quads, and the status. BuildMesh ends with it; a receiver of a sheet
// sent as nodes (the station's FLAT_MESH) rebuilds the same sheet with it.
void ConnectSheet(bool bend_springs, const std::function<cv::Point2d(const cv::Vec3d&)>& project,
                  Mesh* mesh);

}  // namespace vellum
