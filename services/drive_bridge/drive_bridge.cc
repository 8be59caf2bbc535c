#include "services/drive_bridge/drive_bridge.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace cnc::bridge {

BridgeCore::BridgeCore(const config::MachineConfig& cfg)
    : cfg_(cfg), n_(static_cast<int>(std::lround(cfg.ipo_period_s / cfg.servo_period_s))),
      servo_s_(cfg.servo_period_s), naxes_(static_cast<int>(cfg.axes.size())) {}

void BridgeCore::reset(const AxisArray& actual_mm) {
  queue_.clear();
  active_ = false;
  have_seg_ = false;
  cmd_ = actual_mm;
  prev_cmd_ = actual_mm;
  last_sp_ = actual_mm;
  vel_.fill(0.0);
  last_cycle_ = -1;
  ticks_since_setpoint_ = 0;
  stopping_ = false;
  faulted_ = false;
  fault_reason_.clear();
}

void BridgeCore::fault(const std::string& why) {
  if (faulted_) return;
  faulted_ = true;
  fault_reason_ = why;
  queue_.clear();
  have_seg_ = false;
  active_ = false;
  vel_.fill(0.0);
}

bool BridgeCore::on_setpoint(int64_t cycle, const AxisArray& p) {
  if (faulted_) return false;
  if (last_cycle_ >= 0 && cycle <= last_cycle_) return true;  // duplicate or stale: ignore
  int gap_cycles = 1;
  if (last_cycle_ >= 0) {
    gap_cycles = static_cast<int>(std::min<int64_t>(cycle - last_cycle_, 1000));
    gaps_ += gap_cycles - 1;
  }
  const AxisArray& ref = last_cycle_ >= 0 ? last_sp_ : cmd_;
  for (int a = 0; a < naxes_; ++a) {
    const auto& ax = cfg_.axes[a];
    std::ostringstream why;
    if (!std::isfinite(p[a]) || p[a] < ax.min_mm || p[a] > ax.max_mm) {
      why << "setpoint cycle " << cycle << ": axis " << ax.name << " at " << p[a] << " mm is outside its travel ["
          << ax.min_mm << ", " << ax.max_mm << "]";
      fault(why.str());
      return false;
    }
    const double v = std::fabs(p[a] - ref[a]) / (gap_cycles * cfg_.ipo_period_s);
    // The first setpoint must start where the axis is.
    if (last_cycle_ < 0 && std::fabs(p[a] - ref[a]) > ax.max_following_error_mm) {
      why << "setpoint cycle " << cycle << ": axis " << ax.name << " commanded " << p[a] << " mm but stands at "
          << ref[a] << " mm";
      fault(why.str());
      return false;
    }
    if (last_cycle_ >= 0 && v > ax.max_velocity_mm_s * 1.01) {
      why << "setpoint cycle " << cycle << ": axis " << ax.name << " would move at " << v << " mm/s, limit "
          << ax.max_velocity_mm_s;
      fault(why.str());
      return false;
    }
  }
  last_sp_ = p;
  last_cycle_ = cycle;
  ticks_since_setpoint_ = 0;
  queue_.push_back(Coarse{cycle, p, n_ * gap_cycles});
  // Jitter buffer of one period; a backlog beyond a few periods means we fell behind.
  while (queue_.size() > 4) queue_.pop_front();
  if (!active_ && queue_.size() >= 2) active_ = true;
  stopping_ = false;
  return true;
}

const AxisArray& BridgeCore::tick() {
  ++ticks_since_setpoint_;
  prev_cmd_ = cmd_;
  if (faulted_) return cmd_;
  if (static_cast<double>(ticks_since_setpoint_) * servo_s_ > cfg_.setpoint_timeout_s && active_) {
    std::ostringstream why;
    why << "no setpoint for " << static_cast<double>(ticks_since_setpoint_) * servo_s_ * 1e3 << " ms after cycle " << last_cycle_
        << ": controlled stop";
    fault_reason_ = why.str();
    stopping_ = true;
    active_ = false;
    have_seg_ = false;
    queue_.clear();
  }
  if (active_ && !have_seg_ && !queue_.empty()) {
    seg_ = queue_.front();
    queue_.pop_front();
    seg_from_ = cmd_;
    seg_tick_ = 0;
    have_seg_ = true;
  }
  if (have_seg_) {
    ++seg_tick_;
    const double f = static_cast<double>(seg_tick_) / seg_.ticks;
    for (int a = 0; a < naxes_; ++a) {
      const double next = seg_tick_ >= seg_.ticks ? seg_.pos[a] : seg_from_[a] + (seg_.pos[a] - seg_from_[a]) * f;
      vel_[a] = (next - cmd_[a]) / servo_s_;
      cmd_[a] = next;
    }
    if (seg_tick_ >= seg_.ticks) have_seg_ = false;
    return cmd_;
  }
  // No segment: brake along the last velocity at the stop deceleration.
  if (active_) ++starved_ticks_;
  double speed = 0;
  for (int a = 0; a < naxes_; ++a) speed += vel_[a] * vel_[a];
  speed = std::sqrt(speed);
  if (speed > 0) {
    const double new_speed = std::max(0.0, speed - cfg_.stop_decel_mm_s2 * servo_s_);
    const double k = new_speed / speed;
    for (int a = 0; a < naxes_; ++a) {
      vel_[a] *= k;
      cmd_[a] += vel_[a] * servo_s_;
      cmd_[a] = std::clamp(cmd_[a], cfg_.axes[a].min_mm, cfg_.axes[a].max_mm);
    }
  }
  if (stopping_ && speed == 0) {
    // Stopped after a timeout: stays faulted until reset.
    faulted_ = true;
  }
  return cmd_;
}

bool BridgeCore::check_following(const AxisArray& actual) {
  if (faulted_) return false;
  for (int a = 0; a < naxes_; ++a) {
    const double fe = following_error(a, actual[a]);
    if (std::fabs(fe) > cfg_.axes[a].max_following_error_mm) {
      std::ostringstream why;
      why << "axis " << cfg_.axes[a].name << " following error " << fe << " mm over its limit "
          << cfg_.axes[a].max_following_error_mm << " mm";
      fault(why.str());
      return false;
    }
  }
  return true;
}

}  // namespace cnc::bridge
