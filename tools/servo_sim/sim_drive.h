#pragma once
// One simulated servo drive: the drive end of its profile (DriveEmulator) moving
// a ServoModel. Like a drive in cyclic synchronous position mode it interpolates
// linearly between the targets it is sent, over the interval it measured between
// them, and feeds the slope forward as velocity; so a 1 kHz TCP stream and a
// 70 Hz RTU stream both give smooth motion.
#include <string>

#include "common/drive/drive_emulator.h"
#include "tools/servo_sim/servo_model.h"

namespace cnc::servo_sim {

class SimDrive {
 public:
  SimDrive(std::string name, int unit, const drive::DriveProfile& profile, const config::ServoSimAxisConfig& sim,
           double max_velocity_mm_s, double start_mm);
  // After a Modbus request that may have written registers.
  void after_request(double now_s);
  // Advances the dynamics by dt to time now_s and refreshes the registers.
  void step(double dt_s, double now_s);

  const std::string& name() const { return name_; }
  int unit() const { return unit_; }
  drive::DriveEmulator& emulator() { return emu_; }
  double position_mm() const { return model_.position_mm(); }
  double velocity_mm_s() const { return model_.velocity_mm_s(); }
  bool follows() const { return emu_.follows(); }

 private:
  std::string name_;
  int unit_;
  drive::DriveEmulator emu_;
  ServoModel model_;
  int64_t writes_seen_ = 0;
  double last_write_s_ = -1;
  double from_mm_;      // interpolation: from the target in force at the last write...
  double to_mm_;        // ...to the target written then...
  double interval_s_;   // ...over the interval measured between the last two writes
  double usual_s_ = 0;  // running average of the write interval
  double step_s_;
};

}  // namespace cnc::servo_sim
