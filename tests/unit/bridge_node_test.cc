// The drive bridge node on the in-process loopback link and an in-memory bus,
// servo ticks driven by the test (no threads, no clock): enable at start, follow
// setpoints, publish AXIS_STATUS; a lost link faults, is reconnected with the
// reconnect counted and the drives kept disabled until ENABLE; a drive fault and a
// following error fault; exceptions and timeouts are counted and not fatal;
// DISABLE stops following. Each profile drives the same scenario. A spindle VFD on
// the same loopback link: SPINDLE_CMD followed and at speed on SPINDLE_STATUS, its
// at-speed timeout a fault of the bridge naming it, and still no allocation per tick.
// A servo spindle with its encoder: the position at 10 rev/s on SPINDLE_STATUS with its
// playback stamp, an orientation carried out and held; the config errors of an encoder.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <modbus.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_drive_command.hpp"
#include "cnc/lcmt_interp_input.hpp"
#include "cnc/lcmt_joint_status.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "cnc/lcmt_spindle_command.hpp"
#include "cnc/lcmt_io_status.hpp"
#include "cnc/lcmt_spindle_status.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/config/yaml_reader.h"
#include "common/drive/loopback_link.h"
#include "services/drive_bridge/drive_bridge_node.h"
#include "tests/unit/alloc_guard.h"

namespace cnc::bridge {
namespace {

using State = DriveBridgeNode::State;
// Read in constant expressions, so the test does not odr-use the generated statics.
constexpr int kEnabled = cnc::lcmt_axis_status::ENABLED;
constexpr int kFault = cnc::lcmt_axis_status::FAULT;
constexpr int kDisabled = cnc::lcmt_axis_status::DISABLED;

std::string machine_yaml(const std::string& profile, bool enable_on_start) {
  std::string y =
      "cell: {name: lb, channel_prefix: \"LB.\"}\n"
      "timing: {ipo_period_s: 0.004, servo_period_s: 0.001, setpoint_timeout_s: 0.05, stop_decel_mm_s2: 2000}\n"
      "drive_bridge: {enable_on_start: " + std::string(enable_on_start ? "true" : "false") +
      ", link_loss_timeout_s: 0.05, reconnect_min_s: 0.01, reconnect_max_s: 0.04}\n"
      "axes:\n";
  for (int i = 0; i < 2; ++i) {
    y += "  - {name: " + std::string(i == 0 ? "X" : "Y") +
         ", min_mm: -5, max_mm: 300, max_velocity_mm_s: 250, max_accel_mm_s2: 3000, max_jerk_mm_s3: 60000,"
         " max_following_error_mm: 0.5, home_mm: 10,"
         " drive: {transport: loopback, unit_id: " + std::to_string(i + 1) + ", profile: " + profile + "}}\n";
  }
  return y;
}

// A VFD as unit 3 on the axes' loopback link.
const std::string kSpindle =
    "spindle: {drive: {transport: loopback, unit_id: 3, profile: delta_vfd}, at_speed_tolerance: 0.02,"
    " at_speed_timeout_s: 0.2}\n";

// An I/O module as unit 4 on the axes' loopback link: coolant, two outputs, an input, two registers.
const std::string kIo =
    "io:\n"
    "  modules: [{name: io1, transport: loopback, unit_id: 4}]\n"
    "  points:\n"
    "    - {name: mist, kind: coil, address: 0}\n"
    "    - {name: flood, kind: coil, address: 1}\n"
    "    - {name: clamp, kind: coil, address: 8}\n"
    "    - {name: lamp, kind: coil, address: 9}\n"
    "    - {name: door, kind: discrete_input, address: 2}\n"
    "    - {name: pressure, kind: input_register, address: 1, scale: 0.01}\n"
    "    - {name: valve, kind: holding_register, address: 0, scale: 0.5, signed: true}\n"
    "  coolant: {mist: mist, flood: flood}\n"
    "  digital_outputs: [clamp, lamp]\n"
    "  digital_inputs: [door]\n"
    "  analog_inputs: [pressure]\n"
    "  analog_outputs: [valve]\n";

class Cell {
 public:
  Cell(const std::string& profile, bool enable_on_start, const std::string& extra = "")
      : Cell(config::parse_machine_config(machine_yaml(profile, enable_on_start) + extra, "lb.yaml")) {}
  explicit Cell(config::MachineConfig c)
      : cfg(std::move(c)), bus("memq://"), node(cfg, bus, DriveBridgeNode::Options{false}) {
    bus.subscribe<cnc::lcmt_axis_status>("LB.AXIS_STATUS", [this](const auto& m) { status = m; });
    bus.subscribe<cnc::lcmt_spindle_status>("LB.SPINDLE_STATUS", [this](const auto& m) { spindle = m; });
    bus.subscribe<cnc::lcmt_io_status>("LB.IO_STATUS", [this](const auto& m) { io = m; });
    bus.subscribe<cnc::lcmt_alarm>("LB.ALARM", [this](const auto& m) { alarms.push_back(m.code + ": " + m.text); });
    node.start();
  }
  // One servo tick at 1 ms; a setpoint every 4th tick when `sp` is given.
  void tick() {
    t += 0.001;
    if (count_allocations) {
      // The servo tick and the status publish (the cyclic path, which here also
      // runs the link's round on this thread and delivers the bus's messages).
      test::AllocGuard g;
      node.servo_tick(t);
      node.publish_status(0);
      cyclic_allocations += g.allocations() + g.frees();
    } else {
      node.servo_tick(t);
      node.publish_status(0);
    }
    bus.drain();
  }
  void ticks(int n) {
    for (int i = 0; i < n; ++i) tick();
  }
  // A setpoint carrying the last three (newest first), as the interpolator sends
  // them; `lose` drops it on the way.
  void setpoint(double x, double y, bool lose = false) {
    cnc::lcmt_setpoint m{};
    m.stream = 1;
    m.engagement = node.core().engagement();  // what the interpolator echoes from AXIS_STATUS
    m.cycle = cycle++;
    m.period_s = 0.004;
    m.num_axes = 2;
    m.position_mm = {x, y};
    for (size_t j = past.size(); j-- > 0 && past.size() - j <= 3;) {
      m.prev_position_mm.push_back(past[j][0]);
      m.prev_position_mm.push_back(past[j][1]);
    }
    m.num_prev_values = static_cast<int32_t>(m.prev_position_mm.size());
    past.push_back({x, y});
    if (!lose) bus.publish("LB.SETPOINTS", m);
  }
  std::vector<std::array<double, 2>> past;
  // X from `from` to `to` at up to 25 mm/s, accelerating at 625 mm/s^2 (0.01 mm per cycle per cycle).
  double move_x(double from, double to, double y = 10) {
    const double dir = to > from ? 1 : -1;
    double x = from, v = 0;
    while (std::fabs(to - x) > 1e-9) {
      const double left = std::fabs(to - x);
      // Brake when the distance to go is what braking from v takes.
      const double brake = v * (v / 0.01 + 1) / 2;
      v = left <= brake + 1e-12 ? std::max(0.01, v - 0.01) : std::min(0.1, v + 0.01);
      x = std::fabs(to - x) < v ? to : x + dir * v;
      setpoint(x, y);
      ticks(4);
    }
    return x;
  }
  // X from `from` to `to` as a jerk-limited interpolator streams it: a quintic
  // smoothstep over `t_s` (1 mm in 0.2 s: jerk 7500 mm/s^3, well under the limit).
  double move_x_smooth(double from, double to, double t_s = 0.2, double y = 10) {
    const int n = static_cast<int>(std::lround(t_s / 0.004));
    for (int i = 1; i <= n; ++i) {
      const double u = static_cast<double>(i) / n;
      setpoint(from + (to - from) * u * u * u * (10 - 15 * u + 6 * u * u), y);
      ticks(4);
    }
    return to;
  }
  // The stream of an idle interpolator at (x, y) for n cycles.
  void hold_stream(double x, double y, int n) {
    for (int i = 0; i < n; ++i) {
      setpoint(x, y);
      ticks(4);
    }
  }
  void command(int8_t c) {
    cnc::lcmt_drive_command m{};
    m.command = c;
    bus.publish("LB.DRIVE_CMD", m);
  }
  drive::LoopbackLink& link() { return dynamic_cast<drive::LoopbackLink&>(node.link_of(0)); }
  double drive_mm(int unit) {
    drive::DriveEmulator* d = link().drive(unit);
    const auto& f = d->profile().field(drive::Role::kActualPosition);
    uint16_t r[2];
    d->read(f.address, 2, r);
    return f.decode(r);
  }
  bool alarmed(const std::string& code) const {
    for (const auto& a : alarms)
      if (a.rfind(code, 0) == 0) return true;
    return false;
  }

  void spindle_command(int64_t seq, int8_t direction, double rpm) {
    cnc::lcmt_spindle_command m{};
    m.command_seq = seq;
    m.direction = direction;
    m.rpm = rpm;
    bus.publish("LB.SPINDLE_CMD", m);
  }
  void spindle_orient(int64_t seq, double degrees, int8_t mode) {
    cnc::lcmt_spindle_command m{};
    m.command_seq = seq;
    m.orient = true;
    m.orient_deg = degrees;
    m.orient_mode = mode;
    bus.publish("LB.SPINDLE_CMD", m);
  }

  void io_command(int64_t seq, int8_t coolant, int64_t outputs, std::vector<double> analog = {}) {
    cnc::lcmt_io_command m{};
    m.command_seq = seq;
    m.coolant = coolant;
    m.outputs = outputs;
    m.num_analog = static_cast<int32_t>(analog.size());
    m.analog = std::move(analog);
    bus.publish("LB.IO_CMD", m);
  }
  int coil(int addr) { return link().io_module(4)->coil(addr); }
  double io_value(const std::string& name) const {
    for (int i = 0; i < io.num_points; ++i)
      if (io.name[static_cast<size_t>(i)] == name) return io.value[static_cast<size_t>(i)];
    return -1e9;
  }

  config::MachineConfig cfg;
  bus::Bus bus;
  DriveBridgeNode node;
  cnc::lcmt_io_status io{};
  cnc::lcmt_axis_status status{};
  cnc::lcmt_spindle_status spindle{};
  std::vector<std::string> alarms;
  double t = 0;
  int64_t cycle = 0;
  bool count_allocations = false;
  long cyclic_allocations = 0;
};

class EveryProfile : public ::testing::TestWithParam<std::string> {};

TEST_P(EveryProfile, EnablesAtStartAndFollowsSetpoints) {
  Cell c(GetParam(), true);
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_TRUE(c.node.ready());
  EXPECT_TRUE(c.alarmed("drives_enabled"));
  const double x = c.move_x(10, 19.5);
  // The stream stops from 2.5 mm/s within one cycle (over the jerk limit): the
  // bridge's limiter lands on it within the limits, asymptotically (time constant
  // ~50 ms): 400 ms later within 0.1 µm.
  c.hold_stream(x, 10, 100);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_NEAR(c.drive_mm(1), x, 2e-3);
  EXPECT_NEAR(c.drive_mm(2), 10, 2e-3);
  ASSERT_EQ(c.status.num_axes, 2);
  EXPECT_EQ(int{c.status.drive_state[0]}, kEnabled);
  EXPECT_NEAR(c.status.actual_mm[0], x, 2e-3);
  EXPECT_NEAR(c.status.commanded_mm[0], x, 1e-4);
  EXPECT_GT(c.status.transactions[0], 400);
  EXPECT_EQ(c.status.timeouts[0] + c.status.exceptions[0] + c.status.crc_errors[0] + c.status.reconnects[0], 0);
}

TEST_P(EveryProfile, LostLinkFaultsReconnectsAndStaysDisabledUntilEnable) {
  Cell c(GetParam(), true);
  c.ticks(40);
  c.hold_stream(10, 10, 5);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  c.link().set_reachable(false);
  c.hold_stream(10, 10, 5);
  EXPECT_EQ(c.node.state(), State::kFault) << c.node.detail();
  EXPECT_NE(c.node.detail().find("link loopback lost"), std::string::npos) << c.node.detail();
  EXPECT_TRUE(c.alarmed("drive_fault"));
  EXPECT_EQ(int{c.status.drive_state[0]}, kFault);
  // Back: reconnected and counted, the drives disabled, nothing moves.
  c.link().set_reachable(true);
  c.hold_stream(10, 10, 30);
  EXPECT_EQ(c.status.reconnects[0], 1);
  EXPECT_EQ(c.status.reconnects[1], 1);
  EXPECT_TRUE(c.alarmed("drive_reconnected"));
  EXPECT_FALSE(c.link().drive(1)->follows());
  EXPECT_FALSE(c.link().drive(2)->follows());
  EXPECT_EQ(c.node.state(), State::kFault);
  EXPECT_NEAR(c.drive_mm(1), 10, 1e-3);
  // ENABLE: enabled again, following.
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(10, 10, 20);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_TRUE(c.link().drive(1)->follows());
  const double x = c.move_x(10, 12);
  c.hold_stream(x, 10, 100);  // landing within the jerk limit (see above)
  EXPECT_NEAR(c.drive_mm(1), x, 2e-3);
}

TEST_P(EveryProfile, DriveFaultFaultsAndEnableResetsIt) {
  Cell c(GetParam(), true);
  c.ticks(40);
  c.hold_stream(10, 10, 5);
  c.link().drive(2)->inject_fault(0x7500);
  c.hold_stream(10, 10, 5);
  EXPECT_EQ(c.node.state(), State::kFault);
  EXPECT_NE(c.node.detail().find("axis Y: the drive reports a fault"), std::string::npos) << c.node.detail();
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(10, 10, 20);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_TRUE(c.link().drive(2)->follows());
}

INSTANTIATE_TEST_SUITE_P(Shipped, EveryProfile, ::testing::Values("sim", "cia402_modbus", "leadshine_el"));

TEST(BridgeNode, ServoTickAndStatusPublishAllocateNothing) {
  Cell c("sim", true);
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  // A first move sizes what grows once (the bus's reused messages and buffers).
  double x = c.move_x(10, 19.5);
  c.hold_stream(x, 10, 20);
  c.count_allocations = true;
  // Accelerate, cruise, decelerate, stand: every tick counted (operator new and
  // delete on this thread; LCM's C core is not C++ and not counted).
  x = c.move_x(x, 12);
  c.hold_stream(x, 10, 50);
  x = c.move_x(x, 25);
  c.hold_stream(x, 10, 100);
  c.count_allocations = false;
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_NEAR(c.drive_mm(1), x, 0.2);
  EXPECT_EQ(c.cyclic_allocations, 0);
}

TEST(BridgeNode, SpindleFollowsItsCommandsAndReportsAtSpeed) {
  Cell c("sim", true, kSpindle);
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  ASSERT_NE(c.node.spindle(), nullptr);
  c.spindle_command(101, 1, 6000);
  c.hold_stream(10, 10, 5);
  drive::VfdEmulator* vfd = c.link().vfd(3);
  ASSERT_NE(vfd, nullptr);
  EXPECT_TRUE(vfd->running());
  EXPECT_NEAR(vfd->command_hz(), 100.0, 1e-9);  // 6000 rpm at 60 rpm/Hz
  EXPECT_EQ(c.spindle.command_seq, 101);
  EXPECT_EQ(c.spindle.at_speed_seq, 101);
  EXPECT_EQ(int{c.spindle.state}, int{cnc::lcmt_spindle_status::RUNNING});
  EXPECT_NEAR(c.spindle.actual_rpm, 6000, 1e-6);
  EXPECT_GT(c.spindle.current_a, 0);
  EXPECT_GT(c.spindle.transactions, 0);
  // Counterclockwise, then a repeat of an older command changes nothing.
  c.spindle_command(102, -1, 3000);
  c.hold_stream(10, 10, 5);
  EXPECT_NEAR(c.spindle.actual_rpm, -3000, 1e-6);
  c.spindle_command(101, 1, 6000);
  c.hold_stream(10, 10, 5);
  EXPECT_NEAR(c.spindle.actual_rpm, -3000, 1e-6);
  // DISABLE stops it; the command it had is not taken again after ENABLE.
  c.command(cnc::lcmt_drive_command::DISABLE);
  c.hold_stream(10, 10, 5);
  EXPECT_FALSE(vfd->running());
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.spindle_command(102, -1, 3000);
  c.hold_stream(10, 10, 20);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_FALSE(vfd->running());
  c.spindle_command(103, 1, 1000);
  c.hold_stream(10, 10, 5);
  EXPECT_TRUE(vfd->running());
  EXPECT_EQ(c.spindle.at_speed_seq, 103);
}

// A servo spindle (cia402_spindle: a CiA-402 drive in profile velocity mode, its
// 17-bit encoder) as unit 3 on the axes' loopback link.
const std::string kServoSpindle =
    "spindle: {drive: {transport: loopback, unit_id: 3, profile: cia402_spindle}, max_rpm: 6000,"
    " at_speed_tolerance: 0.02, at_speed_timeout_s: 0.5, encoder_counts_per_rev: 131072,"
    " orient_tolerance_deg: 0.2, orient_timeout_s: 2, orient_rpm: 120, orient_gain_per_s: 20}\n";
constexpr int kOriented = cnc::lcmt_spindle_status::ORIENTED;
constexpr int kOrientNone = cnc::lcmt_spindle_status::ORIENT_NONE;

TEST(BridgeNode, ServoSpindlePublishesItsEncodersPositionAndOrients) {
  Cell c("sim", true, kServoSpindle);
  c.link().set_clock([&c] { return c.t; });  // the encoder counts on the test's clock
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  drive::VfdEmulator* drive = c.link().vfd(3);
  ASSERT_NE(drive, nullptr);
  c.hold_stream(10, 10, 5);
  EXPECT_TRUE(drive->running()) << "enabled through its state machine while the bridge follows setpoints";
  EXPECT_TRUE(c.spindle.position_valid);
  EXPECT_EQ(int{c.spindle.orient_state}, kOrientNone);
  // 600 rpm clockwise: the position advances at +10 rev/s, stamped on the playback's clock.
  c.spindle_command(101, 1, 600);
  c.hold_stream(10, 10, 50);
  ASSERT_EQ(c.spindle.at_speed_seq, 101);
  const cnc::lcmt_spindle_status a = c.spindle;
  const double ta = c.t;
  c.hold_stream(10, 10, 125);  // 0.5 s
  const cnc::lcmt_spindle_status b = c.spindle;
  const double tb = c.t;
  EXPECT_NEAR((b.position_rev - a.position_rev) / (tb - ta), 10.0, 0.05);
  ASSERT_GE(a.sample_playback_cycle, 0);
  EXPECT_NEAR((b.sample_playback_cycle - a.sample_playback_cycle) * 0.004, tb - ta, 0.002);
  // The sample was taken in the round the last tick posted: the playback then, within a tick.
  EXPECT_NEAR(b.sample_playback_cycle, c.status.playback_cycle, 0.25 + 1e-6);
  EXPECT_NEAR(b.position_rev, drive->revolutions(), 10.0 * 0.002) << "within two ticks of the drive's";
  // Orientation to 90 deg the shortest way: ORIENTED for its command_seq within the tolerance.
  c.spindle_orient(102, 90, 0);
  int ticks = 0;
  while (!(c.spindle.command_seq == 102 && c.spindle.orient_state == kOriented) && ticks < 2000) {
    c.hold_stream(10, 10, 1);
    ticks += 4;
  }
  ASSERT_EQ(int{c.spindle.orient_state}, kOriented) << c.spindle.fault;
  const double angle = (c.spindle.position_rev - std::floor(c.spindle.position_rev)) * 360;
  EXPECT_NEAR(angle, 90, 0.2);
  EXPECT_EQ(c.spindle.at_speed_seq, 102) << "an orientation is not waited for at speed";
  c.hold_stream(10, 10, 100);
  EXPECT_NEAR((drive->revolutions() - std::floor(drive->revolutions())) * 360, 90, 0.2) << "held";
  EXPECT_EQ(int{c.spindle.orient_state}, kOriented);
  // DISABLE: the bridge stops following; the drive is disabled once it stands.
  c.command(cnc::lcmt_drive_command::DISABLE);
  c.hold_stream(10, 10, 10);
  EXPECT_FALSE(drive->running());
}

TEST(BridgeNode, AnEncoderWithoutItsRegisterOrAToleranceTheDriveCannotHoldIsAConfigError) {
  const auto config_error = [](const std::string& spindle) {
    const config::MachineConfig cfg = config::parse_machine_config(machine_yaml("sim", true) + spindle, "lb.yaml");
    bus::Bus bus("memq://");
    try {
      DriveBridgeNode node(cfg, bus, DriveBridgeNode::Options{false});
    } catch (const config::ConfigError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_THAT(config_error("spindle: {drive: {transport: loopback, unit_id: 3, profile: delta_vfd},"
                           " encoder_counts_per_rev: 4096}\n"),
              ::testing::HasSubstr("spindle.encoder_counts_per_rev: 4096 counts: the spindle's drive profile "
                                   "'delta_vfd' ("));
  EXPECT_THAT(config_error("spindle: {drive: {transport: loopback, unit_id: 3, profile: delta_vfd}, encoder_counts_per_rev: "
                           "4096}\n"),
              ::testing::HasSubstr(") maps no encoder (registers.encoder_position)"));
  // The Delta map's 0.01 Hz (0.6 rpm at 60 rpm/Hz) at a gain of 2: a dead zone of 0.9 deg.
  EXPECT_THAT(config_error("spindle: {drive: {transport: loopback, unit_id: 3, profile: delta_vfd_encoder},"
                           " encoder_counts_per_rev: 4096, orient_tolerance_deg: 0.5, orient_gain_per_s: 2}\n"),
              ::testing::HasSubstr("spindle.orient_tolerance_deg: 0.5 deg: the drive's speed step (0.6 rpm, profile "
                                   "'delta_vfd_encoder') at spindle.orient_gain_per_s 2 leaves the orientation's "
                                   "position loop a dead zone of 0.9 deg: raise the tolerance or the gain"));
  EXPECT_EQ(config_error("spindle: {drive: {transport: loopback, unit_id: 3, profile: delta_vfd_encoder},"
                         " encoder_counts_per_rev: 4096, orient_tolerance_deg: 1}\n"),
            "no error");
}

TEST(BridgeNode, IoModuleFollowsItsCommandsAndReportsItsPoints) {
  Cell c("sim", true, kIo);
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  ASSERT_NE(c.node.io(), nullptr);
  drive::IoEmulator* m = c.link().io_module(4);
  ASSERT_NE(m, nullptr);
  m->set_point("door", 1);
  m->set_point("pressure", 612);
  m->set_point("valve", 0xFFF6);  // -10 counts
  c.io_command(11, 2, 0b10);  // flood, P1 (lamp)
  c.hold_stream(10, 10, 5);
  EXPECT_EQ(c.coil(1), 1);
  EXPECT_EQ(c.coil(0), 0);
  EXPECT_EQ(c.coil(8), 0);
  EXPECT_EQ(c.coil(9), 1);
  EXPECT_EQ(c.io.command_seq, 11);
  EXPECT_EQ(c.io.coolant, 2);
  EXPECT_EQ(c.io_value("flood"), 1.0) << "as read back";
  EXPECT_EQ(c.io_value("lamp"), 1.0);
  EXPECT_EQ(c.io_value("door"), 1.0);
  EXPECT_DOUBLE_EQ(c.io_value("pressure"), 6.12);
  EXPECT_DOUBLE_EQ(c.io_value("valve"), -5.0);
  ASSERT_EQ(c.io.num_modules, 1);
  EXPECT_TRUE(c.io.answering[0]);
  EXPECT_GT(c.io.transactions[0], 0);
  // An older command changes nothing; a coil changed behind the bridge's back is set again.
  c.io_command(10, 1, 0b01);
  m->set_point("lamp", 0);
  c.hold_stream(10, 10, 5);
  EXPECT_EQ(c.coil(1), 1);
  EXPECT_EQ(c.coil(9), 1);
  // DISABLE turns the coolant off, the outputs stay; ENABLE does not turn it on again.
  c.command(cnc::lcmt_drive_command::DISABLE);
  c.hold_stream(10, 10, 5);
  EXPECT_EQ(c.coil(1), 0);
  EXPECT_EQ(c.coil(9), 1);
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.io_command(11, 2, 0b10);
  c.hold_stream(10, 10, 20);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(c.coil(1), 0);
  c.io_command(12, 1, 0b01);  // mist, P0 (clamp)
  c.hold_stream(10, 10, 5);
  EXPECT_EQ(c.coil(0), 1);
  EXPECT_EQ(c.coil(1), 0);
  EXPECT_EQ(c.coil(8), 1);
  EXPECT_EQ(c.coil(9), 0);
  // The analog output (M67/M68): the module kept its own value until a command gave
  // one; -7.5 at scale 0.5, signed: -15 counts, written and read back.
  EXPECT_DOUBLE_EQ(c.io_value("valve"), -5.0);
  c.io_command(13, 1, 0b01, {-7.5});
  c.hold_stream(10, 10, 5);
  int raw = 0;
  ASSERT_TRUE(m->point("valve", &raw));
  EXPECT_EQ(raw, 0xFFF1);
  EXPECT_DOUBLE_EQ(c.io_value("valve"), -7.5);
  // A DISABLE keeps it.
  c.command(cnc::lcmt_drive_command::DISABLE);
  c.hold_stream(10, 10, 5);
  ASSERT_TRUE(m->point("valve", &raw));
  EXPECT_EQ(raw, 0xFFF1);
}

TEST(BridgeNode, IoServoTickAllocatesNothing) {
  Cell c("sim", true, kIo);
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  c.io_command(1, 2, 1);
  double x = c.move_x(10, 15);
  c.hold_stream(x, 10, 20);
  c.count_allocations = true;
  c.io_command(2, 0, 3);
  x = c.move_x(x, 12);
  c.io_command(3, 1, 0);
  c.hold_stream(x, 10, 20);
  c.count_allocations = false;
  EXPECT_EQ(c.coil(0), 1);
  EXPECT_EQ(c.cyclic_allocations, 0);
}

TEST(BridgeNode, IoCoolantStopsAtAFault) {
  Cell c("sim", true, kIo);
  c.ticks(40);
  c.io_command(5, 3, 1);
  c.hold_stream(10, 10, 5);
  EXPECT_EQ(c.coil(0), 1);
  EXPECT_EQ(c.coil(1), 1);
  // No setpoints: the watchdog faults the bridge, the coolant goes off, the output stays.
  c.ticks(200);
  EXPECT_EQ(c.node.state(), State::kFault) << c.node.detail();
  EXPECT_EQ(c.coil(0), 0);
  EXPECT_EQ(c.coil(1), 0);
  EXPECT_EQ(c.coil(8), 1);
}

// A Huanyang VFD (its own frames, huanyang_frame.h) as unit 3 on the axes' loopback link.
const std::string kHuanyang =
    "spindle: {drive: {transport: loopback, unit_id: 3, profile: huanyang}, at_speed_tolerance: 0.02,"
    " at_speed_timeout_s: 0.2}\n";

TEST(BridgeNode, HuanyangSpindleFollowsItsCommandsAndReportsAtSpeed) {
  Cell c("sim", true, kHuanyang);
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  c.spindle_command(11, 1, 6000);
  c.hold_stream(10, 10, 5);
  drive::VfdEmulator* vfd = c.link().vfd(3);
  ASSERT_NE(vfd, nullptr);
  EXPECT_TRUE(vfd->running());
  EXPECT_NEAR(vfd->command_hz(), 100.0, 1e-9);
  EXPECT_EQ(c.spindle.at_speed_seq, 11);
  EXPECT_EQ(int{c.spindle.state}, int{cnc::lcmt_spindle_status::RUNNING});
  EXPECT_NEAR(c.spindle.actual_rpm, 6000, 1e-6);
  EXPECT_GT(c.spindle.current_a, 0);
  c.spindle_command(12, -1, 3000);
  c.hold_stream(10, 10, 5);
  EXPECT_NEAR(c.spindle.actual_rpm, -3000, 1e-6);
  EXPECT_EQ(c.spindle.at_speed_seq, 12);
  c.spindle_command(13, 0, 0);
  c.hold_stream(10, 10, 5);
  EXPECT_FALSE(vfd->running());
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
}

TEST(BridgeNode, HuanyangShortRepliesWhileItTurnsAreALostLinkNamingThem) {
  Cell c("sim", true, kHuanyang);
  c.ticks(40);
  c.spindle_command(5, 1, 6000);
  c.hold_stream(10, 10, 5);
  ASSERT_EQ(c.spindle.at_speed_seq, 5);
  c.link().inject_short_replies(1000000);
  c.hold_stream(10, 10, 30);  // 120 ms: beyond the 50 ms link-loss timeout
  EXPECT_EQ(c.node.state(), State::kFault) << c.node.detail();
  EXPECT_NE(c.node.detail().find("spindle: the link to its drive was lost while it turned (error: Invalid data: "
                                 "short reply from unit 3 to function 0x0"),
            std::string::npos)
      << c.node.detail();
  EXPECT_TRUE(c.alarmed("drive_fault: spindle: the link to its drive was lost"));
}

TEST(BridgeNode, HuanyangSetUpForItsPanelIsAFaultNamingThePdParameter) {
  Cell c("sim", true, kHuanyang);
  c.link().vfd(3)->set_pd(1, 0);  // run commands from the panel
  c.ticks(40);
  c.spindle_command(5, 1, 6000);
  c.hold_stream(10, 10, 5);
  EXPECT_FALSE(c.link().vfd(3)->running());
  EXPECT_NE(c.node.detail().find("spindle: the VFD takes its run command (PD001 = 0)"), std::string::npos)
      << c.node.detail();
  EXPECT_EQ(int{c.spindle.state}, int{cnc::lcmt_spindle_status::FAULT});
}

TEST(BridgeNode, AHuanyangThatTripsWhileItTurnsIsAFault) {
  // The protocol has no fault code: a trip shows as a status byte that says it does not run.
  Cell c("sim", true, kHuanyang);
  c.ticks(40);
  c.spindle_command(5, 1, 6000);
  c.hold_stream(10, 10, 5);
  ASSERT_EQ(c.spindle.at_speed_seq, 5);
  c.link().vfd(3)->inject_fault(1);
  c.hold_stream(10, 10, 100);  // 0.4 s: within kNotRunningS
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  c.hold_stream(10, 10, 50);
  EXPECT_EQ(c.node.state(), State::kFault);
  EXPECT_NE(c.node.detail().find("spindle: its drive does not run although commanded to"), std::string::npos)
      << c.node.detail();
  EXPECT_TRUE(c.alarmed("drive_fault: spindle: its drive does not run"));
}

TEST(BridgeNode, AHuanyangOverModbusTcpIsRefusedNamingTheKey) {
  const std::string tcp =
      "spindle: {drive: {transport: modbus_tcp, host: 127.0.0.1, port: 1502, unit_id: 3, profile: huanyang}}\n";
  const config::MachineConfig cfg = config::parse_machine_config(machine_yaml("sim", true) + tcp, "lb.yaml");
  bus::Bus bus("memq://");
  try {
    DriveBridgeNode node(cfg, bus, DriveBridgeNode::Options{false});
    ADD_FAILURE() << "a Huanyang over Modbus TCP accepted";
  } catch (const config::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("spindle.drive.transport"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("modbus_rtu"), std::string::npos) << e.what();
  }
}

TEST(BridgeNode, SpindleNotAtSpeedInTimeIsAFaultNamingIt) {
  Cell c("sim", true, kSpindle);
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  c.link().set_stalled(true);  // the motor does not turn
  c.spindle_command(7, 1, 6000);
  c.hold_stream(10, 10, 40);  // 160 ms: within the 0.2 s timeout
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_TRUE(c.link().vfd(3)->running());
  c.hold_stream(10, 10, 20);
  EXPECT_NE(c.node.detail().find("spindle: 6000 rpm not reached within 0.2 s (at 0 rpm"), std::string::npos)
      << c.node.detail();
  EXPECT_TRUE(c.alarmed("drive_fault: spindle: 6000 rpm not reached"));
  EXPECT_EQ(int{c.status.drive_state[0]}, kFault);
  EXPECT_FALSE(c.link().vfd(3)->running()) << "the fault stops the spindle";
  EXPECT_EQ(int{c.spindle.state}, int{cnc::lcmt_spindle_status::FAULT});
  EXPECT_NE(c.spindle.fault.find("not reached"), std::string::npos);
}

TEST(BridgeNode, SpindleDriveFaultIsAFault) {
  Cell c("sim", true, kSpindle);
  c.ticks(40);
  c.spindle_command(7, 1, 6000);
  c.hold_stream(10, 10, 5);
  c.link().vfd(3)->inject_fault(0x0007);
  c.hold_stream(10, 10, 5);
  EXPECT_NE(c.node.detail().find("spindle: drive fault 0x0007"), std::string::npos) << c.node.detail();
  // ENABLE resets the VFD's fault; the spindle stays stopped until a newer change.
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(10, 10, 30);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(c.spindle.error_code, 0);
  EXPECT_FALSE(c.link().vfd(3)->running());
}

TEST(BridgeNode, ServoTickAndStatusPublishAllocateNothingWithASpindle) {
  Cell c("sim", true, kSpindle);
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  c.spindle_command(1, 1, 6000);
  double x = c.move_x(10, 19.5);
  c.hold_stream(x, 10, 20);
  c.count_allocations = true;
  c.spindle_command(2, 1, 8000);  // a change and its at-speed (no line of log when at speed at once)
  x = c.move_x(x, 12);
  c.hold_stream(x, 10, 50);
  c.count_allocations = false;
  EXPECT_EQ(c.spindle.at_speed_seq, 2);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(c.cyclic_allocations, 0);
}

TEST(BridgeNode, LostSetpointsComeBackExactlyFromTheNextOnesHistory) {
  // The same move twice: once complete, once with three setpoints in a row lost at
  // cruise and two more later. Each setpoint carries the three before it, so the
  // bridge gets every point of the path back (no gap to bridge by a line). While
  // the three were missing the playback saw the stream late and slowed down (its
  // rate follows the buffer), so the command runs a little behind the complete run
  // on the same line and catches up: a time shift, bounded here by 2.5 cycles of
  // motion (0.25 mm at 25 mm/s; 0.16 mm measured).
  auto run = [](bool lossy, std::vector<double>* trace) {
    Cell c("sim", true);
    c.ticks(40);
    EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
    double x = 10, v = 0;
    for (int k = 0; k < 150; ++k) {
      v = k < 10 ? v + 0.01 : k >= 140 ? std::max(0.0, v - 0.01) : v;
      x += v;
      const bool lose = lossy && (k == 60 || k == 61 || k == 62 || k == 100 || k == 120);
      c.setpoint(x, 10, lose);
      for (int i = 0; i < 4; ++i) {
        c.tick();
        trace->push_back(c.node.core().commanded()[0]);
      }
    }
    c.hold_stream(x, 10, 100);
    EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
    EXPECT_NEAR(c.drive_mm(1), x, 2e-3);
    return std::make_pair(c.node.recovered_setpoints(), c.node.core().setpoint_gaps());
  };
  std::vector<double> full, lossy;
  const auto [rec_full, gaps_full] = run(false, &full);
  const auto [rec_lossy, gaps_lossy] = run(true, &lossy);
  EXPECT_EQ(rec_full, 0);
  EXPECT_EQ(rec_lossy, 5);
  EXPECT_EQ(gaps_lossy, 0);
  ASSERT_EQ(full.size(), lossy.size());
  double worst = 0;
  for (size_t i = 0; i < full.size(); ++i) worst = std::max(worst, std::fabs(full[i] - lossy[i]));
  EXPECT_LE(worst, 0.25);
  std::printf("[ figures  ] 5 setpoints lost (3 in a row) at 25 mm/s: 5 recovered, 0 gaps, command max |diff| %.3g mm\n",
              worst);
}

TEST(BridgeNode, WithoutEnableOnStartWaitsForEnable) {
  Cell c("cia402_modbus", false);
  c.hold_stream(10, 10, 20);
  EXPECT_EQ(c.node.state(), State::kDisabled);
  EXPECT_TRUE(c.node.ready());
  EXPECT_FALSE(c.link().drive(1)->follows());
  EXPECT_EQ(int{c.status.drive_state[0]}, kDisabled);
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(10, 10, 20);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  c.command(cnc::lcmt_drive_command::DISABLE);
  c.hold_stream(10, 10, 5);
  EXPECT_EQ(c.node.state(), State::kDisabled);
  EXPECT_FALSE(c.link().drive(1)->follows());
  EXPECT_EQ(int{c.status.drive_state[0]}, kDisabled);
}

TEST(BridgeNode, ExceptionsAndTimeoutsAreCountedNotFatal) {
  Cell c("sim", true);
  c.ticks(40);
  c.hold_stream(10, 10, 5);
  c.link().inject_exceptions(5, MODBUS_EXCEPTION_SLAVE_OR_SERVER_BUSY);
  c.hold_stream(10, 10, 5);
  c.link().inject_timeouts(3);
  c.hold_stream(10, 10, 5);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(c.status.exceptions[0] + c.status.exceptions[1], 5);
  EXPECT_EQ(c.status.timeouts[0] + c.status.timeouts[1], 3);
  EXPECT_EQ(c.status.reconnects[0], 0);
}

TEST(BridgeNode, FollowingErrorOverTheLimitFaults) {
  Cell c("leadshine_el", true);
  c.ticks(40);
  c.hold_stream(10, 10, 5);
  c.link().set_stalled(true);  // the axes stop moving
  double x = 10, v = 0;
  for (int i = 0; i < 60 && c.node.state() == State::kEnabled; ++i) {
    v = std::min(0.1, v + 0.01);
    x += v;
    c.setpoint(x, 10);
    c.ticks(4);
  }
  c.hold_stream(x, 10, 60);
  EXPECT_EQ(c.node.state(), State::kFault);
  EXPECT_NE(c.node.detail().find("axis X: following error"), std::string::npos) << c.node.detail();
  EXPECT_NE(c.node.detail().find("over its limit 0.5 mm"), std::string::npos) << c.node.detail();
  EXPECT_FALSE(c.link().drive(1)->follows());  // the axis at fault is disabled
}

TEST(BridgeNode, SetpointTimeoutIsAControlledStopThenFault) {
  Cell c("sim", true);
  c.ticks(40);
  c.hold_stream(10, 10, 5);
  c.ticks(100);  // the interpolator went silent
  EXPECT_EQ(c.node.state(), State::kFault);
  EXPECT_NE(c.node.detail().find("no setpoint for"), std::string::npos) << c.node.detail();
  EXPECT_TRUE(c.link().drive(1)->follows());  // holding position, enabled
  // Setpoints again are not followed until ENABLE.
  c.hold_stream(10, 10, 5);
  EXPECT_EQ(c.node.state(), State::kFault);
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(10, 10, 10);
  EXPECT_EQ(c.node.state(), State::kEnabled);
}

// After a watchdog trip the stream's next setpoint names whose stall it was, by its
// publish stamp (set here) against its arrival (the ticks' simulated time).
std::string trip_cause(int64_t publish_delay_us) {
  Cell c("sim", true);
  cnc::lcmt_setpoint last{};
  c.bus.subscribe<cnc::lcmt_setpoint>("LB.SETPOINTS", [&](const auto& m) { last = m; });
  c.ticks(40);
  c.hold_stream(10, 10, 5);
  c.ticks(100);  // nothing arrives for 100 ms
  EXPECT_EQ(c.node.state(), State::kFault);
  cnc::lcmt_setpoint m = last;  // the stream's next cycle, stamped publish_delay_us after the last
  m.utime = last.utime + publish_delay_us;
  m.seq = last.seq + 1;
  m.cycle = last.cycle + 1;
  m.prev_position_mm.clear();
  m.num_prev_values = 0;
  std::vector<uint8_t> buf(static_cast<size_t>(m.getEncodedSize()));
  m.encode(buf.data(), 0, static_cast<int>(buf.size()));
  c.bus.publish_raw("LB.SETPOINTS", buf.data(), buf.size());
  c.ticks(8);
  std::string cause;
  int n = 0;
  for (const auto& a : c.alarms)
    if (a.rfind("watchdog_cause: ", 0) == 0) cause = a, ++n;
  EXPECT_EQ(n, 1);
  return cause;
}

TEST(BridgeNode, AWatchdogTripIsExplainedByTheNextSetpointAsADeliveryStall) {
  const std::string cause = trip_cause(4000);  // stamped on time, arrived ~100 ms later
  EXPECT_NE(cause.find("published 4.0 ms after it (due after 4 ms) and arrived 10"), std::string::npos) << cause;
  EXPECT_NE(cause.find("the delivery between the processes stalled, not the interpolator"), std::string::npos) << cause;
}

TEST(BridgeNode, AWatchdogTripIsExplainedByTheNextSetpointAsAPublisherStall) {
  const std::string cause = trip_cause(104000);
  EXPECT_NE(cause.find("published 104.0 ms after it"), std::string::npos) << cause;
  EXPECT_NE(cause.find("the interpolator (or its host) stalled"), std::string::npos) << cause;
}

TEST(BridgeNode, MissingProfileIsAConfigErrorNamingTheKey) {
  const config::MachineConfig cfg = config::parse_machine_config(machine_yaml("no_such_drive", true), "lb.yaml");
  bus::Bus bus("memq://");
  try {
    DriveBridgeNode node(cfg, bus, DriveBridgeNode::Options{false});
    FAIL() << "constructed with a missing profile";
  } catch (const config::ConfigError& e) {
    EXPECT_EQ(e.key_path(), "axes[0].drive.profile");
    EXPECT_NE(std::string(e.what()).find("no drive profile 'no_such_drive'"), std::string::npos) << e.what();
  }
}


// The E-stop: a normally closed discrete input of the I/O module (kIo's module, unit 4).
std::string with_estop() {
  std::string y = kIo;
  y.insert(y.find("    - {name: door"), "    - {name: estop_ok, kind: discrete_input, address: 3}\n");
  return y + "safety: {estop: {input: estop_ok}}\n";
}
const std::string kEstop = with_estop();

// Commanded X per servo tick, with its differences (velocity, acceleration, jerk).
struct Motion {
  std::vector<double> x;
  double v(size_t i) const { return (x[i] - x[i - 1]) / 0.001; }
  double a(size_t i) const { return (v(i) - v(i - 1)) / 0.001; }
  double j(size_t i) const { return (a(i) - a(i - 1)) / 0.001; }
};

TEST(BridgeNode, EstopBrakesThenDisablesAndStaysLatchedUntilResetAndEnable) {
  Cell c("sim", true, kSpindle + kEstop);
  drive::IoEmulator* m = c.link().io_module(4);
  ASSERT_NE(m, nullptr);
  ASSERT_TRUE(m->set_point("estop_ok", 1));  // released, the wire whole
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(int{c.io.estop}, int{cnc::lcmt_io_status::ESTOP_OK});
  EXPECT_EQ(c.io.estop_input, "estop_ok");
  c.spindle_command(1, 1, 6000);
  c.hold_stream(10, 10, 5);
  ASSERT_TRUE(c.link().vfd(3)->running());
  // X up to 25 mm/s (0.1 mm per cycle) and cruising; the steady servo tick allocates nothing.
  Motion mo;
  double x = 10, v = 0;
  for (int i = 0; i < 60; ++i) {
    v = std::min(0.1, v + 0.01);
    x += v;
    c.setpoint(x, 10);
    c.count_allocations = i >= 30;
    for (int k = 0; k < 4; ++k) {
      c.tick();
      mo.x.push_back(c.node.core().commanded()[0]);
    }
  }
  c.count_allocations = false;
  EXPECT_EQ(c.cyclic_allocations, 0);
  const size_t edge = mo.x.size();
  const double v0 = mo.v(edge - 1);
  EXPECT_NEAR(v0, 25.0, 0.5);
  // Pressed. The interpolator streams on for a few cycles until it sees the stop.
  ASSERT_TRUE(m->set_point("estop_ok", 0));
  size_t braking = 0;
  for (int i = 0; i < 100; ++i) {
    if (i < 5) {
      x += v;
      c.setpoint(x, 10);
    }
    for (int k = 0; k < 4; ++k) {
      c.tick();
      mo.x.push_back(c.node.core().commanded()[0]);
      if (braking == 0 && c.node.core().faulted()) braking = mo.x.size() - 1;
    }
  }
  ASSERT_GT(braking, 0u);
  EXPECT_LE(braking - edge, 2u) << "the input is read in the link's round and acted on in the next tick";
  EXPECT_TRUE(c.alarmed("estop: E-stop: input estop_ok on module io1 reads 0")) << ::testing::PrintToString(c.alarms);
  EXPECT_FALSE(c.link().vfd(3)->running()) << "the spindle stops with the E-stop";
  // A controlled stop within the stop deceleration and the jerk limit, never reversing.
  double vmax_after = 0;
  for (size_t i = braking + 1; i < mo.x.size(); ++i) {
    EXPECT_GE(mo.v(i), -1e-9) << "tick " << i;
    EXPECT_LE(mo.v(i), mo.v(i - 1) + 1e-6) << "tick " << i;
    EXPECT_LE(std::fabs(mo.a(i)), 2000 * 1.0001) << "tick " << i;
    if (i > braking + 2) {
      EXPECT_LE(std::fabs(mo.j(i)), 60000 * 1.0001) << "tick " << i;
    }
    vmax_after = std::max(vmax_after, mo.v(i));
  }
  EXPECT_LE(vmax_after, v0 + 1e-6);
  const double dist = mo.x.back() - mo.x[edge - 1];
  const double bound = v0 * v0 / (2 * 2000) + v0 * 2000 / (2 * 60000) + v0 * 0.002;
  EXPECT_LE(dist, bound) << "stop distance against v^2/(2a) + v*a/(2j) + 2 ticks";
  EXPECT_GT(dist, v0 * v0 / (2 * 2000)) << "no harder than the stop deceleration";
  // Standing: the drives disabled, the state published, nothing follows the setpoints.
  EXPECT_EQ(c.node.state(), State::kFault) << c.node.detail();
  EXPECT_NE(c.node.detail().find("E-stop: input estop_ok on module io1 reads 0"), std::string::npos) << c.node.detail();
  EXPECT_FALSE(c.link().drive(1)->follows());
  EXPECT_FALSE(c.link().drive(2)->follows());
  EXPECT_EQ(int{c.status.drive_state[0]}, kFault);
  EXPECT_EQ(int{c.io.estop}, int{cnc::lcmt_io_status::ESTOP_DISABLED});
  EXPECT_GT(c.io.estop_utime, 0);
  EXPECT_GT(c.io.estop_stop_ms, 0);
  EXPECT_LT(c.io.estop_stop_ms, 200) << "the command at rest (the limiter's last creep under 0.1 um/s included)";
  std::printf("E-stop at %.2f mm/s: braking %zu tick(s) after the edge, stop distance %.4f mm (bound %.4f), drives "
              "disabled %.0f ms after the trip\n",
              v0, braking - edge, dist, bound, c.io.estop_stop_ms);
  const double rest = c.drive_mm(1);
  // ENABLE and FAULT_RESET are refused while the input reads 0.
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(rest, 10, 20);
  EXPECT_TRUE(c.alarmed("enable_refused: ENABLE refused: E-stop input estop_ok on module io1 reads 0"));
  c.command(cnc::lcmt_drive_command::FAULT_RESET);
  c.hold_stream(rest, 10, 5);
  EXPECT_TRUE(c.alarmed("estop_reset_refused: FAULT_RESET refused: E-stop input estop_ok on module io1 still reads 0"));
  EXPECT_EQ(c.node.state(), State::kFault);
  EXPECT_FALSE(c.link().drive(1)->follows());
  // Released: still latched until the operator resets; ENABLE alone is refused.
  ASSERT_TRUE(m->set_point("estop_ok", 1));
  c.alarms.clear();
  c.hold_stream(rest, 10, 5);
  EXPECT_TRUE(c.alarmed("estop_released"));
  EXPECT_EQ(int{c.io.estop}, int{cnc::lcmt_io_status::ESTOP_RELEASED});
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(rest, 10, 20);
  EXPECT_TRUE(c.alarmed("enable_refused: ENABLE refused: the E-stop (input estop_ok on module io1) is latched"));
  EXPECT_EQ(c.node.state(), State::kFault);
  EXPECT_FALSE(c.link().drive(1)->follows());
  EXPECT_NEAR(c.drive_mm(1), rest, 1e-9) << "nothing moved";
  // Reset, then enable: following again, from where the axes stand.
  c.command(cnc::lcmt_drive_command::FAULT_RESET);
  c.hold_stream(rest, 10, 5);
  EXPECT_TRUE(c.alarmed("fault_reset_done: FAULT_RESET: the E-stop reset"));
  EXPECT_EQ(c.node.state(), State::kDisabled) << c.node.detail();
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(rest, 10, 20);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_TRUE(c.link().drive(1)->follows());
  EXPECT_EQ(int{c.io.estop}, int{cnc::lcmt_io_status::ESTOP_OK});
}

TEST(BridgeNode, EstopWireCutAtStartUpEnablesNothing) {
  // The input reads 0 from the start (a wire cut, or the button pressed at power-on).
  Cell c("sim", true, kEstop);
  c.ticks(40);
  EXPECT_EQ(c.node.state(), State::kFault) << c.node.detail();
  EXPECT_TRUE(c.node.ready());
  EXPECT_TRUE(c.alarmed("enable_refused: ENABLE refused: E-stop input estop_ok on module io1 reads 0"));
  EXPECT_TRUE(c.alarmed("estop: E-stop: input estop_ok on module io1 reads 0"));
  EXPECT_FALSE(c.link().drive(1)->follows());
  EXPECT_EQ(int{c.io.estop}, int{cnc::lcmt_io_status::ESTOP_DISABLED});
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.ticks(40);
  EXPECT_FALSE(c.link().drive(1)->follows());
  // Mended: reset and enable.
  ASSERT_TRUE(c.link().io_module(4)->set_point("estop_ok", 1));
  c.ticks(5);
  c.command(cnc::lcmt_drive_command::FAULT_RESET);
  c.ticks(5);
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.ticks(40);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_TRUE(c.link().drive(1)->follows());
}

TEST(BridgeNode, EstopModuleThatStopsAnsweringIsAnEstop) {
  Cell c("sim", true, kEstop);
  ASSERT_TRUE(c.link().io_module(4)->set_point("estop_ok", 1));
  c.ticks(40);
  c.hold_stream(10, 10, 5);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  // Every transaction times out: the module (and the drives) stop answering.
  c.link().inject_timeouts(1000000);
  c.hold_stream(10, 10, 30);
  EXPECT_TRUE(c.alarmed("estop: E-stop: input estop_ok on module io1 is not read: its module does not answer")) << ::testing::PrintToString(c.alarms);
  c.link().inject_timeouts(0);
}

// The guard door's switch (1: shut): its alarms name the input and its module, and say
// when the module does not answer rather than calling the door open.
TEST(BridgeNode, DoorAlarmsNameTheInputAndItsModule) {
  std::string y = kIo;
  y.replace(y.find("  digital_inputs: [door]\n"), std::string("  digital_inputs: [door]\n").size(), "");
  Cell c("sim", true, y + "safety: {door: {input: door}}\n");
  drive::IoEmulator* m = c.link().io_module(4);
  ASSERT_NE(m, nullptr);
  ASSERT_TRUE(m->set_point("door", 1));
  c.ticks(40);
  ASSERT_EQ(int{c.io.door}, int{cnc::lcmt_io_status::DOOR_CLOSED});
  ASSERT_TRUE(m->set_point("door", 0));
  c.ticks(10);
  EXPECT_EQ(int{c.io.door}, int{cnc::lcmt_io_status::DOOR_OPEN});
  EXPECT_TRUE(c.alarmed("door_open: guard door: input door on module io1 reads 0 (open): feed hold"))
      << ::testing::PrintToString(c.alarms);
  ASSERT_TRUE(m->set_point("door", 1));
  c.ticks(10);
  EXPECT_TRUE(c.alarmed("door_closed: guard door: input door on module io1 reads 1 (shut)"))
      << ::testing::PrintToString(c.alarms);
  c.link().inject_timeouts(1000000);
  c.ticks(400);
  EXPECT_TRUE(c.alarmed("door_open: guard door: input door on module io1 is not read: its module does not answer"))
      << ::testing::PrintToString(c.alarms);
  c.link().inject_timeouts(0);
}

// A touch probe on the I/O module's input 6; `latch` is probe.latch.
std::string with_probe(const std::string& latch) {
  std::string y = kIo;
  y.insert(y.find("    - {name: door"), "    - {name: probe_tip, kind: discrete_input, address: 6}\n");
  return y + "probe: {input: probe_tip, latch: " + latch + "}\n";
}

// probe.latch: drives. An edge of the input takes every drive's own latch of it, come
// before or after the input's sample; an edge no drive latched takes, after 5 servo
// periods, the positions sampled with the input (a warning, counted).
TEST(BridgeNode, ProbeEdgesTakeTheDrivesLatches) {
  Cell c("sim", true, with_probe("drives"));
  drive::IoEmulator* m = c.link().io_module(4);
  ASSERT_NE(m, nullptr);
  ASSERT_TRUE(m->set_point("probe_tip", 0));
  c.ticks(40);
  ASSERT_EQ(c.status.num_probe_axes, 2);
  ASSERT_EQ(c.status.probe_rises, 0);
  // The drives latch first (12.3456, 20.5) and the input follows two ticks later.
  c.link().drive(1)->set_probe_latch(true, 12.3456, 1);
  c.link().drive(2)->set_probe_latch(true, 20.5, 1);
  c.ticks(2);
  EXPECT_EQ(c.status.probe_rises, 0);  // no edge without the input's
  ASSERT_TRUE(m->set_point("probe_tip", 1));
  c.ticks(3);
  ASSERT_EQ(c.status.probe_rises, 1);
  EXPECT_NEAR(c.status.probe_rise_mm[0], 12.3456, 1e-9);
  EXPECT_NEAR(c.status.probe_rise_mm[1], 20.5, 1e-9);
  // The input first; X's drive latches at once, Y's three ticks later: taken when both have.
  ASSERT_TRUE(m->set_point("probe_tip", 0));
  c.link().drive(1)->set_probe_latch(false, 12.4, 1);
  c.ticks(2);
  EXPECT_EQ(c.status.probe_falls, 0);
  c.link().drive(2)->set_probe_latch(false, 20.25, 1);
  // (The loopback link reads a device every few ticks: up to 4 ticks until Y's latch is seen.)
  c.ticks(5);
  ASSERT_EQ(c.status.probe_falls, 1);
  EXPECT_NEAR(c.status.probe_fall_mm[0], 12.4, 1e-9);
  EXPECT_NEAR(c.status.probe_fall_mm[1], 20.25, 1e-9);
  // An edge neither drive latches: the sampled positions (the drives stand at their
  // start, home_mm 10), 5 periods after the input's sample, not before.
  ASSERT_TRUE(m->set_point("probe_tip", 1));
  int waited = 0;
  while (c.status.probe_rises == 1 && waited < 50) {
    c.tick();
    ++waited;
  }
  ASSERT_EQ(c.status.probe_rises, 2);
  EXPECT_GE(waited, 6);
  EXPECT_NEAR(c.status.probe_rise_mm[0], c.drive_mm(1), 1e-4);
  EXPECT_NEAR(c.status.probe_rise_mm[1], c.drive_mm(2), 1e-4);
  // A drive's old latch is not taken for a later edge: Y's rise (count 2) 20 ms before
  // the next edge, X's with it; the edge falls back to the sampled positions.
  c.link().drive(2)->set_probe_latch(true, 99.0, 2);
  c.ticks(10);
  ASSERT_TRUE(m->set_point("probe_tip", 0));
  c.ticks(10);
  ASSERT_TRUE(m->set_point("probe_tip", 1));
  c.link().drive(1)->set_probe_latch(true, 55.0, 2);
  c.ticks(15);
  ASSERT_EQ(c.status.probe_rises, 3);
  EXPECT_NEAR(c.status.probe_rise_mm[0], c.drive_mm(1), 1e-4);
  EXPECT_NEAR(c.status.probe_rise_mm[1], c.drive_mm(2), 1e-4);
}

// A CiA-402 drive's touch probe latches only once armed (0x60B8): the bridge writes the
// function (TP1, continuous, both edges: 0x0033) before it enables the drive (as the mode
// of operation: forgotten with a lost link, so written again at the next enable); the
// latch then reaches AXIS_STATUS through an edge of the input.
// cia402_modbus.yaml (object index = register) cannot hold the adjacent 32-bit 0x60BA and
// 0x60BB: the test's profile puts the probe's objects where a gateway's table would.
TEST(BridgeNode, ACia402DrivesTouchProbeIsArmedBeforeEnablingAndLatches) {
  const std::string file = ::testing::TempDir() + "cia402_tp.yaml";
  {
    std::ofstream out(file);
    out << "name: cia402_tp\nstate_machine: cia402\nwrite_and_read: true\nread_gap_max: 0\nmode_of_operation: 8\n"
           "registers:\n"
           "  error_code:      {address: 0x603F}\n"
           "  controlword:     {address: 0x6040}\n"
           "  statusword:      {address: 0x6041}\n"
           "  mode:            {address: 0x6060, signed: true}\n"
           "  mode_display:    {address: 0x6061, signed: true}\n"
           "  actual_position: {address: 0x6064, words: 2, signed: true, word_order: low_first, scale: 26214.4}\n"
           "  target_position: {address: 0x607A, words: 2, signed: true, word_order: low_first, scale: 26214.4}\n"
           "  probe_function:  {address: 0x60B8}\n"
           "  probe_rise_position: {address: 0x2000, words: 2, signed: true, word_order: low_first, scale: 26214.4}\n"
           "  probe_fall_position: {address: 0x2002, words: 2, signed: true, word_order: low_first, scale: 26214.4}\n"
           "  probe_rise_count: {address: 0x2004}\n"
           "  probe_fall_count: {address: 0x2005}\n";
  }
  Cell c(file, false, with_probe("drives"));
  drive::DriveEmulator* x = c.link().drive(1);
  auto function = [&] {
    uint16_t v = 0;
    x->read(0x60B8, 1, &v);
    return v;
  };
  c.ticks(40);
  EXPECT_EQ(function(), 0);  // not armed before ENABLE
  x->set_probe_latch(true, 7.0, 1);
  uint16_t count = 0;
  x->read(0x2004, 1, &count);
  EXPECT_EQ(count, 0);  // an unarmed drive latches nothing
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(function(), 0x0033);
  drive::IoEmulator* m = c.link().io_module(4);
  ASSERT_TRUE(m->set_point("probe_tip", 0));
  c.ticks(20);
  x->set_probe_latch(true, 12.5, 1);
  c.link().drive(2)->set_probe_latch(true, 3.25, 1);
  ASSERT_TRUE(m->set_point("probe_tip", 1));
  c.ticks(10);
  ASSERT_EQ(c.status.probe_rises, 1);
  EXPECT_NEAR(c.status.probe_rise_mm[0], 12.5, 1e-4);
  EXPECT_NEAR(c.status.probe_rise_mm[1], 3.25, 1e-4);
}

// probe.latch: drives on a drive whose profile maps no touch probe: refused at start.
TEST(BridgeNode, ProbeDriveLatchWithoutTheRegistersIsAConfigErrorNamingTheKey) {
  const config::MachineConfig cfg =
      config::parse_machine_config(machine_yaml("leadshine_el", true) + with_probe("drives"), "lb.yaml");
  bus::Bus bus("memq://");
  try {
    DriveBridgeNode node(cfg, bus, DriveBridgeNode::Options{false});
    FAIL() << "constructed with probe.latch: drives on drives without a touch probe";
  } catch (const config::ConfigError& e) {
    EXPECT_EQ(e.key_path(), "probe.latch");
    EXPECT_NE(std::string(e.what()).find("axis X's drive profile 'leadshine_el'"), std::string::npos) << e.what();
  }
}

// X's max limit switch, normally closed, on the I/O module.
std::string with_limit() {
  std::string y = kIo;
  y.insert(y.find("    - {name: door"), "    - {name: x_max_ok, kind: discrete_input, address: 5}\n");
  return y + "safety: {hard_limits: [{axis: X, max: x_max_ok}]}\n";
}

TEST(BridgeNode, HardLimitStopsDisablesAndOnlyAMoveAwayIsAllowedOnIt) {
  Cell c("sim", true, with_limit());
  drive::IoEmulator* m = c.link().io_module(4);
  ASSERT_TRUE(m->set_point("x_max_ok", 1));
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(int{c.io.limit}, int{cnc::lcmt_io_status::LIMIT_OK});
  // X up to 25 mm/s and cruising.
  Motion mo;
  double x = 10, v = 0;
  for (int i = 0; i < 40; ++i) {
    v = std::min(0.1, v + 0.01);
    x += v;
    c.setpoint(x, 10);
    c.count_allocations = i >= 20;
    for (int k = 0; k < 4; ++k) {
      c.tick();
      mo.x.push_back(c.node.core().commanded()[0]);
    }
  }
  c.count_allocations = false;
  EXPECT_EQ(c.cyclic_allocations, 0);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  const size_t edge = mo.x.size();
  const double v0 = mo.v(edge - 1);
  ASSERT_TRUE(m->set_point("x_max_ok", 0));  // X runs into its switch
  size_t braking = 0;
  for (int i = 0; i < 60; ++i) {
    if (i < 5) x += v;  // the interpolator streams on until it sees the fault
    c.setpoint(x, 10);
    for (int k = 0; k < 4; ++k) {
      c.tick();
      mo.x.push_back(c.node.core().commanded()[0]);
      if (braking == 0 && c.node.core().faulted()) braking = mo.x.size() - 1;
    }
  }
  ASSERT_GT(braking, 0u);
  EXPECT_LE(braking - edge, 2u) << "read in the link's round, acted on in the next tick";
  EXPECT_TRUE(c.alarmed("hard_limit: hard limit: axis X's max switch (input x_max_ok on module io1) reads 0"))
      << ::testing::PrintToString(c.alarms);
  for (size_t i = braking + 1; i < mo.x.size(); ++i) {
    EXPECT_GE(mo.v(i), -1e-9) << "tick " << i;
    EXPECT_LE(std::fabs(mo.a(i)), 2000 * 1.0001) << "tick " << i;
  }
  const double dist = mo.x.back() - mo.x[edge - 1];
  const double bound = v0 * v0 / (2 * 2000) + v0 * 2000 / (2 * 60000) + v0 * 0.002;
  EXPECT_LE(dist, bound) << "stop distance against v^2/(2a) + v*a/(2j) + 2 ticks";
  EXPECT_GT(dist, v0 * v0 / (2 * 2000)) << "no harder than the stop deceleration";
  // Standing: a fault naming the axis, the end and the input; the drives disabled.
  EXPECT_EQ(c.node.state(), State::kFault) << c.node.detail();
  EXPECT_NE(c.node.detail().find("axis X's max switch (input x_max_ok on module io1)"), std::string::npos) << c.node.detail();
  EXPECT_FALSE(c.link().drive(1)->follows());
  EXPECT_FALSE(c.link().drive(2)->follows());
  EXPECT_EQ(int{c.io.limit}, int{cnc::lcmt_io_status::LIMIT_DISABLED});
  EXPECT_EQ(c.io.limit_input, "x_max_ok");
  EXPECT_GT(c.io.limit_utime, 0);
  EXPECT_GT(c.io.limit_stop_ms, 0);
  std::printf("hard limit at %.2f mm/s: braking %zu tick(s) after the edge, stop distance %.4f mm (bound %.4f), "
              "drives disabled %.0f ms after the trip\n",
              v0, braking - edge, dist, bound, c.io.limit_stop_ms);
  const double rest = c.drive_mm(1);
  // ENABLE alone is refused: latched until the operator's FAULT_RESET (allowed on the switch).
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(rest, 10, 20);
  EXPECT_TRUE(c.alarmed("enable_refused: ENABLE refused: the hard limit (axis X's max switch (input x_max_ok on module io1)) is latched"))
      << ::testing::PrintToString(c.alarms);
  EXPECT_FALSE(c.link().drive(1)->follows());
  EXPECT_NEAR(c.drive_mm(1), rest, 1e-9) << "nothing moved";
  c.command(cnc::lcmt_drive_command::FAULT_RESET);
  c.hold_stream(rest, 10, 5);
  EXPECT_TRUE(c.alarmed("fault_reset_done: FAULT_RESET: the hard limit reset")) << ::testing::PrintToString(c.alarms);
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(rest, 10, 30);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(int{c.io.limit}, int{cnc::lcmt_io_status::LIMIT_ON_SWITCH});
  // Off the switch (towards min), as the interpolator streams it: followed.
  c.alarms.clear();
  const double away = c.move_x_smooth(rest, rest - 1);
  c.hold_stream(away, 10, 40);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_NEAR(c.node.core().commanded()[0], away, 1e-5) << "at the end of the move (the limiter's last creep)";
  EXPECT_FALSE(c.alarmed("hard_limit")) << ::testing::PrintToString(c.alarms);
  // Towards it again while it still reads 0: refused at the first setpoint, a stop and a fault.
  c.move_x_smooth(away, away + 0.5);
  EXPECT_TRUE(c.alarmed("hard_limit_refused: hard limit: axis X's max switch (input x_max_ok on module io1) reads 0: setpoint cycle"))
      << ::testing::PrintToString(c.alarms);
  EXPECT_NE(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_LE(c.node.core().commanded()[0], away + 1e-3) << "nothing of the move towards it was followed";
  // Off the switch (it reads 1 again): reset, enable, and X moves either way.
  ASSERT_TRUE(m->set_point("x_max_ok", 1));
  const double here = c.node.core().commanded()[0];
  c.command(cnc::lcmt_drive_command::FAULT_RESET);
  c.hold_stream(here, 10, 5);
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(here, 10, 30);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(int{c.io.limit}, int{cnc::lcmt_io_status::LIMIT_OK});
  c.move_x(here, here + 0.5);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
}

TEST(BridgeNode, HardLimitWireCutWhileMovingAwayIsATrip) {
  // The min switch's wire cut while X moves towards max: a trip all the same.
  std::string y = kIo;
  y.insert(y.find("    - {name: door"), "    - {name: x_min_ok, kind: discrete_input, address: 6}\n");
  Cell c("sim", true, y + "safety: {hard_limits: [{axis: X, min: x_min_ok}]}\n");
  ASSERT_TRUE(c.link().io_module(4)->set_point("x_min_ok", 1));
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  double x = c.move_x(10, 12);
  ASSERT_TRUE(c.link().io_module(4)->set_point("x_min_ok", 0));
  x = c.move_x(x, x + 1);
  c.hold_stream(x, 10, 60);
  EXPECT_TRUE(c.alarmed("hard_limit: hard limit: axis X's min switch (input x_min_ok on module io1) reads 0"))
      << ::testing::PrintToString(c.alarms);
  EXPECT_EQ(c.node.state(), State::kFault) << c.node.detail();
  EXPECT_FALSE(c.link().drive(1)->follows());
}

TEST(BridgeNode, HardLimitSetpointsTheBridgeWaitsOnSetNoBound) {
  // Enabled on the switch: the interpolator's old stream stands elsewhere (its path braked
  // on after the bridge's stop) until its RESET; neither side of it counts.
  Cell c("sim", true, with_limit());
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  c.hold_stream(10.5, 10, 10);  // towards the switch: not joined, no fault
  EXPECT_TRUE(c.alarmed("hard_limit_not_joined: hard limit: axis X's max switch (input x_max_ok on module io1) reads 0: a setpoint "
                        "stream at 10.5000 mm, towards it from 10.0000 mm, is not joined"))
      << ::testing::PrintToString(c.alarms);
  c.hold_stream(9.5, 10, 10);    // away from it: waited on (too far to join), no bound
  c.hold_stream(10.01, 10, 10);  // near enough to join, but towards it: not joined either
  EXPECT_FALSE(c.alarmed("hard_limit_refused")) << ::testing::PrintToString(c.alarms);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_NEAR(c.drive_mm(1), 10, 1e-9);
  c.alarms.clear();
  c.hold_stream(10, 10, 10);  // the stream from where X stands (the interpolator's RESET): joined
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_FALSE(c.alarmed("hard_limit")) << ::testing::PrintToString(c.alarms);
  c.move_x_smooth(10, 9.8);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
}

TEST(BridgeNode, HardLimitAtZeroWhenEnabledIsNoTripAndAMoveOffIsFollowed) {
  // Powered on standing on the switch: enabled, and only a move off it is followed.
  Cell c("sim", true, with_limit());
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(int{c.io.limit}, int{cnc::lcmt_io_status::LIMIT_ON_SWITCH});
  c.hold_stream(10, 10, 10);
  // move_x's stream reverses its acceleration at 5 times the jerk limit: the limiter
  // runs 0.3 mm past its end and comes back towards the switch (never nearer it than
  // the stream began). Setpoints, not the limiter's command, are held against the switch.
  const double x = c.move_x(10, 9);
  c.hold_stream(x, 10, 20);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  c.move_x(x, x + 0.01);
  EXPECT_TRUE(c.alarmed("hard_limit_refused")) << ::testing::PrintToString(c.alarms);
}

}  // namespace
}  // namespace cnc::bridge

namespace cnc::bridge {
namespace {

// Y a gantry: its second drive Y2 is unit 5 on the same loopback link, skew limit 0.2 mm.
std::string gantry_yaml() {
  std::string y = machine_yaml("sim", true);
  const std::string tail = "profile: sim}}\n";
  const size_t at = y.rfind(tail);
  y.replace(at, tail.size(),
            "profile: sim}, gantry: {name: Y2, skew_limit_mm: 0.2,"
            " drive: {transport: loopback, unit_id: 5, profile: sim}}}\n");
  return y;
}

// The interpolator's HOMED of Y as recorded: Y's offset `first`, Y2's `second`.
void publish_homed(bus::Bus& bus, double first, double second) {
  cnc::lcmt_interp_input in{};
  in.kind = cnc::lcmt_interp_input::COMMAND;
  in.command.command = cnc::lcmt_program_command::HOMED;
  in.command.axis = 1;
  in.command.value = first;
  in.command.num_axes = 1;
  in.command.position_mm = {second};
  bus.publish("LB.INTERP_INPUT", in);
}

TEST(BridgeNodeGantry, BothDrivesFollowTheAxisPlusTheSquaringThenASkewStopsAndDisables) {
  Cell c(config::parse_machine_config(gantry_yaml(), "lb.yaml"));
  cnc::lcmt_joint_status js{};
  c.bus.subscribe<cnc::lcmt_joint_status>("LB.JOINT_STATUS", [&](const auto& m) { js = m; });
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  ASSERT_EQ(c.node.joints(), 1u);
  ASSERT_NE(c.link().drive(5), nullptr);
  EXPECT_TRUE(c.link().drive(5)->follows()) << "the second drive is enabled with the axes";
  ASSERT_EQ(js.num_joints, 1);
  EXPECT_EQ(js.name[0], "Y2");
  EXPECT_EQ(js.axis[0], 1);
  EXPECT_EQ(int{js.drive_state[0]}, kEnabled);
  // Y moves 2 mm (a quintic over 0.2 s); Y2 gets Y's command every tick (squaring 0),
  // and the cyclic path allocates nothing.
  for (int i = 1; i <= 50; ++i) {
    const double u = i / 50.0;
    c.setpoint(10, 10 + 2 * u * u * u * (10 - 15 * u + 6 * u * u));
    c.count_allocations = i > 5;  // once the setpoints' history has grown to three
    for (int k = 0; k < 4; ++k) {
      c.tick();
      EXPECT_EQ(c.node.joint_command(0), c.node.core().commanded()[1]) << "cycle " << i;
    }
  }
  c.count_allocations = false;
  EXPECT_EQ(c.cyclic_allocations, 0);
  c.hold_stream(10, 12, 40);
  EXPECT_NEAR(c.drive_mm(2), 12, 1e-5) << "at the end of the move (the limiter's last creep)";
  EXPECT_EQ(c.drive_mm(5), c.drive_mm(2));
  EXPECT_NEAR(js.max_skew_mm[0], 0, 1e-6) << "ideal drives: no skew";

  // HOMED: Y's offset 0.1 mm, Y2's 0.4 mm: Y2 moves 0.3 mm further than Y, at the axis's
  // home search velocity (10 mm/s) and acceleration (3000 mm/s^2): 0.3 mm in 30-40 ms.
  publish_homed(c.bus, 0.1, 0.4);
  std::vector<double> sq;
  for (int i = 0; i < 20; ++i) {
    c.setpoint(10, 12);
    for (int k = 0; k < 4; ++k) {
      c.tick();
      sq.push_back(c.node.joint_squaring(0));
    }
  }
  EXPECT_DOUBLE_EQ(sq.back(), 0.3);
  for (size_t i = 2; i < sq.size(); ++i) {
    const double v = (sq[i] - sq[i - 1]) / 0.001, v0 = (sq[i - 1] - sq[i - 2]) / 0.001;
    EXPECT_LE(std::fabs(v), 10 * 1.000001) << "tick " << i;
    EXPECT_LE(std::fabs(v - v0) / 0.001, 3000 * 1.000001 + 1e-6) << "tick " << i;
  }
  EXPECT_NEAR(c.drive_mm(5) - c.drive_mm(2), 0.3, 1e-6);
  EXPECT_DOUBLE_EQ(js.squaring_target_mm[0], 0.3);
  EXPECT_NEAR(js.skew_mm[0], 0, 1e-6);
  EXPECT_EQ(c.node.state(), State::kEnabled) << c.node.detail();

  // Y2 jams while Y moves at 25 mm/s: the skew grows by 0.025 mm per tick and crosses
  // 0.2 mm in the 9th; the bridge brakes in the tick that reads it.
  c.link().set_jammed(5, true);
  double y = 12, v = 0;
  int braking = -1, tick = 0, crossed = -1, decelerating = -1;
  double skew_at_fault = 0;
  std::vector<double> cmd_y;
  for (int i = 0; i < 80; ++i) {
    if (braking < 0) {
      v = std::min(0.1, v + 0.01);
      y += v;
    }
    c.setpoint(10, y);
    for (int k = 0; k < 4; ++k, ++tick) {
      c.tick();
      // The drives' own skew (after this tick's round), the command's deceleration.
      if (crossed < 0 && std::fabs(c.drive_mm(5) - c.drive_mm(2) - 0.3) > 0.2) crossed = tick;
      if (braking < 0 && c.node.core().faulted()) {
        braking = tick;
        skew_at_fault = c.node.joint_skew(0);
      }
      cmd_y.push_back(c.node.core().commanded()[1]);
      const size_t n = cmd_y.size();
      // The brake: the command's acceleration falls (at the jerk limit, 60 mm/s^2 per tick).
      if (decelerating < 0 && braking >= 0 && n >= 4) {
        const double a1 = (cmd_y[n - 1] - 2 * cmd_y[n - 2] + cmd_y[n - 3]) / 1e-6;
        const double a0 = (cmd_y[n - 2] - 2 * cmd_y[n - 3] + cmd_y[n - 4]) / 1e-6;
        if (a1 < a0 - 30) decelerating = tick;
      }
    }
  }
  ASSERT_GE(braking, 0) << "no skew fault";
  ASSERT_GE(crossed, 0);
  ASSERT_GE(decelerating, 0);
  // The drives' positions reach the bridge with the next round (the tick after); the
  // command decelerates from the tick that sees it.
  EXPECT_LE(braking - crossed, 1) << "ticks from the crossing to the fault";
  EXPECT_EQ(decelerating, braking) << "the brake begins in the fault's tick";
  EXPECT_LT(skew_at_fault, -0.2);
  EXPECT_GT(skew_at_fault, -0.2 - 0.03) << "seen within a tick of the crossing (25 mm/s: 0.025 mm per tick)";
  EXPECT_GE(c.node.skew_reaction_ms(), 0.0);
  EXPECT_LE(c.node.skew_reaction_ms(), 1.0) << "between the two reads around the crossing, a tick apart";
  EXPECT_TRUE(c.alarmed("gantry_skew: gantry skew: axis Y's drives Y (unit 2) at ")) << ::testing::PrintToString(c.alarms);
  bool names_both = false;
  for (const auto& a : c.alarms) names_both = names_both || a.find("and Y2 (unit 5) at ") != std::string::npos;
  EXPECT_TRUE(names_both) << ::testing::PrintToString(c.alarms);
  // Standing: a fault, every drive disabled, nothing moves.
  EXPECT_EQ(c.node.state(), State::kFault) << c.node.detail();
  EXPECT_FALSE(c.link().drive(1)->follows());
  EXPECT_FALSE(c.link().drive(2)->follows());
  EXPECT_FALSE(c.link().drive(5)->follows());
  const double y_rest = c.drive_mm(2), y2_rest = c.drive_mm(5);
  c.hold_stream(10, y, 20);
  EXPECT_EQ(c.drive_mm(2), y_rest);
  EXPECT_EQ(c.drive_mm(5), y2_rest);
  std::printf("gantry skew fault at 25 mm/s: skew %.4f mm at the fault (limit 0.2), crossed %.2f ms before the read "
              "(interpolated); the drives crossed in tick %d, the fault in tick %d, the command's acceleration "
              "falling from tick %d; standing %.4f mm apart\n",
              skew_at_fault, c.node.skew_reaction_ms(), crossed, braking, decelerating, y2_rest - y_rest);
  // Freed, FAULT_RESET and ENABLE: the squaring starts where the drives stand and moves
  // back to the homed one: square again.
  c.link().set_jammed(5, false);
  c.command(cnc::lcmt_drive_command::FAULT_RESET);
  c.hold_stream(10, y_rest, 5);
  c.command(cnc::lcmt_drive_command::ENABLE);
  c.hold_stream(10, y_rest, 100);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_NEAR(c.drive_mm(5) - c.drive_mm(2), 0.3, 1e-6);
  EXPECT_NEAR(c.drive_mm(2), y_rest, 1e-6) << "the axis itself stays";
}

TEST(BridgeNodeGantry, AMachineWithoutAGantryPublishesNoJointStatus) {
  Cell c("sim", true);
  int n = 0;
  c.bus.subscribe<cnc::lcmt_joint_status>("LB.JOINT_STATUS", [&](const auto&) { ++n; });
  c.ticks(40);
  ASSERT_EQ(c.node.state(), State::kEnabled) << c.node.detail();
  EXPECT_EQ(c.node.joints(), 0u);
  EXPECT_EQ(n, 0);
}

}  // namespace
}  // namespace cnc::bridge
