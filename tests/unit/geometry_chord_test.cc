// Kim, Song & Kwon's chord-error limit: the step length on a circle, its feed, and the
// measured chord error of a step on a circle NURBS against the closed form.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "common/geometry/chord.h"
#include "common/geometry/nurbs.h"

namespace cnc::geometry {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

NurbsCurve circle(double r) {
  const double s = std::sqrt(0.5);
  return NurbsCurve(3, {0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1},
                    {{r, 0, 0}, {r, r, 0}, {0, r, 0}, {-r, r, 0}, {-r, 0, 0}, {-r, -r, 0}, {0, -r, 0}, {r, -r, 0},
                     {r, 0, 0}},
                    {1, s, 1, s, 1, s, 1, s, 1});
}

// The sagitta of a chord of length l on a circle of radius r, without cancellation.
double sagitta(double r, double l) { return l * l / 4 / (r + std::sqrt(r * r - l * l / 4)); }

TEST(ChordStep, IsTheExactCircleChord) {
  for (double rho : {0.5, 3.0, 100.0, 1e4}) {
    for (double eps : {5e-8, 2e-6, 1e-3}) {
      const double l = chord_step_length(rho, eps);
      EXPECT_NEAR(l, 2 * std::sqrt(2 * rho * eps - eps * eps), 1e-15 * l);
      EXPECT_NEAR(sagitta(rho, l), eps, 1e-12 * eps) << "rho=" << rho << " eps=" << eps;
      // The paper's small-error form, κ·L²/8 = ε, differs by O(ε/ρ).
      EXPECT_NEAR(l, std::sqrt(8 * eps * rho), 1e-3 * l);
    }
  }
}

TEST(ChordStep, EdgeCases) {
  EXPECT_EQ(chord_step_length(kInf, 1e-6), kInf);
  EXPECT_EQ(chord_step_length(0.0, 1e-6), 0.0);
  EXPECT_EQ(chord_step_length(-1.0, 1e-6), 0.0);
  EXPECT_EQ(chord_step_length(std::nan(""), 1e-6), 0.0);
  EXPECT_EQ(chord_step_length(1.0, 0.0), 0.0);
  // eps >= rho: the diameter, continuous at eps = rho and never decreasing in eps.
  EXPECT_DOUBLE_EQ(chord_step_length(1.0, 1.0), 2.0);
  EXPECT_EQ(chord_step_length(1.0, 1.5), 2.0);
  EXPECT_EQ(chord_step_length(1.0, 7.0), 2.0);
  double prev = 0.0;
  for (int i = 1; i <= 300; ++i) {
    const double l = chord_step_length(1.0, i * 0.01);
    EXPECT_GE(l, prev);
    prev = l;
  }
}

TEST(ChordFeed, IsSixtyStepsPerPeriodPerMinute) {
  // Kim, Song & Kwon's simulation: ΔT = 8 ms, ε = 0.05 µm.
  const double rho = 20.0;
  const double eps = 0.05e-3;
  EXPECT_DOUBLE_EQ(chord_feed_limit_mm_per_min(rho, eps, 0.008), 60.0 * chord_step_length(rho, eps) / 0.008);
  EXPECT_NEAR(chord_feed_limit_mm_per_min(rho, eps, 0.008), 60.0 / 0.008 * std::sqrt(8 * eps * rho), 1.0);
  EXPECT_EQ(chord_feed_limit_mm_per_min(kInf, eps, 0.004), kInf);
}

TEST(ChordError, OfAStepOnACircleIsTheSagitta) {
  for (double r : {0.5, 5.0, 200.0}) {
    const NurbsCurve c = circle(r);
    // Steps inside a span, across the double knot at 0.25, short and long.
    const std::vector<std::pair<double, double>> steps = {
        {0.1, 0.1001}, {0.1, 0.11}, {0.24, 0.26}, {0.3, 0.45}, {0.6, 0.7999}, {0.9, 1.0}, {0.0, 0.2}};
    for (auto [u0, u1] : steps) {
      const double l = (c.point(u1) - c.point(u0)).norm();
      const double expect = sagitta(r, l);
      EXPECT_NEAR(chord_error_of_step(c, u0, u1), expect, 1e-6 * expect) << "r=" << r << " u " << u0 << ".." << u1;
      EXPECT_EQ(chord_error_of_step(c, u1, u0), chord_error_of_step(c, u0, u1));
    }
  }
}

TEST(ChordError, StepAtTheLimitHasTheToleratedError) {
  // A step of chord_step_length on the circle leaves exactly eps.
  const double r = 12.0;
  const double eps = 2e-3;
  const NurbsCurve c = circle(r);
  const double l = chord_step_length(r, eps);
  const double u0 = 0.05;
  // Bisect u1 for the chord length l (within the first quarter, chord length grows with u1).
  double lo = u0;
  double hi = 0.25;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    ((c.point(mid) - c.point(u0)).norm() < l ? lo : hi) = mid;
  }
  EXPECT_NEAR(chord_error_of_step(c, u0, lo), eps, 1e-6 * eps);
}

TEST(ChordError, ZeroOnStraightLinesAndEmptySteps) {
  const NurbsCurve line(3, {0, 0, 0, 1, 1, 1}, {{0, 0, 0}, {1, 2, 3}, {4, 8, 12}}, {1, 3, 1});
  EXPECT_LT(chord_error_of_step(line, 0.1, 0.9), 1e-14);
  EXPECT_EQ(chord_error_of_step(circle(1.0), 0.3, 0.3), 0.0);
}

TEST(ChordError, FindsTheLargerOfTwoBulges) {
  // An S-shaped cubic Bézier: two bulges of different heights on opposite sides of
  // the chord. The maximum is checked against a dense scan.
  const NurbsCurve s(4, {0, 0, 0, 0, 1, 1, 1, 1}, {{0, 0, 0}, {1, 2, 0}, {2, -1, 0}, {3, 0, 0}}, {1, 1, 1, 1});
  double scan = 0.0;
  for (int i = 0; i <= 200000; ++i) scan = std::max(scan, std::abs(s.point(i / 200000.0).y()));
  EXPECT_NEAR(chord_error_of_step(s, 0, 1), scan, 1e-6 * scan);
  EXPECT_GE(chord_error_of_step(s, 0, 1), scan);
}

}  // namespace
}  // namespace cnc::geometry
