// The core's input wait (an M66 event, program::InputWait): the path comes to rest at
// it (the motion before has ended) and stands there until an INPUT_VALUE ends it, or
// until its timeout, which the core counts in cycles (#5399 = -1, no error); the
// blocks after it (made by the program server with the value) then run from there.
// A value with no wait on is refused; STOP ends the program at the wait; the dry run
// passes it at once; the same inputs at the same cycles give the same setpoints.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/input_wait.h"
#include "common/motion/interpolator.h"
#include "common/program/block.h"

namespace cnc::interp {
namespace {

config::MachineConfig load(const char* name) {
  return config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/" + name);
}

program::Block line_block(int64_t index, double from, double to) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kLine;
  b.start = {from, 0, 0};
  b.end = {to, 0, 0};
  b.feed_mm_per_min = 3000;
  return b;
}

program::Block wait_block(int64_t index, double x, program::InputWait w, double timeout_s) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kEvent;
  b.start = b.end = {x, 0, 0};
  b.event.kind = program::EventKind::kWaitInput;
  b.event.number = w.number();
  b.event.value = timeout_s;
  return b;
}

program::Block end_block(int64_t index, double x) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kEnd;
  b.start = b.end = {x, 0, 0};
  return b;
}

struct WaitRun {
  std::vector<Setpoint> sp;
  int64_t start_cycle = -1, value_cycle = -1, end_cycle = -1;
  double value = 0;
};

// G1 X10, M66 P1 L1 Q<timeout>, then (made once the wait ended, as the program server
// does) G1 X20 and END. value_at: the wait's cycles after which the value 1 comes (-1 never).
WaitRun run(const config::MachineConfig& cfg, double timeout_s, int64_t value_at, int64_t replay_cycle = -1) {
  Interpolator core(cfg);
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  EXPECT_TRUE(core.apply_block(line_block(0, 0, 10)));
  EXPECT_TRUE(core.apply_block(wait_block(1, 10, {1, false, program::InputWait::kRise}, timeout_s)));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  WaitRun r;
  bool more = false;
  Command value;
  value.kind = Command::Kind::kInputValue;
  value.value = 1;
  for (int i = 0; i < 20000 && core.state() != RunState::kDone; ++i) {
    const InputWaitState& w = core.input_wait();
    if (w.waiting && r.start_cycle < 0) r.start_cycle = w.start_cycle;
    const bool now = replay_cycle >= 0 ? core.cycle() == replay_cycle
                                       : value_at >= 0 && w.waiting && core.cycle() - w.start_cycle == value_at;
    if (now) {
      EXPECT_TRUE(core.apply_command(value));
      r.value_cycle = core.cycle();
    }
    if (!more && w.results == 1 && !w.waiting) {
      more = true;
      r.end_cycle = core.cycle();
      r.value = w.value;
      EXPECT_EQ(w.block_index, 1);
      EXPECT_TRUE(core.apply_block(line_block(2, 10, 20))) << core.last_refusal();
      EXPECT_TRUE(core.apply_block(end_block(3, 20)));
    }
    r.sp.push_back(core.step());
  }
  EXPECT_EQ(core.state(), RunState::kDone);
  return r;
}

TEST(InterpolatorInput, ThePathStandsAtTheWaitUntilTheValueComes) {
  const config::MachineConfig cfg = load("sim3_io.yaml");
  const WaitRun r = run(cfg, 5.0, 100);
  ASSERT_GE(r.start_cycle, 0);
  ASSERT_GE(r.value_cycle, 0);
  EXPECT_EQ(r.value_cycle - r.start_cycle, 100);
  EXPECT_EQ(r.value, 1.0);
  // The wait starts once the motion before it has ended: the cycle before it reached X 10.
  ASSERT_GE(r.start_cycle, 1);
  EXPECT_EQ(r.sp[static_cast<size_t>(r.start_cycle - 1)].position_mm[0], 10.0);
  // Nothing moves from the wait's start until the value: X stands at 10, not a hair past.
  for (size_t i = static_cast<size_t>(r.start_cycle); i <= static_cast<size_t>(r.value_cycle); ++i) {
    EXPECT_EQ(r.sp[i].position_mm[0], 10.0) << "cycle " << i;
    EXPECT_EQ(r.sp[i].feed_mm_per_min, 0.0);
  }
  for (size_t i = 0; i < static_cast<size_t>(r.value_cycle); ++i) EXPECT_LE(r.sp[i].position_mm[0], 10.0);
  EXPECT_EQ(r.sp.back().position_mm[0], 20.0);
}

TEST(InterpolatorInput, ATimeoutEndsTheWaitWithMinusOneAtItsCycle) {
  const config::MachineConfig cfg = load("sim3_io.yaml");
  const double q = 0.2;
  const WaitRun r = run(cfg, q, -1);
  EXPECT_EQ(r.value, -1.0);
  const auto cycles = static_cast<int64_t>(std::ceil(q / cfg.ipo_period_s - 1e-9));
  EXPECT_EQ(r.end_cycle - r.start_cycle, cycles + 1);  // timed out in the step of cycle start + Q/T
  EXPECT_EQ(r.sp.back().position_mm[0], 20.0);
}

TEST(InterpolatorInput, ReplayedValueGivesTheSameSetpoints) {
  const config::MachineConfig cfg = load("sim3_io.yaml");
  const WaitRun live = run(cfg, 5.0, 37);
  const WaitRun again = run(cfg, 5.0, -1, live.value_cycle);
  ASSERT_EQ(live.sp.size(), again.sp.size());
  for (size_t i = 0; i < live.sp.size(); ++i) {
    ASSERT_EQ(live.sp[i].position_mm[0], again.sp[i].position_mm[0]) << "cycle " << i;
    ASSERT_EQ(live.sp[i].feed_mm_per_min, again.sp[i].feed_mm_per_min) << "cycle " << i;
  }
}

TEST(InterpolatorInput, AValueWithNoWaitOnIsRefusedAndStopEndsTheWait) {
  const config::MachineConfig cfg = load("sim3_io.yaml");
  Interpolator core(cfg);
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  ASSERT_TRUE(core.apply_block(line_block(0, 0, 10)));
  ASSERT_TRUE(core.apply_block(wait_block(1, 10, {0, false, program::InputWait::kImmediate}, 0)));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  Command value;
  value.kind = Command::Kind::kInputValue;
  value.value = 0;
  for (int i = 0; i < 10; ++i) core.step();
  EXPECT_FALSE(core.apply_command(value)) << "on the way to the wait";
  for (int i = 0; i < 20000 && !core.input_wait().waiting; ++i) core.step();
  ASSERT_TRUE(core.input_wait().waiting);
  // An immediate read has no timeout: it stands until the value comes.
  for (int i = 0; i < 2000; ++i) core.step();
  EXPECT_TRUE(core.input_wait().waiting);
  EXPECT_EQ(core.state(), RunState::kRunning);
  core.apply_command({Command::Kind::kStop, 1.0, {}});
  for (int i = 0; i < 10 && core.state() != RunState::kIdle; ++i) core.step();
  EXPECT_EQ(core.state(), RunState::kIdle);
  EXPECT_FALSE(core.input_wait().waiting);
  EXPECT_FALSE(core.apply_command(value));
}

TEST(InterpolatorInput, ATimeoutDuringAHoldTakesEffectAtResume) {
  const config::MachineConfig cfg = load("sim3_io.yaml");
  Interpolator core(cfg);
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  ASSERT_TRUE(core.apply_block(line_block(0, 0, 10)));
  ASSERT_TRUE(core.apply_block(wait_block(1, 10, {0, false, program::InputWait::kHigh}, 0.1)));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  for (int i = 0; i < 20000 && !core.input_wait().waiting; ++i) core.step();
  ASSERT_TRUE(core.input_wait().waiting);
  core.apply_command({Command::Kind::kHold, 1.0, {}});
  for (int i = 0; i < 100; ++i) core.step();  // 0.4 s, past the 0.1 s timeout
  EXPECT_EQ(core.state(), RunState::kHeld);
  EXPECT_TRUE(core.input_wait().waiting);
  EXPECT_EQ(core.last().position_mm[0], 10.0);
  core.apply_command({Command::Kind::kResume, 1.0, {}});
  core.step();
  EXPECT_FALSE(core.input_wait().waiting);
  EXPECT_EQ(core.input_wait().value, -1.0);
  EXPECT_EQ(core.input_wait().results, 1);
}

TEST(InterpolatorInput, TheDryRunPassesTheWait) {
  const config::MachineConfig cfg = load("sim3_io.yaml");
  Interpolator core(cfg);
  core.set_auto_resume_pauses(true);
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  ASSERT_TRUE(core.apply_block(line_block(0, 0, 10)));
  ASSERT_TRUE(core.apply_block(wait_block(1, 10, {1, false, program::InputWait::kHigh}, 30)));
  ASSERT_TRUE(core.apply_block(line_block(2, 10, 20)));
  ASSERT_TRUE(core.apply_block(end_block(3, 20)));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  int cycles = 0;
  for (; cycles < 20000 && core.state() != RunState::kDone; ++cycles) core.step();
  EXPECT_EQ(core.state(), RunState::kDone);
  EXPECT_LT(cycles * cfg.ipo_period_s, 5.0);  // two 10 mm moves at 50 mm/s, not the 30 s timeout
  EXPECT_EQ(core.input_wait().results, 0);
}

TEST(InputWaitCondition, LinuxCncsModes) {
  using W = program::InputWait;
  auto first_met = [](int mode, std::vector<double> readings) {
    InputWaitCondition c(mode);
    for (size_t i = 0; i < readings.size(); ++i)
      if (c.met(readings[i])) return static_cast<int>(i);
    return -1;
  };
  EXPECT_EQ(first_met(W::kImmediate, {1}), 0);
  EXPECT_EQ(first_met(W::kImmediate, {0}), 0);
  EXPECT_EQ(first_met(W::kRise, {0, 0, 1}), 2);
  EXPECT_EQ(first_met(W::kRise, {1, 1, 0, 1}), 3) << "already high: it must fall, then rise";
  EXPECT_EQ(first_met(W::kRise, {1, 1, 1}), -1);
  EXPECT_EQ(first_met(W::kFall, {0, 1, 0}), 2) << "already low: it must rise, then fall";
  EXPECT_EQ(first_met(W::kFall, {1, 0}), 1);
  EXPECT_EQ(first_met(W::kHigh, {0, 0, 1}), 2);
  EXPECT_EQ(first_met(W::kHigh, {1}), 0);
  EXPECT_EQ(first_met(W::kLow, {1, 0}), 1);
  InputWaitCondition c(W::kRise);
  c.met(0);
  EXPECT_TRUE(c.met(1));
  EXPECT_TRUE(c.met(0)) << "once met, it stays met";
}

TEST(InputWaitNumber, RoundTrips) {
  for (const program::InputWait w : {program::InputWait{0, false, 0}, program::InputWait{63, false, 4},
                                     program::InputWait{7, true, 0}, program::InputWait{12, false, 1}}) {
    const program::InputWait b = program::InputWait::of(w.number());
    EXPECT_EQ(b.index, w.index);
    EXPECT_EQ(b.analog, w.analog);
    EXPECT_EQ(b.mode, w.mode);
  }
  EXPECT_EQ((program::InputWait{3, false, 2}.number()), 2003);
  EXPECT_EQ((program::InputWait{1, true, 0}.number()), 10001);
}

}  // namespace
}  // namespace cnc::interp
