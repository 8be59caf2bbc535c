// The core's coolant and digital outputs (machine_outputs.h): each event is taken
// when the path reaches it, in order with motion; M64/M65 and the coolant change at
// the event (the motion before it ended), M62/M63 when the path next moves (after a
// dwell between them, not before); a later M62/M63 for the same output overwrites
// an earlier one; program end and STOP turn the coolant off and drop what is queued,
// the outputs keep their state.
#include <gtest/gtest.h>

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

program::Block event_block(int64_t index, double x, program::EventKind kind, int number, double value) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kEvent;
  b.start = b.end = {x, 0, 0};
  b.event.kind = kind;
  b.event.number = number;
  b.event.value = value;
  return b;
}

program::Block dwell_block(int64_t index, double x, double s) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kDwell;
  b.start = b.end = {x, 0, 0};
  b.dwell_s = s;
  return b;
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

program::Block end_block(int64_t index, double x) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kEnd;
  b.start = b.end = {x, 0, 0};
  return b;
}

using K = program::EventKind;

TEST(MachineOutputs, ImmediateQueuedAndEnd) {
  MachineOutputs o;
  o.take({K::kCoolant, 2, 0, {}});
  EXPECT_EQ(o.coolant, 2);
  EXPECT_EQ(o.seq, 1);
  o.take({K::kDigitalOutput, 3, 1 + 2, {}});  // M62 P3: queued
  EXPECT_EQ(o.outputs, 0u);
  o.take({K::kDigitalOutput, 3, 0 + 2, {}});  // M63 P3 overwrites it
  o.take({K::kDigitalOutput, 5, 1 + 2, {}});  // M62 P5
  o.take({K::kDigitalOutput, 0, 1, {}});      // M64 P0: at once
  EXPECT_EQ(o.outputs, 1u);
  EXPECT_EQ(o.seq, 2);
  o.motion();
  EXPECT_EQ(o.outputs, 1u | (1u << 5));
  EXPECT_EQ(o.seq, 3);
  o.motion();
  EXPECT_EQ(o.seq, 3) << "nothing queued: no change";
  o.take({K::kDigitalOutput, 7, 1 + 2, {}});
  o.end();
  EXPECT_EQ(o.coolant, 0);
  EXPECT_EQ(o.outputs, 1u | (1u << 5)) << "outputs keep their state; the queued M62 is dropped";
  o.motion();
  EXPECT_EQ(o.outputs, 1u | (1u << 5));
}

TEST(MachineOutputs, AnalogImmediateAndWithTheNextMotion) {
  MachineOutputs o;
  o.take({K::kAnalogOutput, 2, 42.5, {}});  // M68 E2 Q42.5: at once
  EXPECT_EQ(o.analog[2], 42.5);
  EXPECT_EQ(o.seq, 1);
  o.take({K::kAnalogOutput, 1000 + 3, 7, {}});  // M67 E3 Q7: queued
  o.take({K::kAnalogOutput, 1000 + 3, 8, {}});  // a later one overwrites it
  EXPECT_EQ(o.analog[3], 0.0);
  EXPECT_EQ(o.seq, 1);
  o.take({K::kAnalogOutput, 2, 42.5, {}});
  EXPECT_EQ(o.seq, 1) << "the same value: no change";
  o.motion();
  EXPECT_EQ(o.analog[3], 8.0);
  EXPECT_EQ(o.seq, 2);
  o.take({K::kAnalogOutput, 1000 + 3, -1, {}});
  o.take({K::kAnalogOutput, 3, 5, {}});  // M68 for the same output drops the queued M67
  o.motion();
  EXPECT_EQ(o.analog[3], 5.0);
  o.take({K::kAnalogOutput, 1000 + 2, 1, {}});
  o.end();
  o.motion();
  EXPECT_EQ(o.analog[2], 42.5) << "analog outputs keep their values; the queued M67 is dropped";
  EXPECT_EQ(o.analog[3], 5.0);
}

// M8, G1 X10, M62 P1, M64 P2, G4 P0.2, G1 X20, M65 P2, M30.
struct IoRun {
  std::vector<Setpoint> sp;
  std::vector<MachineOutputs> out;  // after each step
};

IoRun run_program(const config::MachineConfig& cfg) {
  Interpolator core(cfg);
  core.set_auto_resume_pauses(true);
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  const std::vector<program::Block> blocks = {
      event_block(0, 0, K::kCoolant, 2, 0),          line_block(1, 0, 10),
      event_block(2, 10, K::kDigitalOutput, 1, 3),   event_block(3, 10, K::kDigitalOutput, 2, 1),
      dwell_block(4, 10, 0.2),                       line_block(5, 10, 20),
      event_block(6, 20, K::kDigitalOutput, 2, 0),   end_block(7, 20)};
  for (const auto& b : blocks) EXPECT_TRUE(core.apply_block(b)) << core.last_refusal();
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  IoRun r;
  for (int i = 0; i < 5000 && core.state() != RunState::kDone; ++i) {
    r.sp.push_back(core.step());
    r.out.push_back(core.outputs());
  }
  EXPECT_EQ(core.state(), RunState::kDone);
  return r;
}

TEST(InterpolatorIo, OutputsChangeInOrderWithMotion) {
  const config::MachineConfig cfg = load("sim3_io.yaml");
  const IoRun r = run_program(cfg);
  ASSERT_FALSE(r.sp.empty());
  auto first = [&](auto pred) {
    for (size_t i = 0; i < r.out.size(); ++i)
      if (pred(r.out[i])) return static_cast<int64_t>(i);
    return int64_t{-1};
  };
  const int64_t flood = first([](const MachineOutputs& o) { return o.coolant == 2; });
  const int64_t p2_on = first([](const MachineOutputs& o) { return (o.outputs & 4) != 0; });
  const int64_t p1_on = first([](const MachineOutputs& o) { return (o.outputs & 2) != 0; });
  const int64_t p2_off = first([&](const MachineOutputs& o) { return p2_on >= 0 && o.seq > r.out[p2_on].seq + 1 && !(o.outputs & 4); });
  ASSERT_GE(flood, 0);
  ASSERT_GE(p2_on, 0);
  ASSERT_GE(p1_on, 0);
  ASSERT_GE(p2_off, 0);
  EXPECT_EQ(r.sp[flood].position_mm[0], 0.0) << "M8 before the first move";
  // M64 P2 at X10 at rest, before the dwell; M62 P1 when the second move starts, after the dwell.
  EXPECT_EQ(r.sp[p2_on].position_mm[0], 10.0);
  EXPECT_EQ(r.sp[p2_on].feed_mm_per_min, 0.0);
  EXPECT_GT(r.sp[p1_on].feed_mm_per_min, 0.0) << "M62 with the next motion";
  EXPECT_GT(r.sp[p1_on].position_mm[0], 10.0);
  EXPECT_EQ(r.sp[p1_on - 1].position_mm[0], 10.0) << "...its first cycle";
  const double dwell_s = static_cast<double>(p1_on - p2_on) * cfg.ipo_period_s;
  EXPECT_GE(dwell_s, 0.2) << "M62 waited out the dwell";
  EXPECT_EQ(r.sp[p2_off].position_mm[0], 20.0) << "M65 P2 at the end of the second move";
  // M30: the coolant off, the outputs as the program left them (P1 on, P2 off).
  EXPECT_EQ(r.out.back().coolant, 0);
  EXPECT_EQ(r.out.back().outputs, 2u);
  // Each change a new seq, in this order: flood, P2 on, P1 on, P2 off, coolant off.
  EXPECT_EQ(r.out.back().seq, 5);
  EXPECT_LT(flood, p2_on);
  EXPECT_LT(p2_on, p1_on);
  EXPECT_LT(p1_on, p2_off);
}

TEST(InterpolatorIo, TheSetpointsAreTheSameWithAndWithoutIo) {
  // The outputs ride along: the path is the one a machine without io: runs.
  const IoRun a = run_program(load("sim3_io.yaml"));
  const IoRun b = run_program(load("sim3.yaml"));
  ASSERT_EQ(a.sp.size(), b.sp.size());
  for (size_t i = 0; i < a.sp.size(); ++i) EXPECT_EQ(a.sp[i].position_mm, b.sp[i].position_mm) << "cycle " << i;
}

TEST(InterpolatorIo, StopTurnsTheCoolantOff) {
  Interpolator core(load("sim3_io.yaml"));
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  ASSERT_TRUE(core.apply_block(event_block(0, 0, K::kCoolant, 1, 0)));
  ASSERT_TRUE(core.apply_block(event_block(1, 0, K::kDigitalOutput, 3, 1)));
  ASSERT_TRUE(core.apply_block(line_block(2, 0, 100)));
  ASSERT_TRUE(core.apply_block(end_block(3, 100)));
  core.apply_command({Command::Kind::kStart, 1.0, {}});
  for (int i = 0; i < 100; ++i) core.step();
  EXPECT_EQ(core.outputs().coolant, 1);
  EXPECT_EQ(core.outputs().outputs, 8u);
  core.apply_command({Command::Kind::kStop, 1.0, {}});
  for (int i = 0; i < 2000 && core.state() != RunState::kIdle; ++i) core.step();
  EXPECT_EQ(core.state(), RunState::kIdle);
  EXPECT_EQ(core.outputs().coolant, 0) << "a finished STOP turns the coolant off";
  EXPECT_EQ(core.outputs().outputs, 8u);
}

}  // namespace
}  // namespace cnc::interp
