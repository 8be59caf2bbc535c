// Geometry of a path segment: an arc whose end point lies off its start radius (as
// LinuxCNC accepts within its spiral tolerance) is a spiral, radius linear in the
// angle, from the start point exactly to the end point; its derivatives agree
// with finite differences. A true circle keeps its radius.
#include <gtest/gtest.h>

#include <cmath>

#include "common/motion/path_segment.h"

namespace cnc::motion {
namespace {

program::Block arc(double ex, double ey, bool ccw) {
  program::Block b;
  b.kind = ccw ? program::BlockKind::kArcCcw : program::BlockKind::kArcCw;
  b.start = {110, 100, 0};
  b.end = {ex, ey, -2};  // with a helix in Z
  b.arc.plane = 17;
  b.arc.center = {100, 100, 0};
  b.feed_mm_per_min = 600;
  return b;
}

TEST(PathSegment, AnEndOffTheStartRadiusIsReachedOnASpiral) {
  const PathSegment p(arc(89.981, 100, true), 3);  // end radius 10.019, half a turn
  for (int i = 0; i <= 100; ++i) {
    const double u = i / 100.0;
    const AxisVec q = p.point(u);
    const double r = std::hypot(q[0] - 100, q[1] - 100);
    EXPECT_NEAR(r, 10.0 + 0.019 * u, 1e-12) << "u " << u;
    EXPECT_NEAR(q[2], -2.0 * u, 1e-12);
  }
  const AxisVec e = p.point(1.0);
  EXPECT_NEAR(e[0], 89.981, 1e-12);
  EXPECT_NEAR(e[1], 100.0, 1e-12);
  // First and second derivatives against central differences.
  const double h = 1e-5;
  for (double u : {0.1, 0.37, 0.8}) {
    AxisVec p0{}, d1{}, d2{}, pm{}, pp{}, t1{}, t2{};
    p.eval(u, &p0, &d1, &d2);
    p.eval(u - h, &pm, &t1, &t2);
    AxisVec d1m = t1;
    p.eval(u + h, &pp, &t1, &t2);
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(d1[a], (pp[a] - pm[a]) / (2 * h), 1e-6 * (1 + std::fabs(d1[a]))) << "axis " << a << " u " << u;
      EXPECT_NEAR(d2[a], (t1[a] - d1m[a]) / (2 * h), 1e-5 * (1 + std::fabs(d2[a]))) << "axis " << a << " u " << u;
    }
  }
}

TEST(PathSegment, ACircleKeepsItsRadius) {
  const PathSegment p(arc(90, 100, false), 3);  // clockwise half turn, end on the circle
  for (int i = 0; i <= 50; ++i) {
    const AxisVec q = p.point(i / 50.0);
    EXPECT_NEAR(std::hypot(q[0] - 100, q[1] - 100), 10.0, 1e-12);
  }
  EXPECT_NEAR(p.arc_sweep_rad(), M_PI, 1e-12);
}

}  // namespace
}  // namespace cnc::motion
