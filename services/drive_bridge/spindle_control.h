#pragma once
// The spindle's logic in the drive bridge (a pure core: no LCM, no clock, no
// threads; time comes in as an argument). It takes the interpolator's spindle
// commands (SPINDLE_CMD: each change once, in the order of their command_seq),
// turns them into the VFD's run, direction and frequency, and watches the drive's
// answers: at speed when the output is within spindle.at_speed_tolerance of the
// command (a stop counts at once), and a fault, naming its reason, when a change is
// not at speed within spindle.at_speed_timeout_s, when the drive reports a fault
// code, when its link is lost while it should turn (naming the last failed
// transaction), and when the drive's own settings do not let the link drive it
// (once when read, and at every change that would turn it), and when the drive
// says it does not run although commanded to, for longer than kNotRunningS (a
// Huanyang has no fault code: a trip, or its panel's STOP, shows only so). A fault, and a stop of the
// bridge's own (its FAULT, a shut-down), stops the spindle; a command from before
// that stop is never taken again: only a newer change (after the interpolator's
// STOP or RESET) turns it again.
#include <cstdint>
#include <string>
#include <string_view>

#include "common/config/machine_config.h"

namespace cnc::bridge {

// What the drive answered, as the link worker last saw it.
struct SpindleFeedback {
  bool answering = false;
  bool have_status = false;
  bool running = false;
  uint16_t error_code = 0;
  double output_hz = 0;  // signed
  int64_t lost_events = 0;
  std::string_view last_error;   // the link's last failed transaction (names a lost link's cause)
  std::string_view setup_error;  // what is wrong with the drive's settings for the link, empty if nothing
};

class SpindleControl {
 public:
  // How long a drive may report not running while commanded to: a command's way to it
  // (a link round) and its own reaction, well within it.
  static constexpr double kNotRunningS = 0.5;
  explicit SpindleControl(const config::SpindleConfig& cfg) : cfg_(cfg) {}

  // A SPINDLE_CMD. Taken only when `accept` (the bridge follows setpoints) and newer
  // than every one before; an older or repeated one changes nothing.
  void on_command(int64_t seq, int direction, double rpm, bool accept, double now_s);
  // The bridge stops the spindle on its own (its fault, disable, shut-down).
  void stop();
  // Every servo tick. Returns true when this update raised a fault (fault_reason()).
  bool update(const SpindleFeedback& fb, double now_s);
  // After a fault: RESET / ENABLE of the bridge lets newer commands turn it again.
  void clear_fault();

  int direction() const { return direction_; }
  double commanded_rpm() const { return rpm_; }
  double commanded_hz() const { return rpm_ / cfg_.rpm_per_hz; }
  double actual_rpm(const SpindleFeedback& fb) const { return fb.output_hz * cfg_.rpm_per_hz; }
  int64_t command_seq() const { return seq_; }
  int64_t at_speed_seq() const { return at_speed_seq_; }
  bool at_speed() const { return at_speed_seq_ == seq_; }
  // From the newest change taken to its at-speed (its age while not at speed yet).
  double time_to_speed_s(double now_s) const { return (at_speed() ? at_speed_s_ : now_s) - taken_s_; }
  bool faulted() const { return faulted_; }
  const std::string& fault_reason() const { return fault_; }

 private:
  void raise(std::string why);
  config::SpindleConfig cfg_;
  int64_t seq_ = 0;           // the newest command seen
  int64_t at_speed_seq_ = 0;
  int direction_ = 0;         // as commanded to the drive
  double rpm_ = 0;            // >= 0, as commanded to the drive
  double deadline_s_ = 0;     // the change must be at speed by then
  double taken_s_ = 0;        // when the newest change was taken
  double at_speed_s_ = 0;     // and when it was at speed
  int64_t lost_seen_ = 0;
  double not_running_since_s_ = -1;  // commanded to run, the drive said it does not, since then
  int64_t setup_raised_ = -1;  // the lost_events count of the connection whose setup fault was raised
  bool faulted_ = false;
  std::string fault_;
};

}  // namespace cnc::bridge
