#pragma once
// Servo dynamics of one simulated drive: a second-order position loop (bandwidth,
// damping) with velocity feed-forward (as real drives in position mode have; the
// caller estimates it from the target updates) and a velocity limit; integrated
// semi-implicitly.
// Disabled, the axis brakes to a stop and holds.
#include "common/config/machine_config.h"

namespace cnc::servo_sim {

class ServoModel {
 public:
  ServoModel(const config::ServoSimAxisConfig& sim, double max_velocity_mm_s, double start_mm);
  void step(double dt_s, double target_mm, double feedforward_mm_s, bool enabled);
  double position_mm() const { return pos_; }
  double velocity_mm_s() const { return vel_; }

 private:
  double omega_;
  double zeta_;
  double vmax_;
  double pos_;
  double vel_ = 0;
};

}  // namespace cnc::servo_sim
