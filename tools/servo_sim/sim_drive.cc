#include "tools/servo_sim/sim_drive.h"

#include <algorithm>

namespace cnc::servo_sim {

SimDrive::SimDrive(std::string name, int unit, const drive::DriveProfile& profile,
                   const config::ServoSimAxisConfig& sim, double max_velocity_mm_s, double start_mm)
    : name_(std::move(name)), unit_(unit), emu_(profile, start_mm), model_(sim, max_velocity_mm_s, start_mm),
      from_mm_(start_mm), to_mm_(start_mm), interval_s_(0.001), step_s_(0.001) {}

void SimDrive::after_request(double now_s) {
  if (emu_.target_writes() == writes_seen_) return;
  writes_seen_ = emu_.target_writes();
  const double since = now_s - last_write_s_;
  // Where the interpolated target is now becomes the start of the next ramp.
  const double f = std::clamp((now_s - last_write_s_) / interval_s_, 0.0, 1.0);
  from_mm_ = last_write_s_ < 0 ? emu_.target_mm() : from_mm_ + (to_mm_ - from_mm_) * f;
  to_mm_ = emu_.target_mm();
  // A write after a pause is a new start: no ramp from a stale interval. A late
  // write (a lost or delayed transaction) catches up over the usual interval, as a
  // drive with a fixed interpolation period does, instead of crawling over the gap.
  if (last_write_s_ < 0 || since > 0.1) {
    interval_s_ = step_s_;
  } else {
    usual_s_ = usual_s_ <= 0 ? since : usual_s_ + 0.1 * (std::min(since, 2 * usual_s_) - usual_s_);
    interval_s_ = std::clamp(since, 0.0002, 1.5 * usual_s_);
  }
  last_write_s_ = now_s;
}

void SimDrive::step(double dt_s, double now_s) {
  step_s_ = dt_s;
  const bool follows = emu_.follows();
  if (!follows) {
    // Disabled: the target ramp restarts from wherever the axis comes to rest.
    from_mm_ = to_mm_ = model_.position_mm();
    model_.step(dt_s, to_mm_, 0.0, false);
  } else {
    const double f = last_write_s_ < 0 ? 1.0 : std::clamp((now_s - last_write_s_) / interval_s_, 0.0, 1.0);
    const double target = from_mm_ + (to_mm_ - from_mm_) * f;
    const double ff = f < 1.0 ? (to_mm_ - from_mm_) / interval_s_ : 0.0;
    model_.step(dt_s, target, ff, true);
  }
  emu_.set_actual(model_.position_mm(), model_.velocity_mm_s());
}

}  // namespace cnc::servo_sim
