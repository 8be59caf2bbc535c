#pragma once
// Monitor core: actual feed from consecutive axis statuses, commanded feed from
// the setpoints, following error. Pure: fed with plain values.
#include <cstdint>
#include <vector>

namespace cnc::monitor {

struct FeedSample {
  double commanded_feed_mm_per_min = 0;
  double actual_feed_mm_per_min = 0;
  double max_following_error_mm = 0;
};

class FeedMonitor {
 public:
  explicit FeedMonitor(double ipo_period_s) : period_s_(ipo_period_s) {}
  void on_commanded_feed(double feed_mm_per_min) { commanded_ = feed_mm_per_min; }
  // One axis status: its setpoint cycle and actual positions.
  FeedSample on_status(int64_t cycle, const std::vector<double>& actual_mm, const std::vector<double>& following_mm);
  double largest_following_error_mm() const { return largest_fe_; }

 private:
  double period_s_;
  double commanded_ = 0;
  std::vector<double> last_actual_;
  int64_t last_cycle_ = -1;
  double last_feed_ = 0;
  double largest_fe_ = 0;
};

}  // namespace cnc::monitor
