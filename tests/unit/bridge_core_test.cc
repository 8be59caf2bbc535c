// The drive bridge core: fine interpolation (seed 001's two steps), a missed or
// late setpoint bridged, the limits (travel, velocity, acceleration) faulting
// before anything moves, the watchdog's controlled stop, joining a stream only
// where the axes stand; and a randomised stream (fixed seed) never producing a
// NaN or a command beyond the limits.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

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
  }
  // One coarse cycle: the setpoint (unless skipped), then N servo ticks.
  void cycle(int64_t k, const AxisArray& p, bool deliver = true) {
    if (deliver) last = core.on_setpoint(k, p);
    idle(n);
  }
  // Servo ticks with no new setpoint.
  void idle(int ticks) {
    for (int i = 0; i < ticks; ++i) {
      const AxisArray c = core.tick();
      for (int a = 0; a < 3; ++a) {
        const double v = (c[a] - prev[a]) / cfg.servo_period_s;
        max_speed[a] = std::max(max_speed[a], std::fabs(v));
        max_dv[a] = std::max(max_dv[a], std::fabs(v - prev_v[a]));
        prev_v[a] = v;
      }
      prev = c;
      trace.push_back(c[0]);
    }
  }
  config::MachineConfig cfg;
  BridgeCore core;
  int n;
  BridgeCore::Verdict last = BridgeCore::Verdict::kIgnored;
  AxisArray prev{};
  AxisArray prev_v{};
  AxisArray max_speed{};
  AxisArray max_dv{};
  std::vector<double> trace;
};

TEST(BridgeCore, FineInterpolationIsLinearBetweenCoarseSetpointsTwoPeriodsLate) {
  Runner r(machine());
  const double v = 100.0;  // mm/s: 0.4 mm per 4 ms cycle, 0.1 mm per 1 ms tick
  // Accelerate within the limit first (3000 mm/s^2 -> 12 mm/s per cycle).
  double x = 0, vel = 0;
  int64_t k = 0;
  for (; vel < v; ++k) {
    vel = std::min(v, vel + 10.0);
    x += vel * 0.004;
    r.cycle(k, at(x));
    ASSERT_EQ(r.last, BridgeCore::Verdict::kAccepted) << r.core.fault_reason();
  }
  for (int i = 0; i < 50; ++i, ++k) {
    x += v * 0.004;
    r.cycle(k, at(x));
  }
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
}

TEST(BridgeCore, SingleMissedSetpointIsBridged) {
  Runner r(machine());
  double x = 0, vel = 0;
  int64_t k = 0;
  for (; k < 40; ++k) {
    vel = std::min(50.0, vel + 10.0);
    x += vel * 0.004;
    r.cycle(k, at(x), k != 30);  // cycle 30 is lost
  }
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  EXPECT_EQ(r.core.setpoint_gaps(), 1);
  // The commanded speed stays at the stream's (50 mm/s, within the playback rate's
  // 5 %) with no jump across the gap: the velocity changes by no more than one
  // coarse step's change (10 mm/s) per tick.
  EXPECT_LE(r.max_speed[0], 50.0 * 1.05);
  EXPECT_LE(r.max_dv[0], 10.0 + 1.0);
}

TEST(BridgeCore, LateSetpointIsBridgedOnTheLastVelocity) {
  Runner r(machine());
  double x = 0, vel = 0;
  int64_t k = 0;
  for (; k < 30; ++k) {
    vel = std::min(50.0, vel + 10.0);
    x += vel * 0.004;
    r.cycle(k, at(x));
  }
  r.max_dv = {};
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
}

TEST(BridgeCore, StreamBackBeforeTheTimeoutIsRejoinedWithinTheLimits) {
  Runner r(machine());
  double x = 0, vel = 0;
  int64_t k = 0;
  for (; k < 30; ++k) {
    vel = std::min(50.0, vel + 10.0);
    x += vel * 0.004;
    r.cycle(k, at(x));
  }
  r.idle(28);  // seven periods late (28 ms, under the 50 ms timeout): past the buffer and the bridging
  EXPECT_GT(r.core.starved_ticks(), 0);
  for (int i = 0; i < 30; ++i, ++k) {
    x += vel * 0.004;
    r.cycle(k, at(x));
  }
  EXPECT_FALSE(r.core.faulted()) << r.core.fault_reason();
  EXPECT_EQ(r.core.rejoins(), 1);
  EXPECT_LE(r.max_speed[0], 250.0 * 1.01);
  // Back on the stream: steady at 50 mm/s again.
  EXPECT_NEAR(r.core.velocity()[0], 50.0, 3.0);
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
  double x = 0, vel = 0;
  int64_t k = 0;
  for (; k < 100; ++k) {
    vel = std::min(200.0, vel + 11.0);
    x += vel * 0.004;
    r.cycle(k, at(x));
  }
  ASSERT_FALSE(r.core.faulted()) << r.core.fault_reason();
  const double x_at_silence = r.core.commanded()[0];
  const double v = r.core.velocity()[0];
  EXPECT_NEAR(v, 200.0, 0.01);
  int ticks = 0;
  while (r.core.mode() != BridgeCore::Mode::kStopped && ticks < 10000) {
    r.core.tick();
    ++ticks;
  }
  ASSERT_EQ(r.core.mode(), BridgeCore::Mode::kStopped);
  EXPECT_NE(r.core.fault_reason().find("no setpoint for"), std::string::npos) << r.core.fault_reason();
  const double travelled = r.core.commanded()[0] - x_at_silence;
  // The buffered setpoint, one bridged period, then the brake at stop_decel.
  const double bound = v * v / (2 * cfg.stop_decel_mm_s2) + v * cfg.setpoint_timeout_s;
  EXPECT_LE(travelled, bound);
  EXPECT_GT(travelled, v * v / (2 * cfg.stop_decel_mm_s2));
  EXPECT_LE(travelled, v * v / (2 * cfg.stop_decel_mm_s2) + v * 4 * cfg.ipo_period_s + 1e-6);
  EXPECT_EQ(r.core.velocity()[0], 0.0);
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
