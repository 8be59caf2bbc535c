#pragma once
// Polylines → smooth curves, for CAM output under G64 P: a run of short
// G1 moves is a sampled surface curve; the interpolator runs it at the feed the
// curve allows only when it sees the curve, not the segments.
//
// * fit_cubic: a clamped cubic B-spline through the run's first and last points,
//   every point of it within `tol` of the polyline (bounded span by span on the
//   spans' Bézier control points, halved until proven), and every vertex and
//   segment midpoint within `tol` of it (by projection: a point of the curve).
//   Least squares (vertices, midpoints and quarter points) with a small penalty on
//   the control polygon's second differences (a P-spline: smooth through the
//   rounding noise of posted coordinates, solvable for any knot placement), knots
//   refined where the tolerance is missed; the data keep their chord-length
//   parameters (mm) in every round. Cost: O(n) per round (banded sparse
//   Cholesky), at most 30 rounds and 4 spans per move, else no fit.
// * split_cubic: the fitted spline cut at knots into clamped pieces of at most
//   `max_spans` spans (knot insertion, so the pieces are the same curve: C2 where
//   they join).
// * corner_blend: the quartic Bézier that rounds the corner between two lines
//   within `tol` (zero curvature at both ends, so a line, the blend and the next
//   line join with continuous curvature).
#include <optional>
#include <vector>

#include <Eigen/Core>

namespace cnc::geometry {

struct CubicFit {
  bool ok = false;
  std::vector<double> knots;             // clamped: 4 equal at each end
  std::vector<Eigen::Vector3d> ctrl;     // ctrl.front() == pts.front(), ctrl.back() == pts.back()
  std::vector<double> params;            // each point's parameter on the curve (its projection)
  double max_error = 0;                  // an upper bound of the curve's distance from the polyline and back, mm
  int rounds = 0;
};

// Unit tangents the curve must start and end along (with zero curvature there), so it
// joins a line or a corner blend along that direction with continuous curvature.
struct FitEnds {
  std::optional<Eigen::Vector3d> start, end;
};

// pts: at least 2 points, consecutive points distinct. tol > 0 (mm).
CubicFit fit_cubic(const std::vector<Eigen::Vector3d>& pts, double tol, const FitEnds& ends = {});

struct CubicPiece {
  std::vector<double> knots;
  std::vector<Eigen::Vector3d> ctrl;
};

// Cuts a clamped cubic B-spline into pieces of at most max_spans knot spans.
std::vector<CubicPiece> split_cubic(const std::vector<double>& knots, const std::vector<Eigen::Vector3d>& ctrl,
                                    int max_spans);

// Evaluates a clamped non-rational cubic B-spline (for checks and tests).
Eigen::Vector3d cubic_point(const std::vector<double>& knots, const std::vector<Eigen::Vector3d>& ctrl, double u);

// The corner at `v` between a line arriving along unit `u_in` and one leaving along
// unit `u_out`, rounded within `tol` and using at most `max_leg` of each line:
// control points v - 2d·u_in, v - d·u_in, v, v + d·u_out, v + 2d·u_out. The blend
// is farthest from v at its middle, by (3/8)·d·|u_out - u_in|, which is made `tol`
// unless the legs (2d) would exceed max_leg. Returns d; 0 when the lines are
// collinear, or turn back by more than 150° (no blend: the corner stops).
double corner_blend_leg(const Eigen::Vector3d& u_in, const Eigen::Vector3d& u_out, double tol, double max_leg);

}  // namespace cnc::geometry
