// The core's spindle-synchronised moves. G33: it starts at rest at the spindle's
// index, speeds up to the spindle's rate times the pitch, locks its phase there and
// then follows the spindle's position as predicted for the cycle its setpoint is
// played; a feed hold waits for its end, a STOP does not, and a spindle feedback
// that stops arriving stops the program naming it. G33.1: the tap follows the
// spindle down, through its reversal and back up, stops on its start, and a STOP in
// the hole stops the spindle with the tap following. The dry run (auto_resume_pauses)
// follows a spindle with the VFD's first-order response to its command.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/interpolator.h"
#include "common/program/block.h"

namespace cnc::interp {
namespace {

config::MachineConfig load() {
  config::MachineConfig cfg =
      config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3_spindle.yaml");
  cfg.spindle.encoder_counts_per_rev = 4096;
  return cfg;
}

program::Block spindle_on(int64_t index, const std::vector<double>& at, double rpm) {
  program::Block b;
  b.index = index;
  b.kind = program::BlockKind::kEvent;
  b.start = b.end = at;
  b.event.kind = program::EventKind::kSpindle;
  b.event.number = 1;
  b.event.value = rpm;
  return b;
}

// LOAD, then blocks 0 and 1: M3 S<rpm> and G4 P3 (the dry run's spindle gets to speed).
void load_spindle_start(Interpolator& core, double rpm) {
  core.apply_command({Command::Kind::kLoad, 1.0, {}});
  const std::vector<double> o{0, 0, 0};
  ASSERT_TRUE(core.apply_block(spindle_on(0, o, rpm))) << core.last_refusal();
  program::Block dwell;
  dwell.index = 1;
  dwell.kind = program::BlockKind::kDwell;
  dwell.start = dwell.end = o;
  dwell.dwell_s = 3;
  ASSERT_TRUE(core.apply_block(dwell)) << core.last_refusal();
}

// M3 S<rpm>, G4 P3, G33 Z<z_end> K<pitch>, [G0 Z0,] END.
void load_thread(Interpolator& core, double rpm, double pitch, double z_end, bool rapid_back = false) {
  const std::vector<double> o{0, 0, 0};
  load_spindle_start(core, rpm);
  program::Block g33;
  g33.index = 2;
  g33.kind = program::BlockKind::kLine;
  g33.start = o;
  g33.end = {0, 0, z_end};
  g33.sync = program::kSyncG33;
  g33.sync_pitch_mm = pitch;
  g33.feed_mm_per_min = pitch * rpm;
  g33.spindle_rpm = rpm;
  ASSERT_TRUE(core.apply_block(g33)) << core.last_refusal();
  program::Block end;
  end.index = 3;
  end.kind = program::BlockKind::kEnd;
  end.start = end.end = g33.end;
  if (rapid_back) {
    program::Block g0;
    g0.index = 3;
    g0.kind = program::BlockKind::kRapid;
    g0.start = g33.end;
    g0.end = o;
    ASSERT_TRUE(core.apply_block(g0)) << core.last_refusal();
    end.index = 4;
    end.start = end.end = o;
  }
  ASSERT_TRUE(core.apply_block(end)) << core.last_refusal();
  core.apply_command({Command::Kind::kStart, 1.0, {}});
}

struct Trace {
  std::vector<double> z;         // setpoint Z per cycle
  std::vector<int> phase;        // SyncMove::Phase per cycle
  std::vector<double> rev;       // the spindle's true position when the cycle's setpoint is played
};

// Finite-difference velocity, acceleration and jerk of a trace against limits.
void expect_within_limits(const std::vector<double>& z, double T, double v_max, double a_max, double j_max) {
  double vm = 0, am = 0, jm = 0;
  for (size_t i = 3; i < z.size(); ++i) {
    const double v = (z[i] - z[i - 1]) / T, v1 = (z[i - 1] - z[i - 2]) / T, v2 = (z[i - 2] - z[i - 3]) / T;
    const double a = (v - v1) / T, a1 = (v1 - v2) / T;
    vm = std::max(vm, std::fabs(v));
    am = std::max(am, std::fabs(a));
    jm = std::max(jm, std::fabs((a - a1) / T));
  }
  EXPECT_LE(vm, v_max * (1 + 1e-9));
  EXPECT_LE(am, a_max * (1 + 1e-6));
  EXPECT_LE(jm, j_max * (1 + 1e-6));
}

TEST(InterpolatorSync, TheDryRunFollowsItsSpindleFromTheIndex) {
  const config::MachineConfig cfg = load();
  Interpolator core(cfg);
  core.set_auto_resume_pauses(true);
  const double rpm = 600, pitch = 1.5, T = cfg.ipo_period_s;  // 25 mm/s along -Z
  load_thread(core, rpm, pitch, -30);
  std::vector<double> z;
  int64_t lock_cycle = -1, start_cycle = -1;
  double max_track_err = 0;
  for (int i = 0; i < 6000 && core.state() != RunState::kDone; ++i) {
    const double rev = core.dry_run_spindle_rev();  // where it is when this cycle's setpoint is played
    const Setpoint& sp = core.step();
    z.push_back(sp.position_mm[2]);
    if (start_cycle < 0 && sp.position_mm[2] != 0) {
      start_cycle = sp.cycle;
      EXPECT_LT(rev - std::floor(rev), rpm / 60 * T + 1e-9) << "the move starts within a cycle of the index";
    }
    if (core.sync_move().phase == SyncMove::kTrack) {
      if (lock_cycle < 0) lock_cycle = sp.cycle;
      // Away from the end's brake, and once the phase from the index is made up, the
      // path is where the spindle says.
      if (-sp.position_mm[2] < 30 - 3.0 && sp.cycle - lock_cycle >= SyncMove::kSettleCycles) {
        const double want = pitch * (rev - core.sync_move().lock_rev);
        max_track_err = std::max(max_track_err, std::fabs(want - (-sp.position_mm[2])));
      }
    }
  }
  ASSERT_EQ(core.state(), RunState::kDone);
  ASSERT_GT(start_cycle, 0);
  ASSERT_GT(lock_cycle, start_cycle);
  std::printf("dry run: locked %.3f s after the index, largest error %.2e mm\n",
              static_cast<double>(lock_cycle - start_cycle) * T, max_track_err);
  // The dry run's spindle still speeds up (0.5 s time constant): followed within a micrometre.
  // The phase taken from the index (up to a cycle of the spindle's turn, 0.1 mm here)
  // is made up within kSettleCycles to a few hundredths of a micrometre.
  EXPECT_LT(max_track_err, 1e-4);
  EXPECT_LT(core.sync_move().max_error_mm, 1e-4);
  EXPECT_NEAR(z.back(), -30, 1e-9);
  EXPECT_LT(static_cast<double>(lock_cycle - start_cycle) * T, 0.15);
  expect_within_limits(z, T, 150, 2000, 40000);
}

// A live spindle: samples of its position each cycle, read by the bridge 2-4 cycles
// before the cycle the core computes (jitter), quantised by a 4096-count encoder,
// the spindle's speed rippling by 1 %.
TEST(InterpolatorSync, ALiveSpindleIsFollowedWithinMicrometres) {
  const config::MachineConfig cfg = load();
  Interpolator core(cfg);
  const double rpm = 600, pitch = 1.5, T = cfg.ipo_period_s;
  load_thread(core, rpm, pitch, -30);
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> lag(2, 4);
  auto true_rev = [&](double t) { return rpm / 60 * t + 0.01 * std::sin(2 * M_PI * 3 * t) / (2 * M_PI * 3) * 10; };
  auto true_rps = [&](double t) { return rpm / 60 * (1 + 0.01 * std::cos(2 * M_PI * 3 * t)); };
  std::vector<double> z;
  double max_err = 0;
  bool at_speed_sent = false;
  for (int i = 0; i < 9000 && core.state() != RunState::kDone; ++i) {
    const int64_t n = core.cycle();
    if (core.spindle_waiting() && !at_speed_sent) {
      Command c;
      c.kind = Command::Kind::kSpindleAtSpeed;
      c.value = static_cast<double>(core.spindle().seq);
      ASSERT_TRUE(core.apply_command(c));
      at_speed_sent = true;
    }
    if (core.wants_spindle_position()) {
      const double ps = static_cast<double>(n - lag(rng));
      Command c;
      c.kind = Command::Kind::kSpindlePosition;
      c.position_mm[0] = std::floor(true_rev(ps * T) * 4096) / 4096;
      c.position_mm[1] = true_rps(ps * T);
      c.position_mm[2] = ps;
      ASSERT_TRUE(core.apply_command(c));
    }
    const Setpoint& sp = core.step();
    z.push_back(sp.position_mm[2]);
    if (core.sync_move().phase == SyncMove::kTrack && -sp.position_mm[2] < 27 &&
        sp.cycle - core.sync_move().lock_cycle >= SyncMove::kSettleCycles) {
      const double want = pitch * (true_rev(static_cast<double>(sp.cycle) * T) - core.sync_move().lock_rev);
      max_err = std::max(max_err, std::fabs(want + sp.position_mm[2]));
    }
  }
  ASSERT_EQ(core.state(), RunState::kDone);
  EXPECT_NEAR(z.back(), -30, 1e-9);
  // The prediction's error over 4 cycles of a 1 % ripple at 3 Hz, plus a count.
  std::printf("live spindle: largest synchronisation error %.4f um while tracking\n", max_err * 1e3);
  EXPECT_LT(max_err, 0.005) << "synchronisation error, mm";
  EXPECT_LT(core.sync_move().max_error_mm, 0.005);
  expect_within_limits(z, T, 150, 2000, 40000);
}

TEST(InterpolatorSync, ALostSpindleFeedbackStopsTheProgramNamingIt) {
  const config::MachineConfig cfg = load();
  Interpolator core(cfg);
  load_thread(core, 600, 1.5, -30);
  Command at;
  at.kind = Command::Kind::kSpindleAtSpeed;
  at.value = 1;
  std::string failure;
  for (int i = 0; i < 4000 && core.state() != RunState::kIdle; ++i) {
    if (core.spindle_waiting()) {
      ASSERT_TRUE(core.apply_command(at));
    }
    // Samples for 3.6 s (3 s of them in the dwell), then none.
    if (core.wants_spindle_position() && i < 900) {
      Command c;
      c.kind = Command::Kind::kSpindlePosition;
      c.position_mm[0] = 10.0 * i * cfg.ipo_period_s;
      c.position_mm[1] = 10.0;
      c.position_mm[2] = static_cast<double>(core.cycle());
      ASSERT_TRUE(core.apply_command(c));
    }
    core.step();
    if (failure.empty()) failure = core.take_plan_failure();
  }
  EXPECT_EQ(core.state(), RunState::kIdle);
  EXPECT_NE(failure.find("block 2: the spindle's measured position stopped arriving"), std::string::npos) << failure;
  const double z = core.last().position_mm[2];
  EXPECT_LT(z, -0.5) << "it had started";
  EXPECT_GT(z, -30) << "and stopped before the end";
}

TEST(InterpolatorSync, AFeedHoldWaitsForTheEndOfTheThreadAndAStopDoesNot) {
  const config::MachineConfig cfg = load();
  for (const Command::Kind k : {Command::Kind::kHold, Command::Kind::kStop}) {
    Interpolator core(cfg);
    core.set_auto_resume_pauses(true);
    load_thread(core, 600, 1.5, -30, true);
    bool sent = false;
    for (int i = 0; i < 6000; ++i) {
      if (!sent && core.last().position_mm[2] < -5) {
        ASSERT_TRUE(core.apply_command({k, 1.0, {}}));
        sent = true;
      }
      core.step();
    }
    ASSERT_TRUE(sent);
    if (k == Command::Kind::kHold) {
      EXPECT_NEAR(core.last().position_mm[2], -30, 1e-9) << "the hold took effect at the thread's end";
      EXPECT_EQ(core.state(), RunState::kHeld);
    } else {
      EXPECT_GT(core.last().position_mm[2], -10) << "a STOP brakes inside the thread";
      EXPECT_EQ(core.state(), RunState::kIdle);
    }
  }
}

// M3 S600, G4 P3, G33.1 Z-20 K1.25, G0 X10, END: the tap follows the dry run's spindle
// (a first-order response, spindle.sim.time_constant_s) down, through the reversal
// and back up, stops on its start, and the spindle turns forward again.
void load_tap(Interpolator& core, double rpm, double pitch, double depth, double scale) {
  const std::vector<double> o{0, 0, 0};
  load_spindle_start(core, rpm);
  program::Block tap;
  tap.index = 2;
  tap.kind = program::BlockKind::kLine;
  tap.start = o;
  tap.end = {0, 0, -depth};
  tap.sync = program::kSyncRigidTap;
  tap.sync_pitch_mm = pitch;
  tap.tap_retract_scale = scale;
  tap.feed_mm_per_min = pitch * rpm;
  ASSERT_TRUE(core.apply_block(tap)) << core.last_refusal();
  program::Block g0;
  g0.index = 3;
  g0.kind = program::BlockKind::kRapid;
  g0.start = o;  // a rigid tap ends where it began
  g0.end = {10, 0, 0};
  ASSERT_TRUE(core.apply_block(g0)) << core.last_refusal();
  program::Block end;
  end.index = 4;
  end.kind = program::BlockKind::kEnd;
  end.start = end.end = g0.end;
  ASSERT_TRUE(core.apply_block(end)) << core.last_refusal();
  core.apply_command({Command::Kind::kStart, 1.0, {}});
}

TEST(InterpolatorSync, ARigidTapFollowsTheSpindleThroughItsReversalAndBack) {
  const config::MachineConfig cfg = load();
  const double tau = cfg.spindle.sim.time_constant_s, T = cfg.ipo_period_s;
  for (const double scale : {1.0, 2.0}) {
    Interpolator core(cfg);
    core.set_auto_resume_pauses(true);
    const double rpm = 600, pitch = 1.25, depth = 20;
    load_tap(core, rpm, pitch, depth, scale);
    std::vector<double> z;
    double max_err = 0, deepest = 0;
    int reversals = 0, last_dir = 1, dir_after = 0;
    bool tracked = false;
    for (int i = 0; i < 10000 && core.state() != RunState::kDone; ++i) {
      const double rev = core.dry_run_spindle_rev();
      const Setpoint& sp = core.step();
      z.push_back(sp.position_mm[2]);
      deepest = std::min(deepest, sp.position_mm[2]);
      if (core.spindle().direction != last_dir && core.spindle().direction != 0) {
        ++reversals;
        last_dir = core.spindle().direction;
      }
      if (sp.position_mm[0] > 0 && dir_after == 0) dir_after = core.spindle().direction;
      if (core.sync_move().phase == SyncMove::kTrack &&
          sp.cycle - core.sync_move().lock_cycle >= SyncMove::kSettleCycles) {
        tracked = true;
        max_err = std::max(max_err, std::fabs(pitch * (rev - core.sync_move().lock_rev) + sp.position_mm[2]));
      }
    }
    ASSERT_EQ(core.state(), RunState::kDone);
    EXPECT_TRUE(tracked);
    EXPECT_EQ(reversals, 2) << "reversed at the depth, forward again at the start";
    EXPECT_EQ(dir_after, 1) << "the spindle turns forward again after the tap";
    EXPECT_EQ(core.last().position_mm[0], 10.0);
    EXPECT_EQ(core.last().position_mm[2], 0.0) << "back on its start, then the rapid";
    // Past the depth by what the spindle lags behind its command's ramp (begun so that
    // the command stands at the depth): with the VFD's first-order response, about what
    // a step of the command would leave (the step model: w(t) = -s w0 + (1 + s) w0
    // e^(-t/tau) turns (1 + s) w0 tau (1 - e^(-t0/tau)) - s w0 t0 more, t0 = tau ln((1 + s) / s)).
    const double w0 = rpm / 60, t0 = tau * std::log((1 + scale) / scale);
    const double over = pitch * ((1 + scale) * w0 * tau * (1 - std::exp(-t0 / tau)) - scale * w0 * t0);
    std::printf("rigid tap (retract x%.0f): depth %.3f mm past the programmed %.0f (a step of the command: %.3f), "
                "largest following error %.2e mm\n",
                scale, -deepest - depth, depth, over, max_err);
    EXPECT_GT(-deepest - depth, 0.5 * over);
    EXPECT_LT(-deepest - depth, 1.4 * over);
    EXPECT_NEAR(core.sync_move().overshoot_mm, -deepest - depth, 1e-9);
    EXPECT_LT(max_err, 1e-4) << "the tap follows the spindle's position while it tracks";
    expect_within_limits(z, T, 150, 2000, 40000);
  }
}

// A live spindle for a tap: a first-order response (tau 0.5 s) to what the core
// commands, its samples 2-4 cycles old with their stamps scattered by up to +-0.5 ms
// (a quarter cycle), counted at 131072 per revolution. A tracker that stepped onto
// each predicted position rang on such samples until Z ran at its velocity limit.
TEST(InterpolatorSync, ARigidTapFollowsALiveSpindleThroughItsReversal) {
  const config::MachineConfig cfg = load();
  Interpolator core(cfg);
  const double T = cfg.ipo_period_s, tau = 0.5, pitch = 1.25;
  load_tap(core, 600, pitch, 20, 1.0);
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> lag(2, 4);
  std::uniform_real_distribution<double> scatter(-0.125, 0.125);
  // The spindle's history, one entry per cycle: revolutions and rev/s at cycle n.
  std::vector<double> rev{0}, rps{0};
  std::vector<double> z;
  double max_err = 0, deepest = 0;
  for (int i = 0; i < 12000 && core.state() != RunState::kDone; ++i) {
    const int64_t n = core.cycle();
    if (core.spindle_waiting()) {
      Command at;
      at.kind = Command::Kind::kSpindleAtSpeed;
      at.value = static_cast<double>(core.spindle().seq);
      ASSERT_TRUE(core.apply_command(at));
    }
    if (core.wants_spindle_position() && n >= 5) {
      const int64_t k = n - lag(rng);
      const double stamp = static_cast<double>(k) + scatter(rng);  // when the drive really read it
      const double r = rev[static_cast<size_t>(k)] + rps[static_cast<size_t>(k)] * (stamp - static_cast<double>(k)) * T;
      Command c;
      c.kind = Command::Kind::kSpindlePosition;
      c.position_mm[0] = std::floor(r * 131072) / 131072;
      c.position_mm[1] = rps[static_cast<size_t>(k)];
      c.position_mm[2] = static_cast<double>(k);  // the bridge's stamp: its tick, not the read
      ASSERT_TRUE(core.apply_command(c));
    }
    const Setpoint& sp = core.step();
    z.push_back(sp.position_mm[2]);
    deepest = std::min(deepest, sp.position_mm[2]);
    if (core.sync_move().phase == SyncMove::kTrack && static_cast<size_t>(sp.cycle) < rev.size() &&
        sp.cycle - core.sync_move().lock_cycle >= SyncMove::kSettleCycles)
      max_err = std::max(max_err, std::fabs(pitch * (rev[static_cast<size_t>(sp.cycle)] - core.sync_move().lock_rev) +
                                            sp.position_mm[2]));
    // The spindle answers the command of this cycle.
    const double cmd = core.spindle().direction * core.spindle().rpm / 60.0;
    const double w = cmd + (rps.back() - cmd) * std::exp(-T / tau);
    rev.push_back(rev.back() + 0.5 * (rps.back() + w) * T);
    rps.push_back(w);
  }
  ASSERT_EQ(core.state(), RunState::kDone);
  std::printf("rigid tap on a live spindle: largest synchronisation error %.2f um, %.3f mm past the depth\n",
              max_err * 1e3, -deepest - 20);
  // Through the reversal the samples are 2-4 cycles old: predicted with the samples'
  // acceleration and the reversal commanded as a ramp within the tap's limits, 3.1 um
  // (a step of the command, predicted with the samples' speed alone: 17.6 um).
  EXPECT_LT(max_err, 0.006);
  // A step of the command would leave 1.534 revolutions (tau 0.5 s, 10 rev/s): 1.917 mm.
  EXPECT_GT(-deepest - 20, 1.0);
  EXPECT_LT(-deepest - 20, 1.4 * 1.917);
  EXPECT_EQ(core.last().position_mm[2], 0.0);
  expect_within_limits(z, T, 150, 2000, 40000);
}

TEST(InterpolatorSync, AStopInTheHoleStopsTheSpindleAndTheTapFollowsItToRest) {
  const config::MachineConfig cfg = load();
  Interpolator core(cfg);
  core.set_auto_resume_pauses(true);
  load_tap(core, 600, 1.25, 20, 1.0);
  bool sent = false;
  double z_at_stop = 0;
  std::vector<double> z;
  for (int i = 0; i < 6000 && core.state() != RunState::kIdle; ++i) {
    if (!sent && core.last().position_mm[2] < -10) {
      ASSERT_TRUE(core.apply_command({Command::Kind::kStop, 1.0, {}}));
      sent = true;
      z_at_stop = core.last().position_mm[2];
    }
    z.push_back(core.step().position_mm[2]);
  }
  ASSERT_TRUE(sent);
  EXPECT_EQ(core.state(), RunState::kIdle);
  EXPECT_EQ(core.spindle().direction, 0);
  // The spindle (tau 0.5 s at 10 rev/s) turns 5 more revolutions: 6.25 mm.
  const double tau = cfg.spindle.sim.time_constant_s;
  EXPECT_NEAR(z_at_stop - core.last().position_mm[2], 1.25 * 10 * tau, 0.15);
  expect_within_limits(z, cfg.ipo_period_s, 150, 2000, 40000);
}

// M3 S600, M19 R90 P1 [Q2], M3: the spindle stands oriented at 90 degrees, turning
// clockwise to it; with a Q the path waits until the drive reports that change done.
TEST(InterpolatorSync, M19OrientsTheSpindleAndItsQWaitsForIt) {
  const config::MachineConfig cfg = load();
  for (const double q : {0.0, 2.0}) {
    Interpolator core(cfg);
    core.apply_command({Command::Kind::kLoad, 1.0, {}});
    const std::vector<double> o{0, 0, 0};
    ASSERT_TRUE(core.apply_block(spindle_on(0, o, 600)));
    program::Block m19;
    m19.index = 1;
    m19.kind = program::BlockKind::kEvent;
    m19.start = m19.end = o;
    m19.event.kind = program::EventKind::kSpindleOrient;
    m19.event.number = 1;
    m19.event.value = 90;
    m19.dwell_s = q;
    ASSERT_TRUE(core.apply_block(m19));
    ASSERT_TRUE(core.apply_block(spindle_on(2, o, 600)));
    program::Block end;
    end.index = 3;
    end.kind = program::BlockKind::kEnd;
    end.start = end.end = o;
    ASSERT_TRUE(core.apply_block(end));
    core.apply_command({Command::Kind::kStart, 1.0, {}});
    bool seen = false, waited = false;
    for (int i = 0; i < 200; ++i) {
      if (core.spindle_waiting() && core.spindle().seq != 2) {
        Command at;
        at.kind = Command::Kind::kSpindleAtSpeed;
        at.value = static_cast<double>(core.spindle().seq);
        ASSERT_TRUE(core.apply_command(at));
      }
      core.step();
      if (core.spindle().seq != 2) continue;
      if (!seen) {
        seen = true;
        EXPECT_TRUE(core.spindle().orient);
        EXPECT_EQ(core.spindle().direction, 0);
        EXPECT_EQ(core.spindle().orient_deg, 90);
        EXPECT_EQ(core.spindle().orient_mode, 1);
      }
      if (core.spindle_waiting()) {
        waited = true;
        if (i > 100) {  // oriented, as the bridge would report it
          Command at;
          at.kind = Command::Kind::kSpindleAtSpeed;
          at.value = 2;
          ASSERT_TRUE(core.apply_command(at));
        }
      }
    }
    EXPECT_TRUE(seen);
    EXPECT_EQ(waited, q > 0) << "Q " << q;
    EXPECT_FALSE(core.spindle().orient) << "M3 turns an oriented spindle again";
    EXPECT_EQ(core.state(), RunState::kDone);
  }
}

}  // namespace
}  // namespace cnc::interp
