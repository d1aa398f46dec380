// Flying points: the mixed pixels at a silhouette, an occlusion or a leaf's edge, where the
// decoder's window straddles two surfaces and triangulates a point on neither (in mid-air between
// a curled edge and the table behind it). A point is flying when, along some direction (a row, a
// column or a diagonal), it lies off the surface on both sides of it: the surface `reach` to
// 2 * `reach` pixels away on each side (past the decoder's window), extrapolated linearly to the
// point, misses it by more than `max_off_mm` plus that side's own bend (its second difference
// one step further out, which is what a linear extrapolation misses on a curved surface: a
// curl seen by a coarse camera keeps its points). Where one side has no points (a shadow, the
// unseen background), the point must be far off the other side (three times the limit) or off
// along two directions; a point a little off along one direction only is kept (a leaf's corner).
// A steep curl's corner seen edge on can still lose a few good points. A true step (a leaf's
// edge on its support) keeps its points: each lies on its own side's surface.
#pragma once
#include <opencv2/core.hpp>

namespace vellum {

// Sets the flying points of a CV_32FC3 point map (NaN: no point) to NaN and returns how many.
int RejectFlyingPoints(cv::Mat* points, double max_off_mm, int reach);

}  // namespace vellum
