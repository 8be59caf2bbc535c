#pragma once
// Servo dynamics of one simulated drive: a second-order position loop (bandwidth,
// damping) with velocity and acceleration (torque) feed-forward, as real drives in
// position mode have them (the caller estimates both from the target updates), and
// a velocity limit; integrated semi-implicitly:
//   x'' = ω²(target − x) + 2ζω(v_ff − x') + a_ff.
// With exact feed-forward the error is zero at constant velocity and constant
// acceleration (without a_ff it would be a/ω² while accelerating).
// Disabled, the axis brakes to a stop and holds.
#include "common/config/machine_config.h"

namespace cnc::servo_sim {

class ServoModel {
 public:
  ServoModel(const config::ServoSimAxisConfig& sim, double max_velocity_mm_s, double start_mm);
  void step(double dt_s, double target_mm, double feedforward_mm_s, double accel_ff_mm_s2, bool enabled);
  // Jammed: stands where it is; the target (the demand) moves on without it.
  void jam(double target_mm) {
    vel_ = 0;
    last_target_ = target_mm;
  }
  double position_mm() const { return pos_; }
  double velocity_mm_s() const { return vel_; }
  double max_velocity_mm_s() const { return vmax_; }

 private:
  double omega_;
  double zeta_;
  double vmax_;
  double pos_;
  double vel_ = 0;
  double last_target_;  // the target at the end of the previous step: substeps ramp from it
};

}  // namespace cnc::servo_sim
