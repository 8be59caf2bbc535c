// The interpolator core, driven cycle by cycle with plain structs: exact block ends,
// speed and acceleration limits from finite differences of the setpoints, feed hold,
// override, stop, dwell, refusal of out-of-order blocks and bit-identical reruns.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/interpolator.h"
#include "common/program/block.h"
#include "tests/unit/lookahead_reference.h"

namespace cnc::interp {
namespace {

using program::Block;
using program::BlockKind;
using Point = std::vector<double>;

constexpr int kMaxCycles = 200'000;

const config::MachineConfig& sim3() {
  static const config::MachineConfig cfg =
      config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  return cfg;
}

Block motion(int64_t index, BlockKind kind, Point start, Point end, double feed_mm_per_min = 0) {
  Block b;
  b.index = index;
  b.source_line = static_cast<int32_t>(index + 1);
  b.kind = kind;
  b.start = std::move(start);
  b.end = std::move(end);
  b.feed_mm_per_min = feed_mm_per_min;
  return b;
}

Block dwell(int64_t index, Point at, double seconds) {
  Block b = motion(index, BlockKind::kDwell, at, at);
  b.dwell_s = seconds;
  return b;
}

Block end_block(int64_t index, Point at) { return motion(index, BlockKind::kEnd, at, at); }

// Chains points into blocks 0..n-1 of one kind and feed, then the end block.
std::vector<Block> polyline(const std::vector<Point>& pts, BlockKind kind, double feed_mm_per_min) {
  std::vector<Block> blocks;
  for (size_t i = 1; i < pts.size(); ++i)
    blocks.push_back(motion(static_cast<int64_t>(i - 1), kind, pts[i - 1], pts[i], feed_mm_per_min));
  blocks.push_back(end_block(static_cast<int64_t>(blocks.size()), pts.back()));
  return blocks;
}

Command cmd(Command::Kind kind, double feed_override = 1.0) {
  Command c;
  c.kind = kind;
  c.feed_override = feed_override;
  return c;
}

double distance(const Setpoint& a, const Setpoint& b, int naxes) {
  double d2 = 0;
  for (int i = 0; i < naxes; ++i) d2 += (b.position_mm[i] - a.position_mm[i]) * (b.position_mm[i] - a.position_mm[i]);
  return std::sqrt(d2);
}

void load_all(Interpolator& ip, const std::vector<Block>& blocks) {
  for (const Block& b : blocks) ASSERT_TRUE(ip.apply_block(b)) << "block " << b.index;
}

// Steps until kDone (or the cap); the first entry is the state before the first step.
std::vector<Setpoint> run_to_done(Interpolator& ip, int max_cycles = kMaxCycles) {
  std::vector<Setpoint> sps{ip.last()};
  sps[0].num_axes = static_cast<int>(sim3().axes.size());
  for (int a = 0; a < sps[0].num_axes; ++a) sps[0].position_mm[a] = sim3().axes[a].home_mm;
  for (int i = 0; i < max_cycles && ip.state() != RunState::kDone; ++i) sps.push_back(ip.step());
  EXPECT_EQ(ip.state(), RunState::kDone) << "not done after " << max_cycles << " cycles";
  return sps;
}

std::vector<Setpoint> run_program(const std::vector<Block>& blocks, double feed_override = 1.0) {
  Interpolator ip(sim3());
  ip.apply_command(cmd(Command::Kind::kOverride, feed_override));
  ip.apply_command(cmd(Command::Kind::kStart));
  load_all(ip, blocks);
  return run_to_done(ip);
}

void expect_at(const Setpoint& sp, const Point& p, double tol = 1e-12) {
  ASSERT_EQ(sp.num_axes, static_cast<int>(p.size()));
  for (size_t a = 0; a < p.size(); ++a) EXPECT_NEAR(sp.position_mm[a], p[a], tol) << "axis " << a;
}

// Speed and acceleration limits, from finite differences of consecutive setpoints.
// Each entry of `sps` holds the position at the end of its cycle; the machine is at
// rest before the first and after the last.
void expect_limits_held(const std::vector<Setpoint>& sps, const std::vector<Block>& blocks,
                        double feed_override = 1.0) {
  const config::MachineConfig& cfg = sim3();
  const int n = static_cast<int>(cfg.axes.size());
  const double T = cfg.ipo_period_s;
  std::vector<std::array<double, program::kMaxAxes>> vel(sps.size() + 1);  // vel[k]: cycle k-1 -> k
  for (size_t k = 1; k < sps.size(); ++k)
    for (int a = 0; a < n; ++a) vel[k][a] = (sps[k].position_mm[a] - sps[k - 1].position_mm[a]) / T;
  int speed_faults = 0;
  int accel_faults = 0;
  for (size_t k = 1; k < sps.size(); ++k) {
    const double speed = distance(sps[k - 1], sps[k], n) / T;
    const int64_t bi = sps[k].block_index;
    if (speed > 0) {
      ASSERT_GE(bi, 0);
      ASSERT_LT(bi, static_cast<int64_t>(blocks.size()));
      const Block& b = blocks[static_cast<size_t>(bi)];
      // A step that crosses a block boundary may carry the previous block's feed.
      const int64_t prev_bi = sps[k - 1].block_index;
      const double prev_feed = prev_bi >= 0 && prev_bi < bi ? blocks[static_cast<size_t>(prev_bi)].feed_mm_per_min : 0;
      if (b.kind == BlockKind::kLine) {
        const double v_max = std::max(b.feed_mm_per_min, prev_feed) / 60.0 * feed_override;
        if (speed > v_max * (1 + 1e-9) && ++speed_faults <= 5)
          ADD_FAILURE() << "cycle " << sps[k].cycle << " block " << bi << ": path speed " << speed << " > " << v_max;
      } else if (b.kind != BlockKind::kRapid && ++speed_faults <= 5) {
        ADD_FAILURE() << "cycle " << sps[k].cycle << ": a " << program::to_string(b.kind) << " block moved";
      }
    }
    for (int a = 0; a < n; ++a) {
      const double v_lim = cfg.axes[a].max_velocity_mm_s * 1.001;
      if (std::fabs(vel[k][a]) > v_lim && ++speed_faults <= 5)
        ADD_FAILURE() << "cycle " << sps[k].cycle << " axis " << cfg.axes[a].name << ": velocity " << vel[k][a];
    }
  }
  // vel[sps.size()] stays zero: at rest after the last setpoint.
  int jerk_faults = 0;
  for (size_t k = 2; k <= sps.size(); ++k) {
    for (int a = 0; a < n; ++a) {
      const double jerk = std::fabs(vel[k][a] - 2 * vel[k - 1][a] + vel[k - 2][a]) / (T * T);
      if (jerk > cfg.axes[a].max_jerk_mm_s3 * 1.01 && ++jerk_faults <= 5)
        ADD_FAILURE() << "cycle " << k << " axis " << cfg.axes[a].name << ": jerk " << jerk << " > "
                      << cfg.axes[a].max_jerk_mm_s3;
    }
  }
  EXPECT_EQ(jerk_faults, 0);
  for (size_t k = 1; k <= sps.size(); ++k) {
    double dv2 = 0;
    for (int a = 0; a < n; ++a) {
      const double dv = vel[k][a] - vel[k - 1][a];
      dv2 += dv * dv;
      const double acc = std::fabs(dv) / T;
      if (acc > cfg.axes[a].max_accel_mm_s2 * 1.01 && ++accel_faults <= 5)
        ADD_FAILURE() << "cycle " << k << " axis " << cfg.axes[a].name << ": acceleration " << acc << " > "
                      << cfg.axes[a].max_accel_mm_s2;
    }
    const double path_acc = std::sqrt(dv2) / T;
    if (path_acc > cfg.path_accel_mm_s2 * 1.01 && ++accel_faults <= 5)
      ADD_FAILURE() << "cycle " << k << " (block " << (k < sps.size() ? sps[k].block_index : -1)
                    << "): path acceleration " << path_acc << " > " << cfg.path_accel_mm_s2;
  }
  EXPECT_EQ(speed_faults, 0);
  EXPECT_EQ(accel_faults, 0);
}

double peak_speed(const std::vector<Setpoint>& sps, int64_t block_index) {
  const int n = static_cast<int>(sim3().axes.size());
  double peak = 0;
  for (size_t k = 1; k < sps.size(); ++k)
    if (sps[k].block_index == block_index)
      peak = std::max(peak, distance(sps[k - 1], sps[k], n) / sim3().ipo_period_s);
  return peak;
}

int64_t cycles_in_block(const std::vector<Setpoint>& sps, int64_t block_index) {
  return std::count_if(sps.begin() + 1, sps.end(), [&](const Setpoint& s) { return s.block_index == block_index; });
}

TEST(Interpolator, Sim3Limits) {
  // The expectations below are derived from these values.
  EXPECT_DOUBLE_EQ(sim3().ipo_period_s, 0.004);
  EXPECT_DOUBLE_EQ(sim3().path_accel_mm_s2, 3000);
  EXPECT_DOUBLE_EQ(sim3().path_jerk_mm_s3, 60000);
  ASSERT_EQ(sim3().axes.size(), 3u);
  for (const auto& a : sim3().axes) EXPECT_EQ(a.home_mm, 0.0);
}

TEST(Interpolator, IdleUntilStarted) {
  Interpolator ip(sim3());
  ASSERT_TRUE(ip.apply_block(motion(0, BlockKind::kLine, {0, 0, 0}, {10, 0, 0}, 600)));
  for (int i = 0; i < 10; ++i) {
    const Setpoint& sp = ip.step();
    EXPECT_EQ(sp.state, RunState::kIdle);
    expect_at(sp, {0, 0, 0}, 0);
  }
  EXPECT_EQ(ip.cycle(), 10);
}

TEST(Interpolator, SingleLineEndsExactlyAtItsEndPoint) {
  const Point end = {123.456789, -3.3, -17.0000001};
  const auto blocks = polyline({{0, 0, 0}, end}, BlockKind::kLine, 3000);
  const auto sps = run_program(blocks);
  ASSERT_GT(sps.size(), 2u);
  expect_at(sps.back(), end, 1e-12);
  EXPECT_EQ(sps.back().state, RunState::kDone);
  EXPECT_EQ(sps.back().block_index, 1);
  // The last motion cycle already lands on the end point.
  expect_at(sps[sps.size() - 2], end, 1e-12);
  EXPECT_EQ(sps[sps.size() - 2].block_index, 0);
  expect_limits_held(sps, blocks);
}

TEST(Interpolator, ANewProgramNamesNoBlockUntilItsFirstStep) {
  // After a program ends at u = 1 of its block 0, the next one is loaded and
  // started: until its first step the setpoints name no block (index -1, u 0), not
  // the last program's block and u, which would be read on the new program's
  // block 0 (the monitor saw a 22 mm chord error there).
  Interpolator ip(sim3());
  ip.apply_command(cmd(Command::Kind::kStart));
  load_all(ip, polyline({{0, 0, 0}, {10, 0, 0}}, BlockKind::kLine, 3000));
  run_to_done(ip);
  ip.apply_command(cmd(Command::Kind::kLoad));
  ip.apply_command(cmd(Command::Kind::kStart));
  const Setpoint& starved = ip.step();
  EXPECT_EQ(starved.state, RunState::kStarved);
  EXPECT_EQ(starved.block_index, -1);
  EXPECT_EQ(starved.u, 0.0);
  load_all(ip, polyline({{10, 0, 0}, {30, 10, 2}}, BlockKind::kRapid, 0));
  bool moved = false;
  for (int i = 0; i < 200 && !moved; ++i) {
    const Setpoint& sp = ip.step();
    if (sp.block_index == -1) {
      expect_at(sp, {10, 0, 0}, 0);
    } else {
      EXPECT_EQ(sp.block_index, 0);
      moved = true;
    }
  }
  EXPECT_TRUE(moved);
}

TEST(Interpolator, LimitsHeldOnAMixedProgram) {
  // Corners, a Z reversal, rapids limited by one axis, blocks shorter than one
  // cycle's travel and a zero-length block.
  const std::vector<Point> pts = {{0, 0, 0},       {50, 0, 0},     {50, 40, 0},     {50, 40, -20},  {50, 40, 0},
                                  {50.01, 40, 0},  {50.01, 40, 0}, {0, 0, 0},       {-3, 250, -100}, {0, 0, 0}};
  std::vector<Block> blocks;
  for (size_t i = 1; i < pts.size(); ++i) {
    const bool rapid = i == 7 || i == 8;
    blocks.push_back(motion(static_cast<int64_t>(i - 1), rapid ? BlockKind::kRapid : BlockKind::kLine, pts[i - 1],
                            pts[i], 2000.0 * static_cast<double>(i)));
  }
  blocks.push_back(end_block(static_cast<int64_t>(blocks.size()), pts.back()));
  const auto sps = run_program(blocks);
  expect_at(sps.back(), pts.back(), 1e-12);
  expect_limits_held(sps, blocks);
  // The rapid to (-3, 250, -100) is limited by Y at 250 mm/s.
  const double len = std::sqrt(3.0 * 3.0 + 250.0 * 250.0 + 100.0 * 100.0);
  EXPECT_NEAR(peak_speed(sps, 7), 250.0 * len / 250.0, 1e-6 * len);
}

TEST(Interpolator, LimitsHeldOnRandomPrograms) {
  std::mt19937 rng(20240611);  // fixed seed: reproducible
  std::uniform_real_distribution<double> coord(-5.0, 60.0);
  std::uniform_real_distribution<double> short_step(-0.02, 0.02);
  std::uniform_real_distribution<double> feed(30.0, 30000.0);
  std::uniform_int_distribution<int> pick(0, 9);
  for (int program = 0; program < 200; ++program) {
    std::vector<Block> blocks;
    Point p = {0, 0, 0};
    for (int i = 0; i < 25; ++i) {
      Point q = p;
      const int kind = pick(rng);
      if (kind < 3) {  // short moves, a few cycles or less
        for (double& c : q) c += short_step(rng);
      } else {
        q = {coord(rng), coord(rng), -coord(rng)};
      }
      blocks.push_back(motion(i, kind == 9 ? BlockKind::kRapid : BlockKind::kLine, p, q, feed(rng)));
      p = q;
    }
    blocks.push_back(end_block(static_cast<int64_t>(blocks.size()), p));
    SCOPED_TRACE("program " + std::to_string(program));
    const auto sps = run_program(blocks);
    expect_at(sps.back(), p, 1e-12);
    expect_limits_held(sps, blocks);
    if (HasFailure()) break;
  }
}

TEST(Interpolator, LimitsHeldWithRandomHoldsAndOverrides) {
  std::mt19937 rng(7);  // fixed seed: reproducible
  std::uniform_real_distribution<double> coord(-5.0, 40.0);
  std::uniform_real_distribution<double> feed(300.0, 40000.0);
  std::uniform_real_distribution<double> ovr(0.0, 1.5);
  std::uniform_int_distribution<int> event(0, 99);
  for (int program = 0; program < 50; ++program) {
    std::vector<Block> blocks;
    Point p = {0, 0, 0};
    for (int i = 0; i < 10; ++i) {
      const Point q = {coord(rng), coord(rng), -coord(rng)};
      blocks.push_back(motion(i, i % 4 == 3 ? BlockKind::kRapid : BlockKind::kLine, p, q, feed(rng)));
      p = q;
    }
    blocks.push_back(end_block(static_cast<int64_t>(blocks.size()), p));
    Interpolator ip(sim3());
    ip.apply_command(cmd(Command::Kind::kStart));
    load_all(ip, blocks);
    std::vector<Setpoint> sps = {ip.last()};
    bool held = false;
    for (int i = 0; i < kMaxCycles && ip.state() != RunState::kDone; ++i) {
      const int e = event(rng);
      if (e == 0) ip.apply_command(cmd(Command::Kind::kOverride, ovr(rng)));
      if (e == 1 || (held && e < 12)) {
        held = !held;
        ip.apply_command(cmd(held ? Command::Kind::kHold : Command::Kind::kResume));
      }
      if (ip.feed_override() < 0.05) ip.apply_command(cmd(Command::Kind::kOverride, 0.05));  // keep moving
      sps.push_back(ip.step());
    }
    SCOPED_TRACE("program " + std::to_string(program));
    EXPECT_EQ(ip.state(), RunState::kDone);
    expect_at(sps.back(), p, 1e-12);
    expect_limits_held(sps, blocks, 1.5);
    if (HasFailure()) break;
  }
}

TEST(Interpolator, RapidIsLimitedByTheAxes) {
  const auto blocks = polyline({{0, 0, 0}, {0, 0, -120}}, BlockKind::kRapid, 0);
  const auto sps = run_program(blocks);
  EXPECT_NEAR(peak_speed(sps, 0), 150.0, 150.0 * 1e-9);  // Z: 150 mm/s
  expect_limits_held(sps, blocks);
}

TEST(Interpolator, LongLineTakesTheTrapezoidTime) {
  // Jerk-limited: the S-curve time L/v + v/a + a/j, or L/v + 2·sqrt(v/j) where the
  // ramp never reaches a (v < a²/j). The line starts and ends at rest, so it runs
  // with X's own limits (no junction of it is crossed at speed).
  const double L = 300, v = 6000.0 / 60.0;
  const double a = std::min(sim3().path_accel_mm_s2, sim3().axes[0].max_accel_mm_s2);
  const double j = std::min(sim3().path_jerk_mm_s3, sim3().axes[0].max_jerk_mm_s3);
  const auto blocks = polyline({{0, 0, 0}, {L, 0, 0}}, BlockKind::kLine, 6000);
  const auto sps = run_program(blocks);
  const double T = sim3().ipo_period_s;
  const double ramp = v < a * a / j ? 2.0 * std::sqrt(v / j) : v / a + a / j;
  const double expected_cycles = (L / v + ramp) / T;
  EXPECT_NEAR(static_cast<double>(cycles_in_block(sps, 0)), expected_cycles, 4.0);  // discrete ramps and the creep onto the end
  EXPECT_NEAR(peak_speed(sps, 0), v, v * 1e-9);
  expect_limits_held(sps, blocks);
}

TEST(Interpolator, FeedHoldStopsMidBlockAndResumeFinishes) {
  const Point end = {300, 0, 0};
  const auto blocks = polyline({{0, 0, 0}, end}, BlockKind::kLine, 6000);
  Interpolator ip(sim3());
  ip.apply_command(cmd(Command::Kind::kStart));
  load_all(ip, blocks);
  std::vector<Setpoint> sps = {ip.last()};
  for (int i = 0; i < 300; ++i) sps.push_back(ip.step());
  const double T = sim3().ipo_period_s;
  const double v = 100.0;
  ASSERT_NEAR(distance(sps[sps.size() - 2], sps.back(), 3) / T, v, 1e-9);  // cruising

  ip.apply_command(cmd(Command::Kind::kHold));
  const double a = sim3().path_accel_mm_s2, j = sim3().path_jerk_mm_s3;
  const int max_decel_cycles = static_cast<int>(std::ceil((v / a + a / j) / T)) + 2;
  int decel_cycles = 0;
  while (decel_cycles <= max_decel_cycles) {
    sps.push_back(ip.step());
    ++decel_cycles;
    if (distance(sps[sps.size() - 2], sps.back(), 3) == 0) break;
  }
  EXPECT_LE(decel_cycles, max_decel_cycles);
  EXPECT_EQ(ip.state(), RunState::kHeld);
  const Setpoint held = sps.back();
  EXPECT_GT(held.position_mm[0], 30.0);
  EXPECT_LT(held.position_mm[0], 300.0);
  for (int i = 0; i < 100; ++i) {
    sps.push_back(ip.step());
    EXPECT_EQ(sps.back().state, RunState::kHeld);
    ASSERT_EQ(std::memcmp(sps.back().position_mm.data(), held.position_mm.data(), sizeof(held.position_mm)), 0)
        << "moved while held";
  }
  ip.apply_command(cmd(Command::Kind::kResume));
  for (int i = 0; i < kMaxCycles && ip.state() != RunState::kDone; ++i) sps.push_back(ip.step());
  EXPECT_EQ(ip.state(), RunState::kDone);
  expect_at(sps.back(), end, 1e-12);
  expect_limits_held(sps, blocks);
}

TEST(Interpolator, OverrideScalesTheCruiseSpeed) {
  const auto blocks = polyline({{0, 0, 0}, {0, 200, 0}}, BlockKind::kLine, 6000);
  const auto full = run_program(blocks, 1.0);
  const auto half = run_program(blocks, 0.5);
  EXPECT_NEAR(peak_speed(full, 0), 100.0, 1.0);
  EXPECT_NEAR(peak_speed(half, 0), 50.0, 0.5);
  expect_at(half.back(), {0, 200, 0});
  expect_limits_held(half, blocks, 0.5);
}

TEST(Interpolator, OverrideChangedWhileMoving) {
  const auto blocks = polyline({{0, 0, 0}, {300, 0, 0}}, BlockKind::kLine, 6000);
  Interpolator ip(sim3());
  ip.apply_command(cmd(Command::Kind::kStart));
  load_all(ip, blocks);
  std::vector<Setpoint> sps = {ip.last()};
  for (int i = 0; i < 200; ++i) sps.push_back(ip.step());
  ip.apply_command(cmd(Command::Kind::kOverride, 0.5));
  for (int i = 0; i < 100; ++i) sps.push_back(ip.step());
  EXPECT_NEAR(distance(sps[sps.size() - 2], sps.back(), 3) / sim3().ipo_period_s, 50.0, 0.5);
  for (int i = 0; i < kMaxCycles && ip.state() != RunState::kDone; ++i) sps.push_back(ip.step());
  expect_at(sps.back(), {300, 0, 0});
  expect_limits_held(sps, blocks);
}

TEST(Interpolator, OverrideAboveOneKeepsTheAxisVelocityLimit) {
  // F30000 = 500 mm/s along X asks for more than X's 250 mm/s; override 1.5 must not
  // push the axis past its limit. A rapid ignores override above 1.
  std::vector<Block> blocks = {motion(0, BlockKind::kLine, {0, 0, 0}, {200, 0, 0}, 30000),
                               motion(1, BlockKind::kRapid, {200, 0, 0}, {0, 0, 0}), end_block(2, {0, 0, 0})};
  const auto sps = run_program(blocks, 1.5);
  EXPECT_NEAR(peak_speed(sps, 0), 250.0, 250.0 * 1e-9);
  EXPECT_NEAR(peak_speed(sps, 1), 250.0, 250.0 * 1e-9);
  expect_limits_held(sps, blocks, 1.5);
}

TEST(Interpolator, OverrideIsClamped) {
  Interpolator ip(sim3());
  ip.apply_command(cmd(Command::Kind::kOverride, 7.0));
  EXPECT_DOUBLE_EQ(ip.feed_override(), 1.5);
  ip.apply_command(cmd(Command::Kind::kOverride, -1.0));
  EXPECT_DOUBLE_EQ(ip.feed_override(), 0.0);
  ip.apply_command(cmd(Command::Kind::kOverride, std::nan("")));
  EXPECT_DOUBLE_EQ(ip.feed_override(), 0.0);
}

TEST(Interpolator, BlocksOutOfOrderAreRefused) {
  Interpolator ip(sim3());
  EXPECT_FALSE(ip.apply_block(motion(1, BlockKind::kLine, {0, 0, 0}, {1, 0, 0}, 600)));
  EXPECT_TRUE(ip.apply_block(motion(0, BlockKind::kLine, {0, 0, 0}, {1, 0, 0}, 600)));
  EXPECT_FALSE(ip.apply_block(motion(0, BlockKind::kLine, {0, 0, 0}, {1, 0, 0}, 600)));
  EXPECT_FALSE(ip.apply_block(motion(2, BlockKind::kLine, {1, 0, 0}, {2, 0, 0}, 600)));
  EXPECT_FALSE(ip.apply_block(motion(1, BlockKind::kLine, {1, 0}, {2, 0}, 600)));  // two axes on a 3-axis cell
  EXPECT_FALSE(ip.apply_block(motion(1, BlockKind::kLine, {1, 0, 0}, {std::nan(""), 0, 0}, 600)));
  EXPECT_TRUE(ip.apply_block(motion(1, BlockKind::kLine, {1, 0, 0}, {2, 0, 0}, 600)));
  EXPECT_EQ(ip.next_block_index(), 2);
  EXPECT_EQ(ip.queued_blocks(), 2u);
}

TEST(Interpolator, StopDeceleratesToIdleAndDropsTheProgram) {
  const auto blocks = polyline({{0, 0, 0}, {300, 0, 0}, {300, 100, 0}}, BlockKind::kLine, 6000);
  Interpolator ip(sim3());
  ip.apply_command(cmd(Command::Kind::kStart));
  load_all(ip, blocks);
  std::vector<Setpoint> sps = {ip.last()};
  for (int i = 0; i < 300; ++i) sps.push_back(ip.step());
  ip.apply_command(cmd(Command::Kind::kStop));
  const double T = sim3().ipo_period_s;
  const double a = sim3().path_accel_mm_s2, j = sim3().path_jerk_mm_s3;
  const int max_cycles = static_cast<int>(std::ceil((100.0 / a + a / j) / T)) + 3;
  int cycles = 0;
  while (ip.state() != RunState::kIdle && cycles < max_cycles) {
    sps.push_back(ip.step());
    ++cycles;
  }
  EXPECT_EQ(ip.state(), RunState::kIdle);
  EXPECT_LE(cycles, max_cycles);
  EXPECT_EQ(ip.queued_blocks(), 0u);
  const Setpoint stopped = sps.back();
  EXPECT_LT(stopped.position_mm[0], 300.0);
  for (int i = 0; i < 50; ++i) {
    sps.push_back(ip.step());
    EXPECT_EQ(sps.back().state, RunState::kIdle);
    ASSERT_EQ(std::memcmp(sps.back().position_mm.data(), stopped.position_mm.data(), sizeof(stopped.position_mm)), 0);
  }
  // The (unfinished) program is no longer part of the limits check; the motion is.
  expect_limits_held(sps, blocks);

  // A new program from where it stopped.
  ip.apply_command(cmd(Command::Kind::kLoad));
  EXPECT_EQ(ip.next_block_index(), 0);
  const Point here = {stopped.position_mm[0], 0, 0};
  const auto next = polyline({here, {0, 0, 0}}, BlockKind::kLine, 6000);
  load_all(ip, next);
  ip.apply_command(cmd(Command::Kind::kStart));
  const auto sps2 = run_to_done(ip);
  expect_at(sps2.back(), {0, 0, 0});
}

TEST(Interpolator, StarvesWithoutBlocksAndContinuesWhenTheyArrive) {
  Interpolator ip(sim3());
  ip.apply_command(cmd(Command::Kind::kStart));
  for (int i = 0; i < 5; ++i) EXPECT_EQ(ip.step().state, RunState::kStarved);
  EXPECT_EQ(ip.starved_cycles(), 5);
  load_all(ip, polyline({{0, 0, 0}, {0, 0, -1}}, BlockKind::kLine, 600));
  EXPECT_EQ(ip.step().state, RunState::kRunning);
  const auto sps = run_to_done(ip);
  expect_at(sps.back(), {0, 0, -1});
  EXPECT_EQ(ip.starved_cycles(), 5);
}

TEST(Interpolator, DwellHoldsForWholeCycles) {
  const Point a = {0, 0, 0}, b = {10, 0, 0}, c = {10, 5, 0};
  const std::vector<Block> blocks = {motion(0, BlockKind::kLine, a, b, 3000), dwell(1, b, 0.1),
                                     motion(2, BlockKind::kLine, b, c, 3000), end_block(3, c)};
  const auto sps = run_program(blocks);
  const int64_t expected = static_cast<int64_t>(std::ceil(0.1 / sim3().ipo_period_s - 1e-9));
  EXPECT_EQ(expected, 25);
  EXPECT_EQ(cycles_in_block(sps, 1), expected);
  for (const Setpoint& sp : sps)
    if (sp.block_index == 1) expect_at(sp, b, 0);
  expect_at(sps.back(), c);
  expect_limits_held(sps, blocks);
}

TEST(Interpolator, RerunsAreBitIdentical) {
  const auto blocks = polyline({{0, 0, 0}, {37.1, 12.9, -3.3}, {1.7, 80.2, -40.1}, {0.1, 0.2, 0.3}}, BlockKind::kLine,
                               4321);
  auto run = [&] {
    Interpolator ip(sim3());
    ip.apply_command(cmd(Command::Kind::kStart));
    load_all(ip, blocks);
    std::vector<Setpoint> sps;
    for (int i = 0; i < kMaxCycles && ip.state() != RunState::kDone; ++i) {
      if (i == 150) ip.apply_command(cmd(Command::Kind::kOverride, 0.73));
      if (i == 400) ip.apply_command(cmd(Command::Kind::kHold));
      if (i == 480) ip.apply_command(cmd(Command::Kind::kResume));
      sps.push_back(ip.step());
    }
    return sps;
  };
  const auto first = run();
  const auto second = run();
  ASSERT_EQ(first.size(), second.size());
  ASSERT_GT(first.size(), 500u);
  for (size_t k = 0; k < first.size(); ++k) {
    ASSERT_EQ(std::memcmp(first[k].position_mm.data(), second[k].position_mm.data(), sizeof(first[k].position_mm)),
              0)
        << "cycle " << k;
    ASSERT_EQ(first[k].block_index, second[k].block_index);
    ASSERT_EQ(std::memcmp(&first[k].feed_mm_per_min, &second[k].feed_mm_per_min, sizeof(double)), 0);
  }
}

}  // namespace
}  // namespace cnc::interp

namespace cnc::interp {
namespace {

// A wavy NURBS pass (cubic, 7 control points a block, G1 joins): the path is under a
// look-ahead limit most of the time, the bisection over the acceleration runs often.
std::vector<Block> dense_nurbs(int n_blocks) {
  std::vector<Block> blocks;
  std::array<double, 3> p = {0, 0, 0};
  double heading = 0;
  for (int i = 0; i < n_blocks; ++i) {
    Block b = motion(i, BlockKind::kNurbs, {p[0], p[1], p[2]}, {}, 3000);
    b.nurbs.order = 4;
    std::vector<std::array<double, 3>> cp = {p};
    for (int k = 1; k < 7; ++k) {
      heading += 0.12 * std::sin(0.05 * (i * 7 + k));
      std::array<double, 3> q = cp.back();
      q[0] += 0.5 * std::cos(heading);
      q[1] += 0.5 * std::sin(heading);
      q[2] = -2.0 - 2.0 * std::sin(0.02 * (i * 7 + k)) + (k == 6 ? 0 : 0.01 * ((i * 7 + k) % 5 - 2));
      cp.push_back(q);
    }
    if (!blocks.empty()) {
      const auto& prev = blocks.back().nurbs.control_points;
      for (int d = 0; d < 3; ++d) cp[1][d] = p[d] + (p[d] - prev[prev.size() - 2][d]);
    }
    b.nurbs.control_points = cp;
    b.nurbs.weights.assign(7, 1.0);
    b.nurbs.knots = {0, 0, 0, 0, 0.25, 0.5, 0.75, 1, 1, 1, 1};
    b.end = {cp.back()[0], cp.back()[1], cp.back()[2]};
    p = cp.back();
    blocks.push_back(b);
  }
  blocks.push_back(end_block(n_blocks, {p[0], p[1], p[2]}));
  return blocks;
}

// The look-ahead's shortcuts (the rest of a block skipped where its least limit
// cannot be missed, the samples of a cycle's acceleration search gathered once, the
// one that failed last tried first) answer every check as the plain scan of every
// sample to the horizon does, limit included: on NURBS, and on lines with holds
// and override changes (an override re-plans every block's limits).
TEST(Interpolator, LookaheadShortcutsAnswerAsThePlainScan) {
  {
    Interpolator ip(sim3());
    LookaheadReference reference;
    ip.set_lookahead_check(&reference);
    ip.apply_command(cmd(Command::Kind::kStart));
    load_all(ip, dense_nurbs(40));
    std::mt19937 rng(3);
    std::uniform_int_distribution<int> event(0, 399);
    std::uniform_real_distribution<double> ovr(0.05, 1.5);
    for (int i = 0; i < kMaxCycles && ip.state() != RunState::kDone; ++i) {
      if (event(rng) == 0) ip.apply_command(cmd(Command::Kind::kOverride, ovr(rng)));
      ip.step();
    }
    EXPECT_EQ(ip.state(), RunState::kDone);
    EXPECT_EQ(reference.mismatches, 0);
    EXPECT_GT(reference.checks, 0);
    const WorkCounters& w = ip.work();
    std::printf("NURBS: %lld cycles, %lld searches gathered, %lld checks in full in them, %lld block rests skipped\n",
                static_cast<long long>(ip.cycle()), static_cast<long long>(w.look_builds),
                static_cast<long long>(w.look_fallbacks), static_cast<long long>(w.safe_skips));
    EXPECT_GT(w.look_builds, 300);
    EXPECT_GT(w.safe_skips, 300);
    EXPECT_LT(w.look_fallbacks, w.look_builds);
  }
  std::mt19937 rng(11);  // fixed seed: reproducible
  std::uniform_real_distribution<double> coord(-5.0, 40.0);
  std::uniform_real_distribution<double> feed(300.0, 40000.0);
  std::uniform_real_distribution<double> ovr(0.0, 1.5);
  std::uniform_int_distribution<int> event(0, 99);
  int64_t builds = 0;
  for (int program = 0; program < 20; ++program) {
    std::vector<Block> blocks;
    Point p = {0, 0, 0};
    for (int i = 0; i < 10; ++i) {
      const Point q = {coord(rng), coord(rng), -coord(rng)};
      blocks.push_back(motion(i, i % 4 == 3 ? BlockKind::kRapid : BlockKind::kLine, p, q, feed(rng)));
      p = q;
    }
    blocks.push_back(end_block(static_cast<int64_t>(blocks.size()), p));
    Interpolator ip(sim3());
    LookaheadReference reference;
    ip.set_lookahead_check(&reference);
    ip.apply_command(cmd(Command::Kind::kStart));
    load_all(ip, blocks);
    bool held = false;
    for (int i = 0; i < kMaxCycles && ip.state() != RunState::kDone; ++i) {
      const int e = event(rng);
      if (e == 0) ip.apply_command(cmd(Command::Kind::kOverride, ovr(rng)));
      if (e == 1 || (held && e < 12)) {
        held = !held;
        ip.apply_command(cmd(held ? Command::Kind::kHold : Command::Kind::kResume));
      }
      if (ip.feed_override() < 0.05) ip.apply_command(cmd(Command::Kind::kOverride, 0.05));
      ip.step();
    }
    SCOPED_TRACE("program " + std::to_string(program));
    EXPECT_EQ(ip.state(), RunState::kDone);
    EXPECT_EQ(reference.mismatches, 0);
    EXPECT_GT(reference.checks, 0);
    builds += ip.work().look_builds;
    if (HasFailure()) break;
  }
  EXPECT_GT(builds, 100);
}

}  // namespace
}  // namespace cnc::interp
