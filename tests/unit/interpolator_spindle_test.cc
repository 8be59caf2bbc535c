// The core's spindle: a spindle event (M3, M4, M5, S) is taken when the path
// reaches it, in order with motion; on a machine with a spindle the path stands at a
// change to a speed until the recorded at-speed input names that change (through
// inputs.cc, as replay applies it); program end and STOP turn the spindle off, the
// end of an operator's line or move (MDI, jog) does not; a
// machine without one, and the dry run, never wait. The spindle override (a recorded
// input, SPINDLE_OVERRIDE) scales the commanded speed at once, within its configured
// range and spindle.max_rpm, with no at-speed wait; M51 P0 disables it, M51 P1 again.
#include <gtest/gtest.h>

#include <string>

#include "cnc/lcmt_interp_input.hpp"
#include "common/config/machine_config.h"
#include "common/motion/interpolator.h"
#include "common/program/block.h"
#include "services/interpolator/inputs.h"

namespace cnc::interp {
namespace {

config::MachineConfig load(const char* name) {
  return config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/" + name);
}

program::Block event_block(int64_t index, const std::vector<double>& at, int direction, double rpm) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kEvent;
  b.start = b.end = at;
  b.event.kind = program::EventKind::kSpindle;
  b.event.number = direction;
  b.event.value = rpm;
  return b;
}

program::Block line_block(int64_t index, const std::vector<double>& from, double x) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kLine;
  b.start = from;
  b.end = from;
  b.end[0] = x;
  b.feed_mm_per_min = 3000;
  return b;
}

// M3 S6000, G1 X10, M5, G1 X20, M30 (its own spindle stop is M5's), END.
void load_program(Interpolator& core) {
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  const std::vector<double> o{0, 0, 0}, x10{10, 0, 0}, x20{20, 0, 0};
  ASSERT_TRUE(core.apply_block(event_block(0, o, 1, 6000))) << core.last_refusal();
  ASSERT_TRUE(core.apply_block(line_block(1, o, 10))) << core.last_refusal();
  ASSERT_TRUE(core.apply_block(event_block(2, x10, 0, 0))) << core.last_refusal();
  ASSERT_TRUE(core.apply_block(line_block(3, x10, 20))) << core.last_refusal();
  program::Block end;
  end.index = 4;
  end.kind = program::BlockKind::kEnd;
  end.start = end.end = x20;
  ASSERT_TRUE(core.apply_block(end)) << core.last_refusal();
  core.apply_command({Command::Kind::kStart, 1.0, {}});
}

cnc::lcmt_interp_input at_speed_input(int64_t seq) {
  cnc::lcmt_interp_input in{};
  in.kind = cnc::lcmt_interp_input::COMMAND;
  in.command.command = cnc::lcmt_program_command::SPINDLE_AT_SPEED;
  in.command.value = static_cast<double>(seq);
  return in;
}

TEST(InterpolatorSpindle, ThePathStandsAtAChangeUntilItIsAtSpeed) {
  const config::MachineConfig cfg = load("sim3_spindle.yaml");
  ASSERT_TRUE(cfg.spindle.enabled);
  Interpolator core(cfg);
  load_program(core);
  for (int i = 0; i < 500; ++i) core.step();
  EXPECT_TRUE(core.spindle_waiting());
  EXPECT_EQ(core.spindle().seq, 1);
  EXPECT_EQ(core.spindle().direction, 1);
  EXPECT_EQ(core.spindle().rpm, 6000);
  EXPECT_EQ(core.state(), RunState::kRunning);
  EXPECT_EQ(core.last().position_mm[0], 0.0) << "no feed move before the spindle is at speed";
  // An at-speed input of an older change does not end the wait; the change's own does.
  EXPECT_EQ(apply_recorded_input(core, at_speed_input(0), 3), "");
  core.step();
  EXPECT_TRUE(core.spindle_waiting());
  EXPECT_EQ(apply_recorded_input(core, at_speed_input(1), 3), "");
  EXPECT_FALSE(core.spindle_waiting());
  bool moved = false;
  int64_t m5_cycle = -1;
  for (int i = 0; i < 100000 && core.state() != RunState::kDone; ++i) {
    core.step();
    moved = moved || core.last().position_mm[0] > 0;
    if (m5_cycle < 0 && core.spindle().direction == 0) {
      m5_cycle = core.cycle();
      EXPECT_NEAR(core.last().position_mm[0], 10.0, 1e-9) << "M5 is taken where the path reaches it";
    }
    EXPECT_FALSE(core.spindle_waiting()) << "a stop is not waited for";
  }
  EXPECT_TRUE(moved);
  EXPECT_EQ(core.state(), RunState::kDone);
  EXPECT_EQ(core.spindle().seq, 2);
  EXPECT_EQ(core.last().position_mm[0], 20.0);
}

cnc::lcmt_interp_input command_input(int8_t command, double value) {
  cnc::lcmt_interp_input in{};
  in.kind = cnc::lcmt_interp_input::COMMAND;
  in.command.command = command;
  in.command.value = value;
  return in;
}

TEST(InterpolatorSpindle, TheDoorsHoldStopsItAndResumeWaitsForItAtSpeed) {
  // The guard door's HOLD (value 1): the path brakes, the spindle stops once it stands;
  // RESUME turns it on again and the path stands, RUNNING, until it is at speed.
  const config::MachineConfig cfg = load("sim3_spindle.yaml");
  Interpolator core(cfg);
  load_program(core);
  for (int i = 0; i < 500; ++i) core.step();
  EXPECT_EQ(apply_recorded_input(core, at_speed_input(1), 3), "");
  while (core.last().position_mm[0] < 5) core.step();
  EXPECT_EQ(apply_recorded_input(core, command_input(cnc::lcmt_program_command::HOLD, 1), 3), "");
  int64_t braking = 0;
  while (core.state() != RunState::kHeld && braking < 1000) {
    core.step();
    ++braking;
    if (core.state() != RunState::kHeld) {
      EXPECT_EQ(core.spindle().direction, 1) << "turning while the path brakes";
    }
  }
  ASSERT_EQ(core.state(), RunState::kHeld);
  EXPECT_EQ(core.spindle().direction, 0) << "stopped once the path stands";
  EXPECT_EQ(core.spindle().seq, 2);
  const double held_at = core.last().position_mm[0];
  for (int i = 0; i < 100; ++i) core.step();
  EXPECT_EQ(core.last().position_mm[0], held_at);
  EXPECT_EQ(apply_recorded_input(core, command_input(cnc::lcmt_program_command::RESUME, 0), 3), "");
  // A RESUME again (an operator's client sends it until it sees the effect) changes nothing.
  EXPECT_EQ(apply_recorded_input(core, command_input(cnc::lcmt_program_command::RESUME, 0), 3), "");
  for (int i = 0; i < 200; ++i) core.step();
  EXPECT_EQ(core.spindle().seq, 3);
  EXPECT_EQ(core.spindle().direction, 1);
  EXPECT_EQ(core.spindle().rpm, 6000);
  EXPECT_TRUE(core.spindle_waiting());
  EXPECT_EQ(core.state(), RunState::kRunning);
  EXPECT_EQ(core.last().position_mm[0], held_at) << "no motion before the spindle is at speed";
  EXPECT_EQ(apply_recorded_input(core, at_speed_input(3), 3), "");
  for (int i = 0; i < 10; ++i) core.step();
  EXPECT_GT(core.last().position_mm[0], held_at);
  ASSERT_LT(core.last().position_mm[0], 9.0) << "short of the M5 at X 10";
  // An operator's HOLD (value 0) does not touch the spindle.
  EXPECT_EQ(apply_recorded_input(core, command_input(cnc::lcmt_program_command::HOLD, 0), 3), "");
  for (int i = 0; i < 1000 && core.state() != RunState::kHeld; ++i) core.step();
  ASSERT_EQ(core.state(), RunState::kHeld);
  for (int i = 0; i < 50; ++i) core.step();
  EXPECT_EQ(core.spindle().direction, 1);
  EXPECT_EQ(core.spindle().seq, 3);
}

TEST(InterpolatorSpindle, ProgramEndAndStopTurnItOff) {
  const config::MachineConfig cfg = load("sim3_spindle.yaml");
  Interpolator core(cfg);
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  const std::vector<double> o{0, 0, 0};
  ASSERT_TRUE(core.apply_block(event_block(0, o, -1, 3000)));
  ASSERT_TRUE(core.apply_block(line_block(1, o, 50)));
  program::Block end;
  end.index = 2;
  end.kind = program::BlockKind::kEnd;
  end.start = end.end = {50, 0, 0};
  ASSERT_TRUE(core.apply_block(end));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  for (int i = 0; i < 10; ++i) core.step();
  ASSERT_TRUE(core.spindle_waiting());
  Command at;
  at.kind = Command::Kind::kSpindleAtSpeed;
  at.value = 1;
  core.apply_command(at);
  for (int i = 0; i < 50; ++i) core.step();
  EXPECT_EQ(core.spindle().direction, -1);
  core.apply_command({Command::Kind::kStop, 1.0, {}});
  for (int i = 0; i < 10000 && core.state() != RunState::kIdle; ++i) core.step();
  EXPECT_EQ(core.state(), RunState::kIdle);
  EXPECT_EQ(core.spindle().direction, 0) << "STOP turns the spindle off";
  EXPECT_EQ(core.spindle().seq, 2);
  // Program end turns it off too (a program whose end comes without M5).
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  const std::vector<double> here{core.machine_position(0), 0, 0};
  ASSERT_TRUE(core.apply_block(event_block(0, here, 1, 1000)));
  end.index = 1;
  end.start = end.end = here;
  ASSERT_TRUE(core.apply_block(end));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  for (int i = 0; i < 5; ++i) core.step();
  core.apply_command(Command{Command::Kind::kSpindleAtSpeed, 1.0, {}, -1, 3.0});
  for (int i = 0; i < 100 && core.state() != RunState::kDone; ++i) core.step();
  EXPECT_EQ(core.state(), RunState::kDone);
  EXPECT_EQ(core.spindle().direction, 0);
  EXPECT_EQ(core.spindle().seq, 4);
}

TEST(InterpolatorSpindle, AnOperatorLinesEndLeavesTheSpindleAndCoolantOnAProgramsEndTurnsThemOff) {
  // MDI "M3 S1000" and "M8", then a jog (each ends in a kEnd of an operator line): the
  // spindle turns on and the flood stays on, as LinuxCNC's MDI leaves them; before,
  // every such end was a program end (M2), so MDI M3 stopped again at once and a jog
  // stopped a spindle the operator had started. A program's end (M2) turns both off.
  const config::MachineConfig cfg = load("sim3_spindle.yaml");
  Interpolator core(cfg);
  auto run = [&](std::vector<program::Block> blocks, int32_t end_kind) {
    core.apply_command({Command::Kind::kLoad, 1.0, {}});
    const std::vector<double> here{core.machine_position(0), 0, 0};
    program::Block end;
    end.kind = program::BlockKind::kEnd;
    end.event.number = end_kind;
    blocks.push_back(end);
    for (size_t i = 0; i < blocks.size(); ++i) {
      blocks[i].index = static_cast<int64_t>(i);
      if (blocks[i].start.empty()) blocks[i].start = blocks[i].end = i > 0 ? blocks[i - 1].end : here;
      ASSERT_TRUE(core.apply_block(blocks[i])) << core.last_refusal();
    }
    core.apply_command({Command::Kind::kStart, 1.0, {}});
    for (int i = 0; i < 5000 && core.state() != RunState::kDone; ++i) {
      core.step();
      if (core.spindle_waiting()) core.apply_command(Command{Command::Kind::kSpindleAtSpeed, 1.0, {}, -1, double(core.spindle().seq)});
    }
    ASSERT_EQ(core.state(), RunState::kDone);
  };
  program::Block m3;
  m3.kind = program::BlockKind::kEvent;
  m3.event.kind = program::EventKind::kSpindle;
  m3.event.number = 1;
  m3.event.value = 1000;
  run({m3}, program::kEndOfOperatorLine);
  EXPECT_EQ(core.spindle().direction, 1) << "MDI M3 S1000";
  EXPECT_EQ(core.spindle().rpm, 1000);
  program::Block m8;
  m8.kind = program::BlockKind::kEvent;
  m8.event.kind = program::EventKind::kCoolant;
  m8.event.number = 2;
  run({m8}, program::kEndOfOperatorLine);
  EXPECT_EQ(core.outputs().coolant, 2) << "MDI M8";
  EXPECT_EQ(core.spindle().direction, 1);
  run({line_block(0, {core.machine_position(0), 0, 0}, core.machine_position(0) + 5)}, program::kEndOfOperatorLine);
  EXPECT_EQ(core.spindle().direction, 1) << "a jog";
  EXPECT_EQ(core.outputs().coolant, 2);
  run({line_block(0, {core.machine_position(0), 0, 0}, core.machine_position(0) + 5)}, program::kEndOfProgram);
  EXPECT_EQ(core.spindle().direction, 0) << "a program's M2";
  EXPECT_EQ(core.outputs().coolant, 0);
}

TEST(InterpolatorSpindle, NoSpindleOrADryRunNeverWaits) {
  for (const char* name : {"sim3.yaml", "sim3_spindle.yaml"}) {
    const config::MachineConfig cfg = load(name);
    Interpolator core(cfg);
    if (cfg.spindle.enabled) core.set_auto_resume_pauses(true);  // the dry run
    load_program(core);
    for (int i = 0; i < 100000 && core.state() != RunState::kDone; ++i) {
      core.step();
      EXPECT_FALSE(core.spindle_waiting()) << name;
    }
    EXPECT_EQ(core.state(), RunState::kDone) << name;
    EXPECT_EQ(core.spindle().seq, 2) << name << ": the changes are taken all the same";
  }
}

cnc::lcmt_interp_input spindle_override_input(double value) {
  cnc::lcmt_interp_input in{};
  in.kind = cnc::lcmt_interp_input::COMMAND;
  in.command.command = cnc::lcmt_program_command::SPINDLE_OVERRIDE;
  in.command.feed_override = value;
  return in;
}

TEST(InterpolatorSpindle, TheOverrideScalesTheCommandedSpeedAtOnceWithinItsRangeAndNoWait) {
  config::MachineConfig cfg = load("sim3_spindle.yaml");
  EXPECT_EQ(cfg.spindle.min_override, 0.5);  // LinuxCNC's MIN_SPINDLE_OVERRIDE and MAX_SPINDLE_OVERRIDE defaults
  EXPECT_EQ(cfg.spindle.max_override, 1.0);
  cfg.spindle.max_override = 1.5;
  Interpolator core(cfg);
  // Set before the program: M3 S6000 turns at 80 %.
  EXPECT_EQ(apply_recorded_input(core, spindle_override_input(0.8), 3), "");
  EXPECT_EQ(core.spindle_override(), 0.8);
  EXPECT_EQ(core.spindle().seq, 0) << "a stopped spindle changes nothing";
  load_program(core);
  for (int i = 0; i < 50; ++i) core.step();
  ASSERT_TRUE(core.spindle_waiting());
  EXPECT_EQ(core.spindle().seq, 1);
  EXPECT_EQ(core.spindle().program_rpm, 6000);
  EXPECT_NEAR(core.spindle().rpm, 4800, 1e-9);
  EXPECT_EQ(apply_recorded_input(core, at_speed_input(1), 3), "");
  while (core.last().position_mm[0] < 2) core.step();
  // Mid-cut: a new change at once, not waited for; the path goes on.
  EXPECT_EQ(apply_recorded_input(core, spindle_override_input(1.25), 3), "");
  EXPECT_EQ(core.spindle().seq, 2);
  EXPECT_NEAR(core.spindle().rpm, 7500, 1e-9);
  EXPECT_FALSE(core.spindle_waiting());
  const double x = core.last().position_mm[0];
  core.step();
  EXPECT_GT(core.last().position_mm[0], x) << "the path does not stand for an override's change";
  // Beyond its range: clamped (the node refuses such a command; replay applies what was recorded).
  EXPECT_EQ(apply_recorded_input(core, spindle_override_input(2.0), 3), "");
  EXPECT_EQ(core.spindle_override(), 1.5);
  EXPECT_NEAR(core.spindle().rpm, 9000, 1e-9);
  EXPECT_EQ(apply_recorded_input(core, spindle_override_input(0.1), 3), "");
  EXPECT_EQ(core.spindle_override(), 0.5);
  EXPECT_NEAR(core.spindle().rpm, 3000, 1e-9);
  EXPECT_EQ(core.spindle().seq, 4);
  // The same value again: no change.
  EXPECT_EQ(apply_recorded_input(core, spindle_override_input(0.5), 3), "");
  EXPECT_EQ(core.spindle().seq, 4);
  // M5: off whatever the override; it stays for the next M3.
  for (int i = 0; i < 100000 && core.state() != RunState::kDone; ++i) core.step();
  EXPECT_EQ(core.spindle().direction, 0);
  EXPECT_EQ(core.spindle().rpm, 0);
  EXPECT_EQ(core.spindle_override(), 0.5);
  // S above what spindle.max_rpm allows under the override: at most max_rpm (24000).
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  EXPECT_EQ(apply_recorded_input(core, spindle_override_input(1.5), 3), "");
  const std::vector<double> here{core.machine_position(0), 0, 0};
  ASSERT_TRUE(core.apply_block(event_block(0, here, -1, 20000)));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  for (int i = 0; i < 5; ++i) core.step();
  EXPECT_EQ(core.spindle().direction, -1);
  EXPECT_NEAR(core.spindle().rpm, 24000, 1e-9);
}

program::Block overrides_block(int64_t index, const std::vector<double>& at, int bits) {
  program::Block b = event_block(index, at, 0, 0);
  b.event.kind = program::EventKind::kOverrides;
  b.event.number = bits;
  return b;
}

TEST(InterpolatorSpindle, M51P0DisablesTheOverrideUntilM51P1AndAProgramStartsWithItOn) {
  const config::MachineConfig cfg = load("sim3_spindle.yaml");
  Interpolator core(cfg);
  EXPECT_EQ(apply_recorded_input(core, spindle_override_input(0.5), 3), "");
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  // M3 S6000, M51 P0 (bits feed, adaptive, hold: 0xD), G1 X10, M51 P1 (0xF), G1 X20, END.
  const std::vector<double> o{0, 0, 0}, x10{10, 0, 0}, x20{20, 0, 0};
  ASSERT_TRUE(core.apply_block(event_block(0, o, 1, 6000)));
  ASSERT_TRUE(core.apply_block(overrides_block(1, o, 0xD)));
  ASSERT_TRUE(core.apply_block(line_block(2, o, 10)));
  ASSERT_TRUE(core.apply_block(overrides_block(3, x10, 0xF)));
  ASSERT_TRUE(core.apply_block(line_block(4, x10, 20)));
  program::Block end;
  end.index = 5;
  end.kind = program::BlockKind::kEnd;
  end.start = end.end = x20;
  ASSERT_TRUE(core.apply_block(end));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  for (int i = 0; i < 20; ++i) core.step();
  ASSERT_TRUE(core.spindle_waiting());
  EXPECT_NEAR(core.spindle().rpm, 3000, 1e-9);
  EXPECT_EQ(apply_recorded_input(core, at_speed_input(1), 3), "");
  for (int i = 0; i < 20; ++i) core.step();
  EXPECT_FALSE(core.spindle_override_enabled());
  EXPECT_EQ(core.spindle().seq, 2);
  EXPECT_NEAR(core.spindle().rpm, 6000, 1e-9) << "M51 P0: S as programmed";
  EXPECT_FALSE(core.spindle_waiting()) << "an override's change is not waited for";
  // The operator's override meanwhile is kept, not applied.
  EXPECT_EQ(apply_recorded_input(core, spindle_override_input(0.7), 3), "");
  EXPECT_EQ(core.spindle().seq, 2);
  EXPECT_NEAR(core.spindle().rpm, 6000, 1e-9);
  while (core.last().position_mm[0] < 10 - 1e-9) core.step();
  for (int i = 0; i < 20; ++i) core.step();
  EXPECT_TRUE(core.spindle_override_enabled());
  EXPECT_EQ(core.spindle().seq, 3);
  EXPECT_NEAR(core.spindle().rpm, 4200, 1e-9) << "M51 P1: the override again";
  for (int i = 0; i < 100000 && core.state() != RunState::kDone; ++i) core.step();
  EXPECT_EQ(core.state(), RunState::kDone);
  EXPECT_TRUE(core.spindle_override_enabled());
}

TEST(InterpolatorSpindle, TheOverrideAsARecordedInputReplaysBitForBit) {
  const config::MachineConfig cfg = load("sim3_spindle.yaml");
  auto run = [&](std::vector<double>* xs, std::vector<double>* rpms) {
    Interpolator core(cfg);
    load_program(core);
    for (int64_t i = 0; i < 100000 && core.state() != RunState::kDone; ++i) {
      if (i == 40) {
        EXPECT_EQ(apply_recorded_input(core, at_speed_input(1), 3), "");
      }
      if (i == 45) {
        EXPECT_EQ(apply_recorded_input(core, spindle_override_input(0.65), 3), "");
      }
      core.step();
      xs->push_back(core.last().position_mm[0]);
      rpms->push_back(core.spindle().rpm);
    }
  };
  std::vector<double> x1, r1, x2, r2;
  run(&x1, &r1);
  run(&x2, &r2);
  EXPECT_EQ(x1, x2);
  EXPECT_EQ(r1, r2);
  EXPECT_NEAR(r1[50], 3900, 1e-9);
}

}  // namespace
}  // namespace cnc::interp
