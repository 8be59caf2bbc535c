#include "services/drive_bridge/spindle_control.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace cnc::bridge {

void SpindleControl::on_command(int64_t seq, int direction, double rpm, bool accept, double now_s) {
  if (seq <= seq_) return;
  seq_ = seq;
  encoder_check_s_ = -1;
  orient_ = false;
  orient_state_ = OrientState::kNone;
  if (!accept || faulted_ || !std::isfinite(rpm)) {
    // Not to be followed now, and never later: this change is spent.
    direction_ = 0;
    rpm_ = 0;
    at_speed_seq_ = seq;
    return;
  }
  direction_ = direction > 0 ? 1 : direction < 0 ? -1 : 0;
  rpm_ = direction_ == 0 ? 0.0 : std::clamp(rpm, 0.0, cfg_.max_rpm);
  deadline_s_ = now_s + cfg_.at_speed_timeout_s;
  taken_s_ = at_speed_s_ = now_s;
  if (direction_ == 0 || rpm_ == 0) at_speed_seq_ = seq;  // a stop is not waited for
}

void SpindleControl::on_orient(int64_t seq, double degrees, int mode, bool accept, double now_s) {
  if (seq <= seq_) return;
  seq_ = seq;
  encoder_check_s_ = -1;
  // Not a speed change: nothing waits for it at speed (the interpolator waits on orient_state).
  at_speed_seq_ = seq;
  direction_ = 0;
  rpm_ = 0;
  orient_ = false;
  target_known_ = false;
  if (!accept || faulted_ || !std::isfinite(degrees) || mode < 0 || mode > 2) {
    orient_state_ = OrientState::kFault;  // spent: it will not be carried out
    return;
  }
  if (cfg_.encoder_counts_per_rev <= 0) {
    raise("spindle: orientation (M19) needs the spindle's encoder: spindle.encoder_counts_per_rev is 0");
    orient_state_ = OrientState::kFault;
    return;
  }
  orient_ = true;
  orient_state_ = OrientState::kOrienting;
  orient_deg_ = degrees;
  orient_mode_ = mode;
  taken_s_ = now_s;
  deadline_s_ = now_s + cfg_.orient_timeout_s;
}

void SpindleControl::stop() {
  if (orient_ && orient_state_ == OrientState::kOrienting) orient_state_ = OrientState::kFault;
  orient_ = false;
  not_running_since_s_ = -1;
  direction_ = 0;
  rpm_ = 0;
  at_speed_seq_ = seq_;
}

void SpindleControl::clear_fault() {
  faulted_ = false;
  fault_.clear();
}

void SpindleControl::raise(std::string why) {
  stop();
  faulted_ = true;
  raised_ = true;
  fault_ = std::move(why);
}

bool SpindleControl::update(const SpindleFeedback& fb, double now_s) {
  take_sample(fb);  // also while faulted: the position stays on the bus
  if (!faulted_) check(fb, now_s);
  // A fault raised here or since the last update (a command that could not be carried out), once.
  const bool raised = raised_;
  raised_ = false;
  return raised;
}

void SpindleControl::check(const SpindleFeedback& fb, double now_s) {
  const bool lost = fb.lost_events > lost_seen_;
  lost_seen_ = fb.lost_events;
  if (lost && direction_ != 0) {
    std::string why = "spindle: the link to its drive was lost while it turned";
    if (!fb.last_error.empty()) why.append(" (").append(fb.last_error).append(")");
    raise(std::move(why));
    return;
  }
  if (fb.have_status && !fb.setup_error.empty() && (direction_ != 0 || setup_raised_ != fb.lost_events)) {
    setup_raised_ = fb.lost_events;
    raise(std::string("spindle: ").append(fb.setup_error));
    return;
  }
  if (fb.have_status && (fb.drive_fault || fb.error_code != 0)) {
    char text[96];
    std::snprintf(text, sizeof text, "spindle: drive fault 0x%04X", fb.error_code);
    raise(text);
    return;
  }
  if (direction_ != 0 && fb.have_status && !fb.running) {
    if (not_running_since_s_ < 0) not_running_since_s_ = now_s;
    if (now_s - not_running_since_s_ > kNotRunningS) {
      char text[160];
      std::snprintf(text, sizeof text,
                    "spindle: its drive does not run although commanded to (%.1f s): tripped, or stopped at its panel",
                    now_s - not_running_since_s_);
      raise(text);
      return;
    }
  } else {
    not_running_since_s_ = -1;
  }
  if (orient_) {
    orient_step(now_s);
    return;
  }
  if (at_speed()) {
    if (encoder_check_s_ >= 0 && now_s >= encoder_check_s_) {
      encoder_check_s_ = -1;
      check_encoder(fb);
    }
    return;
  }
  const double want = direction_ * rpm_;
  const double actual = actual_rpm(fb);
  if (fb.have_status && std::fabs(actual - want) <= cfg_.at_speed_tolerance * rpm_) {
    at_speed_seq_ = seq_;
    at_speed_s_ = now_s;
    encoder_check_s_ = now_s + kEncoderCheckS;
    return;
  }
  if (now_s > deadline_s_) {
    char text[200];
    if (fb.have_status)
      std::snprintf(text, sizeof text, "spindle: %.0f rpm not reached within %.1f s (at %.0f rpm, tolerance %.1f %%)",
                    want, cfg_.at_speed_timeout_s, actual, cfg_.at_speed_tolerance * 100);
    else
      std::snprintf(text, sizeof text, "spindle: %.0f rpm not reached within %.1f s: its drive does not answer%s%.*s%s",
                    want, cfg_.at_speed_timeout_s, fb.last_error.empty() ? "" : " (",
                    static_cast<int>(fb.last_error.size()), fb.last_error.data(), fb.last_error.empty() ? "" : ")");
    raise(text);
    return;
  }
}

void SpindleControl::take_sample(const SpindleFeedback& fb) {
  if (!fb.has_position || cfg_.encoder_counts_per_rev <= 0) {
    position_valid_ = speed_known_ = false;
    sample_count_ = 0;
    return;
  }
  position_valid_ = true;
  if (sample_count_ > 0 && fb.sample_s <= sample_s_) return;  // the same read again
  position_rev_ = static_cast<double>(fb.position_counts) / static_cast<double>(cfg_.encoder_counts_per_rev);
  sample_s_ = fb.sample_s;
  samples_[sample_head_] = Sample{sample_s_, position_rev_};
  sample_head_ = (sample_head_ + 1) % kSamples;
  sample_count_ = std::min(sample_count_ + 1, kSamples);
  // The speed against the newest sample at least kSpeedWindowS older.
  speed_known_ = false;
  for (size_t k = 1; k < sample_count_; ++k) {
    const Sample& old = samples_[(sample_head_ + kSamples - 1 - k) % kSamples];
    if (sample_s_ - old.t >= kSpeedWindowS) {
      speed_rev_s_ = (position_rev_ - old.rev) / (sample_s_ - old.t);
      speed_known_ = true;
      break;
    }
  }
}

void SpindleControl::check_encoder(const SpindleFeedback& fb) {
  const double drive_rpm = actual_rpm(fb);
  if (!speed_known_ || direction_ == 0 || std::fabs(drive_rpm) < 60) return;
  const double encoder_rpm = speed_rev_s_ * 60;
  const double ratio = encoder_rpm / drive_rpm;
  if (ratio >= 0.5 && ratio <= 2) return;
  char text[320];
  if (ratio < 0)
    std::snprintf(text, sizeof text,
                  "spindle: its encoder counts against the drive's turning (the drive at %.0f rpm, the encoder %.0f "
                  "rpm): its counter must count up clockwise (M3): set the encoder's polarity in the drive",
                  drive_rpm, encoder_rpm);
  else
    std::snprintf(text, sizeof text,
                  "spindle: its encoder reads %.0f rpm, the drive %.0f rpm: spindle.encoder_counts_per_rev (%lld) is not "
                  "the encoder's counts per spindle revolution",
                  encoder_rpm, drive_rpm, static_cast<long long>(cfg_.encoder_counts_per_rev));
  raise(text);
}

void SpindleControl::command_speed(double rev_s) {
  direction_ = rev_s > 0 ? 1 : rev_s < 0 ? -1 : 0;
  rpm_ = std::min(std::fabs(rev_s) * 60, cfg_.max_rpm);
}

void SpindleControl::orient_step(double now_s) {
  const double tol_rev = cfg_.orient_tolerance_deg / 360;
  const double max_rev_s = cfg_.orient_rpm / 60;
  if (orient_state_ == OrientState::kOrienting && now_s > deadline_s_) {
    char text[320];
    if (!position_valid_) {
      std::snprintf(text, sizeof text,
                    "spindle: orientation to %.2f deg not reached within %.1f s (spindle.orient_timeout_s): its encoder "
                    "position is not read",
                    orient_deg_, cfg_.orient_timeout_s);
    } else {
      const double angle = (position_rev_ - std::floor(position_rev_)) * 360;
      std::snprintf(text, sizeof text,
                    "spindle: orientation to %.2f deg not reached within %.1f s (spindle.orient_timeout_s): at %.2f deg, "
                    "%.2f deg off, %s (tolerance %.2f deg)",
                    orient_deg_, cfg_.orient_timeout_s, angle,
                    target_known_ ? (target_rev_ - position_rev_) * 360 : std::remainder(orient_deg_ - angle, 360.0),
                    speed_known_ && std::fabs(speed_rev_s_) * kRestS <= tol_rev ? "at rest" : "moving",
                    cfg_.orient_tolerance_deg);
    }
    raise(text);
    orient_state_ = OrientState::kFault;
    return;
  }
  if (!position_valid_ || !speed_known_) {
    command_speed(0);  // nothing to steer by yet
    return;
  }
  if (!target_known_) {
    if (std::fabs(speed_rev_s_) > 1.1 * max_rev_s) {
      // Faster than the orientation's speed: down to it first, in the direction it turns.
      command_speed(std::copysign(max_rev_s, speed_rev_s_));
      return;
    }
    const double frac = position_rev_ - std::floor(position_rev_);
    const double want = orient_deg_ / 360 - std::floor(orient_deg_ / 360);
    double cw = want - frac;  // [0, 1): clockwise to it
    if (cw < 0) cw += 1;
    const double ccw = cw - 1;  // (-1, 0]: counterclockwise to it
    double d = 0;
    if (cw <= tol_rev) d = cw;          // there (or just short of it)
    else if (-ccw <= tol_rev) d = ccw;  // just past it: no whole turn
    else if (orient_mode_ == 1) d = cw;
    else if (orient_mode_ == 2) d = ccw;
    else d = cw <= 0.5 ? cw : ccw;
    target_rev_ = position_rev_ + d;
    target_known_ = true;
  }
  const double err = target_rev_ - position_rev_;
  command_speed(std::clamp(cfg_.orient_gain_per_s * err, -max_rev_s, max_rev_s));
  if (orient_state_ == OrientState::kOrienting && std::fabs(err) <= tol_rev &&
      std::fabs(speed_rev_s_) * kRestS <= tol_rev)
    orient_state_ = OrientState::kOriented;
}

}  // namespace cnc::bridge
