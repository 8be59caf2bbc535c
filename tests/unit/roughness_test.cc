// Choi et al. 2005's extended roughness model and feed law: the digest's check table
// (r = 5 mm, f_p = 0.5 mm, two flutes), the region boundary, and the feed law as the
// exact inverse of the model, continuous at α_c and monotone in |α|.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/process/roughness.h"

namespace cnc::process {
namespace {

using ::testing::HasSubstr;

constexpr double kPi = std::numbers::pi;
constexpr double kR = 5.0;    // ball radius, mm
constexpr double kFp = 0.5;   // pick feed, mm
constexpr double kUm = 1e-3;  // mm per µm

double deg(double d) { return d * kPi / 180.0; }

// Three significant figures, the precision of the digest's table.
void expect_3sf(double value, double expected) { EXPECT_NEAR(value, expected, 0.5e-2 * std::abs(expected)); }

// ---- the digest's check table ---------------------------------------------------

TEST(RoughnessCheckTable, Region2AtTenDegrees) {
  const double alpha = deg(10);
  ASSERT_GT(alpha, critical_angle(kR, kFp, kFp));
  expect_3sf(rmax_region2(kR, kFp, kFp, phase_feed_law(kFp)) / kUm, 10.67);
  expect_3sf(rmax_region2(kR, kFp, kFp, phase_general(kR, kFp, kFp, alpha)) / kUm, 10.42);
  expect_3sf(rmax_extended(kR, kFp, kFp, alpha) / kUm, 10.67);
}

TEST(RoughnessCheckTable, Region1AtZeroDegrees) {
  expect_3sf(rmax_region1(kR, kFp, 0.0) / kUm, 25.06);
  expect_3sf(rmax_extended(kR, kFp, kFp, 0.0) / kUm, 25.06);
}

TEST(RoughnessCheckTable, CriticalAngle) { expect_3sf(critical_angle(kR, kFp, kFp) * 180 / kPi, 4.34); }

TEST(RoughnessCheckTable, FeedRatioAtZeroDegreesHolding10_67um) {
  const double target = rmax_region2(kR, kFp, kFp, phase_feed_law(kFp));
  expect_3sf(feed_per_tooth_for_rmax(kR, kFp, target, 0.0) / kFp, 0.653);
}

TEST(RoughnessCheckTable, FeedPerToothAtZeroDegreesFor10_2um) {
  expect_3sf(feed_per_tooth_for_rmax(kR, kFp, 10.2 * kUm, 0.0), 0.319);
}

TEST(RoughnessCheckTable, IsotropicTarget) {
  expect_3sf(isotropic_target_rmax(3.0, 0.2) / kUm, 3.33);
  // Cutter mark equal to cusp: the cusp term alone is half of it.
  EXPECT_DOUBLE_EQ(isotropic_target_rmax(3.0, 0.2), 2 * rmax_classic(3.0, 0.0, 0.2, INFINITY, INFINITY));
}

// ---- the model ------------------------------------------------------------------

TEST(RoughnessModel, ClassicIsCutterMarkPlusCusp) {
  EXPECT_DOUBLE_EQ(rmax_classic(kR, 0.4, kFp, INFINITY, INFINITY), (0.16 + 0.25) / 40);
  // Curvature of the surface scales each term by ρ/(ρ + r).
  EXPECT_DOUBLE_EQ(rmax_classic(kR, 0.4, kFp, 15.0, 45.0), 0.16 / 40 * 0.75 + 0.25 / 40 * 0.9);
}

TEST(RoughnessModel, Region1EqualsTheBoundaryValueAtTheCriticalAngle) {
  for (double ratio = 0.55; ratio <= 1.0001; ratio += 0.05) {
    const double f_t = ratio * kFp;
    const double q = f_t - kFp / (2 * kPi);
    const double a = kFp * kFp + q * q;
    const double alpha_c = critical_angle(kR, f_t, kFp);
    EXPECT_GT(alpha_c, 0.0);
    EXPECT_NEAR(rmax_region1(kR, f_t, alpha_c), a / (8 * kR), 1e-12) << "f_t=" << f_t;
    EXPECT_NEAR(rmax_region1(kR, f_t, alpha_c), rmax_region2(kR, f_t, kFp, phase_feed_law(kFp)), 1e-12);
  }
}

TEST(RoughnessModel, CriticalAngleVanishesNearTheFigure7Bound) {
  // Paper, Fig. 7: the model means something for f_t from 0.53·f_p (0.27 mm here).
  EXPECT_EQ(critical_angle(kR, 0.265, kFp), 0.0);
  EXPECT_GT(critical_angle(kR, 0.268, kFp), 0.0);
  EXPECT_EQ(rmax_extended(kR, 0.2, kFp, 0.0), rmax_region2(kR, 0.2, kFp, phase_feed_law(kFp)));
}

TEST(RoughnessModel, ExtendedIsTheLargerOfTheTwoRegions) {
  for (double f_t = 0.05; f_t <= 0.8; f_t += 0.01) {
    for (double a = -90; a <= 90; a += 0.25) {
      const double alpha = deg(a);
      const double expect =
          std::max(rmax_region1(kR, f_t, alpha), rmax_region2(kR, f_t, kFp, phase_feed_law(kFp)));
      EXPECT_NEAR(rmax_extended(kR, f_t, kFp, alpha), expect, 1e-15) << "f_t=" << f_t << " α=" << a;
    }
  }
}

TEST(RoughnessModel, PhaseGeneralIsClamped) {
  EXPECT_EQ(phase_general(kR, 0.4, kFp, 0.0), 0.2);
  EXPECT_EQ(phase_general(kR, 0.4, kFp, deg(1)), 0.2);
  EXPECT_NEAR(phase_general(kR, 0.4, kFp, deg(30)), 0.4 / kPi * 0.5 / 2.5, 1e-15);
  EXPECT_EQ(phase_general(kR, 0.4, kFp, deg(-30)), phase_general(kR, 0.4, kFp, deg(30)));
}

TEST(RoughnessModel, FeedInclinationAngle) {
  EXPECT_DOUBLE_EQ(feed_inclination_angle({1, 0, 0}), 0.0);
  EXPECT_DOUBLE_EQ(feed_inclination_angle({0, 0, -2}), kPi / 2);
  EXPECT_DOUBLE_EQ(feed_inclination_angle({1, 1, -std::sqrt(2.0)}), kPi / 4);
  EXPECT_DOUBLE_EQ(feed_inclination_angle({3, 0, 3 * std::tan(deg(10))}), deg(10));
  EXPECT_EQ(feed_inclination_angle({0, 0, 0}), 0.0);
}

// ---- the feed law ---------------------------------------------------------------

TEST(RoughnessFeedLaw, InvertsTheExtendedModel) {
  const double cusp = kFp * kFp / (8 * kR);
  int region1 = 0;
  int region2 = 0;
  for (double target_um = cusp / kUm; target_um <= 60.0; target_um += 0.37) {
    const double target = target_um * kUm;
    for (double a = -90; a <= 90; a += 0.1) {
      const double alpha = deg(a);
      const double f_t = feed_per_tooth_for_rmax(kR, kFp, target, alpha);
      EXPECT_NEAR(rmax_extended(kR, f_t, kFp, alpha), target, 1e-9 * target) << "R=" << target_um << " α=" << a;
      (std::abs(alpha) < critical_angle(kR, f_t, kFp) ? region1 : region2)++;
    }
  }
  EXPECT_GT(region1, 1000);  // both branches are exercised
  EXPECT_GT(region2, 1000);
}

TEST(RoughnessFeedLaw, IsTheSmallerOfEquations5And6) {
  for (double target_um = 7.0; target_um <= 40.0; target_um += 1.1) {
    const double r_max = target_um * kUm;
    for (double a = -30; a <= 30; a += 0.05) {
      const double alpha = deg(a);
      const double eq5 = kFp / (2 * kPi) + std::sqrt(8 * kR * r_max - kFp * kFp);
      const double eq6 = std::sqrt(std::pow(kR * std::sin(alpha), 2) + 2 * kR * r_max - r_max * r_max);
      EXPECT_NEAR(feed_per_tooth_for_rmax(kR, kFp, r_max, alpha), std::min(eq5, eq6), 1e-14);
    }
  }
}

TEST(RoughnessFeedLaw, ContinuousAtTheCriticalAngle) {
  for (double target_um : {8.0, 10.67, 15.0, 30.0}) {
    const double target = target_um * kUm;
    const double f_t2 = feed_per_tooth_for_rmax(kR, kFp, target, deg(45));  // region II
    const double alpha_c = critical_angle(kR, f_t2, kFp);
    ASSERT_GT(alpha_c, 0.0);
    for (double d : {1e-6, 1e-9, 1e-12}) {
      const double below = feed_per_tooth_for_rmax(kR, kFp, target, alpha_c - d);
      const double above = feed_per_tooth_for_rmax(kR, kFp, target, alpha_c + d);
      EXPECT_EQ(above, f_t2);
      // Eq. 6 has slope r²·sin(2α)/(2·f_t) in α: the jump is that times d, no more.
      const double slope = kR * kR * std::sin(2 * alpha_c) / (2 * f_t2);
      EXPECT_NEAR(below, f_t2, 2 * slope * d + 1e-15) << "R=" << target_um << " d=" << d;
    }
  }
}

TEST(RoughnessFeedLaw, MonotoneInInclinationAndSymmetric) {
  for (double target_um = 7.0; target_um <= 40.0; target_um += 3.0) {
    const double target = target_um * kUm;
    double prev_ft = 0.0;
    double prev_r = INFINITY;
    const double fixed_ft = 0.5;
    for (double a = 0; a <= 90; a += 0.05) {
      const double f_t = feed_per_tooth_for_rmax(kR, kFp, target, deg(a));
      EXPECT_GE(f_t, prev_ft) << "α=" << a;
      EXPECT_EQ(f_t, feed_per_tooth_for_rmax(kR, kFp, target, deg(-a)));
      prev_ft = f_t;
      const double r = rmax_extended(kR, fixed_ft, kFp, deg(a));
      EXPECT_LE(r, prev_r) << "α=" << a;
      prev_r = r;
    }
  }
}

TEST(RoughnessFeedLaw, TargetBelowTheCuspGivesTheLeastRoughFeed) {
  const double cusp = kFp * kFp / (8 * kR);
  for (double a : {0.0, 3.0, 45.0}) {
    EXPECT_DOUBLE_EQ(feed_per_tooth_for_rmax(kR, kFp, 0.5 * cusp, deg(a)), phase_feed_law(kFp));
    EXPECT_DOUBLE_EQ(rmax_extended(kR, phase_feed_law(kFp), kFp, deg(a)), cusp);
  }
}

// ---- RoughnessLaw ---------------------------------------------------------------

TEST(RoughnessLaw, FeedIsFlutesTimesSpindleTimesFeedPerTooth) {
  const RoughnessLaw law{kR, 2, kFp, 10.2 * kUm};
  EXPECT_EQ(law.validate(), "");
  EXPECT_DOUBLE_EQ(law.feed_mm_per_min(10000, 0.0), 2 * 10000 * feed_per_tooth_for_rmax(kR, kFp, 10.2 * kUm, 0.0));
  expect_3sf(law.feed_mm_per_min(10000, 0.0), 2 * 10000 * 0.319);
  // Table 1 of the paper: r = 3, f_p = 0.2, isotropic target, 12 500 rpm.
  const RoughnessLaw table1{3.0, 2, 0.2, isotropic_target_rmax(3.0, 0.2)};
  EXPECT_EQ(table1.validate(), "");
  EXPECT_LT(table1.feed_mm_per_min(12500, 0.0), table1.feed_mm_per_min(12500, deg(20)));
}

TEST(RoughnessLaw, ValidateNamesTheFault) {
  EXPECT_THAT((RoughnessLaw{0, 2, kFp, 0.01}).validate(), HasSubstr("ball_radius_mm must be positive"));
  EXPECT_THAT((RoughnessLaw{kR, 0, kFp, 0.01}).validate(), HasSubstr("flutes must be at least 1"));
  EXPECT_THAT((RoughnessLaw{kR, 2, -1, 0.01}).validate(), HasSubstr("pick_feed_mm must be positive"));
  EXPECT_THAT((RoughnessLaw{kR, 2, kFp, 0.005}).validate(), HasSubstr("below the cusp height"));
  EXPECT_THAT((RoughnessLaw{kR, 2, kFp, INFINITY}).validate(), HasSubstr("target_rmax_mm must be finite"));
  EXPECT_THAT((RoughnessLaw{kR, 2, kFp, 6.0}).validate(), HasSubstr("not below the ball radius"));
}

}  // namespace
}  // namespace cnc::process
