// Paths the random-curve tests never generated, run from G-code through the
// interpreter and the interpolator core (sim3's limits): a NURBS whose tangent
// vanishes at both ends (LinuxCNC's trident does this) entered from a G1, a NURBS
// with a sharp corner inside, and an arc that ends off its start radius. Each must
// give finite setpoints only, end on the programmed end point, and keep every
// axis's acceleration and jerk (finite differences of the setpoints) within its
// limits, within 1 %.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/interpolator.h"
#include "tests/unit/program_test_util.h"

namespace cnc::interp {
namespace {

struct Use {
  double v = 0, a = 0, j = 0;  // peak use of the limits over the axes
  bool finite = true;
  std::vector<double> end;
};

Use run_text(const std::string& text) {
  test::TempDir dir;
  const std::string path = (dir.path() / "p.ngc").string();
  test::write_file(path, text);
  const std::vector<program::Block> blocks = test::run_program(path);
  const config::MachineConfig cfg =
      config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  Interpolator ip(cfg);
  ip.apply_command({Command::Kind::kStart, 1.0});
  for (const auto& b : blocks) EXPECT_TRUE(ip.apply_block(b)) << ip.last_refusal();
  std::vector<std::array<double, 3>> p;
  p.push_back({0, 0, 0});
  Use u;
  for (int k = 0; k < 2'000'000 && ip.state() != RunState::kDone; ++k) {
    const Setpoint& s = ip.step();
    for (int a = 0; a < 3; ++a) u.finite = u.finite && std::isfinite(s.position_mm[a]);
    p.push_back({s.position_mm[0], s.position_mm[1], s.position_mm[2]});
  }
  EXPECT_EQ(ip.state(), RunState::kDone);
  const double T = cfg.ipo_period_s;
  for (int a = 0; a < 3; ++a) {
    const auto& ax = cfg.axes[static_cast<size_t>(a)];
    for (size_t i = 3; i < p.size(); ++i) {
      const double v = (p[i][a] - p[i - 1][a]) / T;
      const double acc = (p[i][a] - 2 * p[i - 1][a] + p[i - 2][a]) / (T * T);
      const double jerk = (p[i][a] - 3 * p[i - 1][a] + 3 * p[i - 2][a] - p[i - 3][a]) / (T * T * T);
      u.v = std::max(u.v, std::fabs(v) / ax.max_velocity_mm_s);
      u.a = std::max(u.a, std::fabs(acc) / ax.max_accel_mm_s2);
      u.j = std::max(u.j, std::fabs(jerk) / ax.max_jerk_mm_s3);
    }
  }
  u.end = {p.back()[0], p.back()[1], p.back()[2]};
  return u;
}

TEST(InterpolatorPaths, ANurbsWithZeroTangentsAtBothEndsEnteredFromALine) {
  // trident-like: the first and last control points doubled (P' = 0 at both ends),
  // entered from a G1 at right angles to where the curve first heads.
  const Use u = run_text(
      "G21 G90 G17\nG0 X0 Y10 Z0\nG1 X10 F3000\nG5.2 P1 X10 Y10\nX10 Y10 P1\nX20 Y20 P1\nX30 Y10 P1\nX40 Y10 P1\n"
      "X40 Y10 P1\nG5.3\nG1 X40 Y0\nM2\n");
  EXPECT_TRUE(u.finite);
  EXPECT_LE(u.a, 1.01);
  EXPECT_LE(u.j, 1.01);
  EXPECT_NEAR(u.end[0], 40, 1e-9);
  EXPECT_NEAR(u.end[1], 0, 1e-9);
}

TEST(InterpolatorPaths, ACornerInsideANurbsKeepsTheLimits) {
  // The paths issue's program: 4.7x the acceleration and 59x the jerk limits before.
  const Use u = run_text(
      "G0 X5 Y5 Z0\nG06.2 P3 K0 X5 Y5 Z0 R1 F3000\nK0 X10 Y6 Z0 R1\nK0 X15 Y5 Z0 R1\nK0.5 X16 Y10 Z0 R1\n"
      "K0.5 X15 Y15 Z0 R1\nK1\nK1\nK1\nM30\n");
  EXPECT_TRUE(u.finite);
  EXPECT_LE(u.a, 1.01);
  EXPECT_LE(u.j, 1.01);
  EXPECT_NEAR(u.end[0], 15, 1e-9);
  EXPECT_NEAR(u.end[1], 15, 1e-9);
}

TEST(InterpolatorPaths, AnArcEndingOffItsRadiusIsASpiralWithinTheLimits) {
  const Use u = run_text("G21 G90 G17\nG0 X110 Y100 Z0\nG3 X89.981 Y100 I-10 J0 F600\nM2\n");
  EXPECT_TRUE(u.finite);
  EXPECT_LE(u.a, 1.01);
  EXPECT_LE(u.j, 1.01);
  EXPECT_NEAR(u.end[0], 89.981, 1e-9);
}

// Found by cnc-path-property: control points in a line (clamped onto Y 0)
// with weights 0.1-20, so the curve turns back on itself twice (cusps, P' = 0 inside).
// Before: the path stopped at the second cusp for good (an interior curvature of
// 1e24 from rounding at a vanishing tangent), or crossed a cusp at speed (jerk 188x).
// The block builder now ends a piece at each cusp, a junction that stops.
TEST(InterpolatorPaths, ANurbsWithCuspsStopsAtEachAndRunsToItsEnd) {
  const Use u = run_text(
      "G21 G90 G17\nG0 X68.563832 Y0 Z-47.500509\nF5523\nG5.2 X74.847881 Y0 P20 L3\nX44.525233 Y0 P20\n"
      "X60.393030 Y0 P0.099233\nX45.249800 Y0 P4.240332\nG5.3\nM2\n");
  EXPECT_TRUE(u.finite);
  EXPECT_LE(u.a, 1.01);
  EXPECT_LE(u.j, 1.01);
  EXPECT_NEAR(u.end[0], 45.2498, 1e-9);
}

// A degree-1 G6.2 whose first span has no length (the first control point doubled):
// the curve stands still over u 0..0.47. Its direction at the junction with the G0
// is where it then goes (59 degrees off the G0: a stop), not "none" (taken at full
// feed before: jerk 71x).
TEST(InterpolatorPaths, ADegreeOneNurbsThatStandsStillAtItsStartTurnsTheCorner) {
  const Use u = run_text(
      "G21 G90 G17\nG0 X0 Y144.204233 Z-51.685071\n"
      "G6.2 P2 K0 X0 Y144.204233 Z-51.685071 R1 F5239\nK0 X0 Y144.204233 Z-51.685071 R1\n"
      "K0.469439 X0 Y166.375478 Z-33.652321 R1\nK0.799001 X0 Y159.495506 Z-25.851762 R1\nK1\nK1\nM2\n");
  EXPECT_TRUE(u.finite);
  EXPECT_LE(u.a, 1.01);
  EXPECT_LE(u.j, 1.01);
  EXPECT_NEAR(u.end[1], 159.495506, 1e-9);
}

// A doubled first control point with weights 0.07 / 0.14 / 2.7: the derivatives'
// rounding (about the machine's coordinates) left a tangent of 1e-14 mm at u = 0
// and a speed limit of 4e-28 mm/s there: the path never left the start.
TEST(InterpolatorPaths, ADoubledStartWithExtremeWeightsLeavesTheStart) {
  const Use u = run_text(
      "G21 G90 G17\nG0 X101.318188 Y223.030657 Z-115.210513\n"
      "G6.2 P3 K0 X101.318188 Y223.030657 Z-115.210513 R0.067415 F178\n"
      "K0 X101.318188 Y223.030657 Z-115.210513 R0.139525\nK0 X65.459104 Y194.655982 Z-110.884415 R2.715873\n"
      "K1\nK1\nK1\nM2\n");
  EXPECT_TRUE(u.finite);
  EXPECT_LE(u.a, 1.01);
  EXPECT_LE(u.j, 1.01);
  EXPECT_NEAR(u.end[0], 65.459104, 1e-9);
}

}  // namespace
}  // namespace cnc::interp
