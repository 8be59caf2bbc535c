#include "common/geometry/chord.h"

#include "common/geometry/maximize.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cnc::geometry {
namespace {

// Distance from p to the segment ab (to the point a when the segment is degenerate).
double distance_to_segment(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 ab = b - a;
  const double len2 = ab.squaredNorm();
  if (len2 == 0.0) return (p - a).norm();
  const double t = std::clamp((p - a).dot(ab) / len2, 0.0, 1.0);
  return (p - (a + t * ab)).norm();
}

}  // namespace

double chord_step_length(double radius_of_curvature, double eps) {
  const double rho = radius_of_curvature;
  if (!(eps > 0.0) || !(rho > 0.0)) return 0.0;
  if (std::isinf(rho)) return std::numeric_limits<double>::infinity();
  if (eps >= rho) return 2.0 * rho;
  return 2.0 * std::sqrt(eps * (2.0 * rho - eps));
}

double chord_feed_limit_mm_per_min(double radius_of_curvature, double eps, double period_s) {
  return 60.0 * chord_step_length(radius_of_curvature, eps) / period_s;
}

double chord_error_of_step(const NurbsCurve& curve, double u0, double u1) {
  u0 = std::clamp(u0, curve.u_min(), curve.u_max());
  u1 = std::clamp(u1, curve.u_min(), curve.u_max());
  if (u1 < u0) std::swap(u0, u1);
  if (u1 == u0) return 0.0;
  const Vec3 a = curve.point(u0);
  const Vec3 b = curve.point(u1);
  return maximize_on_interval([&](double u) { return distance_to_segment(curve.point(u), a, b); }, u0, u1);
}

}  // namespace cnc::geometry
