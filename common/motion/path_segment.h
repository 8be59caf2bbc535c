#pragma once
// The geometry of one block as a parametric curve in machine axes: P(u) and its
// first two derivatives for lines, circular arcs / helices and NURBS. The
// interpolator steps along it; nothing here knows about time.
#include <array>
#include <cmath>
#include <vector>
#include <memory>
#include <string>

#include "common/program/block.h"

namespace cnc::geometry {
class NurbsCurve;
}

namespace cnc::motion {

using AxisVec = std::array<double, program::kMaxAxes>;

class PathSegment {
 public:
  // Throws std::invalid_argument when the block's geometry is unusable.
  PathSegment(const program::Block& block, int num_axes);
  ~PathSegment();
  PathSegment(PathSegment&&) noexcept;
  PathSegment& operator=(PathSegment&&) noexcept;

  double u_begin() const { return u0_; }
  double u_end() const { return u1_; }
  // Position, first and second derivative with respect to u. No allocation.
  void eval(double u, AxisVec* p, AxisVec* d1, AxisVec* d2) const;
  AxisVec point(double u) const;
  const AxisVec& start() const { return start_; }
  const AxisVec& end() const { return end_; }
  int num_axes() const { return n_; }
  bool curved() const { return kind_ != program::BlockKind::kLine && kind_ != program::BlockKind::kRapid; }
  // A block that does not move (zero length).
  bool degenerate() const { return degenerate_; }
  // NURBS: the distinct knot values of the domain (span boundaries); else {u0, u1}.
  std::vector<double> nurbs_breakpoints() const;
  // Arcs: the absolute swept angle; else 0.
  double arc_sweep_rad() const { return std::fabs(sweep_); }

 private:
  program::BlockKind kind_;
  int n_;
  double u0_ = 0, u1_ = 1;
  AxisVec start_{}, end_{};
  bool degenerate_ = false;
  // Arc / helix: centre, the plane's two axes, start angle, signed sweep, radius,
  // and the linear axes (everything else moves linearly with u in [0, 1]).
  int ax1_ = 0, ax2_ = 1;
  double cx_ = 0, cy_ = 0, radius_ = 0, theta0_ = 0, sweep_ = 0;
  double dradius_ = 0;  // end radius minus start radius: a spiral when not 0
  // NURBS: X Y Z from the curve (the first three axes), other axes held.
  std::unique_ptr<geometry::NurbsCurve> nurbs_;  // control points relative to origin_
  std::array<double, 3> origin_{};
};

}  // namespace cnc::motion
