// The core's HOMED input: the drive offset it records moves the machine
// position and not the setpoint, later moves are in machine coordinates with the
// offset on every setpoint, a RESET takes the drives' positions less the offset, and
// the recorded command applies the same through inputs.cc (as replay applies it).
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "cnc/lcmt_interp_input.hpp"
#include "common/config/machine_config.h"
#include "common/motion/interpolator.h"
#include "common/program/block.h"
#include "common/program/block_msg.h"
#include "services/interpolator/inputs.h"

namespace cnc::interp {
namespace {

const config::MachineConfig& sim3() {
  static const config::MachineConfig cfg =
      config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  return cfg;
}

// A line of X from where the path stands to x, and END; run to the end.
void move_x(Interpolator& core, double x) {
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  program::Block line;
  line.index = 0;
  line.kind = program::BlockKind::kLine;
  line.start = {core.machine_position(0), core.machine_position(1), core.machine_position(2)};
  line.end = line.start;
  line.end[0] = x;
  line.feed_mm_per_min = 3000;
  ASSERT_TRUE(core.apply_block(line)) << core.last_refusal();
  program::Block end;
  end.index = 1;
  end.kind = program::BlockKind::kEnd;
  end.start = end.end = line.end;
  ASSERT_TRUE(core.apply_block(end)) << core.last_refusal();
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  for (int i = 0; i < 100000 && core.state() != RunState::kDone; ++i) core.step();
  ASSERT_EQ(core.state(), RunState::kDone);
}

Command homed(int axis, double offset) {
  Command c;
  c.kind = Command::Kind::kHomed;
  c.axis = axis;
  c.value = offset;
  return c;
}

TEST(InterpolatorHomed, OffsetMovesTheMachinePositionNotTheSetpoint) {
  Interpolator core(sim3());
  move_x(core, -3.9990);  // the search latched the switch here (drive coordinates)
  const double drive_before = core.last().position_mm[0];
  EXPECT_FALSE(core.homed(0));
  // The latch is switch_position_mm = -4 in machine coordinates: offset +0.001.
  core.apply_command(homed(0, 0.001));
  EXPECT_TRUE(core.homed(0));
  EXPECT_FALSE(core.homed(1));
  EXPECT_NEAR(core.last().position_mm[0], drive_before, 1e-12) << "the drive stays where it is";
  EXPECT_NEAR(core.machine_position(0), -4.0, 1e-12);
  // To machine 0: the drive goes to 0.001, every setpoint offset by it.
  move_x(core, 0.0);
  EXPECT_EQ(core.machine_position(0), 0.0);
  EXPECT_NEAR(core.last().position_mm[0], 0.001, 1e-12);
  EXPECT_EQ(core.last().position_mm[1], 0.0);
  // RESET takes the drives' positions less the offset.
  Command reset{Command::Kind::kReset, 1.0, {}};
  reset.position_mm[0] = 10.001;
  reset.position_mm[1] = 2.0;
  reset.position_mm[2] = -1.0;
  core.apply_command(reset);
  EXPECT_NEAR(core.machine_position(0), 10.0, 1e-12);
  EXPECT_EQ(core.machine_position(1), 2.0);
  EXPECT_NEAR(core.last().position_mm[0], 10.001, 1e-12);
  EXPECT_TRUE(core.homed(0)) << "a reset keeps the homing (the drives kept counting)";
}

TEST(InterpolatorHomed, NotAppliedWhileMovingAndRecordedLikeAnyCommand) {
  Interpolator core(sim3());
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  program::Block line;
  line.index = 0;
  line.kind = program::BlockKind::kLine;
  line.start = {0, 0, 0};
  line.end = {50, 0, 0};
  line.feed_mm_per_min = 3000;
  ASSERT_TRUE(core.apply_block(line));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  for (int i = 0; i < 50; ++i) core.step();
  const double x = core.machine_position(0);
  core.apply_command(homed(0, 5.0));
  EXPECT_FALSE(core.homed(0)) << "homing never moves the frame under a running path";
  EXPECT_EQ(core.machine_position(0), x);

  // The recorded form (lcmt_program_command HOMED) through inputs.cc, as replay applies it.
  Interpolator other(sim3());
  cnc::lcmt_interp_input in{};
  in.kind = cnc::lcmt_interp_input::COMMAND;
  in.command.command = cnc::lcmt_program_command::HOMED;
  in.command.axis = 2;
  in.command.value = -0.25;
  in.block.num_axes = 0;
  EXPECT_EQ(apply_recorded_input(other, in, 3), "");
  EXPECT_TRUE(other.homed(2));
  EXPECT_EQ(other.machine_position(2), 0.25);
  EXPECT_EQ(other.last().position_mm[2], 0.0);
  in.command.value = std::nan("");
  EXPECT_NE(apply_recorded_input(other, in, 3), "") << "a HOMED that is not a number is refused";
}

}  // namespace
}  // namespace cnc::interp
