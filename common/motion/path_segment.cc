#include "common/motion/path_segment.h"

#include <cmath>
#include <numbers>
#include <stdexcept>

#include "common/geometry/nurbs.h"

namespace cnc::motion {

PathSegment::~PathSegment() = default;
PathSegment::PathSegment(PathSegment&&) noexcept = default;
PathSegment& PathSegment::operator=(PathSegment&&) noexcept = default;

PathSegment::PathSegment(const program::Block& b, int num_axes) : kind_(b.kind), n_(num_axes) {
  if (static_cast<int>(b.start.size()) != n_ || static_cast<int>(b.end.size()) != n_)
    throw std::invalid_argument("block has the wrong number of axes");
  for (int a = 0; a < n_; ++a) {
    start_[a] = b.start[a];
    end_[a] = b.end[a];
  }
  switch (b.kind) {
    case program::BlockKind::kRapid:
    case program::BlockKind::kLine: {
      double len2 = 0;
      for (int a = 0; a < n_; ++a) len2 += (end_[a] - start_[a]) * (end_[a] - start_[a]);
      degenerate_ = len2 == 0;
      break;
    }
    case program::BlockKind::kArcCw:
    case program::BlockKind::kArcCcw: {
      // Plane axes by RS274: G17 X→Y, G18 Z→X, G19 Y→Z (counter-clockwise seen from +normal).
      const int p = b.arc.plane;
      if (p == 17) ax1_ = 0, ax2_ = 1;
      else if (p == 18) ax1_ = 2, ax2_ = 0;
      else if (p == 19) ax1_ = 1, ax2_ = 2;
      else throw std::invalid_argument("arc plane must be 17, 18 or 19");
      if (ax1_ >= n_ || ax2_ >= n_ || static_cast<int>(b.arc.center.size()) != n_)
        throw std::invalid_argument("arc needs the plane's axes");
      cx_ = b.arc.center[ax1_];
      cy_ = b.arc.center[ax2_];
      const double sx = start_[ax1_] - cx_, sy = start_[ax2_] - cy_;
      const double ex = end_[ax1_] - cx_, ey = end_[ax2_] - cy_;
      radius_ = std::hypot(sx, sy);
      if (!(radius_ > 0)) throw std::invalid_argument("arc radius is zero");
      theta0_ = std::atan2(sy, sx);
      double theta1 = std::atan2(ey, ex);
      const bool ccw = b.kind == program::BlockKind::kArcCcw;
      double sweep = ccw ? theta1 - theta0_ : theta0_ - theta1;
      while (sweep <= 1e-12) sweep += 2 * std::numbers::pi;  // start == end: a full circle
      sweep += 2 * std::numbers::pi * b.arc.turns;
      sweep_ = ccw ? sweep : -sweep;
      // An end point off the start radius (within the interpreter's tolerance, as
      // LinuxCNC accepts it) is reached on a spiral: the radius changes linearly
      // with the angle, as LinuxCNC draws it, instead of a radial jump at the end.
      dradius_ = std::hypot(ex, ey) - radius_;
      break;
    }
    case program::BlockKind::kNurbs: {
      // Control points relative to the first one: the derivatives (A4.2 subtracts
      // terms of the size of the coordinates) then lose digits to the curve's size,
      // not to the machine's (near a vanishing tangent, hundreds of mm of cancellation
      // left a tangent of 1e-14 mm and a curvature of 1e60 at a doubled end point).
      if (!b.nurbs.control_points.empty())
        for (int a = 0; a < 3; ++a) origin_[a] = b.nurbs.control_points.front()[static_cast<size_t>(a)];
      std::vector<geometry::Vec3> ctrl;
      for (const auto& c : b.nurbs.control_points)
        ctrl.emplace_back(c[0] - origin_[0], c[1] - origin_[1], c[2] - origin_[2]);
      nurbs_ = std::make_unique<geometry::NurbsCurve>(b.nurbs.order, b.nurbs.knots, ctrl, b.nurbs.weights);
      u0_ = nurbs_->u_min();
      u1_ = nurbs_->u_max();
      if (n_ < 3) throw std::invalid_argument("NURBS needs X, Y and Z axes");
      break;
    }
    default: degenerate_ = true; break;
  }
}

void PathSegment::eval(double u, AxisVec* p, AxisVec* d1, AxisVec* d2) const {
  switch (kind_) {
    case program::BlockKind::kArcCw:
    case program::BlockKind::kArcCcw: {
      const double th = theta0_ + sweep_ * u;
      const double c = std::cos(th), s = std::sin(th);
      for (int a = 0; a < n_; ++a) {
        (*p)[a] = start_[a] + (end_[a] - start_[a]) * u;
        (*d1)[a] = end_[a] - start_[a];
        (*d2)[a] = 0;
      }
      // r(u) = r0 + dr·u: P = C + r(cos, sin); P' = dr(cos, sin) + r·sweep(−sin, cos);
      // P'' = 2·dr·sweep(−sin, cos) − r·sweep²(cos, sin). (dr = 0: the circle.)
      const double r = radius_ + dradius_ * u;
      (*p)[ax1_] = cx_ + r * c;
      (*p)[ax2_] = cy_ + r * s;
      (*d1)[ax1_] = dradius_ * c - r * s * sweep_;
      (*d1)[ax2_] = dradius_ * s + r * c * sweep_;
      (*d2)[ax1_] = -2 * dradius_ * s * sweep_ - r * c * sweep_ * sweep_;
      (*d2)[ax2_] = 2 * dradius_ * c * sweep_ - r * s * sweep_ * sweep_;
      if (u >= 1.0) {  // land exactly on the programmed end point
        (*p)[ax1_] = end_[ax1_];
        (*p)[ax2_] = end_[ax2_];
      }
      return;
    }
    case program::BlockKind::kNurbs: {
      geometry::Vec3 d[3];
      nurbs_->derivatives(u, 2, d);
      for (int a = 0; a < n_; ++a) {
        (*p)[a] = start_[a];
        (*d1)[a] = 0;
        (*d2)[a] = 0;
      }
      for (int a = 0; a < 3; ++a) {
        (*p)[a] = origin_[a] + d[0][a];
        (*d1)[a] = d[1][a];
        (*d2)[a] = d[2][a];
      }
      if (u >= u1_)
        for (int a = 0; a < 3; ++a) (*p)[a] = end_[a];
      return;
    }
    default:
      for (int a = 0; a < n_; ++a) {
        (*p)[a] = u >= 1.0 ? end_[a] : start_[a] + (end_[a] - start_[a]) * u;
        (*d1)[a] = end_[a] - start_[a];
        (*d2)[a] = 0;
      }
      return;
  }
}

std::vector<double> PathSegment::nurbs_breakpoints() const {
  if (nurbs_) return nurbs_->breakpoints();
  return {u0_, u1_};
}

AxisVec PathSegment::point(double u) const {
  AxisVec p{}, d1{}, d2{};
  eval(u, &p, &d1, &d2);
  return p;
}

}  // namespace cnc::motion
