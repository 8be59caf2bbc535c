// Rotary axes (sim4_rotary: X Y Z in mm and a rotary A in degrees) under LinuxCNC's
// feed rules, from G-code through the interpreter, the block builder and the
// interpolator core: in G94 a move with X/Y/Z takes F along their length (A arrives
// with them), a move of A alone takes F in deg/min (also in G20), G93 takes 1/F
// minutes; every axis keeps its own velocity, acceleration and jerk limit (finite
// differences of the setpoints, within 1 %) where A is the bottleneck, in a rapid and
// across G64 junctions.
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

const config::MachineConfig& sim4() {
  static const config::MachineConfig cfg =
      config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim4_rotary.yaml");
  return cfg;
}

struct Trace {
  std::vector<std::array<double, 4>> p;  // X Y Z A per cycle, from the start point
  double v = 0, a = 0, j = 0;            // peak use of the axes' limits
  double seconds = 0;
};

Trace run_text(const std::string& text) {
  test::TempDir dir;
  const std::string path = (dir.path() / "p.ngc").string();
  test::write_file(path, text);
  const config::MachineConfig& cfg = sim4();
  const std::vector<program::Block> blocks = test::run_program(path, pps::program_setup(cfg));
  Interpolator ip(cfg);
  ip.apply_command({Command::Kind::kStart, 1.0});
  for (const auto& b : blocks) EXPECT_TRUE(ip.apply_block(b)) << ip.last_refusal();
  Trace r;
  r.p.push_back({0, 0, 0, 0});
  for (int k = 0; k < 1'000'000 && ip.state() != RunState::kDone; ++k) {
    const Setpoint& s = ip.step();
    r.p.push_back({s.position_mm[0], s.position_mm[1], s.position_mm[2], s.position_mm[3]});
  }
  EXPECT_EQ(ip.state(), RunState::kDone);
  const double T = cfg.ipo_period_s;
  r.seconds = static_cast<double>(r.p.size() - 1) * T;
  for (size_t a = 0; a < 4; ++a) {
    const auto& ax = cfg.axes[a];
    for (size_t i = 3; i < r.p.size(); ++i) {
      const auto& q = r.p;
      const double v = (q[i][a] - q[i - 1][a]) / T;
      const double acc = (q[i][a] - 2 * q[i - 1][a] + q[i - 2][a]) / (T * T);
      const double jerk = (q[i][a] - 3 * q[i - 1][a] + 3 * q[i - 2][a] - q[i - 3][a]) / (T * T * T);
      r.v = std::max(r.v, std::fabs(v) / ax.max_velocity_mm_s);
      r.a = std::max(r.a, std::fabs(acc) / ax.max_accel_mm_s2);
      r.j = std::max(r.j, std::fabs(jerk) / ax.max_jerk_mm_s3);
    }
  }
  return r;
}

// Speeds at the cycle half way through the run: along X Y Z (mm/s) and of A (deg/s).
void mid_speeds(const Trace& r, double* xyz, double* a) {
  const size_t i = r.p.size() / 2;
  const double T = sim4().ipo_period_s;
  const auto& q = r.p;
  *xyz = std::sqrt(std::pow(q[i][0] - q[i - 1][0], 2) + std::pow(q[i][1] - q[i - 1][1], 2) +
                   std::pow(q[i][2] - q[i - 1][2], 2)) / T;
  *a = std::fabs(q[i][3] - q[i - 1][3]) / T;
}

void expect_within_limits(const Trace& r, const char* what) {
  EXPECT_LE(r.v, 1.01) << what;
  EXPECT_LE(r.a, 1.01) << what;
  EXPECT_LE(r.j, 1.01) << what;
  std::printf("%-28s time %.3f s, peak use of the limits: v %.3f a %.3f j %.3f\n", what, r.seconds, r.v, r.a, r.j);
}

TEST(RotaryFeed, MixedMoveTakesFAlongXYZAndARidesAlong) {
  // 30 mm at 600 mm/min: 10 mm/s along X Y Z for 3 s, A turns 90° in that time (30 °/s).
  const Trace r = run_text("G21 G90 G94 G1 X18 Y24 A90 F600\nM2\n");
  double xyz = 0, a = 0;
  mid_speeds(r, &xyz, &a);
  EXPECT_NEAR(xyz, 10.0, 1e-6);
  EXPECT_NEAR(a, 30.0, 1e-6);
  EXPECT_NEAR(r.p.back()[3], 90.0, 1e-9);
  EXPECT_GT(r.seconds, 3.0);
  EXPECT_LT(r.seconds, 3.2);  // plus the ramps at 3000 mm/s²
  expect_within_limits(r, "G94 X Y A");
}

TEST(RotaryFeed, RotaryOnlyMoveTakesFInDegreesPerMinute) {
  for (const char* units : {"G21", "G20"}) {
    // 1800 °/min = 30 °/s in either unit system (G20 does not make it 762 °/s).
    const Trace r = run_text(std::string(units) + " G90 G94 G1 A90 F1800\nM2\n");
    double xyz = 0, a = 0;
    mid_speeds(r, &xyz, &a);
    EXPECT_EQ(xyz, 0.0) << units;
    EXPECT_NEAR(a, 30.0, 1e-6) << units;
    EXPECT_GT(r.seconds, 3.0) << units;
    EXPECT_LT(r.seconds, 3.2) << units;
    expect_within_limits(r, units);
  }
}

TEST(RotaryFeed, InverseTimeTakesOneOverFMinutes) {
  // F30: 2 s, whatever moves: X at 5 mm/s and A at 90 °/s; A alone at 45 °/s.
  {
    const Trace r = run_text("G21 G90 G93 G1 X10 A180 F30\nG94\nM2\n");
    double xyz = 0, a = 0;
    mid_speeds(r, &xyz, &a);
    EXPECT_NEAR(xyz, 5.0, 1e-6);
    EXPECT_NEAR(a, 90.0, 1e-6);
    EXPECT_GT(r.seconds, 2.0);
    EXPECT_LT(r.seconds, 2.2);
    expect_within_limits(r, "G93 X A");
  }
  {
    const Trace r = run_text("G21 G90 G93 G1 A90 F30\nG94\nM2\n");
    double xyz = 0, a = 0;
    mid_speeds(r, &xyz, &a);
    EXPECT_NEAR(a, 45.0, 1e-6);
    EXPECT_GT(r.seconds, 2.0);
    EXPECT_LT(r.seconds, 2.2);
    expect_within_limits(r, "G93 A");
  }
}

TEST(RotaryFeed, TheRotaryAxisLimitsTheMixedMove) {
  // 1 mm at 600 mm/min would turn A at 3600 °/s: A's 180 °/s holds, 2 s for 360°.
  const Trace r = run_text("G21 G90 G94 G1 X1 A360 F600\nM2\n");
  double xyz = 0, a = 0;
  mid_speeds(r, &xyz, &a);
  EXPECT_LE(a, 180.0 * 1.0001);
  EXPECT_GT(a, 180.0 * 0.9);
  EXPECT_NEAR(xyz * 360.0, a * 1.0, 1e-6 * a);  // still on the straight line
  EXPECT_GT(r.seconds, 2.0);
  expect_within_limits(r, "G94 X A, A-bound");
}

TEST(RotaryFeed, RapidKeepsEveryAxisAndArrivesTogether) {
  // X alone would take 0.4 s at 250 mm/s, A 0.5 s at 180 °/s: A sets the pace, X follows.
  const Trace r = run_text("G21 G90 G0 X100 A90\nM2\n");
  double xyz = 0, a = 0;
  mid_speeds(r, &xyz, &a);
  EXPECT_NEAR(xyz / a, 100.0 / 90.0, 1e-9);
  EXPECT_GT(r.seconds, 0.5);
  EXPECT_NEAR(r.p.back()[0], 100.0, 1e-9);
  EXPECT_NEAR(r.p.back()[3], 90.0, 1e-9);
  expect_within_limits(r, "G0 X A");
}

TEST(RotaryFeed, JunctionsWithRotaryMotionUnderG64KeepEveryAxisLimit) {
  // Not blended (the fit is X Y Z only): the corner rule holds each axis's limits.
  const Trace r = run_text(
      "G21 G90 G64 P0.01 G1 F3000\nX10 A30\nX20 Y5 A-20\nX25 Y5 A40\nX25 Y15\nX30 Y15 A400\nG2 X40 Y15 I5 A300\n"
      "G1 X0 Y0 A0\nM2\n");
  EXPECT_NEAR(r.p.back()[3], 0.0, 1e-9);
  expect_within_limits(r, "G64 junctions with A");
}

TEST(RotaryFeed, HelixWithARidesAtTheXYZFeed) {
  // A half circle of radius 10 (31.416 mm) at 1200 mm/min = 20 mm/s with A turning 60°.
  const Trace r = run_text("G21 G90 G0 X10\nG17 G3 X-10 Y0 I-10 J0 A60 F1200\nM2\n");
  double xyz = 0, a = 0;
  mid_speeds(r, &xyz, &a);
  EXPECT_NEAR(xyz, 20.0, 1e-3);  // a chord, not the arc: 1e-3 covers the sagitta's share
  EXPECT_NEAR(a, 60.0 * 20.0 / (10 * M_PI), 1e-3);
  expect_within_limits(r, "G3 with A");
}

// Soft limits in degrees: a program that would turn A past its travel is refused at
// load, naming the axis, the angle and the line; a wrapped A has none.
TEST(RotaryFeed, SoftLimitsInDegreesAndNoneWhenWrapped) {
  test::TempDir dir;
  const std::string path = (dir.path() / "far.ngc").string();
  test::write_file(path, "G21 G90 G0 A700\nG91 G1 A30 F3600\nM2\n");
  {
    pps::ProgramServer server(sim4());
    const auto r = server.load(path, 1);
    EXPECT_FALSE(r.ok);
    EXPECT_NE(r.error.find(":2:"), std::string::npos) << r.error;
    EXPECT_NE(r.error.find("A 730.0000 deg (machine coordinates, the block's end) is outside the axis's travel "
                           "[-720, 720]"),
              std::string::npos)
        << r.error;
  }
  config::MachineConfig wrapped = sim4();
  wrapped.axes[3].wrapped = true;
  wrapped.axes[3].min_mm = -config::kWrappedTravelDeg;
  wrapped.axes[3].max_mm = config::kWrappedTravelDeg;
  const std::string turns = (dir.path() / "turns.ngc").string();
  test::write_file(turns, "G21 G90 G0 A300\nG91 G1 A1000 F36000\nG90 G0 A-10\nM2\n");
  pps::ProgramServer server(wrapped);
  const auto r = server.load(turns, 1);
  EXPECT_TRUE(r.ok) << r.error;
}

}  // namespace
}  // namespace cnc::interp
