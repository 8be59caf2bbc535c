#include "services/drive_bridge/drive_bridge.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace cnc::bridge {
namespace {
// Tolerances of the limit checks: rounding in the interpolator, and its corners,
// which take a velocity step of up to a·T_ipo within one cycle.
constexpr double kVelocityTolerance = 1.01;
constexpr double kAccelTolerance = 1.05;
// Playback rate: between 0.9 and 1.05 of the stream's, changed by at most 0.2 %
// per servo tick (at 250 mm/s that is 500 mm/s^2, a sixth of a typical limit).
constexpr double kRateMin = 0.90;
constexpr double kRateMax = 1.05;
constexpr double kRateSlewPerTick = 0.002;
// The jitter buffer is drive_bridge.lead_cycles (default 2): the playback trails the
// newest setpoint by that many periods on average, so a setpoint may come up to that
// less half a period late (plus one bridged) unnoticed.
// The most a stalled link's hold may let the newest setpoint lead the playback:
// 4 cycles over the usual lead (16 ms at T_ipo = 4 ms). The lag a hold adds is made
// up only at the playback's 5 % over real time, and only where the stream leaves room
// for it (catch_up_cap: not at an axis's velocity limit, nor braking at its
// acceleration limit); a link that is slow again and again (a drive emulated in Python) would
// otherwise pile up lag until the end of a program came 100 ms late, and a stop of
// the interpolator right after it ended the path short of its end point.
constexpr double kMaxHoldOverLead = 4.0;
// The limiter's feedback, nested loops (position -> velocity -> acceleration ->
// jerk). Small errors: linear gains, each loop four times slower than the one
// inside it (poles near -20, -80 (double) 1/s at T_servo = 1 ms: no overshoot).
// Large errors: the time-optimal curves of a limited approach, on a share of the
// limits so that a loop never asks for more than the inner one can deliver:
// velocity wanted sqrt(2·(a/4)·|e|), acceleration wanted sqrt(2·(j/2)·|Δv|).
constexpr double kPosGain = 20.0;
constexpr double kVelGain = 80.0;
constexpr double kAccGain = 320.0;
constexpr double kAccShare = 0.25;
constexpr double kJerkShare = 0.5;
// A stop has ended when velocity and acceleration are this small: snapping them to
// zero then is a jerk far below any limit.
constexpr double kStandstillVel = 1e-4;   // mm/s
constexpr double kStandstillAcc = 1e-2;   // mm/s^2

std::string fmt(const char* f, auto... args) {
  char buf[256];
  std::snprintf(buf, sizeof buf, f, args...);
  return buf;
}
}  // namespace

BridgeCore::BridgeCore(const config::MachineConfig& cfg)
    : cfg_(cfg), joints_(kinematics::make_kinematics(cfg)->joint_limits()), n_(static_cast<int>(std::lround(cfg.ipo_period_s / cfg.servo_period_s))),
      servo_s_(cfg.servo_period_s), ipo_s_(cfg.ipo_period_s), naxes_(static_cast<int>(cfg.axes.size())),
      lead_window_(std::min(n_, 128)), window_(std::clamp(n_, 1, kMaxWindow)),
      lead_cycles_(cfg.drive_bridge.lead_cycles) {}

void BridgeCore::engage(const AxisArray& hold_mm, int64_t engagement) {
  mode_ = Mode::kFollowing;
  engagement_ = engagement;
  stream_ = 0;
  cmd_ = hold_mm;
  vel_.fill(0.0);
  acc_.fill(0.0);
  rate_ = 1.0;
  braking_ = false;
  restart_stream();
  ticks_since_setpoint_ = 0;
  fault_reason_.clear();
  watchdog_tripped_ = false;
  waiting_reason_.clear();
}

void BridgeCore::restart_stream() {
  braking_ = false;
  last_sp_ = cmd_;
  sp_vel_.fill(0.0);
  stream_vel_.fill(0.0);
  p_size_ = 0;
  reset_smoothing(cmd_);
  seg_cycle_ = -1;
  last_cycle_ = -1;
  last_gap_ = 1;
}

void BridgeCore::disengage(const AxisArray& at_mm) {
  engage(at_mm);
  mode_ = Mode::kIdle;
}

void BridgeCore::fault(const std::string& why) {
  if (faulted()) return;
  fault_reason_ = why;
  mode_ = Mode::kStopping;
  stop_held_ticks_ = 0;
  p_size_ = 0;
  seg_cycle_ = -1;
}

void BridgeCore::push(const Point& p) {
  if (p_size_ == kPoints) {  // the oldest is long past τ when 64 are kept
    p_head_ = (p_head_ + 1) % kPoints;
    --p_size_;
  }
  points_[static_cast<size_t>((p_head_ + p_size_) % kPoints)] = p;
  ++p_size_;
}

BridgeCore::Verdict BridgeCore::on_setpoint(int64_t cycle, const AxisArray& p, const StreamStamp& from) {
  if (mode_ != Mode::kFollowing) return Verdict::kIgnored;
  if (from.engagement != engagement_ || from.stream < stream_) {
    ++stale_;
    return Verdict::kStale;
  }
  if (from.stream > stream_ && last_cycle_ >= 0) {
    // A new stream (the interpolator was reset or restarted). RESET is taken only
    // where the path stands, so an old stream whose newest setpoint still moved was
    // cut off: its interpolator died and a new one began within the watchdog's
    // timeout, or a second one publishes. Neither is joined: a controlled stop.
    for (int a = 0; a < naxes_; ++a) {
      if (std::fabs(stream_vel_[a]) <= kStillVelocity) continue;
      fault(fmt("setpoint stream %lld began where stream %lld had left off moving (axis %s at %.2f mm/s at its "
                "cycle %lld): a restarted or second interpolator is not followed; controlled stop",
                static_cast<long long>(from.stream), static_cast<long long>(stream_), cfg_.axes[a].name.c_str(),
                std::fabs(stream_vel_[a]), static_cast<long long>(last_cycle_)));
      return Verdict::kFault;
    }
    // Otherwise joined where the axes stand, once the playback of the old one has
    // come to rest (a limiter steering back onto a stream that broke its limits
    // approaches rest only asymptotically; what is left of it, it takes into the
    // new stream's start).
    // Whether the playback brakes for the old stream does not count: once a brake
    // has begun only a setpoint of the old stream ends it, and a quiet old stream
    // (the interpolator resetting) then held the new one off until the watchdog.
    bool still = true;
    for (int a = 0; a < naxes_; ++a)
      still = still && std::fabs(vel_[a]) <= kStillVelocity && std::fabs(acc_[a]) <= kStillAccel;
    if (!still) {
      waiting_reason_ = "a new setpoint stream while the axes still move: waiting until they stand";
      return Verdict::kWaiting;
    }
    restart_stream();
  }
  if (last_cycle_ >= 0 && cycle <= last_cycle_) return Verdict::kIgnored;  // duplicate or stale
  const bool first = last_cycle_ < 0;
  const int64_t gap = first ? 1 : std::min<int64_t>(cycle - last_cycle_, 1000);
  for (int a = 0; a < naxes_; ++a) {
    const auto& j = joints_[static_cast<size_t>(a)];
    if (!std::isfinite(p[a]) || p[a] < j.min_mm || p[a] > j.max_mm) {
      fault(fmt("setpoint cycle %lld: axis %s at %.4f mm is outside its travel [%g, %g]",
                static_cast<long long>(cycle), j.name.c_str(), p[a], j.min_mm, j.max_mm));
      return Verdict::kFault;
    }
  }
  if (first) {
    // Join a stream only where the axes stand: a step no larger than the axis
    // could take from rest within one period at its acceleration limit.
    for (int a = 0; a < naxes_; ++a) {
      const auto& ax = cfg_.axes[a];
      const double tol = std::max(1e-4, ax.max_accel_mm_s2 * ipo_s_ * ipo_s_);
      if (std::fabs(p[a] - cmd_[a]) > tol) {
        waiting_reason_ = fmt("setpoints put axis %s at %.4f mm, it stands at %.4f mm: waiting for setpoints from there",
                              ax.name.c_str(), p[a], cmd_[a]);
        return Verdict::kWaiting;
      }
    }
  }
  AxisArray v{};
  const double dt = static_cast<double>(gap) * ipo_s_;
  // The velocity change happens between the middles of the last step and this one.
  const double dt_accel = 0.5 * static_cast<double>(gap + last_gap_) * ipo_s_;
  for (int a = 0; a < naxes_; ++a) {
    const auto& ax = cfg_.axes[a];
    v[a] = (p[a] - last_sp_[a]) / dt;
    if (std::fabs(v[a]) > ax.max_velocity_mm_s * kVelocityTolerance + 1e-9) {
      fault(fmt("setpoint cycle %lld: axis %s would move at %.2f mm/s, limit %g mm/s", static_cast<long long>(cycle),
                ax.name.c_str(), std::fabs(v[a]), ax.max_velocity_mm_s));
      return Verdict::kFault;
    }
    const double acc = std::fabs(v[a] - sp_vel_[a]) / dt_accel;
    if (acc > ax.max_accel_mm_s2 * kAccelTolerance + 1e-6) {
      fault(fmt("setpoint cycle %lld: axis %s would accelerate at %.0f mm/s^2, limit %g mm/s^2",
                static_cast<long long>(cycle), ax.name.c_str(), acc, ax.max_accel_mm_s2));
      return Verdict::kFault;
    }
  }
  if (first) {
    // The axes' standstill is the stream's virtual previous point; playback
    // starts with the lead it keeps.
    push(Point{cycle - 1, cmd_, AxisArray{}});
    tau_ = static_cast<double>(cycle) - lead_cycles_ - 0.5;
    lead_ring_.fill(lead_cycles_);
    lead_sum_ = lead_cycles_ * lead_window_;
    lead_i_ = 0;
  }
  push(Point{cycle, p, v});
  if (braking_) {
    // The stream is back before the timeout, after the brake had begun: rejoin it
    // with the usual lead. The reference jumps back onto the stream; the limiter
    // takes the command from where the brake left it onto it within the limits.
    braking_ = false;
    ++rejoins_;
    tau_ = static_cast<double>(cycle) - lead_cycles_;
    lead_ring_.fill(lead_cycles_);
    lead_sum_ = lead_cycles_ * lead_window_;
    AxisArray on_path{};
    path_at(tau_, on_path);
    reset_smoothing(on_path);
  }
  gaps_ += gap - 1;
  last_gap_ = gap;
  sp_vel_ = v;
  if (first) {
    stream_vel_.fill(0.0);
  } else {
    stream_vel_ = v;
  }
  last_sp_ = p;
  last_cycle_ = cycle;
  stream_ = from.stream;
  ticks_since_setpoint_ = 0;
  waiting_reason_.clear();
  return Verdict::kAccepted;
}

void BridgeCore::path_at(double tau, AxisArray& out) {
  // Drop the points the playback has passed, keeping the one at or before τ.
  while (p_size_ >= 2 && static_cast<double>(point(1).cycle) <= tau) {
    p_head_ = (p_head_ + 1) % kPoints;
    --p_size_;
  }
  const Point& a = point(0);
  if (tau <= static_cast<double>(a.cycle)) {
    out = a.pos;
    seg_cycle_ = a.cycle;
  } else if (p_size_ >= 2) {
    const Point& b = point(1);
    const double f = (tau - static_cast<double>(a.cycle)) / static_cast<double>(b.cycle - a.cycle);
    for (int i = 0; i < naxes_; ++i) out[i] = a.pos[i] + (b.pos[i] - a.pos[i]) * f;
    seg_cycle_ = b.cycle;
  } else {
    // Past the newest setpoint: on along its step's velocity (bridging a late one).
    const double dt = (tau - static_cast<double>(a.cycle)) * ipo_s_;
    for (int i = 0; i < naxes_; ++i)
      out[i] = std::clamp(a.pos[i] + a.vel[i] * dt, cfg_.axes[i].min_mm, cfg_.axes[i].max_mm);
    seg_cycle_ = a.cycle;
    ++bridged_ticks_;
  }
}

void BridgeCore::reset_smoothing(const AxisArray& at) {
  for (int i = 0; i < naxes_; ++i) {
    ma1_[static_cast<size_t>(i)].fill(at[i]);
    ma2_[static_cast<size_t>(i)].fill(at[i]);
  }
  ma_i_ = 0;
  ref_ = at;
  ref_v_.fill(0.0);
  ref_a_.fill(0.0);
  ref_j_.fill(0.0);
  ref_fresh_ = true;
}

void BridgeCore::smooth(const AxisArray& p) {
  const auto slot = static_cast<size_t>(ma_i_);
  ma_i_ = (ma_i_ + 1) % window_;
  const double inv = 1.0 / window_;
  for (int i = 0; i < naxes_; ++i) {
    auto& m1 = ma1_[static_cast<size_t>(i)];
    auto& m2 = ma2_[static_cast<size_t>(i)];
    // Summed afresh every tick (at most 128 terms): no running sum to drift.
    m1[slot] = p[i];
    double s1 = 0;
    for (int k = 0; k < window_; ++k) s1 += m1[static_cast<size_t>(k)];
    m2[slot] = s1 * inv;
    double s2 = 0;
    for (int k = 0; k < window_; ++k) s2 += m2[static_cast<size_t>(k)];
    const double x = s2 * inv;
    const double v = (x - ref_[i]) / servo_s_;
    const double acc = (v - ref_v_[i]) / servo_s_;
    ref_j_[i] = ref_fresh_ ? 0.0 : (acc - ref_a_[i]) / servo_s_;
    ref_a_[i] = ref_fresh_ ? 0.0 : acc;
    ref_v_[i] = v;
    ref_[i] = x;
  }
  ref_fresh_ = false;
}

void BridgeCore::limit_step(bool follow) {
  const double t = servo_s_;
  for (int i = 0; i < naxes_; ++i) {
    const auto& ax = cfg_.axes[static_cast<size_t>(i)];
    const double vmax = ax.max_velocity_mm_s;
    const double amax = follow ? ax.max_accel_mm_s2 : std::min(ax.max_accel_mm_s2, cfg_.stop_decel_mm_s2);
    const double jmax = ax.max_jerk_mm_s3 > 0 ? ax.max_jerk_mm_s3 : 1e300;
    const double v = vel_[i];
    const double a = acc_[i];
    double a_want = 0;
    double j_ff = 0;
    // The approach to a wanted value over a distance: linear near it, the
    // limited time-optimal curve further away (whichever asks less).
    auto approach = [](double err, double gain, double limit) {
      const double lin = gain * std::fabs(err);
      const double curve = std::sqrt(2.0 * limit * std::fabs(err));
      return std::copysign(std::min(lin, curve), err);
    };
    if (follow) {
      // Feed-forward of the reference (clamped to the limits: a jump of the
      // reference is no reason to command one), plus the feedback.
      const double e = ref_[i] - cmd_[i];
      const double v_ff = std::clamp(ref_v_[i], -vmax, vmax);
      const double v_want = std::clamp(v_ff + approach(e, kPosGain, kAccShare * amax), -vmax, vmax);
      const double a_ff = std::clamp(ref_a_[i], -amax, amax);
      a_want = std::clamp(a_ff + approach(v_want - v, kVelGain, kJerkShare * jmax), -amax, amax);
      j_ff = std::clamp(ref_j_[i], -jmax, jmax);
    } else {
      a_want = std::clamp(approach(0.0 - v, kVelGain, kJerkShare * jmax), -amax, amax);
    }
    double j = std::clamp(j_ff + kAccGain * (a_want - a), -jmax, jmax);
    double a_new = std::clamp(a + j * t, -amax, amax);
    // Velocity look-ahead: from the new state the acceleration can still be brought
    // to zero at the jerk limit before the velocity passes its limit,
    // v + a·T + a²/(2J) + a·T/2 <= vmax (and the mirror), kept unless the jerk
    // limit forbids it (it cannot: the bound moves by less than J·T a tick).
    const double room_up = std::max(0.0, vmax - v);
    const double room_dn = std::max(0.0, vmax + v);
    const double a_hi = jmax * (-1.5 * t + std::sqrt(2.25 * t * t + 2.0 * room_up / jmax));
    const double a_lo = -jmax * (-1.5 * t + std::sqrt(2.25 * t * t + 2.0 * room_dn / jmax));
    a_new = std::max(std::min(a_new, a_hi), a_lo);
    // Jerk first, then acceleration (|a| <= amax already, so both hold together).
    a_new = std::max(std::min(a_new, a + jmax * t), a - jmax * t);
    a_new = std::max(std::min(a_new, amax), -amax);
    double v_new = v + a_new * t;
    double x_new = cmd_[i] + v_new * t;
    if (!follow && std::fabs(v_new) < kStandstillVel && std::fabs(a_new) < kStandstillAcc) {
      // Standing: the remaining creep is below a micrometre per second.
      a_new = 0;
      v_new = 0;
      x_new = cmd_[i];
    }
    // Travel: the last line of defence (the reference never leaves it; a command
    // that would is held at the end, at the cost of the limits in that tick).
    // After it the command stands at the end: its state is at rest there. (Kept as
    // the clamped step's finite differences, the state went on from an acceleration
    // of about -v/T: with a reference that ends exactly at Z's travel end (a G0 Z5 on
    // sim3) a micrometre of the limiter's overshoot threw Z 3.4 mm back and it swung
    // between 1.6 and 5 mm for 0.8 s about a standing setpoint.)
    bool at_end = false;
    if (x_new < ax.min_mm || x_new > ax.max_mm) {
      x_new = std::clamp(x_new, ax.min_mm, ax.max_mm);
      at_end = true;
    }
    // The state is the command's own finite differences (no rounding drift
    // between what is sent and what the limits were applied to).
    const double v_fd = (x_new - cmd_[i]) / t;
    acc_[i] = at_end || (a_new == 0.0 && v_new == 0.0) ? 0.0 : (v_fd - v) / t;
    vel_[i] = at_end || v_new == 0.0 ? 0.0 : v_fd;
    cmd_[i] = x_new;
  }
}

bool BridgeCore::hold() {
  if (mode_ == Mode::kStopping) {
    // A controlled stop waits for a stalled link as the playback does: stepped on
    // meanwhile, its next command would reach the drive as a jump over the ticks
    // it missed (a speed spike inside the stop: 203 mm/s in a stop from 200 mm/s
    // seen under load). At most timing.setpoint_timeout_s of holds per stop, so a
    // link that stays stalled never holds up the other axes' stop for longer.
    if (static_cast<double>(stop_held_ticks_ + 1) * servo_s_ > cfg_.setpoint_timeout_s) return false;
    ++stop_held_ticks_;
    ++held_ticks_;
    return true;
  }
  if (mode_ != Mode::kFollowing || last_cycle_ < 0) return false;
  // The newest setpoint may lead τ by at most kMaxHoldOverLead cycles over the usual lead: the buffer keeps
  // kPoints, and the lag a hold adds is made up only below the velocity limits.
  if (static_cast<double>(last_cycle_) - tau_ > (lead_cycles_ + kMaxHoldOverLead)) return false;
  // The watchdog counts on: a stream that stopped is not waited for.
  if (static_cast<double>(ticks_since_setpoint_ + 1) * servo_s_ > cfg_.setpoint_timeout_s) return false;
  ++ticks_since_setpoint_;
  ++held_ticks_;
  return true;
}

double BridgeCore::catch_up_cap() const {
  // Played back at rate r, the stream's velocity becomes r·v and its acceleration
  // r²·a + ṙ·v. A rate above 1 must come back to 1 (at kRateSlewPerTick) before the
  // stream reaches its limits, so it is allowed only where, over that time T, the
  // stream (its jerk within the axis's limit J) stays below them: |v| + |a|·T + J·T²/2
  // for the velocity, |a| + J·T for the acceleration. Made up at 5 % while a stop
  // braked at the limit, the reference asked 1.1 times the deceleration the limiter
  // may command, and an A axis stopped 0.63 deg past its end point.
  const double T = (kRateMax - 1.0) / kRateSlewPerTick * servo_s_;
  const double slew = kRateSlewPerTick / servo_s_;
  double cap = kRateMax;
  for (int a = 0; a < naxes_; ++a) {
    const auto& ax = cfg_.axes[static_cast<size_t>(a)];
    const double jmax = ax.max_jerk_mm_s3 > 0 ? ax.max_jerk_mm_s3 : 0.0;
    // The points from the playback on (the first one is at or before τ) to the newest.
    double v = 0, acc = 0;
    for (int k = 0; k < p_size_; ++k) {
      const Point& q = point(k);
      v = std::max(v, std::fabs(q.vel[a]));
      if (k > 0) {
        const Point& b = point(k - 1);
        const double dt = static_cast<double>(q.cycle - b.cycle) * ipo_s_;
        acc = std::max(acc, std::fabs(q.vel[a] - b.vel[a]) / dt);
      }
    }
    const double v_t = v + acc * T + 0.5 * jmax * T * T;
    const double a_t = acc + jmax * T;
    if (v_t > 0) cap = std::min(cap, ax.max_velocity_mm_s / v_t);
    const double room = ax.max_accel_mm_s2 - slew * v_t * kRateMax;
    if (room <= 0) return 1.0;
    if (a_t > 0) cap = std::min(cap, std::sqrt(room / a_t));
  }
  return cap;
}

const AxisArray& BridgeCore::tick() {
  ++ticks_since_setpoint_;
  switch (mode_) {
    case Mode::kIdle:
    case Mode::kStopped:
      vel_.fill(0.0);
      acc_.fill(0.0);
      return cmd_;
    case Mode::kStopping: {
      limit_step(false);
      bool still = true;
      for (int a = 0; a < naxes_; ++a) still = still && vel_[a] == 0.0 && acc_[a] == 0.0;
      if (still) mode_ = Mode::kStopped;
      return cmd_;
    }
    case Mode::kFollowing: break;
  }
  if (last_cycle_ < 0) {  // engaged, no stream yet: hold
    vel_.fill(0.0);
    acc_.fill(0.0);
    return cmd_;
  }
  if (static_cast<double>(ticks_since_setpoint_) * servo_s_ > cfg_.setpoint_timeout_s) {
    watchdog_tripped_ = !faulted();
    fault(fmt("no setpoint for %.0f ms after cycle %lld: controlled stop",
              static_cast<double>(ticks_since_setpoint_) * servo_s_ * 1e3, static_cast<long long>(last_cycle_)));
    --ticks_since_setpoint_;
    return tick();
  }
  if (braking_) {
    ++starved_ticks_;
    limit_step(false);
    return cmd_;
  }
  // Playback rate from the buffer: the newest setpoint should lead τ by
  // lead_cycles_ on average (half a period more just after it arrives, half less
  // just before the next).
  const double lead = static_cast<double>(last_cycle_) - tau_;
  lead_sum_ += lead - lead_ring_[static_cast<size_t>(lead_i_)];
  lead_ring_[static_cast<size_t>(lead_i_)] = lead;
  lead_i_ = (lead_i_ + 1) % lead_window_;
  const double lead_avg = lead_sum_ / lead_window_;
  double want = std::clamp(1.0 + 0.1 * (lead_avg - lead_cycles_), kRateMin, kRateMax);
  if (want > 1.0) want = std::min(want, std::max(1.0, catch_up_cap()));
  rate_ += std::clamp(want - rate_, -kRateSlewPerTick, kRateSlewPerTick);
  const double tau = tau_ + rate_ / n_;
  if (tau > static_cast<double>(last_cycle_) + 1.0) {
    // More than one period past the newest setpoint: brake (a controlled stop
    // unless the stream comes back before the timeout).
    braking_ = true;
    ++starved_ticks_;
    limit_step(false);
    return cmd_;
  }
  tau_ = tau;
  AxisArray p{};
  path_at(tau_, p);
  smooth(p);
  limit_step(true);
  return cmd_;
}

}  // namespace cnc::bridge
