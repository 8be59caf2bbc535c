#include "common/geometry/chord.h"

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
  auto dist = [&](double u) { return distance_to_segment(curve.point(u), a, b); };

  constexpr int kSamples = 16;
  double u[kSamples + 1];
  double f[kSamples + 1];
  for (int i = 0; i <= kSamples; ++i) {
    u[i] = i == kSamples ? u1 : u0 + (u1 - u0) * i / kSamples;
    f[i] = dist(u[i]);
  }
  double best = std::max(f[0], f[kSamples]);
  // Golden section on [u[i-1], u[i+1]] around each sampled local maximum. Near a
  // maximum the error in the value is quadratic in the error in u, so a bracket of
  // 1e-9 of the step leaves far less than 1e-9 of the result.
  const double invphi = (std::sqrt(5.0) - 1.0) / 2.0;
  const double stop = 1e-9 * (u1 - u0);
  for (int i = 1; i < kSamples; ++i) {
    best = std::max(best, f[i]);
    if (f[i] < f[i - 1] || f[i] < f[i + 1]) continue;
    double lo = u[i - 1];
    double hi = u[i + 1];
    double x1 = hi - invphi * (hi - lo);
    double x2 = lo + invphi * (hi - lo);
    double f1 = dist(x1);
    double f2 = dist(x2);
    while (hi - lo > stop) {
      if (f1 < f2) {
        lo = x1;
        x1 = x2;
        f1 = f2;
        x2 = lo + invphi * (hi - lo);
        f2 = dist(x2);
      } else {
        hi = x2;
        x2 = x1;
        f2 = f1;
        x1 = hi - invphi * (hi - lo);
        f1 = dist(x1);
      }
    }
    best = std::max({best, f1, f2});
  }
  return best;
}

}  // namespace cnc::geometry
