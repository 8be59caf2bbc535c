// The drive bridge's spindle logic (spindle_control.h), a pure core driven with
// plain structs and times: at speed within the tolerance, the timeout a fault
// naming its reason, a drive fault and a lost link, and a command from before the
// bridge's own stop never taken again. The encoder: the position's sign and scale,
// its speed, a counter against the drive's direction or of other counts per
// revolution. Orientation against a simulated drive (a first-order speed response and
// its encoder): the shortest way across 0 deg, each way, the tolerance, from a turning
// spindle, and the faults (its timeout, no encoder, not accepted).
#include <gtest/gtest.h>

#include <cmath>
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

// A spindle drive for the orientation: its speed follows the command with a first-order
// lag, its encoder (4096 counts per revolution, counting up clockwise) integrates it.
struct Plant {
  double tau_s = 0.02;
  double rev = 0;     // revolutions
  double rev_s = 0;   // revolutions per second
  int64_t cpr = 4096;
  int polarity = 1;   // -1: the counter counts down clockwise
  bool stuck = false;
  void step(const SpindleControl& s, double dt) {
    const double want = stuck ? 0.0 : s.direction() * s.commanded_rpm() / 60.0;
    rev_s = want + (rev_s - want) * std::exp(-dt / tau_s);
    rev += rev_s * dt;
  }
  SpindleFeedback feedback(double t) const {
    SpindleFeedback f = at_rpm(rev_s * 60.0);
    f.running = true;
    f.has_position = true;
    f.position_counts = static_cast<int64_t>(std::floor(polarity * rev * static_cast<double>(cpr)));
    f.sample_s = t;
    return f;
  }
};

config::SpindleConfig encoder_cfg() {
  config::SpindleConfig c = spindle_cfg();
  c.encoder_counts_per_rev = 4096;
  c.orient_tolerance_deg = 0.5;
  c.orient_timeout_s = 5;
  c.orient_rpm = 60;
  c.orient_gain_per_s = 5;
  return c;
}

// Runs the plant and the control at 1 ms from `t` for `seconds` (or until it faults);
// the least and most position seen and the time it was first ORIENTED go to the pointers.
double run(SpindleControl& s, Plant& p, double t, double seconds, double* lo = nullptr, double* hi = nullptr,
           double* oriented_at = nullptr) {
  for (int k = 0; k < static_cast<int>(std::lround(seconds / 0.001)); ++k) {
    if (s.update(p.feedback(t), t)) break;
    if (oriented_at != nullptr && *oriented_at < 0 && s.orient_state() == OrientState::kOriented) *oriented_at = t;
    p.step(s, 0.001);
    t += 0.001;
    if (lo) *lo = std::min(*lo, p.rev);
    if (hi) *hi = std::max(*hi, p.rev);
  }
  return t;
}

double angle_deg(double rev) { return (rev - std::floor(rev)) * 360.0; }
double off_deg(double rev, double want_deg) { return std::remainder(angle_deg(rev) - want_deg, 360.0); }

TEST(SpindleControl, TheEncodersPositionIsRevolutionsPositiveClockwise) {
  SpindleControl s(encoder_cfg());
  Plant p;
  p.rev = -0.25;  // the counter's value at the first read is where the position starts
  SpindleFeedback f = p.feedback(0.0);
  EXPECT_FALSE(s.update(f, 0.0));
  EXPECT_TRUE(s.position_valid());
  EXPECT_DOUBLE_EQ(s.position_rev(), -0.25);
  EXPECT_FALSE(s.speed_known()) << "one sample: no speed yet";
  s.on_command(1, 1, 600, true, 0.0);
  const double t = run(s, p, 0.0, 1.0);
  EXPECT_TRUE(s.at_speed());
  EXPECT_FALSE(s.update(p.feedback(t), t));
  EXPECT_TRUE(s.speed_known());
  EXPECT_NEAR(s.speed_rev_s(), 10.0, 0.01) << "M3 at 600 rpm: +10 rev/s";
  EXPECT_DOUBLE_EQ(s.position_rev(), std::floor(p.rev * 4096) / 4096) << "counts / encoder_counts_per_rev";
  EXPECT_DOUBLE_EQ(s.sample_s(), t);
  s.on_command(2, -1, 600, true, t);
  run(s, p, t, 1.0);
  EXPECT_NEAR(s.speed_rev_s(), -10.0, 0.01) << "M4: negative";
  // No position from the drive: not valid (the last value stays).
  SpindleFeedback none = at_rpm(-600);
  EXPECT_FALSE(s.update(none, 5.0));
  EXPECT_FALSE(s.position_valid());
  EXPECT_FALSE(s.speed_known());
  // Without spindle.encoder_counts_per_rev the counter is not read as a position.
  SpindleControl plain(spindle_cfg());
  EXPECT_FALSE(plain.update(f, 0.0));
  EXPECT_FALSE(plain.position_valid());
}

TEST(SpindleControl, AnEncoderAgainstTheDriveOrOfOtherCountsIsAFaultNamingIt) {
  {
    SpindleControl s(encoder_cfg());
    Plant p;
    p.polarity = -1;
    s.on_command(1, 1, 600, true, 0.0);
    run(s, p, 0.0, 1.0);
    ASSERT_TRUE(s.faulted());
    // kEncoderCheckS after the change got to speed: the drive's speed and the encoder's then.
    EXPECT_EQ(s.fault_reason(),
              "spindle: its encoder counts against the drive's turning (the drive at 600 rpm, the encoder -600 rpm): "
              "its counter must count up clockwise (M3): set the encoder's polarity in the drive");
  }
  {
    config::SpindleConfig c = encoder_cfg();
    c.encoder_counts_per_rev = 1024;  // the encoder has 4096
    SpindleControl s(c);
    Plant p;
    s.on_command(1, 1, 600, true, 0.0);
    run(s, p, 0.0, 1.0);
    ASSERT_TRUE(s.faulted());
    EXPECT_EQ(s.fault_reason(),
              "spindle: its encoder reads 2399 rpm, the drive 600 rpm: spindle.encoder_counts_per_rev (1024) is not "
              "the encoder's counts per spindle revolution");  // 4 x 600, one count short over the speed's window
  }
}

// Orients from `from_deg` to `to_deg` in `mode`; the target's distance (revolutions) and
// the position's least and most values on the way.
struct Orientation {
  double target_d = 0, lo = 0, hi = 0, end = 0, oriented_at = -1;
  OrientState state = OrientState::kNone;
};
Orientation orient(double from_deg, double to_deg, int mode, double start_rev = 3) {
  SpindleControl s(encoder_cfg());
  Plant p;
  p.rev = start_rev + from_deg / 360.0;
  Orientation o;
  o.lo = o.hi = p.rev;
  double t = run(s, p, 0.0, 0.1);
  s.on_orient(7, to_deg, mode, true, t);
  EXPECT_EQ(s.orient_state(), OrientState::kOrienting);
  EXPECT_TRUE(s.at_speed()) << "nothing waits for an orientation at speed";
  t = run(s, p, t, 3.0, &o.lo, &o.hi, &o.oriented_at);
  EXPECT_TRUE(s.orient_target_known());
  o.target_d = s.orient_target_rev() - (start_rev + from_deg / 360.0);
  o.end = p.rev;
  o.state = s.orient_state();
  EXPECT_FALSE(s.faulted()) << s.fault_reason();
  EXPECT_EQ(s.command_seq(), 7);
  return o;
}

TEST(SpindleControl, OrientsTheShortestWayAcrossZero) {
  const Orientation a = orient(350, 10, 0);  // clockwise through 0 deg: +20 deg
  EXPECT_NEAR(a.target_d * 360, 20, 0.1);
  EXPECT_EQ(a.state, OrientState::kOriented);
  EXPECT_LE(std::fabs(off_deg(a.end, 10)), 0.5);
  EXPECT_GE(a.lo, 3 + 350 / 360.0 - 1e-3) << "never the long way back";
  const Orientation b = orient(10, 350, 0);  // counterclockwise through 0 deg: -20 deg
  EXPECT_NEAR(b.target_d * 360, -20, 0.1);
  EXPECT_LE(std::fabs(off_deg(b.end, 350)), 0.5);
  EXPECT_LE(b.hi, 3 + 10 / 360.0 + 1e-3);
  // Angles beyond a turn are taken modulo 360.
  EXPECT_NEAR(orient(10, 370 + 720, 0).target_d * 360, 0, 0.1);
  EXPECT_NEAR(orient(10, -90, 0).target_d * 360, -100, 0.1);
}

TEST(SpindleControl, OrientsClockwiseOrCounterclockwiseAsAsked) {
  const Orientation cw = orient(10, 350, 1);
  EXPECT_NEAR(cw.target_d * 360, 340, 0.1);
  EXPECT_GE(cw.lo, 3 + 10 / 360.0 - 1e-3) << "clockwise only";
  EXPECT_LE(std::fabs(off_deg(cw.end, 350)), 0.5);
  EXPECT_EQ(cw.state, OrientState::kOriented);
  const Orientation ccw = orient(350, 10, 2);
  EXPECT_NEAR(ccw.target_d * 360, -340, 0.1);
  EXPECT_LE(ccw.hi, 3 + 350 / 360.0 + 1e-3) << "counterclockwise only";
  EXPECT_LE(std::fabs(off_deg(ccw.end, 10)), 0.5);
  EXPECT_NEAR(orient(10, 350, 2).target_d * 360, -20, 0.1);
  EXPECT_NEAR(orient(350, 10, 1).target_d * 360, 20, 0.1);
}

TEST(SpindleControl, WithinTheToleranceNoWholeTurnAndOrientedOnlyThereAtRest) {
  // 0.3 deg past 90 deg, clockwise asked: not a turn round, back by 0.3 deg.
  const Orientation past = orient(90.3, 90, 1);
  EXPECT_NEAR(past.target_d * 360, -0.3, 0.01);
  EXPECT_GT(past.lo, 3 + 89.0 / 360.0);
  EXPECT_EQ(past.state, OrientState::kOriented);
  // 0.3 deg short of it, counterclockwise asked: on by 0.3 deg.
  EXPECT_NEAR(orient(89.7, 90, 2).target_d * 360, 0.3, 0.01);
  // From 10 deg to 100 deg: ORIENTED first where it was within 0.5 deg and at rest.
  SpindleControl s(encoder_cfg());
  Plant p;
  p.rev = 10 / 360.0;
  double t = run(s, p, 0.0, 0.1);
  s.on_orient(3, 100, 0, true, t);
  while (s.orient_state() == OrientState::kOrienting && t < 3) {
    ASSERT_FALSE(s.update(p.feedback(t), t));
    p.step(s, 0.001);
    t += 0.001;
  }
  ASSERT_EQ(s.orient_state(), OrientState::kOriented);
  EXPECT_LE(std::fabs(off_deg(s.position_rev(), 100)), 0.5);
  EXPECT_LE(std::fabs(s.speed_rev_s()) * SpindleControl::kRestS, 0.5 / 360) << "at rest";
  EXPECT_GT(std::fabs(off_deg(s.position_rev(), 100)), 0.0);
  // The loop holds it there, ORIENTED, until the next command.
  t = run(s, p, t, 1.0);
  EXPECT_EQ(s.orient_state(), OrientState::kOriented);
  EXPECT_LE(std::fabs(off_deg(p.rev, 100)), 0.05);
  s.on_command(4, 1, 600, true, t);
  EXPECT_EQ(s.orient_state(), OrientState::kNone);
  EXPECT_EQ(s.direction(), 1);
}

TEST(SpindleControl, ATurningSpindleSlowsToTheOrientationsSpeedFirst) {
  SpindleControl s(encoder_cfg());
  Plant p;
  s.on_command(1, 1, 600, true, 0.0);
  double t = run(s, p, 0.0, 0.5);
  ASSERT_TRUE(s.at_speed());
  s.on_orient(2, 45, 0, true, t);
  EXPECT_FALSE(s.update(p.feedback(t), t));
  EXPECT_EQ(s.direction(), 1);
  EXPECT_DOUBLE_EQ(s.commanded_rpm(), 60) << "down to orient_rpm, in its direction";
  EXPECT_FALSE(s.orient_target_known());
  double oriented_at = -1;
  t = run(s, p, t, 3.0, nullptr, nullptr, &oriented_at);
  EXPECT_EQ(s.orient_state(), OrientState::kOriented);
  EXPECT_LE(std::fabs(off_deg(p.rev, 45)), 0.5);
}

TEST(SpindleControl, NotOrientedInTimeIsAFaultNamingIt) {
  SpindleControl s(encoder_cfg());
  Plant p;
  p.rev = 0.25;
  p.stuck = true;  // a blocked spindle
  double t = run(s, p, 0.0, 0.1);
  s.on_orient(9, 180, 0, true, t);
  bool raised = false;
  for (int k = 0; k < 6000 && !raised; ++k) {
    raised = s.update(p.feedback(t), t);
    t += 0.001;
  }
  ASSERT_TRUE(raised);
  EXPECT_NEAR(t, 0.1 + 5.0, 0.01) << "spindle.orient_timeout_s";
  EXPECT_EQ(s.orient_state(), OrientState::kFault);
  EXPECT_EQ(s.fault_reason(),
            "spindle: orientation to 180.00 deg not reached within 5.0 s (spindle.orient_timeout_s): at 90.00 deg, "
            "90.00 deg off, at rest (tolerance 0.50 deg)");
  EXPECT_EQ(s.direction(), 0) << "the fault stops it";
  EXPECT_TRUE(s.position_valid()) << "the position stays on the bus";
  // No encoder reading at all: said so.
  SpindleControl u(encoder_cfg());
  u.on_orient(1, 90, 0, true, 0.0);
  EXPECT_FALSE(u.update(SpindleFeedback{}, 4.0));
  EXPECT_TRUE(u.update(SpindleFeedback{}, 5.01));
  EXPECT_EQ(u.fault_reason(),
            "spindle: orientation to 90.00 deg not reached within 5.0 s (spindle.orient_timeout_s): its encoder "
            "position is not read");
}

TEST(SpindleControl, AnOrientationThatCannotBeCarriedOut) {
  // Without an encoder: a fault naming the key, raised at the next update.
  SpindleControl s(spindle_cfg());
  s.on_orient(1, 90, 0, true, 0.0);
  EXPECT_EQ(s.orient_state(), OrientState::kFault);
  EXPECT_TRUE(s.update(at_rpm(0), 0.001));
  EXPECT_EQ(s.fault_reason(), "spindle: orientation (M19) needs the spindle's encoder: spindle.encoder_counts_per_rev is 0");
  EXPECT_FALSE(s.update(at_rpm(0), 0.002)) << "raised once";
  // Not accepted (the bridge follows no setpoints), or a way that is none: spent, no fault.
  SpindleControl t(encoder_cfg());
  t.on_orient(1, 90, 0, false, 0.0);
  EXPECT_EQ(t.orient_state(), OrientState::kFault);
  EXPECT_FALSE(t.update(at_rpm(0), 0.001));
  EXPECT_FALSE(t.faulted());
  t.on_orient(2, 90, 3, true, 0.1);
  EXPECT_EQ(t.orient_state(), OrientState::kFault);
  // The bridge's own stop ends one under way.
  t.on_orient(3, 90, 0, true, 0.2);
  EXPECT_EQ(t.orient_state(), OrientState::kOrienting);
  t.stop();
  EXPECT_EQ(t.orient_state(), OrientState::kFault);
  EXPECT_EQ(t.command_seq(), 3);
}

}  // namespace
}  // namespace cnc::bridge
