#include "tools/servo_sim/servo_model.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace cnc::servo_sim {

ServoModel::ServoModel(const config::ServoSimAxisConfig& sim, double max_velocity_mm_s, double start_mm)
    : omega_(2.0 * std::numbers::pi * sim.bandwidth_hz), zeta_(sim.damping),
      vmax_(sim.max_velocity_mm_s > 0 ? sim.max_velocity_mm_s : 1.2 * max_velocity_mm_s), pos_(start_mm) {}

void ServoModel::step(double dt_s, double target_mm, double feedforward_mm_s, bool enabled) {
  // Substeps keep the explicit integration stable for any bandwidth.
  const int n = std::max(1, static_cast<int>(std::ceil(dt_s * omega_ / 0.1)));
  const double h = dt_s / n;
  const double v_ff = enabled ? feedforward_mm_s : 0.0;
  for (int i = 0; i < n; ++i) {
    const double acc = enabled ? omega_ * omega_ * (target_mm - pos_) + 2.0 * zeta_ * omega_ * (v_ff - vel_)
                               : -2.0 * omega_ * vel_;
    vel_ = std::clamp(vel_ + acc * h, -vmax_, vmax_);
    pos_ += vel_ * h;
  }
}

}  // namespace cnc::servo_sim
