#include "common/motion/chord_error.h"

#include <algorithm>
#include <cmath>

namespace cnc::motion {
namespace {

double distance_to_segment(const AxisVec& p, const AxisVec& a, const AxisVec& b, int n) {
  double ab2 = 0, t = 0;
  for (int i = 0; i < n; ++i) {
    ab2 += (b[i] - a[i]) * (b[i] - a[i]);
    t += (p[i] - a[i]) * (b[i] - a[i]);
  }
  t = ab2 > 0 ? std::clamp(t / ab2, 0.0, 1.0) : 0.0;
  double d2 = 0;
  for (int i = 0; i < n; ++i) {
    const double q = a[i] + t * (b[i] - a[i]) - p[i];
    d2 += q * q;
  }
  return std::sqrt(d2);
}

}  // namespace

double chord_error(const PathSegment& path, double u0, double u1, const AxisVec& a, const AxisVec& b) {
  if (u1 < u0) std::swap(u0, u1);
  const int n = path.num_axes();
  auto f = [&](double u) { return distance_to_segment(path.point(u), a, b, n); };
  constexpr int kSub = 16;
  double vals[kSub + 1];
  for (int i = 0; i <= kSub; ++i) vals[i] = f(u0 + (u1 - u0) * i / kSub);
  double best = *std::max_element(vals, vals + kSub + 1);
  const double h = (u1 - u0) / kSub;
  constexpr double kInvPhi = 0.6180339887498949;
  for (int i = 1; i < kSub; ++i) {
    if (vals[i] < vals[i - 1] || vals[i] < vals[i + 1]) continue;
    double lo = u0 + (i - 1) * h, hi = u0 + (i + 1) * h;
    double x1 = hi - kInvPhi * (hi - lo), x2 = lo + kInvPhi * (hi - lo);
    double f1 = f(x1), f2 = f(x2);
    for (int it = 0; it < 40 && hi - lo > 1e-15 * std::max(1.0, std::fabs(hi)); ++it) {
      if (f1 < f2) {
        lo = x1;
        x1 = x2;
        f1 = f2;
        x2 = lo + kInvPhi * (hi - lo);
        f2 = f(x2);
      } else {
        hi = x2;
        x2 = x1;
        f2 = f1;
        x1 = hi - kInvPhi * (hi - lo);
        f1 = f(x1);
      }
    }
    best = std::max({best, f1, f2});
  }
  return best;
}

}  // namespace cnc::motion
