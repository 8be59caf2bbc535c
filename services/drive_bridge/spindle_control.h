#pragma once
// The spindle's logic in the drive bridge (a pure core: no LCM, no clock, no
// threads; time comes in as an argument). It takes the interpolator's spindle
// commands (SPINDLE_CMD: each change once, in the order of their command_seq),
// turns them into the drive's run, direction and speed, and watches the drive's
// answers: at speed when the output is within spindle.at_speed_tolerance of the
// command (a stop counts at once), and a fault, naming its reason, when a change is
// not at speed within spindle.at_speed_timeout_s, when the drive reports a fault,
// when its link is lost while it should turn (naming the last failed
// transaction), and when the drive's own settings do not let the link drive it
// (once when read, and at every change that would turn it), and when the drive
// says it does not run although commanded to, for longer than kNotRunningS (a
// Huanyang has no fault code: a trip, or its panel's STOP, shows only so). A fault, and a stop of the
// bridge's own (its FAULT, a shut-down), stops the spindle; a command from before
// that stop is never taken again: only a newer change (after the interpolator's
// STOP or RESET) turns it again.
//
// The encoder (spindle.encoder_counts_per_rev > 0): its unwrapped counter divided by
// the counts per revolution is the spindle's position in revolutions, positive in the
// clockwise (M3) direction: the drive's counter must count up while the spindle turns
// forward (its polarity setting). kEncoderCheckS after a speed change of 60 rpm or more
// got to speed, the encoder's speed is checked against the drive's: against it is a
// fault naming the polarity, off by more than a factor of two one naming
// encoder_counts_per_rev.
//
// Orientation (M19): a command with an angle and a way (shortest, clockwise,
// counterclockwise). A spindle turning faster than spindle.orient_rpm is first brought
// down to it in its direction; then the target is fixed: the position whose angle is
// the commanded one, the shortest way or the commanded one from where the spindle is
// (not a whole turn when it is within the tolerance already). A proportional loop on
// the measured position turns it there: speed = orient_gain_per_s x the error, at
// most orient_rpm, in whichever direction the error asks (an overshoot is corrected
// back). Oriented (latched for that command) once within orient_tolerance_deg and at
// rest (the encoder moved less than the tolerance in kRestS); the loop holds the
// position afterwards. Not oriented within orient_timeout_s: a fault naming it.
#include <array>
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
  bool drive_fault = false;  // the drive reports a fault (a CiA-402 drive's fault state; a VFD's error code)
  uint16_t error_code = 0;
  double output_hz = 0;  // signed
  int64_t lost_events = 0;
  std::string_view last_error;   // the link's last failed transaction (names a lost link's cause)
  std::string_view setup_error;  // what is wrong with the drive's settings for the link, empty if nothing
  // The encoder's counter (unwrapped) and when the drive sampled it (the bridge's monotonic clock).
  bool has_position = false;
  int64_t position_counts = 0;
  double sample_s = 0;
};

enum class OrientState : int8_t { kNone = 0, kOrienting = 1, kOriented = 2, kFault = 3 };

class SpindleControl {
 public:
  // How long a drive may report not running while commanded to: a command's way to it
  // (a link round) and its own reaction, well within it.
  static constexpr double kNotRunningS = 0.5;
  // The encoder's speed is the position's change over at least this long (the newest sample against an older one).
  static constexpr double kSpeedWindowS = 0.02;
  // At rest: the encoder moves less than the orientation's tolerance in this long.
  static constexpr double kRestS = 0.1;
  // The encoder's speed is checked against the drive's this long after a change got to
  // speed (its speed window then lies at that speed).
  static constexpr double kEncoderCheckS = 0.1;
  explicit SpindleControl(const config::SpindleConfig& cfg) : cfg_(cfg) {}

  // A SPINDLE_CMD. Taken only when `accept` (the bridge follows setpoints) and newer
  // than every one before; an older or repeated one changes nothing.
  void on_command(int64_t seq, int direction, double rpm, bool accept, double now_s);
  // A SPINDLE_CMD asking for orientation: the angle in degrees (any value: taken modulo
  // 360, clockwise from the encoder's zero) and the way, 0 shortest, 1 clockwise (M3's
  // direction), 2 counterclockwise. As on_command otherwise; one not accepted is
  // spent with orient_state kFault, and without an encoder it is a fault.
  void on_orient(int64_t seq, double degrees, int mode, bool accept, double now_s);
  // The bridge stops the spindle on its own (its fault, disable, shut-down); an orientation
  // still under way ends in kFault.
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

  // The encoder: the spindle's position in revolutions (positive clockwise, M3),
  // continuous, as last read; valid while the drive answers with it.
  bool position_valid() const { return position_valid_; }
  double position_rev() const { return position_rev_; }
  double sample_s() const { return sample_s_; }
  // Its speed, revolutions per second, over the last kSpeedWindowS or more; valid when known.
  bool speed_known() const { return speed_known_; }
  double speed_rev_s() const { return speed_rev_s_; }
  // The orientation of command_seq(), and the time since it was taken.
  OrientState orient_state() const { return orient_state_; }
  double orient_age_s(double now_s) const { return now_s - taken_s_; }
  // Where it turns the spindle to (revolutions, on position_rev's scale), once fixed.
  bool orient_target_known() const { return target_known_; }
  double orient_target_rev() const { return target_rev_; }

 private:
  void raise(std::string why);
  void check(const SpindleFeedback& fb, double now_s);
  void take_sample(const SpindleFeedback& fb);
  void check_encoder(const SpindleFeedback& fb);
  void orient_step(double now_s);
  void command_speed(double rev_s);  // a signed speed of the position loop, to the drive
  config::SpindleConfig cfg_;
  int64_t seq_ = 0;           // the newest command seen
  int64_t at_speed_seq_ = 0;
  int direction_ = 0;         // as commanded to the drive
  double rpm_ = 0;            // >= 0, as commanded to the drive
  double deadline_s_ = 0;     // the change must be at speed by then
  double taken_s_ = 0;        // when the newest change was taken
  double at_speed_s_ = 0;     // and when it was at speed
  double encoder_check_s_ = -1;  // when the encoder's speed is checked against the drive's (-1: not due)
  int64_t lost_seen_ = 0;
  double not_running_since_s_ = -1;  // commanded to run, the drive said it does not, since then
  int64_t setup_raised_ = -1;  // the lost_events count of the connection whose setup fault was raised
  bool faulted_ = false;
  bool raised_ = false;  // a fault raised and not yet returned by update()
  std::string fault_;
  // The encoder's last samples, (time, revolutions), a ring: its speed.
  struct Sample {
    double t = 0;
    double rev = 0;
  };
  static constexpr size_t kSamples = 64;
  std::array<Sample, kSamples> samples_{};
  size_t sample_head_ = 0;  // the next slot
  size_t sample_count_ = 0;
  bool position_valid_ = false;
  double position_rev_ = 0;
  double sample_s_ = 0;
  bool speed_known_ = false;
  double speed_rev_s_ = 0;
  // The orientation under way (orient_ while the loop runs).
  bool orient_ = false;
  OrientState orient_state_ = OrientState::kNone;
  double orient_deg_ = 0;
  int orient_mode_ = 0;
  bool target_known_ = false;
  double target_rev_ = 0;
};

}  // namespace cnc::bridge
