// NURBS interpolation against the exact curve: the chord error of every step
// (Kim, Song & Kwon) and the axis limits, on the reference curves, for several tolerances.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "common/config/machine_config.h"
#include "common/geometry/chord.h"
#include "common/geometry/sample_curves.h"
#include "common/motion/interpolator.h"

namespace cnc::interp {
namespace {

using geometry::SampleCurve;
using program::Block;
using program::BlockKind;

config::MachineConfig machine(double period_s, double eps_mm) {
  config::MachineConfig c = config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  c.ipo_period_s = period_s;
  c.chord_tolerance_mm = eps_mm;
  return c;
}

Block nurbs_block(const SampleCurve& sc, double feed) {
  Block b;
  b.index = 0;
  b.source_line = 1;
  b.kind = BlockKind::kNurbs;
  const auto& p0 = sc.control_points.front();
  const auto& p1 = sc.control_points.back();
  b.start = {p0.x(), p0.y(), p0.z()};
  b.end = {p1.x(), p1.y(), p1.z()};
  b.feed_mm_per_min = feed;
  b.nurbs.order = sc.order;
  b.nurbs.knots = sc.knots;
  for (const auto& p : sc.control_points) b.nurbs.control_points.push_back({p.x(), p.y(), p.z()});
  b.nurbs.weights = sc.weights;
  return b;
}

struct RunResult {
  std::vector<Setpoint> sps;
};

RunResult run(const config::MachineConfig& machine, const Block& b) {
  // The machine stands at the curve's start (the path is continuous from there).
  config::MachineConfig cfg = machine;
  for (int a = 0; a < 3; ++a) cfg.axes[a].home_mm = b.start[a];
  Interpolator ip(cfg);
  ip.apply_command({Command::Kind::kStart, 1.0});
  EXPECT_TRUE(ip.apply_block(b)) << ip.last_refusal();
  Block end;
  end.index = 1;
  end.kind = BlockKind::kEnd;
  end.start = end.end = b.end;
  EXPECT_TRUE(ip.apply_block(end));
  RunResult r;
  Setpoint start = ip.last();
  start.position_mm = {b.start[0], b.start[1], b.start[2]};
  start.block_index = 0;
  start.u = 0;
  r.sps.push_back(start);
  for (int i = 0; i < 2'000'000 && ip.state() != RunState::kDone; ++i) r.sps.push_back(ip.step());
  EXPECT_EQ(ip.state(), RunState::kDone);
  return r;
}

struct ChordStats {
  double max_err = 0;
  double max_err_chord_governed = 0;
  int chord_steps = 0;
  int chord_steps_over_90 = 0;
  int steps = 0;
};

ChordStats chord_errors(const SampleCurve& sc, const RunResult& r, double eps) {
  const geometry::NurbsCurve c = sc.curve();
  ChordStats st;
  for (size_t k = 1; k < r.sps.size(); ++k) {
    const Setpoint& a = r.sps[k - 1];
    const Setpoint& b = r.sps[k];
    if (a.block_index != 0 || b.block_index != 0 || b.u <= a.u) continue;
    const double e = geometry::chord_error_of_step(c, a.u, b.u);
    ++st.steps;
    st.max_err = std::max(st.max_err, e);
    if (b.limit == Limit::kChord) {
      ++st.chord_steps;
      st.max_err_chord_governed = std::max(st.max_err_chord_governed, e);
      if (e >= 0.9 * eps) ++st.chord_steps_over_90;
    }
  }
  return st;
}

void expect_axis_limits(const config::MachineConfig& cfg, const RunResult& r) {
  const double T = cfg.ipo_period_s;
  const size_t n = r.sps.size();
  std::vector<std::array<double, 3>> v(n + 1, {0, 0, 0});
  for (size_t k = 1; k < n; ++k)
    for (int a = 0; a < 3; ++a) v[k][a] = (r.sps[k].position_mm[a] - r.sps[k - 1].position_mm[a]) / T;
  double worst_v = 0, worst_a = 0, worst_j = 0;
  for (size_t k = 2; k <= n; ++k) {
    for (int a = 0; a < 3; ++a) {
      const auto& ax = cfg.axes[a];
      worst_v = std::max(worst_v, std::fabs(v[k - 1][a]) / ax.max_velocity_mm_s);
      worst_a = std::max(worst_a, std::fabs(v[k][a] - v[k - 1][a]) / T / ax.max_accel_mm_s2);
      worst_j = std::max(worst_j, std::fabs(v[k][a] - 2 * v[k - 1][a] + v[k - 2][a]) / (T * T) / ax.max_jerk_mm_s3);
    }
  }
  EXPECT_LE(worst_v, 1.01);
  EXPECT_LE(worst_a, 1.01);
  EXPECT_LE(worst_j, 1.01);
  std::printf("    limits used: velocity %.3f, acceleration %.3f, jerk %.3f of the axis limit\n", worst_v, worst_a,
              worst_j);
}

// Kim, Song & Kwon's simulation: T = 8 ms, F = 2000 mm/min, ε = 0.05 µm, 1 µm, 2 µm.
TEST(NurbsInterpolation, ChordErrorBoundedAndReachedOnReferenceCurves) {
  for (double eps_um : {0.05, 1.0, 2.0}) {
    const double eps = eps_um * 1e-3;
    const auto cfg = machine(0.008, eps);
    for (const SampleCurve& sc : geometry::all_sample_curves()) {
      SCOPED_TRACE(sc.name + " eps " + std::to_string(eps_um) + " um");
      const RunResult r = run(cfg, nurbs_block(sc, 2000));
      const ChordStats st = chord_errors(sc, r, eps);
      std::printf("  %-13s eps %5.2f um: %5d steps, max chord error %.4f um (%.3f eps); chord-governed %5d steps, "
                  "max %.3f eps, %d >= 0.9 eps\n",
                  sc.name.c_str(), eps_um, st.steps, st.max_err * 1e3, st.max_err / eps, st.chord_steps,
                  st.max_err_chord_governed / eps, st.chord_steps_over_90);
      EXPECT_GT(st.steps, 10);
      EXPECT_LE(st.max_err, eps * (1 + 1e-9));
      if (st.chord_steps > 0) {
        EXPECT_GE(st.max_err_chord_governed, 0.9 * eps);
      }
      expect_axis_limits(cfg, r);
      // The curve ends where it should.
      const auto& last = r.sps.back().position_mm;
      const auto& p1 = sc.control_points.back();
      EXPECT_NEAR(last[0], p1.x(), 1e-9);
      EXPECT_NEAR(last[1], p1.y(), 1e-9);
      EXPECT_NEAR(last[2], p1.z(), 1e-9);
    }
  }
}

// The chord limit has to govern somewhere on the butterfly at the tight tolerance.
TEST(NurbsInterpolation, ZeroTangentAtTheStartIsInterpolatedWithoutNaN) {
  // A first control point equal to the start point (LinuxCNC's trident and Curva_*
  // examples; the G5.2 P1 program): the tangent vanishes at u = 0, where
  // the parameter update divided by |P'| and wrote NaN setpoints. The steps must
  // be finite, land on the curve's end, and keep the commanded feed once moving.
  Block b;
  b.index = 0;
  b.source_line = 1;
  b.kind = BlockKind::kNurbs;
  b.start = {10, 0, 0};
  b.end = {30, 0, 0};
  b.feed_mm_per_min = 100;
  b.nurbs.order = 3;
  b.nurbs.control_points = {{10, 0, 0}, {10, 0, 0}, {20, 10, 0}, {30, 0, 0}};
  b.nurbs.weights = {1, 1, 1, 1};
  b.nurbs.knots = {0, 0, 0, 0.5, 1, 1, 1};
  const config::MachineConfig cfg = machine(0.004, 0.001);
  const RunResult r = run(cfg, b);
  ASSERT_GT(r.sps.size(), 100u);
  double longest = 0;
  for (size_t i = 0; i < r.sps.size(); ++i) {
    for (int a = 0; a < 3; ++a) ASSERT_TRUE(std::isfinite(r.sps[i].position_mm[a])) << "setpoint " << i;
    ASSERT_TRUE(std::isfinite(r.sps[i].u)) << "setpoint " << i;
    if (i > 0) {
      double d2 = 0;
      for (int a = 0; a < 3; ++a) d2 += std::pow(r.sps[i].position_mm[a] - r.sps[i - 1].position_mm[a], 2);
      longest = std::max(longest, std::sqrt(d2));
    }
  }
  // No step longer than the feed allows (100 mm/min for 4 ms: 6.67 um), +1 %.
  EXPECT_LE(longest, 100.0 / 60.0 * 0.004 * 1.01);
  EXPECT_NEAR(r.sps.back().position_mm[0], 30.0, 1e-9);
  EXPECT_NEAR(r.sps.back().position_mm[1], 0.0, 1e-9);
}

TEST(NurbsInterpolation, ChordLimitGovernsAtTightTolerance) {
  const auto cfg = machine(0.008, 0.05e-3);
  const RunResult r = run(cfg, nurbs_block(geometry::butterfly(), 2000));
  int chord = 0;
  for (const auto& sp : r.sps) chord += sp.limit == Limit::kChord;
  EXPECT_GT(chord, 100);
}

}  // namespace
}  // namespace cnc::interp
