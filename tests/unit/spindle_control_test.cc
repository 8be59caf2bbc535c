// The drive bridge's spindle logic (spindle_control.h), a pure core driven with
// plain structs and times: at speed within the tolerance, the timeout a fault
// naming its reason, a drive fault and a lost link, and a command from before the
// bridge's own stop never taken again.
#include <gtest/gtest.h>

#include <string>

#include "common/config/machine_config.h"
#include "services/drive_bridge/spindle_control.h"

namespace cnc::bridge {
namespace {

config::SpindleConfig spindle_cfg() {
  config::SpindleConfig c;
  c.enabled = true;
  c.max_rpm = 24000;
  c.rpm_per_hz = 60;
  c.at_speed_tolerance = 0.02;
  c.at_speed_timeout_s = 2.0;
  return c;
}

SpindleFeedback at_rpm(double rpm) {
  SpindleFeedback f;
  f.answering = true;
  f.have_status = true;
  f.running = rpm != 0;
  f.output_hz = rpm / 60.0;
  return f;
}

TEST(SpindleControl, AtSpeedWithinTheTolerance) {
  SpindleControl s(spindle_cfg());
  s.on_command(7, 1, 6000, true, 10.0);
  EXPECT_EQ(s.command_seq(), 7);
  EXPECT_EQ(s.direction(), 1);
  EXPECT_DOUBLE_EQ(s.commanded_hz(), 100.0);
  EXPECT_FALSE(s.at_speed());
  EXPECT_FALSE(s.update(at_rpm(3000), 10.5));
  EXPECT_FALSE(s.update(at_rpm(5870), 11.0));  // 2.2 % short
  EXPECT_FALSE(s.at_speed());
  EXPECT_FALSE(s.update(at_rpm(5881), 11.1));  // 1.98 % short
  EXPECT_TRUE(s.at_speed());
  EXPECT_EQ(s.at_speed_seq(), 7);
  // Counterclockwise: the actual speed's sign counts.
  s.on_command(8, -1, 6000, true, 12.0);
  EXPECT_FALSE(s.update(at_rpm(6000), 12.1));
  EXPECT_FALSE(s.at_speed());
  EXPECT_FALSE(s.update(at_rpm(-6000), 12.9));
  EXPECT_EQ(s.at_speed_seq(), 8);
  // A stop is at speed at once; S over max_rpm is limited to it.
  s.on_command(9, 0, 0, true, 13.0);
  EXPECT_TRUE(s.at_speed());
  EXPECT_EQ(s.direction(), 0);
  s.on_command(10, 1, 90000, true, 14.0);
  EXPECT_DOUBLE_EQ(s.commanded_rpm(), 24000);
}

TEST(SpindleControl, RepeatedAndOlderCommandsChangeNothing) {
  SpindleControl s(spindle_cfg());
  s.on_command(5, 1, 6000, true, 0.0);
  s.on_command(5, 1, 9000, true, 0.1);
  s.on_command(4, 0, 0, true, 0.2);
  EXPECT_EQ(s.direction(), 1);
  EXPECT_DOUBLE_EQ(s.commanded_rpm(), 6000);
}

TEST(SpindleControl, NotAtSpeedInTimeIsAFaultNamingIt) {
  SpindleControl s(spindle_cfg());
  s.on_command(3, 1, 6000, true, 100.0);
  EXPECT_FALSE(s.update(at_rpm(2000), 101.0));
  EXPECT_FALSE(s.update(at_rpm(4000), 102.0));  // the deadline itself is not past
  EXPECT_TRUE(s.update(at_rpm(4100), 102.001));
  EXPECT_TRUE(s.faulted());
  EXPECT_EQ(s.fault_reason(), "spindle: 6000 rpm not reached within 2.0 s (at 4100 rpm, tolerance 2.0 %)");
  EXPECT_EQ(s.direction(), 0) << "a fault stops the spindle";
  EXPECT_FALSE(s.update(at_rpm(4000), 103.0)) << "raised once";
  // Nothing turns it while faulted; the change is spent, not taken later.
  s.on_command(4, 1, 6000, true, 104.0);
  EXPECT_EQ(s.direction(), 0);
  s.clear_fault();
  s.on_command(4, 1, 6000, true, 105.0);
  EXPECT_EQ(s.direction(), 0);
  s.on_command(5, 1, 6000, true, 106.0);
  EXPECT_EQ(s.direction(), 1);
}

TEST(SpindleControl, ADriveThatDoesNotAnswerTimesOutSayingSo) {
  SpindleControl s(spindle_cfg());
  s.on_command(1, 1, 6000, true, 0.0);
  SpindleFeedback none;
  EXPECT_FALSE(s.update(none, 1.0));
  EXPECT_TRUE(s.update(none, 2.5));
  EXPECT_EQ(s.fault_reason(), "spindle: 6000 rpm not reached within 2.0 s: its drive does not answer");
}

TEST(SpindleControl, DriveFaultAndLostLinkAreFaults) {
  SpindleControl s(spindle_cfg());
  s.on_command(1, 1, 6000, true, 0.0);
  SpindleFeedback f = at_rpm(6000);
  f.error_code = 0x0007;
  EXPECT_TRUE(s.update(f, 0.5));
  EXPECT_EQ(s.fault_reason(), "spindle: drive fault 0x0007");
  s.clear_fault();
  s.on_command(2, 1, 6000, true, 1.0);
  f = at_rpm(6000);
  EXPECT_FALSE(s.update(f, 1.1));
  f.lost_events = 1;
  EXPECT_TRUE(s.update(f, 1.2));
  EXPECT_EQ(s.fault_reason(), "spindle: the link to its drive was lost while it turned");
  // Lost while stopped: no fault.
  s.clear_fault();
  f.lost_events = 2;
  EXPECT_FALSE(s.update(f, 1.3));
}

TEST(SpindleControl, TheBridgesOwnStopSpendsTheCommand) {
  SpindleControl s(spindle_cfg());
  s.on_command(1, 1, 6000, true, 0.0);
  s.stop();
  EXPECT_EQ(s.direction(), 0);
  EXPECT_TRUE(s.at_speed()) << "nothing left to wait for";
  s.on_command(1, 1, 6000, true, 1.0);  // sent again by the interpolator: still stopped
  EXPECT_EQ(s.direction(), 0);
  // Not accepted (the bridge follows no setpoints): spent as well.
  s.on_command(2, 1, 8000, false, 2.0);
  EXPECT_EQ(s.direction(), 0);
  s.on_command(2, 1, 8000, true, 3.0);
  EXPECT_EQ(s.direction(), 0);
}

TEST(SpindleControl, ADriveThatStopsWhileCommandedToRunIsAFault) {
  SpindleControl s(spindle_cfg());
  s.on_command(3, 1, 6000, true, 1.0);
  SpindleFeedback stopped = at_rpm(0);  // the drive's status: not running
  EXPECT_FALSE(s.update(stopped, 1.0)) << "the command is on its way";
  EXPECT_FALSE(s.update(at_rpm(6000), 1.2));
  EXPECT_TRUE(s.at_speed());
  // Tripped mid-cut (no fault code: a Huanyang's), running down.
  SpindleFeedback trip = at_rpm(5000);
  trip.running = false;
  EXPECT_FALSE(s.update(trip, 5.0));
  EXPECT_FALSE(s.update(trip, 5.0 + SpindleControl::kNotRunningS));
  EXPECT_TRUE(s.update(trip, 5.01 + SpindleControl::kNotRunningS));
  EXPECT_EQ(s.fault_reason(),
            "spindle: its drive does not run although commanded to (0.5 s): tripped, or stopped at its panel");
  EXPECT_EQ(s.direction(), 0) << "the fault stops it";
  // Stopped on purpose: no fault.
  SpindleControl t(spindle_cfg());
  t.on_command(1, 1, 6000, true, 0.0);
  EXPECT_FALSE(t.update(at_rpm(6000), 0.1));
  t.on_command(2, 0, 0, true, 0.2);
  EXPECT_FALSE(t.update(stopped, 0.2));
  EXPECT_FALSE(t.update(stopped, 5.0));
  EXPECT_FALSE(t.faulted());
}

}  // namespace
}  // namespace cnc::bridge
