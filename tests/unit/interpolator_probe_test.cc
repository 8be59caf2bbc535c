// The core's probing move (a G38.x line, Block::probe): it starts and ends at rest; a
// PROBE_TRIP brakes the path to rest in it (jerk-limited) and ends the move there, and
// the next block starts where the path rests; without a trip it runs to its end. A trip
// outside a probing move, or with a block after it already taken, is refused. Replay
// (the same inputs at the same cycles) gives the same setpoints.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/interpolator.h"
#include "common/program/block.h"

namespace cnc::interp {
namespace {

config::MachineConfig load(const char* name) {
  return config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/" + name);
}

program::Block line(int64_t index, std::vector<double> from, std::vector<double> to, double feed, int probe = 0) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kLine;
  b.start = std::move(from);
  b.end = std::move(to);
  b.feed_mm_per_min = feed;
  b.probe = static_cast<int8_t>(probe);
  return b;
}

program::Block end_block(int64_t index, std::vector<double> at) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kEnd;
  b.start = b.end = std::move(at);
  return b;
}

struct ProbeRun {
  std::vector<Setpoint> sp;
  int64_t trip_cycle = -1;
  std::vector<double> rest;
};

// G1 Z-10, G38.2 Z-21 at 100 mm/min (tripped when the path passes Z -20, if trip), then
// G0 back up 0.3 mm from where it rests, END.
ProbeRun run(const config::MachineConfig& cfg, bool trip, int64_t replay_trip_cycle = -1) {
  Interpolator core(cfg);
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  EXPECT_TRUE(core.apply_block(line(0, {0, 0, 0}, {0, 0, -19.7}, 3000)));
  EXPECT_TRUE(core.apply_block(line(1, {0, 0, -19.7}, {0, 0, -21}, 100, 2)));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  ProbeRun r;
  bool more = false;
  for (int i = 0; i < 20000 && core.state() != RunState::kDone; ++i) {
    const ProbeMove& pm = core.probe_move();
    const bool at_trip = replay_trip_cycle >= 0 ? core.cycle() == replay_trip_cycle
                                                : trip && pm.block_index == 1 && !pm.tripped && core.machine_position(2) <= -20;
    if (at_trip) {
      Command c;
      c.kind = Command::Kind::kProbeTrip;
      EXPECT_TRUE(core.apply_command(c));
      r.trip_cycle = core.cycle();
    }
    if (!more && pm.block_index == 1 && pm.done) {
      // The result is known: the next blocks, made from where the path rests.
      more = true;
      r.rest = {core.machine_position(0), core.machine_position(1), core.machine_position(2)};
      const std::vector<double> up = {r.rest[0], r.rest[1], r.rest[2] + 0.3};
      program::Block g0 = line(2, r.rest, up, 0);
      g0.kind = program::BlockKind::kRapid;
      EXPECT_TRUE(core.apply_block(g0)) << core.last_refusal();
      EXPECT_TRUE(core.apply_block(end_block(3, up)));
    }
    r.sp.push_back(core.step());
  }
  EXPECT_EQ(core.state(), RunState::kDone);
  return r;
}

TEST(InterpolatorProbe, ATripBrakesToRestInTheMoveAndTheNextBlockStartsThere) {
  const config::MachineConfig cfg = load("sim3_probe.yaml");
  const ProbeRun r = run(cfg, true);
  ASSERT_GE(r.trip_cycle, 0);
  ASSERT_EQ(r.rest.size(), 3u);
  // At 100 mm/min the path stops within a cycle's travel and a jerk-limited brake
  // (2·sqrt(v/J) at the path's jerk, under 11 ms) past the trip: under 20 um.
  EXPECT_LT(r.rest[2], -20.0);
  EXPECT_GT(r.rest[2], -20.0 - 0.020);
  // The probing move started from rest: the cycle before its first one stood at its start.
  for (size_t i = 1; i < r.sp.size(); ++i)
    if (r.sp[i].block_index == 1) {
      EXPECT_EQ(r.sp[i - 1].position_mm[2], -19.7);
      EXPECT_EQ(r.sp[i - 1].position_mm[2], r.sp[i - 2].position_mm[2]) << "at rest";
      break;
    }
  // No step of the run (trip, brake, the next block's start) jumps: within one cycle's
  // travel at the fastest move's speed, and Z never goes below where the path rested.
  for (size_t i = 1; i < r.sp.size(); ++i) {
    const double dz = std::fabs(r.sp[i].position_mm[2] - r.sp[i - 1].position_mm[2]);
    EXPECT_LE(dz, cfg.axes[2].max_velocity_mm_s * cfg.ipo_period_s + 1e-9) << "cycle " << r.sp[i].cycle;
    EXPECT_GE(r.sp[i].position_mm[2], r.rest[2] - 1e-12);
  }
  EXPECT_NEAR(r.sp.back().position_mm[2], r.rest[2] + 0.3, 1e-12);
}

TEST(InterpolatorProbe, WithoutATripTheMoveRunsToItsEnd) {
  const ProbeRun r = run(load("sim3_probe.yaml"), false);
  ASSERT_EQ(r.rest.size(), 3u);
  EXPECT_EQ(r.rest[2], -21.0);
}

TEST(InterpolatorProbe, ReplayedTripGivesTheSameSetpoints) {
  const config::MachineConfig cfg = load("sim3_probe.yaml");
  const ProbeRun live = run(cfg, true);
  const ProbeRun again = run(cfg, false, live.trip_cycle);
  ASSERT_EQ(live.sp.size(), again.sp.size());
  for (size_t i = 0; i < live.sp.size(); ++i)
    for (int a = 0; a < 3; ++a) ASSERT_EQ(live.sp[i].position_mm[a], again.sp[i].position_mm[a]) << "cycle " << i;
}

TEST(InterpolatorProbe, ATripOutsideAProbingMoveIsRefused) {
  const config::MachineConfig cfg = load("sim3_probe.yaml");
  Interpolator core(cfg);
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  ASSERT_TRUE(core.apply_block(line(0, {0, 0, 0}, {0, 0, -5}, 600)));
  ASSERT_TRUE(core.apply_block(line(1, {0, 0, -5}, {0, 0, -8}, 100, 3)));
  ASSERT_TRUE(core.apply_block(line(2, {0, 0, -8}, {0, 0, -9}, 100)));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  Command c;
  c.kind = Command::Kind::kProbeTrip;
  for (int i = 0; i < 10; ++i) core.step();
  EXPECT_FALSE(core.apply_command(c)) << "in a plain G1";
  for (int i = 0; i < 20000 && core.probe_move().block_index != 1; ++i) core.step();
  ASSERT_EQ(core.probe_move().block_index, 1);
  EXPECT_FALSE(core.apply_command(c)) << "a block after the probing move was already taken";
}

}  // namespace
}  // namespace cnc::interp
