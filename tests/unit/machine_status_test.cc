// cnc-ctl --do status: the lines for the machine's devices, from the shipped guarded
// cell's config (spindle, I/O, E-stop, limits, door) with a probe, and messages as
// the bridge and the interpolator send them.
#include <gtest/gtest.h>

#include "common/config/machine_config.h"
#include "common/program/block.h"
#include "common/service/machine_status.h"

namespace {

using cnc::service::machine_status;
using cnc::service::MachineView;

cnc::config::MachineConfig guarded() {
  auto cfg = cnc::config::load_machine_config(CNC_SOURCE_DIR "/config/machines/sim3_guarded.yaml");
  cfg.probe.input = cfg.io.point_index("clamp_closed");  // a probe on a spare input for this test
  return cfg;
}

// IO_STATUS as the bridge fills it: every point in the config's order, all read.
cnc::lcmt_io_status io_of(const cnc::config::MachineConfig& cfg) {
  cnc::lcmt_io_status io{};
  io.num_points = static_cast<int32_t>(cfg.io.points.size());
  for (const auto& p : cfg.io.points) {
    io.name.push_back(p.name);
    io.kind.push_back(static_cast<int8_t>(p.kind));
    io.value.push_back(p.kind == cnc::config::IoKind::kDiscreteInput ? 1.0 : 0.0);
    io.valid.push_back(true);
  }
  io.num_modules = 1;
  io.module = {"io1"};
  io.answering = {true};
  io.transactions = {1234};
  io.timeouts = {0};
  io.exceptions = {0};
  io.last_error = {""};
  io.estop = cnc::lcmt_io_status::ESTOP_OK;
  io.estop_input = "estop_ok";
  io.limit = cnc::lcmt_io_status::LIMIT_OK;
  io.door = cnc::lcmt_io_status::DOOR_CLOSED;
  io.door_input = "door_closed";
  return io;
}

void set(const cnc::config::MachineConfig& cfg, cnc::lcmt_io_status* io, const char* point, double v) {
  io->value[static_cast<size_t>(cfg.io.point_index(point))] = v;
}

bool has(const std::string& text, const std::string& line) { return text.find(line) != std::string::npos; }

TEST(MachineStatus, NothingForACellWithoutDevices) {
  const auto cfg = cnc::config::load_machine_config(CNC_SOURCE_DIR "/config/machines/sim3.yaml");
  EXPECT_EQ(machine_status(cfg, MachineView{}), "");
}

TEST(MachineStatus, SaysWhatWasNotHeard) {
  const auto text = machine_status(guarded(), MachineView{});
  EXPECT_TRUE(has(text, "spindle: no SPINDLE_STATUS heard\n")) << text;
  EXPECT_TRUE(has(text, "io: no IO_STATUS heard\n")) << text;
  EXPECT_TRUE(has(text, "probe: input clamp_closed ? (not read); no probing result in this program\n")) << text;
}

TEST(MachineStatus, AGantrysSecondDriveItsSquaringAndSkew) {
  const auto cfg = cnc::config::load_machine_config(CNC_SOURCE_DIR "/config/machines/sim3_gantry.yaml");
  EXPECT_EQ(machine_status(cfg, MachineView{}), "gantry Y: Y2 not heard (JOINT_STATUS)\n");
  cnc::lcmt_joint_status j{};
  j.num_joints = 1;
  j.axis = {1};
  j.name = {"Y2"};
  j.actual_mm = {12.8031};
  j.squaring_mm = {0.8031};
  j.squaring_target_mm = {0.8031};
  j.skew_mm = {-0.0012};
  j.max_skew_mm = {0.0185};
  MachineView v;
  v.joints = &j;
  EXPECT_EQ(machine_status(cfg, v),
            "gantry Y: Y2 at 12.8031 mm, squaring 0.8031 mm (to 0.8031), skew -0.0012 mm (limit 0.5, largest since "
            "enable 0.0185)\n");
}

TEST(MachineStatus, SpindleWithOverrideAndLoad) {
  const auto cfg = guarded();
  cnc::lcmt_spindle_status s{};
  s.state = cnc::lcmt_spindle_status::RUNNING;
  s.command_seq = 3;
  s.at_speed_seq = 3;
  s.direction = 1;
  s.commanded_rpm = 8000;
  s.actual_rpm = 7996.4;
  s.current_a = 2.25;
  cnc::lcmt_interp_state in{};
  in.spindle_override = 0.8;
  in.spindle_override_enabled = 1;
  MachineView v;
  v.spindle = &s;
  v.interp = &in;
  EXPECT_TRUE(has(machine_status(cfg, v), "spindle: running, forward (M3), commanded 8000 rpm, actual 7996 rpm, "
                                          "at speed, load 2.25 A, override 0.80 (enabled)\n"))
      << machine_status(cfg, v);
  s.at_speed_seq = 2;  // a change not yet reached
  s.direction = -1;
  in.spindle_override_enabled = 0;
  EXPECT_TRUE(has(machine_status(cfg, v), "reverse (M4), commanded 8000 rpm, actual 7996 rpm, not at speed, load 2.25 A, "
                                          "override 0.80 (disabled: M51 P0)\n"))
      << machine_status(cfg, v);
  s.state = cnc::lcmt_spindle_status::FAULT;
  s.error_code = 7;
  s.fault = "spindle: not at speed within 5 s";
  EXPECT_TRUE(has(machine_status(cfg, v), "spindle: FAULT, "));
  EXPECT_TRUE(has(machine_status(cfg, v), ", drive error code 7: spindle: not at speed within 5 s\n"));
  EXPECT_FALSE(has(machine_status(cfg, v), "spindle position")) << "no encoder";
}

TEST(MachineStatus, TheSpindlesEncoderAndItsOrientation) {
  auto cfg = guarded();
  cfg.spindle.encoder_counts_per_rev = 4096;
  cnc::lcmt_spindle_status s{};
  s.state = cnc::lcmt_spindle_status::STOPPED;
  s.position_valid = true;
  s.position_rev = -2.75;  // the angle is the position's fraction: 0.25 of a turn
  s.orient_state = 2;      // ORIENTED
  MachineView v;
  v.spindle = &s;
  EXPECT_TRUE(has(machine_status(cfg, v), "spindle position: -2.7500 rev (90.00 deg), oriented\n"))
      << machine_status(cfg, v);
  s.position_valid = false;
  s.orient_state = 1;
  EXPECT_TRUE(has(machine_status(cfg, v), "spindle position: not read, orienting\n")) << machine_status(cfg, v);
}

TEST(MachineStatus, CoolantAndEveryPointByName) {
  const auto cfg = guarded();
  auto io = io_of(cfg);
  io.coolant = 2;  // M8
  set(cfg, &io, "coolant_flood", 1);
  set(cfg, &io, "air_pressure_bar", 6.12);
  set(cfg, &io, "coolant_valve_pct", 42.5);
  io.valid[static_cast<size_t>(cfg.io.point_index("lamp_red"))] = false;
  MachineView v;
  v.io = &io;
  const auto text = machine_status(cfg, v);
  EXPECT_TRUE(has(text, "coolant: mist off (coolant_mist reads 0), flood on (coolant_flood reads 1)\n")) << text;
  EXPECT_TRUE(has(text, "io module io1: answering, 1234 transactions, 0 timeouts, 0 exceptions\n")) << text;
  EXPECT_TRUE(has(text, "io clamp            digital out 0        io1 (M62-M65 P0)\n")) << text;
  EXPECT_TRUE(has(text, "io lamp_red         digital out ?        io1 (M62-M65 P3)\n")) << text;
  EXPECT_TRUE(has(text, "io clamp_closed     digital in  1        io1 (M66 P0, probe)\n")) << text;
  EXPECT_TRUE(has(text, "io air_pressure_bar analog in   6.12     io1 (M66 E0)\n")) << text;
  EXPECT_TRUE(has(text, "io coolant_valve_pct analog out  42.5     io1 (M67/M68 E0)\n")) << text;
  EXPECT_TRUE(has(text, "io estop_ok         digital in  1        io1 (E-stop)\n")) << text;
  EXPECT_TRUE(has(text, "io z_max_ok         digital in  1        io1 (Z max limit)\n")) << text;
  // One line per point ("io NAME ..."), besides the module's.
  size_t point_lines = 0;
  for (size_t at = 0; (at = text.find("\nio ", at)) != std::string::npos; ++at)
    if (text.compare(at, 11, "\nio module ") != 0) ++point_lines;
  EXPECT_EQ(point_lines, cfg.io.points.size()) << text;
}

TEST(MachineStatus, SafetyChainNamesItsInputs) {
  const auto cfg = guarded();
  auto io = io_of(cfg);
  MachineView v;
  v.io = &io;
  auto text = machine_status(cfg, v);
  EXPECT_TRUE(has(text, "E-stop: OK, input estop_ok reads 1\n")) << text;
  EXPECT_TRUE(has(text, "door: shut, input door_closed reads 1\n")) << text;
  EXPECT_TRUE(has(text, "limits: OK; X min x_min_ok 1 X max x_max_ok 1 Y min y_min_ok 1 Y max y_max_ok 1 "
                        "Z min z_min_ok 1 Z max z_max_ok 1\n"))
      << text;
  io.estop = cnc::lcmt_io_status::ESTOP_DISABLED;
  io.estop_utime = 1;
  io.estop_stop_ms = 87.31;
  set(cfg, &io, "estop_ok", 0);
  io.door = cnc::lcmt_io_status::DOOR_OPEN;
  set(cfg, &io, "door_closed", 0);
  io.limit = cnc::lcmt_io_status::LIMIT_TRIPPED;
  io.limit_input = "y_max_ok";
  set(cfg, &io, "y_max_ok", 0);
  text = machine_status(cfg, v);
  EXPECT_TRUE(has(text, "E-stop: TRIPPED, drives disabled, input estop_ok reads 0, last trip stood in 87.3 ms\n")) << text;
  EXPECT_TRUE(has(text, "door: OPEN (feed held, motion refused), input door_closed reads 0\n")) << text;
  EXPECT_TRUE(has(text, "limits: TRIPPED (the axes brake) (y_max_ok); X min x_min_ok 1 X max x_max_ok 1 Y min y_min_ok 1 "
                        "Y max y_max_ok 0 "))
      << text;
}

TEST(MachineStatus, ProbeAndItsLastResult) {
  const auto cfg = guarded();
  cnc::lcmt_axis_status ax{};
  ax.probe = 1;
  cnc::lcmt_interp_state in{};
  in.probe_results = 2;
  in.probe_block = 14;
  in.probe_tripped = 1;
  in.num_probe_axes = 3;
  in.probe_trip_mm = {100, 100, -20.0004};
  in.probe_rest_mm = {100, 100, -20.0125};
  MachineView v;
  v.axes = &ax;
  v.interp = &in;
  auto text = machine_status(cfg, v);
  EXPECT_TRUE(has(text, "probe: input clamp_closed 1 (touching); 2 probing moves, the last (block 14) tripped at "
                        "X 100.0000 Y 100.0000 Z -20.0004, rest at X 100.0000 Y 100.0000 Z -20.0125\n"))
      << text;
  in.probe_tripped = 0;
  ax.probe = 0;
  text = machine_status(cfg, v);
  EXPECT_TRUE(has(text, "probe: input clamp_closed 0; 2 probing moves, the last (block 14) did not trip, rest at X 100.0000"))
      << text;
}

TEST(MachineStatus, AnM66WaitWithItsInputModeAndTimeLeft) {
  const auto cfg = guarded();
  auto io = io_of(cfg);
  set(cfg, &io, "clamp_closed", 0);
  cnc::lcmt_interp_state in{};
  in.input_waiting = 1;
  in.input_wait = cnc::program::InputWait{0, false, cnc::program::InputWait::kRise}.number();
  in.input_wait_left_s = 2.46;
  MachineView v;
  v.io = &io;
  v.interp = &in;
  auto text = machine_status(cfg, v);
  EXPECT_TRUE(has(text, "M66: waiting on P0 (clamp_closed, reads 0), mode rise, 2.5 s left of its timeout\n")) << text;
  in.input_wait = cnc::program::InputWait{0, true, cnc::program::InputWait::kImmediate}.number();
  in.input_wait_left_s = -1;
  text = machine_status(cfg, v);
  EXPECT_TRUE(has(text, "M66: waiting on E0 (air_pressure_bar, reads 0), mode immediate, no timeout\n")) << text;
  in.input_waiting = 0;
  in.input_results = 1;
  in.input_block = 9;
  in.input_value = -1;
  text = machine_status(cfg, v);
  EXPECT_TRUE(has(text, "M66: last wait (block 9) timed out (#5399 = -1)\n")) << text;
  EXPECT_FALSE(has(text, "waiting on")) << text;
}

}  // namespace
