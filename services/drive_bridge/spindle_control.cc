#include "services/drive_bridge/spindle_control.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace cnc::bridge {

void SpindleControl::on_command(int64_t seq, int direction, double rpm, bool accept, double now_s) {
  if (seq <= seq_) return;
  seq_ = seq;
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

void SpindleControl::stop() {
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
  fault_ = std::move(why);
}

bool SpindleControl::update(const SpindleFeedback& fb, double now_s) {
  if (faulted_) return false;
  const bool lost = fb.lost_events > lost_seen_;
  lost_seen_ = fb.lost_events;
  if (lost && direction_ != 0) {
    std::string why = "spindle: the link to its drive was lost while it turned";
    if (!fb.last_error.empty()) why.append(" (").append(fb.last_error).append(")");
    raise(std::move(why));
    return true;
  }
  if (fb.have_status && !fb.setup_error.empty() && (direction_ != 0 || setup_raised_ != fb.lost_events)) {
    setup_raised_ = fb.lost_events;
    raise(std::string("spindle: ").append(fb.setup_error));
    return true;
  }
  if (fb.have_status && fb.error_code != 0) {
    char text[96];
    std::snprintf(text, sizeof text, "spindle: drive fault 0x%04X", fb.error_code);
    raise(text);
    return true;
  }
  if (direction_ != 0 && fb.have_status && !fb.running) {
    if (not_running_since_s_ < 0) not_running_since_s_ = now_s;
    if (now_s - not_running_since_s_ > kNotRunningS) {
      char text[160];
      std::snprintf(text, sizeof text,
                    "spindle: its drive does not run although commanded to (%.1f s): tripped, or stopped at its panel",
                    now_s - not_running_since_s_);
      raise(text);
      return true;
    }
  } else {
    not_running_since_s_ = -1;
  }
  if (at_speed()) return false;
  const double want = direction_ * rpm_;
  const double actual = actual_rpm(fb);
  if (fb.have_status && std::fabs(actual - want) <= cfg_.at_speed_tolerance * rpm_) {
    at_speed_seq_ = seq_;
    at_speed_s_ = now_s;
    return false;
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
    return true;
  }
  return false;
}

}  // namespace cnc::bridge
