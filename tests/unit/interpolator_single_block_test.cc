// Single block and optional stop in the interpolator core: with single
// block on, the path comes to rest at the start of every program line and holds there
// until RESUME (START runs the first line); switched on while the path runs at speed,
// it stops at the first line start it can still reach at rest within its jerk and
// acceleration limits, never by a jump in speed; switched off, the path runs through
// the line starts again. An M1 holds only with the optional-stop switch on. The
// switches go through inputs.cc as recorded commands, as replay applies them.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "cnc/lcmt_interp_input.hpp"
#include "common/config/machine_config.h"
#include "common/motion/interpolator.h"
#include "common/program/block.h"
#include "services/interpolator/inputs.h"

namespace cnc::interp {
namespace {

const config::MachineConfig& sim3() {
  static const config::MachineConfig cfg =
      config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  return cfg;
}

// The switch as it is recorded (lcmt_interp_input COMMAND), applied through inputs.cc.
void switch_input(Interpolator& core, int8_t command, bool on) {
  cnc::lcmt_interp_input in{};
  in.kind = cnc::lcmt_interp_input::COMMAND;
  in.command.command = command;
  in.command.value = on ? 1 : 0;
  in.block.num_axes = 0;
  ASSERT_EQ(apply_recorded_input(core, in, 3), "");
}

program::Block line(int64_t index, int src_line, double x0, double x1, double feed = 3000) {
  program::Block b;
  b.index = index;
  b.source_line = src_line;
  b.source_file = "p.ngc";
  b.kind = program::BlockKind::kLine;
  b.start = {x0, 0, 0};
  b.end = {x1, 0, 0};
  b.feed_mm_per_min = feed;
  return b;
}

program::Block event(int64_t index, int src_line, double x, program::EventKind kind) {
  program::Block b;
  b.index = index;
  b.source_line = src_line;
  b.source_file = "p.ngc";
  b.kind = program::BlockKind::kEvent;
  b.start = b.end = {x, 0, 0};
  b.event.kind = kind;
  return b;
}

program::Block end_block(int64_t index, int src_line, double x) {
  program::Block b;
  b.index = index;
  b.source_line = src_line;
  b.source_file = "p.ngc";
  b.kind = program::BlockKind::kEnd;
  b.start = b.end = {x, 0, 0};
  return b;
}

// Lines 1..n along X, 10 mm each (line 3 in two blocks: one line, two blocks), then END.
void load_lines(Interpolator& core, int n) {
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  int64_t i = 0;
  double x = 0;
  for (int l = 1; l <= n; ++l) {
    if (l == 3) {
      ASSERT_TRUE(core.apply_block(line(i++, l, x, x + 5))) << core.last_refusal();
      ASSERT_TRUE(core.apply_block(line(i++, l, x + 5, x + 10))) << core.last_refusal();
    } else {
      ASSERT_TRUE(core.apply_block(line(i++, l, x, x + 10))) << core.last_refusal();
    }
    x += 10;
  }
  ASSERT_TRUE(core.apply_block(end_block(i, n + 1, x))) << core.last_refusal();
}

// Path speed and its changes: within the path's acceleration (and the jerk, with the
// discrete ramp's rounding) over every cycle of `feeds` (mm/min).
void expect_within_limits(const std::vector<double>& feeds) {
  const double T = sim3().ipo_period_s, A = sim3().path_accel_mm_s2, J = sim3().path_jerk_mm_s3;
  double worst_a = 0, worst_j = 0;
  for (size_t i = 2; i < feeds.size(); ++i) {
    const double a1 = (feeds[i] - feeds[i - 1]) / 60.0 / T, a0 = (feeds[i - 1] - feeds[i - 2]) / 60.0 / T;
    worst_a = std::max(worst_a, std::fabs(a1));
    worst_j = std::max(worst_j, std::fabs(a1 - a0) / T);
  }
  EXPECT_LE(worst_a, A * 1.02) << "acceleration over the path's limit";
  EXPECT_LE(worst_j, J * 1.1) << "jerk over the path's limit (discrete ramps: 10 % allowed)";
}

TEST(SingleBlock, HoldsAtEveryLineStartAndResumeRunsOneLine) {
  Interpolator core(sim3());
  switch_input(core, cnc::lcmt_program_command::SINGLE_BLOCK, true);
  EXPECT_TRUE(core.single_block());
  load_lines(core, 5);
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  std::vector<double> feeds, held_at;
  std::vector<int> held_line;
  for (int i = 0; i < 200000 && core.state() != RunState::kDone; ++i) {
    const Setpoint& s = core.step();
    feeds.push_back(s.feed_mm_per_min);
    if (core.state() == RunState::kHeld) {
      ASSERT_TRUE(core.single_block_held());
      EXPECT_EQ(s.feed_mm_per_min, 0.0);
      held_at.push_back(core.machine_position(0));
      held_line.push_back(s.source_line);
      core.apply_command({Command::Kind::kResume, 1.0, {}});
    }
  }
  ASSERT_EQ(core.state(), RunState::kDone);
  // Held after lines 1..4 (line 3's two blocks are one line), exactly at their ends,
  // the setpoint naming the line it holds before; not before END.
  ASSERT_EQ(held_at.size(), 4u);
  for (size_t k = 0; k < held_at.size(); ++k) {
    EXPECT_EQ(held_at[k], 10.0 * static_cast<double>(k + 1)) << "hold " << k;
    EXPECT_EQ(held_line[k], static_cast<int>(k + 2));
  }
  expect_within_limits(feeds);
}

TEST(SingleBlock, SwitchedOnAtSpeedStopsAtTheFirstReachableLineStart) {
  // At 3000 mm/min (50 mm/s) a jerk-limited brake needs about 2 mm: switched on 9 mm
  // into line 2 (1 mm before its end) the path runs through line 3's start and stops
  // at line 4's; switched on 2 mm into a line, it stops at that line's end.
  for (const double at : {12.0, 19.0}) {
    Interpolator core(sim3());
    load_lines(core, 5);
    core.apply_command({Command::Kind::kStart, 1.0, {}});
    std::vector<double> feeds;
    bool on = false;
    double held = -1;
    for (int i = 0; i < 200000 && core.state() != RunState::kDone; ++i) {
      if (!on && core.machine_position(0) >= at) {
        EXPECT_NEAR(core.last().feed_mm_per_min, 3000, 1e-6) << "switched on at full speed";
        switch_input(core, cnc::lcmt_program_command::SINGLE_BLOCK, true);
        on = true;
      }
      const Setpoint& s = core.step();
      feeds.push_back(s.feed_mm_per_min);
      if (core.state() == RunState::kHeld) {
        held = core.machine_position(0);
        break;
      }
    }
    EXPECT_EQ(held, at < 15 ? 20.0 : 30.0) << "switched on at X " << at;
    expect_within_limits(feeds);
  }
}

TEST(SingleBlock, SwitchedOffRunsThroughTheLineStartsAgain) {
  Interpolator core(sim3());
  switch_input(core, cnc::lcmt_program_command::SINGLE_BLOCK, true);
  load_lines(core, 5);
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  int holds = 0;
  double slowest_after = 1e9;
  std::vector<double> feeds;
  for (int i = 0; i < 200000 && core.state() != RunState::kDone; ++i) {
    const Setpoint& s = core.step();
    feeds.push_back(s.feed_mm_per_min);
    if (core.state() == RunState::kHeld) {
      ++holds;
      // Held after line 1: off, and on.
      switch_input(core, cnc::lcmt_program_command::SINGLE_BLOCK, false);
      core.apply_command({Command::Kind::kResume, 1.0, {}});
    }
    const double x = core.machine_position(0);
    if (holds == 1 && x > 15 && x < 45) slowest_after = std::min(slowest_after, s.feed_mm_per_min);
  }
  EXPECT_EQ(holds, 1);
  EXPECT_NEAR(slowest_after, 3000, 1e-6) << "the line starts at 20, 30, 40 are no stops once the switch is off";
  expect_within_limits(feeds);
}

TEST(OptionalStop, M1HoldsOnlyWithTheSwitchOn) {
  for (const bool on : {true, false}) {
    Interpolator core(sim3());
    switch_input(core, cnc::lcmt_program_command::OPTIONAL_STOP, on);
    EXPECT_EQ(core.optional_stop(), on);
    core.apply_command({Command::Kind::kLoad, 1.0, {}});
    ASSERT_TRUE(core.apply_block(line(0, 1, 0, 10)));
    ASSERT_TRUE(core.apply_block(event(1, 2, 10, program::EventKind::kOptionalStop)));
    ASSERT_TRUE(core.apply_block(line(2, 3, 10, 20)));
    ASSERT_TRUE(core.apply_block(end_block(3, 4, 20)));
    core.apply_command({Command::Kind::kStart, 1.0, {}});
    int held_cycles = 0;
    for (int i = 0; i < 100000 && core.state() != RunState::kDone; ++i) {
      core.step();
      if (core.state() == RunState::kHeld) {
        EXPECT_EQ(core.machine_position(0), 10.0);
        if (++held_cycles == 50) core.apply_command({Command::Kind::kResume, 1.0, {}});
      }
    }
    ASSERT_EQ(core.state(), RunState::kDone);
    EXPECT_EQ(held_cycles > 0, on) << "optional stop " << (on ? "on" : "off");
  }
}

TEST(SingleBlock, StopWhileHeldBeforeAnEventEndsTheProgram) {
  Interpolator core(sim3());
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  ASSERT_TRUE(core.apply_block(line(0, 1, 0, 10)));
  ASSERT_TRUE(core.apply_block(event(1, 2, 10, program::EventKind::kProgramStop)));
  ASSERT_TRUE(core.apply_block(line(2, 3, 10, 20)));
  ASSERT_TRUE(core.apply_block(end_block(3, 4, 20)));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  for (int i = 0; i < 100000 && core.state() != RunState::kHeld; ++i) core.step();
  ASSERT_EQ(core.state(), RunState::kHeld);
  core.apply_command({Command::Kind::kStop, 1.0, {}});
  for (int i = 0; i < 10 && core.state() != RunState::kIdle; ++i) core.step();
  EXPECT_EQ(core.state(), RunState::kIdle);
  EXPECT_EQ(core.machine_position(0), 10.0);
}

}  // namespace
}  // namespace cnc::interp
