#pragma once
// Checks of a block's geometry, shared by the block builder (common/rs274, which
// refuses the fault at the program line that made the block) and by from_msg (which
// refuses a block arriving from the network). Header-only: the checks are small and
// used by both sides of cnc_program.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "common/program/block.h"

namespace cnc::program {

// Order = degree + 1. The interpolator's NURBS evaluator works up to order 8;
// Fanuc allows 2..4, LinuxCNC any order its knot builder accepts.
constexpr int kMinNurbsOrder = 2;
constexpr int kMaxNurbsOrder = 8;
// Start and end of an arc may lie at different radii as far as LinuxCNC accepts it
// (its spiral tolerance in inch programs, the looser of its two units, in mm): up
// to 0.0718 mm, or up to 7.18 mm within 0.1 % of the radius. The path is then a
// spiral between the two radii (motion::PathSegment), as LinuxCNC draws it.
inline bool arc_radii_acceptable(double r0_mm, double r1_mm) {
  constexpr double kSpiralAbsMm = 2 * 0.001 * 1.4142135623730951 * 25.4;
  const double abs_err = std::fabs(r1_mm - r0_mm);
  const double rel_err = abs_err / std::max(r0_mm, r1_mm);
  return !(abs_err > 100 * kSpiralAbsMm || (rel_err > 0.001 && abs_err > kSpiralAbsMm));
}
// The first control point of a NURBS must be where the tool is, and the block's end
// its last control point, to this distance per axis.
constexpr double kNurbsContinuityMm = 1e-6;
constexpr int kMaxArcTurns = 1000;
// One curve is one block and one message: CAM curves hold tens to hundreds of
// control points; ten thousand is ~400 kB on the wire.
constexpr int kMaxNurbsControlPoints = 10000;

// Machine axis indices of an arc plane's first and second axis: G17 X→Y, G18 Z→X,
// G19 Y→Z (counter-clockwise seen from the positive normal axis); {-1, -1} if the
// plane is not one of the three.
struct PlaneAxes {
  int first = -1;
  int second = -1;
  int normal = -1;
};
inline PlaneAxes plane_axes(int plane) {
  switch (plane) {
    case 17: return {0, 1, 2};
    case 18: return {2, 0, 1};
    case 19: return {1, 2, 0};
    default: return {};
  }
}

struct GeometryFault {
  enum class Part { kNone, kOrder, kCount, kKnot, kWeight, kControlPoint };
  Part part = Part::kNone;
  int index = -1;    // the knot, weight or control point at fault
  std::string what;  // empty: no fault
  bool ok() const { return what.empty(); }
};

inline std::string fmt_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

// The first fault of a NURBS definition, in the order a reader meets them.
inline GeometryFault check_nurbs(const NurbsGeometry& g) {
  using P = GeometryFault::Part;
  const int order = g.order;
  const int n_ctrl = static_cast<int>(g.control_points.size());
  const int n_knots = static_cast<int>(g.knots.size());
  const std::string ord = std::to_string(order);
  if (order < kMinNurbsOrder || order > kMaxNurbsOrder)
    return {P::kOrder, -1, "order " + ord + " out of range: expected 2 to 8 (degree 1 to 7)"};
  if (static_cast<int>(g.weights.size()) != n_ctrl)
    return {P::kCount, -1, std::to_string(g.weights.size()) + " weights for " + std::to_string(n_ctrl) +
                               " control points: expected one weight per control point"};
  if (n_ctrl > kMaxNurbsControlPoints)
    return {P::kCount, kMaxNurbsControlPoints, std::to_string(n_ctrl) + " control points: at most " +
                                                   std::to_string(kMaxNurbsControlPoints) + " in one curve"};
  if (n_ctrl < order)
    return {P::kCount, -1, "a NURBS of order " + ord + " needs at least " + ord + " control points, found " +
                               std::to_string(n_ctrl)};
  if (n_knots != n_ctrl + order)
    return {P::kCount, -1, std::to_string(n_knots) + " knots for " + std::to_string(n_ctrl) +
                               " control points of order " + ord + ": expected " + std::to_string(n_ctrl + order) +
                               " (control points + order)"};
  for (int i = 0; i < n_knots; ++i)
    if (!std::isfinite(g.knots[i])) return {P::kKnot, i, "knot " + std::to_string(i) + " is not a finite number"};
  for (int i = 1; i < n_knots; ++i)
    if (g.knots[i] < g.knots[i - 1])
      return {P::kKnot, i, "knot " + fmt_number(g.knots[i]) + " is smaller than the knot before it (" +
                               fmt_number(g.knots[i - 1]) + "): expected non-decreasing knots"};
  for (int i = 1; i < order; ++i)
    if (g.knots[i] != g.knots[0])
      return {P::kKnot, i, "knot vector is not clamped: expected the first " + ord + " knots equal (" +
                               fmt_number(g.knots[0]) + "), found " + fmt_number(g.knots[i])};
  const double last = g.knots[n_knots - 1];
  for (int i = n_knots - order; i < n_knots - 1; ++i)
    if (g.knots[i] != last)
      return {P::kKnot, i, "knot vector is not clamped: expected the last " + ord + " knots equal (" +
                               fmt_number(last) + "), found " + fmt_number(g.knots[i])};
  if (g.knots[0] == last)
    return {P::kKnot, n_knots - 1, "all knots are equal (" + fmt_number(last) + "): the curve has no parameter range"};
  if (g.knots[order] == g.knots[0])
    return {P::kKnot, order, "knot " + fmt_number(g.knots[0]) + " repeated more than " + ord +
                                 " times at the start: expected exactly " + ord};
  if (g.knots[n_knots - order - 1] == last)
    return {P::kKnot, n_knots - order - 1, "knot " + fmt_number(last) + " repeated more than " + ord +
                                               " times at the end: expected exactly " + ord};
  // An interior knot repeated `order` times breaks the curve in two.
  for (int i = order, run = 1; i < n_knots - order; ++i) {
    run = g.knots[i] == g.knots[i - 1] && i > order ? run + 1 : 1;
    if (run >= order)
      return {P::kKnot, i, "interior knot " + fmt_number(g.knots[i]) + " repeated " + ord +
                               " times: expected at most " + std::to_string(order - 1) + " (the curve would break)"};
  }
  for (int i = 0; i < n_ctrl; ++i)
    if (!std::isfinite(g.weights[i]) || !(g.weights[i] > 0))
      return {P::kWeight, i, "weight " + fmt_number(g.weights[i]) + " of control point " + std::to_string(i) +
                                 ": expected a positive finite weight"};
  for (int i = 0; i < n_ctrl; ++i)
    for (double c : g.control_points[i])
      if (!std::isfinite(c))
        return {P::kControlPoint, i, "control point " + std::to_string(i) + " is not finite"};
  return {};
}

// A whole NURBS block: the definition, and its first and last control points at the
// block's start and end (X, Y, Z are machine axes 0, 1, 2; others do not move).
inline std::string check_nurbs_block(const Block& b) {
  if (b.start.size() < 3 || b.end.size() != b.start.size()) return "a NURBS needs machine axes X, Y and Z";
  const GeometryFault f = check_nurbs(b.nurbs);
  if (!f.ok()) return f.what;
  const auto& first = b.nurbs.control_points.front();
  const auto& last = b.nurbs.control_points.back();
  for (int a = 0; a < 3; ++a) {
    if (std::fabs(first[a] - b.start[a]) > kNurbsContinuityMm)
      return "the first control point is not the block's start point";
    if (std::fabs(last[a] - b.end[a]) > kNurbsContinuityMm)
      return "the last control point is not the block's end point";
  }
  for (size_t a = 3; a < b.start.size(); ++a)
    if (b.end[a] != b.start[a]) return "a NURBS moves X, Y and Z only";
  return {};
}

// A G2/G3 block: plane, centre, turns, and start and end on one circle.
inline std::string check_arc_block(const Block& b) {
  const PlaneAxes p = plane_axes(b.arc.plane);
  const int n = static_cast<int>(b.start.size());
  if (p.first < 0) return "arc plane " + std::to_string(b.arc.plane) + ": expected 17, 18 or 19";
  if (p.first >= n || p.second >= n) return "arc plane " + std::to_string(b.arc.plane) + " needs axes the machine lacks";
  if (static_cast<int>(b.arc.center.size()) != n) return "arc centre has the wrong number of axes";
  for (double c : b.arc.center)
    if (!std::isfinite(c)) return "arc centre is not finite";
  if (b.arc.turns < 0 || b.arc.turns > kMaxArcTurns) return "arc turns out of range: expected 0 to 1000";
  const double r0 = std::hypot(b.start[p.first] - b.arc.center[p.first], b.start[p.second] - b.arc.center[p.second]);
  const double r1 = std::hypot(b.end[p.first] - b.arc.center[p.first], b.end[p.second] - b.arc.center[p.second]);
  if (!(r0 > 0)) return "arc centre is at the start point";
  if (!arc_radii_acceptable(r0, r1))
    return "arc start and end radii differ: " + fmt_number(r0) + " and " + fmt_number(r1) + " mm";
  return {};
}

}  // namespace cnc::program
