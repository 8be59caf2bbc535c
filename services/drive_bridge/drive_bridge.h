#pragma once
// Drive bridge core: fine interpolation of coarse setpoints (seed 001's two-step
// scheme) and the safety checks the architecture asks of the bridge. Pure: no
// Modbus, no LCM, no clock; driven by servo ticks.
//
// Coarse setpoints are queued and each becomes a linear segment of N = T_ipo/T_servo
// servo ticks, starting one coarse period late so the next setpoint has arrived.
// A missed setpoint (cycle gap) stretches the next segment over the missed time, so
// a single loss is bridged. If the queue runs dry the axes brake at the configured
// deceleration; a silence longer than the timeout faults the bridge.
#include <array>
#include <cstdint>
#include <deque>
#include <string>

#include "common/config/machine_config.h"
#include "common/program/block.h"

namespace cnc::bridge {

using AxisArray = std::array<double, program::kMaxAxes>;

class BridgeCore {
 public:
  explicit BridgeCore(const config::MachineConfig& cfg);

  // Starts from the drives' actual positions (after enabling them).
  void reset(const AxisArray& actual_mm);
  // A coarse setpoint; checks travel and velocity. Returns false and faults on violation.
  bool on_setpoint(int64_t cycle, const AxisArray& position_mm);
  // One servo tick: advances the fine interpolation. Returns the commanded positions.
  const AxisArray& tick();
  // Following error check against the drives' actual positions, read in the same
  // transaction that sent this tick's command: they answer the previous command.
  bool check_following(const AxisArray& actual_mm);
  double following_error(int axis, double actual_mm) const { return prev_cmd_[axis] - actual_mm; }
  void fault(const std::string& why);

  bool faulted() const { return faulted_; }
  bool stopping() const { return stopping_; }
  const std::string& fault_reason() const { return fault_reason_; }
  const AxisArray& commanded() const { return cmd_; }
  int64_t last_cycle() const { return last_cycle_; }
  int64_t setpoint_gaps() const { return gaps_; }
  int64_t ticks_since_setpoint() const { return ticks_since_setpoint_; }
  bool active() const { return active_; }
  // Servo ticks on which the fine interpolation had no coarse setpoint to follow.
  int64_t starved_ticks() const { return starved_ticks_; }

 private:
  struct Coarse {
    int64_t cycle;
    AxisArray pos;
    int ticks;  // servo ticks this segment spans
  };
  config::MachineConfig cfg_;
  int n_;                // servo ticks per coarse period
  double servo_s_;
  int naxes_;
  std::deque<Coarse> queue_;
  bool active_ = false;  // interpolating segments (not waiting for the first two)
  AxisArray seg_from_{};
  Coarse seg_{};
  int seg_tick_ = 0;
  bool have_seg_ = false;
  AxisArray cmd_{};
  AxisArray prev_cmd_{};
  AxisArray vel_{};      // commanded velocity of the last tick, mm/s
  AxisArray last_sp_{};
  int64_t last_cycle_ = -1;
  int64_t gaps_ = 0;
  int64_t starved_ticks_ = 0;
  int64_t ticks_since_setpoint_ = 0;
  bool stopping_ = false;
  bool faulted_ = false;
  std::string fault_reason_;
};

}  // namespace cnc::bridge
