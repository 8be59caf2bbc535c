#pragma once
// Clocks and the periodic loop of the services. Cores never include this file:
// they are driven by cycle indices, not by time.
#include <cstdint>
#include <ctime>

#include "common/util/latency_histogram.h"

namespace cnc::util {

// Wall-clock time in µs since the epoch: the `utime` of every message.
int64_t wall_utime();
// Monotonic time in s, for measuring durations.
double monotonic_s();
// A token larger than `previous` and than every token this function returned in
// an earlier process on this host (the wall clock in µs, unless that stands
// behind): names a setpoint stream or an engagement so that no receiver confuses
// it with one before a reset or a restart.
int64_t next_token(int64_t previous);

// Waits on absolute deadlines (clock_nanosleep TIMER_ABSTIME) so the period does
// not drift with the work done in each cycle. A cycle that starts after its
// deadline has passed by a whole period counts as an overrun and the schedule is
// moved on instead of bursting to catch up.
//
// Every cycle is timed, without allocation, lock or I/O: the wake-up latency (the
// time read after the sleep minus the deadline the cycle was due at, before any
// skipping) and the compute time (from that wake-up to the next call of wait(),
// i.e. the whole work of the cycle). A sleep interrupted by a signal records
// neither.
class PeriodicTimer {
 public:
  explicit PeriodicTimer(double period_s);
  // Sleeps until the next deadline. Returns false when the sleep was interrupted
  // by a signal (the caller then checks its stop flag).
  bool wait();
  int64_t overruns() const { return overruns_; }
  int64_t cycles() const { return cycles_; }
  double period_s() const { return period_s_; }
  const LatencyHistogram& wake_latency() const { return wake_; }
  const LatencyHistogram& compute_time() const { return compute_; }

 private:
  double period_s_;
  int64_t period_ns_;
  timespec next_{};
  int64_t overruns_ = 0;
  int64_t cycles_ = 0;
  int64_t last_wake_ns_ = -1;  // -1: no cycle running
  LatencyHistogram wake_;
  LatencyHistogram compute_;
};

}  // namespace cnc::util
