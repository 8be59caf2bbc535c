// The largest distance of a polyline from a set of segments (tests/unit/path_distance.h),
// on cases with a known answer: on the geometry, parallel offsets, a maximum inside a
// chord (where neither end is farthest), a path far outside every reach, and random
// chords against dense sampling. The G64 P property test and the machining-time bench
// (tools/bench/path_deviation.cc) rest on it.
#include "tests/unit/path_distance.h"

#include <gtest/gtest.h>

#include <random>

namespace cnc::pathdist {
namespace {

constexpr double kEps = 1e-6;

TEST(PathDistance, PathOnTheGeometryIsAtZero) {
  SegmentSet g(0.25);
  g.add({0, 0, 0}, {10, 0, 0});
  g.add({10, 0, 0}, {10, 10, 5});
  FarthestPoint far(g, kEps);
  EXPECT_LE(far.of({0, 0, 0}, {10, 0, 0}).hi, kEps);
  EXPECT_LE(far.of({10, 0, 0}, {10, 5, 2.5}).hi, kEps);
  EXPECT_LE(far.of({3, 0, 0}, {3, 0, 0}).hi, kEps);  // a chord of no length: a point
}

TEST(PathDistance, ParallelOffsetAndGrowingOffset) {
  SegmentSet g(0.25);
  g.add({0, 0, 0}, {10, 0, 0});
  FarthestPoint far(g, kEps);
  const Range r = far.of({0, 0.1, 0}, {10, 0.1, 0});
  EXPECT_NEAR(r.hi, 0.1, kEps);
  EXPECT_NEAR(r.lo, 0.1, kEps);
  EXPECT_NEAR(far.of({0, 0.01, 0}, {10, 0.03, 0.04}).hi, 0.05, kEps);  // the far end: hypot(0.03, 0.04)
}

TEST(PathDistance, MaximumInsideAChord) {
  // Two rails 0.4 mm apart: a chord across them is farthest from both halfway, 0.2 mm,
  // while both its ends lie on a rail.
  SegmentSet g(0.25);
  g.add({0, 0, 0}, {10, 0, 0});
  g.add({0, 0.4, 0}, {10, 0.4, 0});
  FarthestPoint far(g, kEps);
  const Range r = far.of({5, 0, 0}, {5, 0.4, 0});
  EXPECT_NEAR(r.hi, 0.2, 2 * kEps);
  EXPECT_LE(r.lo, r.hi);
  EXPECT_GE(r.lo, 0.2 - 2 * kEps);
}

TEST(PathDistance, FarOutsideEveryReach) {
  SegmentSet g(0.25);
  g.add({0, 0, 0}, {10, 0, 0});
  for (int i = 0; i < 200; ++i) g.add({0.05 * i, 0, 0}, {0.05 * i + 0.05, 0, 0});
  FarthestPoint narrow(g, kEps), schedule(g, kEps, {0.25, 1, 4});
  EXPECT_NEAR(narrow.of({0, 20, 0}, {10, 20, 0}).hi, 20, kEps);
  EXPECT_NEAR(schedule.of({0, 20, 0}, {10, 20, 0}).hi, 20, kEps);
  EXPECT_NEAR(schedule.of({0, 2, 0}, {10, 2, 0}).hi, 2, kEps);  // found with the reach of 4 mm
}

TEST(PathDistance, BoundsHoldAgainstDenseSampling) {
  // A zig-zag of short segments and random chords near it: the largest distance found by
  // sampling each chord densely lies within [lo, hi], and hi - lo stays within eps.
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> u(-1, 1);
  SegmentSet g(0.25);
  V3 p{0, 0, 0};
  for (int i = 0; i < 300; ++i) {
    const V3 q{p[0] + 0.2, p[1] + 0.3 * u(rng), p[2] + 0.05 * u(rng)};
    g.add(p, q);
    p = q;
  }
  std::vector<int> all;
  g.all(&all);
  auto f = [&](const V3& x) {
    double d = 1e300;
    for (int i : all) d = std::min(d, g.dist(i, x));
    return d;
  };
  FarthestPoint far(g, kEps, {0.25, 1});
  for (int trial = 0; trial < 200; ++trial) {
    const double x0 = 60 * (0.5 + 0.5 * u(rng));
    const V3 a{x0, 0.5 * u(rng), 0.1 * u(rng)}, b{x0 + 0.4 * u(rng), 0.5 * u(rng), 0.1 * u(rng)};
    const Range r = far.of(a, b);
    double dense = 0;
    constexpr int kSamples = 2000;
    for (int k = 0; k <= kSamples; ++k) dense = std::max(dense, f(lerp(a, b, static_cast<double>(k) / kSamples)));
    const double spacing = norm(sub(b, a)) / kSamples;
    EXPECT_LE(dense, r.hi + 1e-12) << trial;
    EXPECT_GE(dense + 0.5 * spacing + 1e-12, r.lo) << trial;
    EXPECT_LE(r.hi - r.lo, kEps + 1e-12) << trial;
  }
}

}  // namespace
}  // namespace cnc::pathdist
