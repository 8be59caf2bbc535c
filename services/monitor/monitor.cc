#include "services/monitor/monitor.h"

#include <cmath>

namespace cnc::monitor {

FeedSample FeedMonitor::on_status(int64_t cycle, const std::vector<double>& actual,
                                  const std::vector<double>& following) {
  FeedSample s;
  s.commanded_feed_mm_per_min = commanded_;
  if (last_cycle_ >= 0 && cycle > last_cycle_ && last_actual_.size() == actual.size()) {
    double d2 = 0;
    for (size_t i = 0; i < actual.size(); ++i) d2 += (actual[i] - last_actual_[i]) * (actual[i] - last_actual_[i]);
    last_feed_ = std::sqrt(d2) / (static_cast<double>(cycle - last_cycle_) * period_s_) * 60.0;
  }
  // Statuses of the same setpoint cycle (the bridge idles between setpoints) keep the last feed.
  if (cycle != last_cycle_) {
    last_actual_ = actual;
    last_cycle_ = cycle;
  }
  s.actual_feed_mm_per_min = last_feed_;
  for (double fe : following) s.max_following_error_mm = std::max(s.max_following_error_mm, std::fabs(fe));
  largest_fe_ = std::max(largest_fe_, s.max_following_error_mm);
  return s;
}

}  // namespace cnc::monitor
