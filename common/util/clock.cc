#include "common/util/clock.h"

#include <algorithm>
#include <cerrno>
#include <cmath>

namespace cnc::util {
namespace {
constexpr int64_t kNsPerS = 1'000'000'000;

int64_t to_ns(const timespec& t) { return int64_t{t.tv_sec} * kNsPerS + t.tv_nsec; }
timespec from_ns(int64_t ns) {
  timespec t{};
  t.tv_sec = static_cast<time_t>(ns / kNsPerS);
  t.tv_nsec = static_cast<long>(ns % kNsPerS);
  return t;
}
}  // namespace

int64_t next_token(int64_t previous) { return std::max(previous + 1, wall_utime()); }

int64_t wall_utime() {
  timespec t{};
  clock_gettime(CLOCK_REALTIME, &t);
  return int64_t{t.tv_sec} * 1'000'000 + t.tv_nsec / 1000;
}

double monotonic_s() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec) * 1e-9;
}

PeriodicTimer::PeriodicTimer(double period_s)
    : period_s_(period_s), period_ns_(static_cast<int64_t>(std::llround(period_s * 1e9))) {
  clock_gettime(CLOCK_MONOTONIC, &next_);
}

bool PeriodicTimer::wait() {
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  const int64_t now_ns = to_ns(now);
  if (last_wake_ns_ >= 0) compute_.record_ns(now_ns - last_wake_ns_);
  const int64_t deadline = to_ns(next_) + period_ns_;
  int64_t next = deadline;
  if (now_ns - next >= period_ns_) {
    // Late by at least a whole period: skip the missed deadlines.
    const int64_t missed = (now_ns - next) / period_ns_;
    overruns_ += missed;
    next += missed * period_ns_;
  }
  next_ = from_ns(next);
  ++cycles_;
  const int rc = clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next_, nullptr);
  if (rc == EINTR) {
    last_wake_ns_ = -1;
    return false;
  }
  timespec woke{};
  clock_gettime(CLOCK_MONOTONIC, &woke);
  last_wake_ns_ = to_ns(woke);
  wake_.record_ns(last_wake_ns_ - deadline);
  return true;
}

}  // namespace cnc::util
