// The drive bridge core: fine interpolation (Kim, Song & Kwon's two steps), a missed or
// late setpoint bridged, the limits (travel, velocity, acceleration) faulting
// before anything moves, the watchdog's controlled stop, joining a stream only
// where the axes stand; and a randomised stream (fixed seed) never producing a
// NaN or a command beyond the limits.
//
// Every test checks the fine setpoints themselves by finite differences over the
// servo period (v = Δx/T, a = Δv/T, j = Δa/T, from rest at engage): each axis's
// velocity, acceleration and jerk limits hold in every case — steady streams, a
// missed or late setpoint, a rejoin, the watchdog stop, a fault's stop, streams that
// themselves break the jerk limit. Tolerance: 1e-6 relative (rounding of a third
// difference of positions up to 400 mm over 1 ms^3 is ~1e-3 mm/s^3, 2e-8 of 60000).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <utility>

#include "common/config/machine_config.h"
#include "services/drive_bridge/drive_bridge.h"

namespace cnc::bridge {
namespace {

config::MachineConfig machine() {
  config::MachineConfig c = config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  return c;
}

// A stream along X at constant velocity v from x0, starting at cycle 0.
AxisArray at(double x, double y = 0, double z = 0) {
  AxisArray a{};
  a[0] = x;
  a[1] = y;
  a[2] = z;
  return a;
}

struct Runner {
  explicit Runner(const config::MachineConfig& c) : cfg(c), core(c), n(4) { start(at(0)); }
  void start(const AxisArray& p) {
    core.engage(p);
    prev = p;
    prev_v = {};
    prev_a = {};
  }
  // One coarse cycle: the setpoint (unless skipped), then N servo ticks.
  void cycle(int64_t k, const AxisArray& p, bool deliver = true, const StreamStamp& from = {}) {
    if (deliver) last = core.on_setpoint(k, p, from);
    idle(n);
  }
  // Servo ticks the playback stands still for a stalled link: the drives see none
  // of them (the node neither posts nor changes the command). Returns how many the
  // core accepted.
  int hold(int ticks) {
    int held = 0;
    for (int i = 0; i < ticks; ++i) held += core.hold() ? 1 : 0;
    return held;
  }
  // Servo ticks with no new setpoint.
  void idle(int ticks) {
    const double t = cfg.servo_period_s;
    for (int i = 0; i < ticks; ++i) {
      const AxisArray c = core.tick();
      for (int a = 0; a < 3; ++a) {
        const double v = (c[a] - prev[a]) / t;
        const double acc = (v - prev_v[a]) / t;
        const double jerk = (acc - prev_a[a]) / t;
        max_speed[a] = std::max(max_speed[a], std::fabs(v));
        max_acc[a] = std::max(max_acc[a], std::fabs(acc));
        max_jerk[a] = std::max(max_jerk[a], std::fabs(jerk));
        max_dv[a] = std::max(max_dv[a], std::fabs(v - prev_v[a]));
        prev_v[a] = v;
        prev_a[a] = acc;
        finite = finite && std::isfinite(c[a]);
      }
      prev = c;
      trace.push_back(c[0]);
    }
  }
  // The finite differences of every fine setpoint so far keep each axis's limits;
  // `acc_limit` (when > 0) replaces the acceleration limits (a stop's deceleration).
  void expect_limits(const char* what, double acc_limit = 0) const {
    constexpr double kRel = 1 + 1e-6;
    EXPECT_TRUE(finite) << what;
    for (int a = 0; a < 3; ++a) {
      const auto& ax = cfg.axes[static_cast<size_t>(a)];
      const double amax = acc_limit > 0 ? std::min(acc_limit, ax.max_accel_mm_s2) : ax.max_accel_mm_s2;
      EXPECT_LE(max_speed[a], ax.max_velocity_mm_s * kRel) << what << ": axis " << ax.name;
      EXPECT_LE(max_acc[a], amax * kRel) << what << ": axis " << ax.name;
      EXPECT_LE(max_jerk[a], ax.max_jerk_mm_s3 * kRel) << what << ": axis " << ax.name;
    }
  }
  void print(const char* what) const {
    std::printf("[ figures  ] %s: X max |v| %.2f mm/s, |a| %.1f mm/s^2, |j| %.0f mm/s^3 (limits %g, %g, %g)\n", what,
                max_speed[0], max_acc[0], max_jerk[0], cfg.axes[0].max_velocity_mm_s, cfg.axes[0].max_accel_mm_s2,
                cfg.axes[0].max_jerk_mm_s3);
  }
  void reset_maxima() {
    max_speed = {};
    max_acc = {};
    max_jerk = {};
    max_dv = {};
  }
  config::MachineConfig cfg;
  BridgeCore core;
  int n;
  BridgeCore::Verdict last = BridgeCore::Verdict::kIgnored;
  AxisArray prev{};
  AxisArray prev_v{};
  AxisArray prev_a{};
  AxisArray max_speed{};
  AxisArray max_acc{};
  AxisArray max_jerk{};
  AxisArray max_dv{};
  bool finite = true;
  std::vector<double> trace;
};

// A stream along X that keeps the limits: acceleration ramps at 90 % of the jerk
// limit up to `acc` and down again into a cruise at `v` (coarse finite differences
// within X's 250 mm/s, 3000 mm/s^2, 60000 mm/s^3). Returns the positions per cycle.
std::vector<double> smooth_stream(double v, double acc, int cycles) {
  const double t = 0.004, jerk = 0.9 * 60000.0;
  std::vector<double> xs;
  double x = 0, vel = 0, a = 0;
  for (int k = 0; k < cycles; ++k) {
    // Braking the acceleration down from a takes a/j: start when the velocity
    // still missing is what that ramp adds.
    const double missing = v - vel;
    const double ramp_gain = a * a / (2 * jerk) + a * t;
    if (missing <= ramp_gain) {
      a = std::max(0.0, a - jerk * t);
    } else {
      a = std::min(acc, a + jerk * t);
    }
    vel = std::min(v, vel + a * t);
    x += vel * t;
    xs.push_back(x);
  }
  return xs;
}

TEST(BridgeCore, FineInterpolationIsLinearBetweenCoarseSetpointsTwoPeriodsLate) {
  Runner r(machine());
  const double v = 100.0;  // mm/s: 0.4 mm per 4 ms cycle, 0.1 mm per 1 ms tick
  // Accelerate within the limits first (jerk-limited, to 2700 mm/s^2), then cruise.
  const std::vector<double> xs = smooth_stream(v, 2700.0, 100);
  int64_t k = 0;
  for (; k < 100; ++k) {
    r.cycle(k, at(xs[static_cast<size_t>(k)]));
    ASSERT_EQ(r.last, BridgeCore::Verdict::kAccepted) << r.core.fault_reason();
  }
  const double x = xs.back();
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  // Steady state: every tick advances 0.1 mm (the playback rate has settled at 1),
  // and the command trails the newest setpoint by one to three periods.
  const size_t t = r.trace.size();
  for (size_t i = t - 20; i < t; ++i) EXPECT_NEAR(r.trace[i] - r.trace[i - 1], 0.1, 1e-4);
  EXPECT_NEAR(r.core.playback_rate(), 1.0, 1e-3);
  EXPECT_GE(x - r.trace.back(), 1.0 * v * 0.004);
  EXPECT_LE(x - r.trace.back(), 3.0 * v * 0.004);
  EXPECT_EQ(r.core.setpoint_gaps(), 0);
  EXPECT_EQ(r.core.bridged_ticks(), 0);
  r.expect_limits("steady stream");
}

TEST(BridgeCore, SingleMissedSetpointIsBridged) {
  // A stream within the limits (to 150 mm/s at up to 2700 mm/s^2), once complete,
  // once with one setpoint lost mid-acceleration and one lost at cruise.
  const std::vector<double> xs = smooth_stream(150.0, 2700.0, 80);
  Runner full(machine()), lossy(machine());
  for (int64_t k = 0; k < 80; ++k) {
    full.cycle(k, at(xs[static_cast<size_t>(k)]));
    lossy.cycle(k, at(xs[static_cast<size_t>(k)]), k != 8 && k != 60);
  }
  EXPECT_FALSE(lossy.core.faulted()) << lossy.core.fault_reason();
  EXPECT_EQ(lossy.core.setpoint_gaps(), 2);
  full.expect_limits("complete stream");
  lossy.expect_limits("two setpoints lost");
  lossy.print("two setpoints lost");
  // Bridged: the line between the neighbours misses the lost point by a·T²/8 at
  // most (2700 mm/s^2: 5.4 µm); the playback clock slows a little while the buffer
  // looks short, so the command runs a little behind the complete run's for a while
  // (a shift along the same path: at 150 mm/s, 0.15 mm is 1 ms).
  double worst = 0;
  for (size_t i = 0; i < full.trace.size(); ++i) worst = std::max(worst, std::fabs(full.trace[i] - lossy.trace[i]));
  EXPECT_LE(worst, 0.15);
  std::printf("[ figures  ] two setpoints lost: largest difference from the complete run %.4f mm\n", worst);

  // The stream of the old test: velocity steps of 10 mm/s per cycle (2500 mm/s^2
  // from one cycle to the next, a jerk of 625000 mm/s^3), cycle 30 lost. Straight
  // lines played back tick by tick commanded ~11000 mm/s^2 here.
  Runner r(machine());
  double x = 0, vel = 0;
  for (int64_t k = 0; k < 40; ++k) {
    vel = std::min(50.0, vel + 10.0);
    x += vel * 0.004;
    r.cycle(k, at(x), k != 30);
  }
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  EXPECT_EQ(r.core.setpoint_gaps(), 1);
  r.expect_limits("jerky stream, one setpoint lost");
  r.print("jerky stream, one setpoint lost");
}

TEST(BridgeCore, StalledLinkHoldsThePlaybackAndTheLagIsMadeUp) {
  // A drive link that does not answer for 12 ticks mid-cruise (the drive, its
  // network or the bridge's I/O thread stalled): the playback stands still, the
  // setpoints keep coming. The drive then gets the command sequence without a jump
  // (every difference within the limits), and the lag is made up afterwards by the
  // playback rate: the command ends where the complete run's does, and a while
  // after the stall runs identically again.
  // Up to 150 mm/s, cruise, and down again by the mirrored steps; then standing.
  std::vector<double> xs = smooth_stream(150.0, 2700.0, 130);
  for (size_t k = 130; k-- > 0;) xs.push_back(xs.back() + xs[k] - (k > 0 ? xs[k - 1] : 0.0));
  for (int k = 0; k < 60; ++k) xs.push_back(xs.back());
  Runner full(machine()), held(machine());
  int accepted = 0;
  for (int64_t k = 0; k < static_cast<int64_t>(xs.size()); ++k) {
    full.cycle(k, at(xs[static_cast<size_t>(k)]));
    held.last = held.core.on_setpoint(k, at(xs[static_cast<size_t>(k)]));
    if (k == 120) {
      accepted = held.hold(12);
      held.idle(1);
    } else {
      held.idle(held.n);
    }
  }
  EXPECT_EQ(accepted, 12);
  EXPECT_EQ(held.core.held_ticks(), 12);
  EXPECT_FALSE(held.core.faulted()) << held.core.fault_reason();
  EXPECT_EQ(held.core.starved_ticks(), 0);
  held.expect_limits("a 12-tick hold at 150 mm/s");
  held.print("a 12-tick hold at 150 mm/s");
  // 3 ticks fewer were recorded (12 held, 4 of that cycle's ticks replaced by 1).
  ASSERT_EQ(held.trace.size() + 3, full.trace.size());
  // Both settle onto the end point the same way (the limiter's approach is
  // asymptotic: 11 µm short of it 60 cycles after the stream's end, in both runs).
  EXPECT_NEAR(held.trace.back(), full.trace.back(), 1e-6);
  EXPECT_NEAR(held.trace.back(), xs.back(), 5e-5);
  // A hold beyond the allowance is refused: the lead may grow to 6 cycles (from
  // its usual 2 to 3): 12 to 17 ticks at 4 ticks per cycle.
  Runner r(machine());
  const std::vector<double> slow = smooth_stream(20.0, 1000.0, 40);
  for (int64_t k = 0; k < 40; ++k) r.cycle(k, at(slow[static_cast<size_t>(k)]));
  int n = 0;
  for (int64_t k = 40; k < 80; ++k) {
    r.last = r.core.on_setpoint(k, at(slow.back() + 0.08 * static_cast<double>(k - 39)));
    n += r.hold(4);
  }
  EXPECT_GE(n, 12);
  EXPECT_LE(n, 17);
  std::printf("[ figures  ] hold: 12 ticks at 150 mm/s made up, X |a| %.1f mm/s^2; holds allowed until the lead is 6 cycles: %d ticks\n",
              held.max_acc[0], n);
  // Not while idle.
  BridgeCore idle(machine());
  EXPECT_FALSE(idle.hold());
}

// A move along X that keeps every limit exactly (no discretisation of its own): from
// rest up to `v` and down to rest again, the acceleration ramped at jerk `j` up to `a`
// (a jerk-limited S-curve, integrated at 1 us), `cruise_s` at `v` between; the position
// every 4 ms cycle, then `rest` cycles standing at the end.
std::vector<double> s_curve_move(double v, double a, double j, double cruise_s, int rest) {
  const double tj = std::min(a / j, std::sqrt(v / j));  // the ramp of the acceleration
  const double ap = j * tj;                              // its peak
  const double ta = (v - ap * tj) / ap;                  // at the peak (0: a triangle)
  const double t_acc = 2 * tj + ta, total = 2 * t_acc + cruise_s;
  auto acc_at = [&](double t) {
    const bool down = t > t_acc + cruise_s;
    if (t > t_acc && !down) return 0.0;
    const double u = down ? t - t_acc - cruise_s : t;
    const double s = down ? -1.0 : 1.0;
    if (u < tj) return s * j * u;
    if (u < tj + ta) return s * ap;
    return s * std::max(0.0, ap - j * (u - tj - ta));
  };
  std::vector<double> xs;
  const double dt = 1e-6;
  double x = 0, vel = 0;
  const long steps = std::lround(total / dt), per_cycle = std::lround(0.004 / dt);
  for (long i = 1; i <= steps + per_cycle; ++i) {
    const double t = static_cast<double>(i) * dt;
    const double dv = 0.5 * (acc_at(t - dt) + acc_at(t)) * dt;
    x += (vel + 0.5 * dv) * dt;
    vel = std::max(0.0, vel + dv);
    if (i % per_cycle == 0) xs.push_back(x);
  }
  for (int k = 0; k < rest; ++k) xs.push_back(xs.back());
  return xs;
}

// The largest excess over the end point of the commands of a run of `xs` without a
// hold and of one with a 12-tick hold at cycle 60 (at cruise), in mm.
std::pair<double, double> overshoot_with_and_without_hold(const std::vector<double>& xs, const char* what) {
  Runner full(machine()), held(machine());
  for (int64_t k = 0; k < static_cast<int64_t>(xs.size()); ++k) {
    full.cycle(k, at(xs[static_cast<size_t>(k)]));
    EXPECT_EQ(full.last, BridgeCore::Verdict::kAccepted) << full.core.fault_reason();
    held.last = held.core.on_setpoint(k, at(xs[static_cast<size_t>(k)]));
    if (k == 60) {
      EXPECT_EQ(held.hold(12), 12);
      held.idle(1);
    } else {
      held.idle(held.n);
    }
  }
  EXPECT_FALSE(held.core.faulted()) << held.core.fault_reason();
  full.expect_limits(what);
  held.expect_limits(what);
  const double end = xs.back();
  double over_full = -1e9, over_held = -1e9;
  for (double x : full.trace) over_full = std::max(over_full, x - end);
  for (double x : held.trace) over_held = std::max(over_held, x - end);
  std::printf("[ figures  ] %s: the command's largest excess over the end point %.6f mm, %.6f mm with a 12-tick hold "
              "at cruise\n", what, over_full, over_held);
  return {over_full, over_held};
}

TEST(BridgeCore, TheLagOfAHoldIsNotMadeUpWhereTheStreamIsAtItsLimits) {
  // A hold at cruise leaves the playback behind; the stream then brakes to a stop at
  // the acceleration limit. Made up at 5 % over real time there, the reference braked
  // at 1.05^2 of the stream's deceleration, more than the limiter may command: the
  // command ran past the end point (at all of X's limits 2.05 mm, against 0.25 mm
  // without the hold; live, an A axis braking at 1800 deg/s^2 from 180 deg/s stopped
  // 0.63 deg past 180 and failed integration.replay). Now the lag waits for room.
  const auto exact = overshoot_with_and_without_hold(s_curve_move(250.0, 3000.0, 60000.0, 0.3, 80),
                                                     "an S-curve move at all of X's limits");
  EXPECT_LE(exact.second, exact.first + 1e-6);
  // With 5 % of the acceleration to spare, neither passes the end point. (At all the
  // limits at once, the limiter itself still does by 0.10 mm: it trails the reference
  // at the velocity limit and has no deceleration to spare for catching up.)
  const auto spare = overshoot_with_and_without_hold(s_curve_move(250.0, 2850.0, 60000.0, 0.3, 80),
                                                     "an S-curve move at 95 % of X's acceleration limit");
  EXPECT_LE(spare.first, 1e-6);
  EXPECT_LE(spare.second, 1e-6);
}

TEST(BridgeCore, LateSetpointIsBridgedOnTheLastVelocity) {
  Runner r(machine());
  double x = 0, vel = 0;
  int64_t k = 0;
  const std::vector<double> ramp = smooth_stream(50.0, 2700.0, 30);
  for (; k < 30; ++k) {
    x = ramp[static_cast<size_t>(k)];
    r.cycle(k, at(x));
  }
  vel = 50.0;
  r.expect_limits("before the late setpoint");
  r.reset_maxima();
  // Cycle 30 arrives 2.25 periods late: the jitter buffer absorbs most of it, the
  // command goes on at the last velocity for the rest; then the playback slows a
  // little until the buffer is back.
  r.idle(9);
  for (; k < 40; ++k) {
    x += vel * 0.004;
    r.cycle(k, at(x));
  }
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  EXPECT_GT(r.core.bridged_ticks(), 0);
  EXPECT_EQ(r.core.starved_ticks(), 0);
  EXPECT_LE(r.max_speed[0], 50.0 * 1.01);
  EXPECT_LE(r.max_dv[0], 50.0 * 0.01);  // no jump: only the playback rate's gentle change
  EXPECT_LT(r.core.playback_rate(), 1.0);
  r.expect_limits("late setpoint");
  r.print("late setpoint");
}

TEST(BridgeCore, StreamBackBeforeTheTimeoutIsRejoinedWithinTheLimits) {
  Runner r(machine());
  double x = 0, vel = 0;
  int64_t k = 0;
  const std::vector<double> ramp = smooth_stream(50.0, 2700.0, 30);
  for (; k < 30; ++k) {
    x = ramp[static_cast<size_t>(k)];
    r.cycle(k, at(x));
  }
  vel = 50.0;
  r.idle(28);  // seven periods late (28 ms, under the 50 ms timeout): past the buffer and the bridging
  EXPECT_GT(r.core.starved_ticks(), 0);
  for (int i = 0; i < 30; ++i, ++k) {
    x += vel * 0.004;
    r.cycle(k, at(x));
  }
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  EXPECT_EQ(r.core.rejoins(), 1);
  EXPECT_LE(r.max_speed[0], 250.0 * 1.01);
  // Back on the stream: steady at 50 mm/s again, one to three periods behind the newest setpoint.
  for (int i = 0; i < 40; ++i, ++k) {
    x += vel * 0.004;
    r.cycle(k, at(x));
  }
  // (the playback clock is still settling back onto its lead: within 1 %)
  EXPECT_NEAR(r.core.velocity()[0], 50.0, 0.5);
  const double behind = x - r.core.commanded()[0];
  EXPECT_GE(behind, 1.0 * 50.0 * 0.004);
  EXPECT_LE(behind, 3.0 * 50.0 * 0.004);
  r.expect_limits("brake, then rejoin");
  r.print("brake, then rejoin");
}

TEST(BridgeCore, SetpointBeyondTravelFaultsAndNothingMoves) {
  Runner r(machine());
  for (int64_t k = 0; k < 5; ++k) r.cycle(k, at(0));
  r.cycle(5, at(0.0, 0.0, 6.0));  // Z travel ends at 5 mm
  EXPECT_EQ(r.last, BridgeCore::Verdict::kFault);
  EXPECT_TRUE(r.core.faulted());
  EXPECT_NE(r.core.fault_reason().find("axis Z at 6.0000 mm is outside its travel"), std::string::npos)
      << r.core.fault_reason();
  for (int i = 0; i < 100; ++i) r.core.tick();
  EXPECT_EQ(r.core.mode(), BridgeCore::Mode::kStopped);
  EXPECT_EQ(r.core.commanded()[2], 0.0);
  // Later setpoints are ignored until the core is engaged again.
  EXPECT_EQ(r.core.on_setpoint(7, at(0)), BridgeCore::Verdict::kIgnored);
}

// A rapid that ends exactly at the end of Z's travel: the G0 Z5 of the demo (from
// Z-2, as the interpolator planned it between two stops at 97 % of Z's acceleration
// and jerk; its setpoints as logged), with one setpoint missed on the way (bridged on
// the last velocity, then rejoined). The limiter overshoots the end and the travel
// clamp holds the command there; it must then stand at the end. Before, the clamped
// step's finite differences stayed in the limiter's state (an acceleration of about
// -v/T): here Z was thrown back to 3.86 mm; live, on the demo, it swung between 1.6
// and 5 mm for 0.8 s about the standing setpoint.
TEST(BridgeCore, ARapidEndingAtTheTravelEndStandsThere) {
  const config::MachineConfig cfg = machine();
  ASSERT_DOUBLE_EQ(cfg.axes[2].max_mm, 5.0);
  const std::vector<double> zs = {
      -1.9987584,   -1.993792,    -1.9826176,   -1.962752,    -1.931712,     -1.8870144,  -1.826176,
      -1.7467136,   -1.646144,    -1.521984,    -1.371936216, -1.196156908,  -0.9970678937, -0.7770859891,
      -0.5386225531, -0.2840827312, -0.01586439375, 0.2636426219, 0.5520577234, 0.8470112313, 1.146146197,
      1.447120677,  1.747610459,  2.045312705,  2.337950641,  2.623279778,  2.899096247,   3.163248011,
      3.413651086,  3.648313334,  3.865370538,  4.063143383,  4.240231281,  4.395666809,   4.529145175,
      4.641244589,  4.733395953,  4.807541844,  4.865791556,  4.910263783,  4.943038567,   4.966136238,
      4.9814974,    4.990955355,  4.99619578,   4.998699895,  4.999668228,  5.0};
  Runner r(cfg);
  r.start(at(0, 0, -2.0));
  int64_t k = 0;
  for (; k < 5; ++k) r.cycle(k, at(0, 0, -2.0));
  double z_max = -1e9, z_min_after = 1e9;
  bool arrived = false;
  for (size_t i = 0; i < zs.size() + 300; ++i, ++k) {
    r.cycle(k, at(0, 0, zs[std::min(i, zs.size() - 1)]), i != 30);  // one setpoint missed at 75 mm/s
    ASSERT_NE(r.last, BridgeCore::Verdict::kFault) << r.core.fault_reason();
    const double c = r.core.commanded()[2];
    z_max = std::max(z_max, c);
    arrived = arrived || c > 5.0 - 1e-3;
    if (arrived) z_min_after = std::min(z_min_after, c);
  }
  std::printf("[ figures  ] Z to its travel end: highest command %.6f mm, lowest after arriving %.6f mm\n", z_max,
              z_min_after);
  EXPECT_TRUE(arrived);
  EXPECT_LE(z_max, 5.0);
  EXPECT_GE(z_min_after, 5.0 - 0.05);  // no swing back (was to 3.86 mm)
  EXPECT_NEAR(r.core.commanded()[2], 5.0, 1e-6);
}

TEST(BridgeCore, SetpointBeyondVelocityFaultsAndNothingMoves) {
  Runner r(machine());
  for (int64_t k = 0; k < 5; ++k) r.cycle(k, at(0));
  // 1.2 mm in 4 ms: 300 mm/s against X's 250 mm/s.
  r.cycle(5, at(1.2));
  EXPECT_EQ(r.last, BridgeCore::Verdict::kFault);
  EXPECT_NE(r.core.fault_reason().find("would move at 300.00 mm/s, limit 250"), std::string::npos)
      << r.core.fault_reason();
  for (int i = 0; i < 100; ++i) r.core.tick();
  EXPECT_EQ(r.core.commanded()[0], 0.0);
}

TEST(BridgeCore, SetpointBeyondAccelerationFaultsAndNothingMoves) {
  Runner r(machine());
  for (int64_t k = 0; k < 5; ++k) r.cycle(k, at(0));
  // From rest to 100 mm/s in one cycle: 25000 mm/s^2 against 3000.
  r.cycle(5, at(0.4));
  EXPECT_EQ(r.last, BridgeCore::Verdict::kFault);
  EXPECT_NE(r.core.fault_reason().find("would accelerate at 25000 mm/s^2, limit 3000"), std::string::npos)
      << r.core.fault_reason();
  for (int i = 0; i < 100; ++i) r.core.tick();
  EXPECT_EQ(r.core.commanded()[0], 0.0);
}

TEST(BridgeCore, SilenceMidMoveIsAControlledStopWithinTheStoppingDistance) {
  config::MachineConfig cfg = machine();
  Runner r(cfg);
  int64_t k = 0;
  const std::vector<double> ramp = smooth_stream(200.0, 2700.0, 100);
  for (; k < 100; ++k) r.cycle(k, at(ramp[static_cast<size_t>(k)]));
  ASSERT_FALSE(r.core.faulted()) << r.core.fault_reason();
  r.expect_limits("before the silence");
  const double x_at_silence = r.core.commanded()[0];
  const double v = r.core.velocity()[0];
  EXPECT_NEAR(v, 200.0, 0.01);
  r.reset_maxima();
  int ticks = 0;
  while (r.core.mode() != BridgeCore::Mode::kStopped && ticks < 10000) {
    r.idle(1);
    ++ticks;
  }
  ASSERT_EQ(r.core.mode(), BridgeCore::Mode::kStopped);
  EXPECT_NE(r.core.fault_reason().find("no setpoint for"), std::string::npos) << r.core.fault_reason();
  // The brake decelerates at stop_decel (2000 mm/s^2, under X's 3000) with the
  // jerk limit: finite differences within v, stop_decel and j.
  r.expect_limits("watchdog stop", cfg.stop_decel_mm_s2);
  r.print("watchdog stop");
  const double travelled = r.core.commanded()[0] - x_at_silence;
  const double d = cfg.stop_decel_mm_s2, jerk = cfg.axes[0].max_jerk_mm_s3;
  EXPECT_LE(travelled, v * v / (2 * d) + v * cfg.setpoint_timeout_s);
  EXPECT_GT(travelled, v * v / (2 * d));
  // The buffered setpoints and one bridged period (2.5 periods at most), then a
  // jerk-limited brake: v²/2d, plus v·d/2j while the deceleration builds up, plus
  // d/80² for the approach to standstill (the limiter's velocity loop, 80 1/s).
  const double bound = v * v / (2 * d) + v * d / (2 * jerk) + v * 2.5 * cfg.ipo_period_s + d / (80.0 * 80.0);
  EXPECT_LE(travelled, bound);
  EXPECT_EQ(r.core.velocity()[0], 0.0);
  EXPECT_EQ(r.core.acceleration()[0], 0.0);

  // Resume: engaged again where the axes stand, a new stream is followed within the limits.
  const AxisArray here = r.core.commanded();
  r.core.engage(here);
  r.reset_maxima();
  const std::vector<double> xs = smooth_stream(200.0, 2700.0, 120);
  for (int i = 0; i < 120; ++i, ++k) r.cycle(k, at(here[0] - xs[static_cast<size_t>(i)]));
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  EXPECT_NEAR(r.core.velocity()[0], -200.0, 0.01);
  r.expect_limits("resume after the watchdog stop");
  r.print("resume after the watchdog stop");
}

TEST(BridgeCore, FaultMidMoveIsAStopWithinTheLimits) {
  // Cruising at 200 mm/s on X and 100 mm/s down Z, then a setpoint beyond Z's
  // travel: the controlled stop keeps velocity, stop deceleration and jerk per axis.
  const config::MachineConfig cfg = machine();
  Runner r(cfg);
  r.start(at(0, 0, 0));
  const std::vector<double> xs = smooth_stream(200.0, 1800.0, 100);
  const std::vector<double> zs = smooth_stream(100.0, 1800.0, 100);
  int64_t k = 0;
  for (; k < 100; ++k) r.cycle(k, at(xs[static_cast<size_t>(k)], 0, -zs[static_cast<size_t>(k)]));
  ASSERT_FALSE(r.core.faulted()) << r.core.fault_reason();
  r.expect_limits("cruise");
  r.reset_maxima();
  r.cycle(k, at(xs[99] + 0.8, 0, 6.0));
  EXPECT_EQ(r.last, BridgeCore::Verdict::kFault);
  r.idle(2000);
  EXPECT_EQ(r.core.mode(), BridgeCore::Mode::kStopped);
  r.expect_limits("fault stop", cfg.stop_decel_mm_s2);
  r.print("fault stop");
}

TEST(BridgeCore, StalledLinkHoldsAControlledStopForAtMostTheSetpointTimeout) {
  // A fault mid-cruise, then the drives' link stalls for 10 ticks during the stop:
  // the stop's commands stand still meanwhile (the drives get them one tick after
  // another afterwards, no jump) and the stop ends exactly as one without the stall,
  // 10 ticks later. Holds are allowed for at most timing.setpoint_timeout_s per
  // stop: a link that stays stalled does not hold up the other axes' stop.
  const config::MachineConfig cfg = machine();
  const std::vector<double> xs = smooth_stream(200.0, 1800.0, 100);
  Runner plain(cfg), held(cfg);
  for (int64_t k = 0; k < 100; ++k) {
    plain.cycle(k, at(xs[static_cast<size_t>(k)]));
    held.cycle(k, at(xs[static_cast<size_t>(k)]));
  }
  plain.core.fault("test");
  held.core.fault("test");
  plain.idle(20);
  held.idle(20);
  const AxisArray before = held.core.commanded();
  EXPECT_EQ(held.hold(10), 10);
  EXPECT_EQ(held.core.commanded()[0], before[0]);
  plain.idle(1000);
  held.idle(1000);
  EXPECT_EQ(plain.core.mode(), BridgeCore::Mode::kStopped);
  EXPECT_EQ(held.core.mode(), BridgeCore::Mode::kStopped);
  held.expect_limits("a stop held 10 ticks for a stalled link", cfg.stop_decel_mm_s2);
  EXPECT_EQ(held.core.commanded()[0], plain.core.commanded()[0]);
  // The allowance: setpoint_timeout_s of holds in one stop, then the stop goes on.
  Runner r(cfg);
  for (int64_t k = 0; k < 100; ++k) r.cycle(k, at(xs[static_cast<size_t>(k)]));
  r.core.fault("test");
  const int allowed = r.hold(1000);
  EXPECT_EQ(allowed, static_cast<int>(std::floor(cfg.setpoint_timeout_s / cfg.servo_period_s + 1e-9)));
  EXPECT_FALSE(r.core.hold());
  std::printf("[ figures  ] a controlled stop held 10 ticks ends where the unheld one does (X %.6f mm); "
              "holds allowed per stop: %d ticks\n", held.core.commanded()[0], allowed);
}

TEST(BridgeCore, JoinsOnlyAStreamThatStartsWhereTheAxesStand) {
  Runner r(machine());
  r.cycle(0, at(10.0));
  EXPECT_EQ(r.last, BridgeCore::Verdict::kWaiting);
  EXPECT_TRUE(r.core.waiting());
  EXPECT_NE(r.core.waiting_reason().find("axis X at 10.0000 mm, it stands at 0.0000 mm"), std::string::npos)
      << r.core.waiting_reason();
  for (int64_t k = 1; k < 20; ++k) r.cycle(k, at(10.0));
  EXPECT_EQ(r.core.commanded()[0], 0.0);
  EXPECT_FALSE(r.core.faulted());
  // A stream from where the axes stand is followed.
  double x = 0, vel = 0;
  for (int64_t k = 20; k < 40; ++k) {
    vel = std::min(50.0, vel + 10.0);
    x += vel * 0.004;
    r.cycle(k, at(x));
  }
  EXPECT_FALSE(r.core.waiting());
  EXPECT_GT(r.core.commanded()[0], 0.5);
}

TEST(BridgeCore, DuplicateAndStaleSetpointsAreIgnored) {
  Runner r(machine());
  r.cycle(0, at(0));
  r.cycle(1, at(0.01));
  EXPECT_EQ(r.core.on_setpoint(1, at(0.01)), BridgeCore::Verdict::kIgnored);
  EXPECT_EQ(r.core.on_setpoint(0, at(0.0)), BridgeCore::Verdict::kIgnored);
  EXPECT_EQ(r.core.setpoint_gaps(), 0);
}

// The order of events of a live failure (integration.fault_reset, 1 suite run in
// 15): a publish failure stopped X from 200 mm/s by the watchdog; after the reset
// the bridge, engaged again, received a setpoint the interpolator had made before
// the fault (queued 2249 ms), close enough to where the axes stood to be joined,
// and then the next one, 0.061 mm on: "would accelerate at 3813 mm/s^2", a fault
// that was a jump of the axes on a real machine. Such a setpoint carries the
// engagement the interpolator had seen when it made it, and is dropped.
TEST(BridgeCore, ASetpointQueuedAcrossAFaultAndAResetIsDroppedNotFollowed) {
  const config::MachineConfig cfg = machine();
  const std::vector<double> xs = smooth_stream(200.0, 2700.0, 100);
  // `honest`: the stale setpoints carry the engagement of their time (the fix);
  // otherwise they look like setpoints of the new engagement (the bridge before it).
  auto run = [&](bool honest, Runner& r) {
    const StreamStamp old_stream{100, 1};
    r.core.engage(at(0), 1);
    int64_t k = 0;
    for (; k < 100; ++k) r.cycle(k, at(xs[static_cast<size_t>(k)]), true, old_stream);
    EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
    while (r.core.mode() != BridgeCore::Mode::kStopped) r.idle(1);  // the watchdog's controlled stop
    const AxisArray here = r.core.commanded();
    r.core.engage(here, 2);  // RESET: the drives enabled again
    r.reset_maxima();
    const StreamStamp queued = honest ? old_stream : StreamStamp{100, 2};
    r.cycle(k, here, true, queued);
    const BridgeCore::Verdict first = r.last;
    r.cycle(k + 1, at(here[0] + 0.061), true, queued);
    return std::make_pair(first, r.last);
  };
  Runner before(cfg);
  const auto [b1, b2] = run(false, before);
  EXPECT_EQ(b1, BridgeCore::Verdict::kAccepted);
  EXPECT_EQ(b2, BridgeCore::Verdict::kFault);
  EXPECT_NE(before.core.fault_reason().find("would accelerate"), std::string::npos) << before.core.fault_reason();

  Runner r(cfg);
  const auto [v1, v2] = run(true, r);
  EXPECT_EQ(v1, BridgeCore::Verdict::kStale);
  EXPECT_EQ(v2, BridgeCore::Verdict::kStale);
  EXPECT_EQ(r.core.stale_setpoints(), 2);
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  const AxisArray here = r.core.commanded();
  EXPECT_EQ(r.max_speed[0], 0.0);
  // The interpolator's new stream after its RESET (made after it saw engagement 2),
  // from where the drives stand, is joined and followed within the limits.
  const StreamStamp fresh{200, 2};
  const std::vector<double> ys = smooth_stream(100.0, 2000.0, 80);
  for (int64_t k = 0; k < 80; ++k) r.cycle(5000 + k, at(here[0] - ys[static_cast<size_t>(k)]), true, fresh);
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  EXPECT_EQ(r.core.stream(), 200);
  EXPECT_NEAR(r.core.velocity()[0], -100.0, 0.01);
  r.expect_limits("the new stream after the reset");
  // A late setpoint of the old stream now, even of this engagement, is dropped too.
  EXPECT_EQ(r.core.on_setpoint(5080, here, StreamStamp{100, 2}), BridgeCore::Verdict::kStale);
  EXPECT_EQ(r.core.stale_setpoints(), 3);
}

TEST(BridgeCore, ANewStreamIsJoinedOnlyOnceTheOldOneStands) {
  // The interpolator reset while the bridge follows (a RESET is taken only where the
  // path stands): its new stream (cycles from anywhere) is joined where the axes
  // stand, and not while the playback of the old one still moves.
  const config::MachineConfig cfg = machine();
  Runner r(cfg);
  r.core.engage(at(0), 7);
  const std::vector<double> xs = smooth_stream(100.0, 2000.0, 60);
  int64_t k = 0;
  for (; k < 60; ++k) r.cycle(k, at(xs[static_cast<size_t>(k)]), true, {1, 7});
  // The old stream comes to rest; the new one arrives with the playback still braking.
  double x = xs[59], v = (xs[59] - xs[58]) / 0.004;
  EXPECT_GT(v, 50.0);
  for (; v > 0; ++k) {
    v = std::max(0.0, v - 6.0);
    x += v * 0.004;
    r.cycle(k, at(x), true, {1, 7});
  }
  EXPECT_GT(std::fabs(r.core.velocity()[0]), 0.1);
  EXPECT_EQ(r.core.on_setpoint(0, at(x), {2, 7}), BridgeCore::Verdict::kWaiting);  // the playback moves
  EXPECT_NE(r.core.waiting_reason().find("still move"), std::string::npos);
  for (int j = 0; j < 100; ++j, ++k) r.cycle(k, at(x), true, {1, 7});  // standing until the RESET
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  for (int64_t j = 0; j < 5; ++j) r.cycle(j, at(x), true, {2, 7});
  EXPECT_EQ(r.core.stream(), 2);
  EXPECT_EQ(r.core.last_cycle(), 4);
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  EXPECT_EQ(r.core.on_setpoint(k, at(x), {1, 7}), BridgeCore::Verdict::kStale);
  r.expect_limits("a new stream after the old one stood");
}

TEST(BridgeCore, AStreamThatBeginsWhereAnotherLeftOffMovingIsAFault) {
  // The interpolator killed mid-move and started again before the setpoint watchdog's
  // timeout (or a second interpolator on the channel): the new process's stream
  // stands (at its own start, here where the axes will come to rest). Following it
  // would turn a dead interpolator into a brake and a silent hand-over, with no fault
  // and no RESET. It is a controlled stop within the limits and a fault that names it.
  const config::MachineConfig cfg = machine();
  for (const int silent_cycles : {0, 3, 8}) {
    SCOPED_TRACE("new stream after " + std::to_string(silent_cycles) + " silent cycles");
    Runner r(cfg);
    r.core.engage(at(0), 7);
    const std::vector<double> xs = smooth_stream(100.0, 2000.0, 60);
    for (int64_t k = 0; k < 60; ++k) r.cycle(k, at(xs[static_cast<size_t>(k)]), true, {1, 7});
    for (int j = 0; j < silent_cycles; ++j) r.cycle(0, at(0), false);  // the old one silent
    const double x_then = r.core.commanded()[0];
    EXPECT_EQ(r.core.on_setpoint(0, at(x_then + 5.0), {2, 7}), BridgeCore::Verdict::kFault);
    ASSERT_TRUE(r.core.faulted());
    EXPECT_NE(r.core.fault_reason().find("stream 2 began where stream 1 had left off moving (axis X at"),
              std::string::npos)
        << r.core.fault_reason();
    for (int j = 0; j < 100; ++j) r.cycle(j, at(x_then + 5.0), true, {2, 7});  // neither stream is followed
    EXPECT_EQ(r.core.mode(), BridgeCore::Mode::kStopped);
    EXPECT_EQ(r.core.velocity()[0], 0.0);
    const double x_rest = r.core.commanded()[0];
    // The jerk-limited stop from 100 mm/s: v^2/(2a) + v a/(2j), plus one period of reaction.
    const double a = std::min(cfg.stop_decel_mm_s2, cfg.axes[0].max_accel_mm_s2), j = cfg.axes[0].max_jerk_mm_s3;
    const double stop = 100.0 * 100.0 / (2 * a) + 100.0 * a / (2 * j) + 100.0 * cfg.ipo_period_s;
    EXPECT_GT(x_rest, x_then);
    EXPECT_LT(x_rest, x_then + stop) << "a controlled stop, not a jump to the new stream";
    r.expect_limits("the stop for a stream that broke off moving");
    std::printf("[ figures  ] after %d silent cycles: stopped %.3f mm past the fault (bound %.3f mm)\n",
                silent_cycles, x_rest - x_then, stop);
  }
}

TEST(BridgeCore, AJoinsStepIsNotTheOldStreamMoving) {
  // The soak (epoch 1, after a route cut): cnc-ctl --do reset enabled the drives, the
  // faulted interpolator's standing stream was joined with a step (Z 31 um from where
  // Z stood after the bridge's own stop: within the join's a*T^2), and its RESET's new
  // stream came 4 ms later. The join's step read as the old stream "moving at 7.76
  // mm/s" and the reset faulted. One setpoint of a stream is no motion of it.
  const config::MachineConfig cfg = machine();
  Runner r(cfg);
  r.start(at(100, 50, -10));
  r.core.engage(at(100, 50, -10), 9);
  r.cycle(74497, at(100, 50, -10.031), true, {1, 9});
  ASSERT_EQ(r.last, BridgeCore::Verdict::kAccepted) << r.core.waiting_reason();
  for (int64_t k = 0; k < 40; ++k) {
    r.cycle(74498 + k, at(100, 50, -10.031), true, {2, 9});
    ASSERT_FALSE(r.core.faulted()) << r.core.fault_reason();
  }
  EXPECT_EQ(r.core.stream(), 2);
  EXPECT_NEAR(r.core.commanded()[2], -10.031, 1e-3);  // the limiter settles the step within 1 um
  r.expect_limits("a RESET's stream right after a join");
}

TEST(BridgeCore, ANewStreamAfterTheOldOneWentQuietIsJoined) {
  // fault_reset under two busy loops (run 13 of a 50-run): ENABLE engaged the bridge, two
  // setpoints of the interpolator's standing stream (from before its RESET) were
  // followed, then the RESET's new stream came later than the playback's one-period
  // allowance. The playback had begun to brake, from rest, and the new stream waited
  // for "the old one to stand" on that flag, which only a setpoint of the old stream
  // clears: "no setpoint for 51 ms", a fault after a reset that had done nothing wrong.
  const config::MachineConfig cfg = machine();
  Runner r(cfg);
  r.start(at(212.0316));
  r.core.engage(at(212.0316), 3);
  r.cycle(3348, at(212.0316), true, {10, 3});
  r.cycle(3349, at(212.0316), true, {10, 3});
  ASSERT_EQ(r.last, BridgeCore::Verdict::kAccepted);
  for (int j = 0; j < 6; ++j) r.cycle(0, at(0), false);  // 24 ms without a setpoint: braking, from rest
  EXPECT_GT(r.core.starved_ticks(), 0);
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  for (int64_t j = 0; j < 50; ++j) {
    r.cycle(3350 + j, at(212.0316), true, {11, 3});
    ASSERT_EQ(r.last, BridgeCore::Verdict::kAccepted) << "setpoint " << j << " of the new stream: "
                                                      << r.core.waiting_reason();
  }
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  EXPECT_EQ(r.core.stream(), 11);
  // And the new stream is followed: a move from there keeps the limits.
  const std::vector<double> xs = smooth_stream(100.0, 2000.0, 60);
  for (int64_t j = 0; j < 60; ++j) r.cycle(3400 + j, at(212.0316 - xs[static_cast<size_t>(j)]), true, {11, 3});
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  EXPECT_NEAR(r.core.velocity()[0], -100.0, 0.01);
  r.expect_limits("a new stream after the old one went quiet");
}

TEST(BridgeCore, RandomisedStreamsKeepTheLimits) {
  const config::MachineConfig cfg = machine();
  std::mt19937 rng(20240601);
  std::uniform_real_distribution<double> u(0, 1);
  for (int run = 0; run < 200; ++run) {
    Runner r(cfg);
    AxisArray p{}, v{};
    p[2] = -75;  // mid-travel of Z
    r.start(p);
    int64_t k = 0;
    for (int i = 0; i < 5; ++i, ++k) r.cycle(k, p);  // an idle stream first: the bridge joins it
    for (int step = 0; step < 400; ++step, ++k) {
      for (int a = 0; a < 3; ++a) {
        const auto& ax = cfg.axes[a];
        // A random acceleration within 90 % of the limit, velocity within 90 %.
        double acc = (u(rng) * 2 - 1) * 0.9 * ax.max_accel_mm_s2;
        // Turn around well before the travel ends.
        if (p[a] > ax.max_mm - 50 && v[a] > 0) acc = -0.9 * ax.max_accel_mm_s2;
        if (p[a] < ax.min_mm + 50 && v[a] < 0) acc = 0.9 * ax.max_accel_mm_s2;
        v[a] = std::clamp(v[a] + acc * 0.004, -0.9 * ax.max_velocity_mm_s, 0.9 * ax.max_velocity_mm_s);
        p[a] += v[a] * 0.004;
      }
      const double roll = u(rng);
      if (roll < 0.03) continue;                             // lost
      if (roll < 0.04) r.idle(3);                            // 0.75 periods late
      r.cycle(k, p);
    }
    ASSERT_FALSE(r.core.faulted()) << "run " << run << ": " << r.core.fault_reason();
    // The stream's acceleration jumps at random every cycle (far over the jerk
    // limit): the fine setpoints keep v, a and j all the same.
    r.expect_limits(("random run " + std::to_string(run)).c_str());
    for (int a = 0; a < 3; ++a) {
      ASSERT_TRUE(std::isfinite(r.core.commanded()[a]));
      EXPECT_LE(r.max_speed[a], cfg.axes[a].max_velocity_mm_s * 1.02) << "run " << run << " axis " << a;
      EXPECT_GE(r.core.commanded()[a], cfg.axes[a].min_mm);
      EXPECT_LE(r.core.commanded()[a], cfg.axes[a].max_mm);
    }
  }
}

}  // namespace
}  // namespace cnc::bridge
