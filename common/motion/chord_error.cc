#include "common/motion/chord_error.h"

#include <algorithm>
#include <cmath>

#include "common/geometry/maximize.h"

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
  return geometry::maximize_on_interval([&](double u) { return distance_to_segment(path.point(u), a, b, n); }, u0, u1);
}

}  // namespace cnc::motion
