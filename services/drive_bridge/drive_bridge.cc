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
// The jitter buffer: the playback trails the newest setpoint by two periods on
// average, so a setpoint may come 1.5 periods late (plus one bridged) unnoticed.
constexpr double kLeadCycles = 2.0;

std::string fmt(const char* f, auto... args) {
  char buf[256];
  std::snprintf(buf, sizeof buf, f, args...);
  return buf;
}
}  // namespace

BridgeCore::BridgeCore(const config::MachineConfig& cfg)
    : cfg_(cfg), n_(static_cast<int>(std::lround(cfg.ipo_period_s / cfg.servo_period_s))),
      servo_s_(cfg.servo_period_s), ipo_s_(cfg.ipo_period_s), naxes_(static_cast<int>(cfg.axes.size())),
      lead_window_(std::min(n_, 128)) {}

void BridgeCore::engage(const AxisArray& hold_mm) {
  mode_ = Mode::kFollowing;
  cmd_ = hold_mm;
  last_sp_ = hold_mm;
  vel_.fill(0.0);
  sp_vel_.fill(0.0);
  p_size_ = 0;
  rate_ = 1.0;
  braking_ = false;
  blend_left_ = 0;
  seg_cycle_ = -1;
  last_cycle_ = -1;
  last_gap_ = 1;
  ticks_since_setpoint_ = 0;
  fault_reason_.clear();
  waiting_reason_.clear();
}

void BridgeCore::disengage(const AxisArray& at_mm) {
  engage(at_mm);
  mode_ = Mode::kIdle;
}

void BridgeCore::fault(const std::string& why) {
  if (faulted()) return;
  fault_reason_ = why;
  mode_ = Mode::kStopping;
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

BridgeCore::Verdict BridgeCore::on_setpoint(int64_t cycle, const AxisArray& p) {
  if (mode_ != Mode::kFollowing) return Verdict::kIgnored;
  if (last_cycle_ >= 0 && cycle <= last_cycle_) return Verdict::kIgnored;  // duplicate or stale
  const bool first = last_cycle_ < 0;
  const int64_t gap = first ? 1 : std::min<int64_t>(cycle - last_cycle_, 1000);
  for (int a = 0; a < naxes_; ++a) {
    const auto& ax = cfg_.axes[a];
    if (!std::isfinite(p[a]) || p[a] < ax.min_mm || p[a] > ax.max_mm) {
      fault(fmt("setpoint cycle %lld: axis %s at %.4f mm is outside its travel [%g, %g]",
                static_cast<long long>(cycle), ax.name.c_str(), p[a], ax.min_mm, ax.max_mm));
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
    tau_ = static_cast<double>(cycle) - kLeadCycles - 0.5;
    lead_ring_.fill(kLeadCycles);
    lead_sum_ = kLeadCycles * lead_window_;
    lead_i_ = 0;
  }
  push(Point{cycle, p, v});
  if (braking_) {
    // The stream is back before the timeout, after the brake had begun: rejoin it
    // with the usual lead, blending the command from where the brake took it onto
    // the stream over one period (longer if the velocity limit needs it).
    braking_ = false;
    ++rejoins_;
    tau_ = static_cast<double>(cycle) - kLeadCycles;
    lead_ring_.fill(kLeadCycles);
    lead_sum_ = kLeadCycles * lead_window_;
    AxisArray on_path{};
    path_at(tau_, on_path);
    int ticks = n_;
    for (int a = 0; a < naxes_; ++a) {
      blend_[a] = cmd_[a] - on_path[a];
      const double need = std::fabs(blend_[a]) / (cfg_.axes[a].max_velocity_mm_s * 0.5 * servo_s_);
      ticks = std::max(ticks, static_cast<int>(std::ceil(need)));
    }
    blend_ticks_ = blend_left_ = ticks;
  }
  gaps_ += gap - 1;
  last_gap_ = gap;
  sp_vel_ = v;
  last_sp_ = p;
  last_cycle_ = cycle;
  ticks_since_setpoint_ = 0;
  waiting_reason_.clear();
  return Verdict::kAccepted;
}

void BridgeCore::brake() {
  double speed = 0;
  for (int a = 0; a < naxes_; ++a) speed += vel_[a] * vel_[a];
  speed = std::sqrt(speed);
  if (speed <= 0) return;
  const double k = std::max(0.0, speed - cfg_.stop_decel_mm_s2 * servo_s_) / speed;
  for (int a = 0; a < naxes_; ++a) {
    vel_[a] *= k;
    const double next = std::clamp(cmd_[a] + vel_[a] * servo_s_, cfg_.axes[a].min_mm, cfg_.axes[a].max_mm);
    if (next != cmd_[a] + vel_[a] * servo_s_) vel_[a] = 0;
    cmd_[a] = next;
  }
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

void BridgeCore::play(double tau) {
  AxisArray next{};
  path_at(tau, next);
  if (blend_left_ > 0) {
    --blend_left_;
    const double k = static_cast<double>(blend_left_) / blend_ticks_;
    for (int i = 0; i < naxes_; ++i) next[i] += blend_[i] * k;
  }
  for (int i = 0; i < naxes_; ++i) {
    vel_[i] = (next[i] - cmd_[i]) / servo_s_;
    cmd_[i] = next[i];
  }
}

const AxisArray& BridgeCore::tick() {
  ++ticks_since_setpoint_;
  switch (mode_) {
    case Mode::kIdle:
    case Mode::kStopped:
      vel_.fill(0.0);
      return cmd_;
    case Mode::kStopping:
      brake();
      if (std::all_of(vel_.begin(), vel_.begin() + naxes_, [](double v) { return v == 0.0; })) mode_ = Mode::kStopped;
      return cmd_;
    case Mode::kFollowing: break;
  }
  if (last_cycle_ < 0) {  // engaged, no stream yet: hold
    vel_.fill(0.0);
    return cmd_;
  }
  if (static_cast<double>(ticks_since_setpoint_) * servo_s_ > cfg_.setpoint_timeout_s) {
    fault(fmt("no setpoint for %.0f ms after cycle %lld: controlled stop",
              static_cast<double>(ticks_since_setpoint_) * servo_s_ * 1e3, static_cast<long long>(last_cycle_)));
    return tick();
  }
  if (braking_) {
    ++starved_ticks_;
    brake();
    return cmd_;
  }
  // Playback rate from the buffer: the newest setpoint should lead τ by
  // kLeadCycles on average (half a period more just after it arrives, half less
  // just before the next).
  const double lead = static_cast<double>(last_cycle_) - tau_;
  lead_sum_ += lead - lead_ring_[static_cast<size_t>(lead_i_)];
  lead_ring_[static_cast<size_t>(lead_i_)] = lead;
  lead_i_ = (lead_i_ + 1) % lead_window_;
  const double lead_avg = lead_sum_ / lead_window_;
  double want = std::clamp(1.0 + 0.1 * (lead_avg - kLeadCycles), kRateMin, kRateMax);
  if (want > 1.0) {
    // Never faster than an axis's velocity limit.
    for (int a = 0; a < naxes_; ++a) {
      const double v = std::fabs(sp_vel_[a]);
      if (v > 0) want = std::min(want, std::max(1.0, cfg_.axes[a].max_velocity_mm_s / v));
    }
  }
  rate_ += std::clamp(want - rate_, -kRateSlewPerTick, kRateSlewPerTick);
  const double tau = tau_ + rate_ / n_;
  if (tau > static_cast<double>(last_cycle_) + 1.0) {
    // More than one period past the newest setpoint: brake (a controlled stop
    // unless the stream comes back before the timeout).
    braking_ = true;
    ++starved_ticks_;
    brake();
    return cmd_;
  }
  tau_ = tau;
  play(tau_);
  return cmd_;
}

}  // namespace cnc::bridge
