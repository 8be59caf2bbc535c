// Homing a gantry: the interpolator's node and the drive bridge's node on one
// in-memory bus, the drives emulated in process (loopback) with a home switch each,
// stepped by the test (4 servo ticks per interpolation cycle, no clock, no threads
// but the planner's). Y is a gantry (Y and Y2): Y2's switch 0.8 mm nearer than Y's in
// its drive's coordinates, so the gantry starts 0.8 mm out of square; each switch
// closes at its point plus a normal draw (sigma 2 um), as the simulator's. HOME Y
// searches with both sides, latches each, and the bridge squares the axis: the skew
// after homing is within the switches' repeatability. A second switch that does not
// close within gantry.home_max_difference_mm of the first stops the homing naming both.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/drive/loopback_link.h"
#include "services/drive_bridge/drive_bridge_node.h"
#include "services/interpolator/interpolator_node.h"

namespace cnc {
namespace {

std::string machine(double y2_switch_mm, double start_mm) {
  std::string y =
      "cell: {name: gh, channel_prefix: \"GH.\"}\n"
      "timing: {ipo_period_s: 0.004, servo_period_s: 0.001, setpoint_timeout_s: 0.05, stop_decel_mm_s2: 2000}\n"
      "drive_bridge: {enable_on_start: true}\n"
      "axes:\n";
  const char* names[] = {"X", "Y", "Z"};
  for (int i = 0; i < 3; ++i) {
    y += "  - {name: " + std::string(names[i]) +
         ", min_mm: -5, max_mm: 300, max_velocity_mm_s: 250, max_accel_mm_s2: 3000, max_jerk_mm_s3: 60000,"
         " max_following_error_mm: 1, drive: {transport: loopback, unit_id: " + std::to_string(i + 1) +
         ", profile: sim}";
    if (i == 1) {
      char b[400];
      std::snprintf(b, sizeof b,
                    ", home_mm: %g, home: {method: switch, search_velocity_mm_s: 10, latch_velocity_mm_s: 1, direction: -1,"
                    " switch_position_mm: -4, position_mm: 0, backoff_mm: 1},"
                    " gantry: {name: Y2, switch_position_mm: -4, skew_limit_mm: 0.5, home_max_difference_mm: 2,"
                    " drive: {transport: loopback, unit_id: 4, profile: sim}}  # Y2's switch at %g\n",
                    start_mm, y2_switch_mm);
      y += b;
      y.insert(y.rfind("  #"), "}");
    } else {
      y += "}\n";
    }
  }
  return y;
}

// A home switch of one loopback drive, as the simulator's: closed beyond its trip point
// (direction -1: at and below it), the drive latching its position at each closing edge;
// open again 0.05 mm back, its next trip drawn anew.
struct Switch {
  drive::DriveEmulator* d;
  double at_mm;
  std::mt19937_64 rng;
  std::normal_distribution<double> noise{0.0, 0.002};
  double trip;
  bool closed = false;
  int64_t count = 0;
  Switch(drive::DriveEmulator* drive, double at, uint64_t seed) : d(drive), at_mm(at), rng(seed) {
    trip = at_mm + noise(rng);
  }
  double position() const {
    const auto& f = d->profile().field(drive::Role::kActualPosition);
    uint16_t r[2];
    d->read(f.address, 2, r);
    return f.decode(r);
  }
  void step() {
    const double x = position();
    if (!closed && x <= trip) {
      closed = true;
      d->set_home_latch(x, ++count);
    } else if (closed && x > trip + 0.05) {
      closed = false;
      trip = at_mm + noise(rng);
    }
  }
};

struct HomingRun {
  std::vector<std::string> alarms;
  double squaring_mm = 0;
  double skew_mm = 0;  // (Y2 - its switch) - (Y - its switch), at the end
  bool homed = false;
};

// HOME Y with Y2's switch at `y2_switch_mm`, both sides starting at `start_mm`.
HomingRun home_y(double y2_switch_mm, double start_mm = 0) {
  const config::MachineConfig cfg = config::parse_machine_config(machine(y2_switch_mm, start_mm), "gh.yaml");
  bus::Bus bus("memq://");
  bridge::DriveBridgeNode bridge(cfg, bus, bridge::DriveBridgeNode::Options{false});
  interp::InterpolatorNode interp(cfg, bus);
  HomingRun r;
  cnc::lcmt_interp_state st{};
  bus.subscribe<cnc::lcmt_alarm>("GH.ALARM", [&](const auto& m) { r.alarms.push_back(m.code + ": " + m.text); });
  bus.subscribe<cnc::lcmt_interp_state>("GH.INTERP_STATE", [&](const auto& m) { st = m; });
  bridge.start();
  auto& link = dynamic_cast<drive::LoopbackLink&>(bridge.link_of(0));
  Switch sy(link.drive(2), -4.0, 12), sy2(link.drive(4), y2_switch_mm, 14);
  double t = 0;
  auto cycle = [&] {
    // A starved path waits for the planner thread: give it the time a real cycle would.
    if (interp.core().state() == interp::RunState::kStarved) std::this_thread::sleep_for(std::chrono::microseconds(200));
    interp.cycle();
    interp.publish_state(false);
    for (int k = 0; k < 4; ++k) {
      t += 0.001;
      bridge.servo_tick(t);
      bridge.publish_status(0);
      sy.step();
      sy2.step();
    }
    bus.drain();
  };
  for (int i = 0; i < 50; ++i) cycle();
  EXPECT_EQ(bridge.state(), bridge::DriveBridgeNode::State::kEnabled) << bridge.detail();
  cnc::lcmt_program_command home{};
  home.command = cnc::lcmt_program_command::HOME;
  home.axis = 1;
  bus.publish("GH.PROGRAM_CMD", home);
  // Up to 40 s of machine time; the planner thread may lag a tight loop, so the path
  // may stand meanwhile (starved): the homing waits, it does not change.
  for (int i = 0; i < 20000; ++i) {
    cycle();
    bool done = false;
    for (const auto& a : r.alarms) done = done || a.rfind("home_done", 0) == 0 || a.rfind("home_aborted", 0) == 0;
    if (done) break;
  }
  for (int i = 0; i < 100; ++i) cycle();  // the squaring's last motion, the axes at rest
  for (const auto& a : r.alarms) r.homed = r.homed || a.rfind("home_done", 0) == 0;
  r.squaring_mm = bridge.joint_squaring(0);
  r.skew_mm = (sy2.position() - y2_switch_mm) - (sy.position() - -4.0);
  EXPECT_EQ(bridge.state(), bridge::DriveBridgeNode::State::kEnabled) << bridge.detail();
  bridge.shut_down();
  return r;
}

TEST(GantryHoming, BothSidesLatchTheirOwnSwitchesAndTheAxisEndsSquare) {
  const HomingRun r = home_y(-3.2);
  ASSERT_TRUE(r.homed) << ::testing::PrintToString(r.alarms);
  bool squared = false;
  for (const auto& a : r.alarms) squared = squared || a.rfind("gantry_squared: gantry Y: Y2 squared to Y", 0) == 0;
  EXPECT_TRUE(squared) << ::testing::PrintToString(r.alarms);
  // Started 0.8 mm out of square; the squaring takes it back: the switches' draws
  // (sigma 2 um each) and a latch at 1 mm/s on the 1 ms tick (1 um) remain.
  EXPECT_NEAR(r.squaring_mm, 0.8, 0.01);
  EXPECT_LE(std::fabs(r.skew_mm), 0.01);
  std::printf("gantry homing: skew before -0.8000 mm, squaring %.4f mm, skew after %.4f mm\n", r.squaring_mm,
              r.skew_mm);
}

TEST(GantryHoming, ASecondSideStandingOnItsSwitchBacksOffFirst) {
  // Both at -3.5 mm: Y2's switch (-3.2) closed and latched there (a homing stopped on
  // it), Y's (-4) open. The homing backs off Y2's switch first, then searches as usual.
  const HomingRun r = home_y(-3.2, -3.5);
  ASSERT_TRUE(r.homed) << ::testing::PrintToString(r.alarms);
  EXPECT_NEAR(r.squaring_mm, 0.8, 0.01);
  EXPECT_LE(std::fabs(r.skew_mm), 0.01);
}

TEST(GantryHoming, ASecondSwitchBeyondTheAllowedDifferenceStopsTheHomingNamingBoth) {
  const HomingRun r = home_y(-1.0);  // 3 mm before Y's: over home_max_difference_mm (2)
  EXPECT_FALSE(r.homed);
  bool named = false;
  for (const auto& a : r.alarms)
    named = named || a.rfind("home_aborted: homing aborted: axis Y (search): Y2's switch closed, Y's not within 2.0000 mm", 0) == 0;
  EXPECT_TRUE(named) << ::testing::PrintToString(r.alarms);
}

}  // namespace
}  // namespace cnc
