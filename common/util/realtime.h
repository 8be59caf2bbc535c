#pragma once
// Real-time set-up for the cyclic services (interpolator, drive bridge, servo
// simulator; the monitor and the logger at lower priorities): SCHED_FIFO at the
// given priority, locked memory and, from `timing.realtime_cpus`, CPU affinity, so
// a busy shop-floor PC does not stall the servo loop. SCHED_FIFO and mlockall need
// root or CAP_SYS_NICE / CAP_IPC_LOCK. Threads created afterwards inherit all three.
//
// And the evidence: the cycle timing every cyclic loop records (PeriodicTimer, or
// two LatencyHistograms beside an event loop), printed to the service's log and
// written as DIR/<service>.json at the end of the run.
#include <cstdint>
#include <string>
#include <vector>

#include "common/util/clock.h"
#include "common/util/latency_histogram.h"

namespace cnc::util {

// priority 1..98; 0 does nothing. Returns "" on success, else why it failed: the
// scheduling policy is then unchanged unless the reason says "SCHED_FIFO set".
std::string make_realtime(int priority);

// Pins the calling thread to `cpus` (empty: no pinning). A CPU this machine does
// not have (or this process may not use) is left out; *applied receives the CPUs
// pinned to (empty when none). Returns "" when every CPU was applied, else why not.
std::string pin_to_cpus(const std::vector<int>& cpus, std::vector<int>* applied = nullptr);

// make_realtime, then pin_to_cpus; each refusal is logged as a warning naming the
// service, what was asked, why it is not possible and how the service runs instead.
void apply_realtime(const std::string& service, int priority, const std::vector<int>& cpus);

// Memory for a cyclic thread without page faults in its cycles: mlockall(MCL_CURRENT |
// MCL_FUTURE) unless make_realtime locked it already, where permitted (CAP_IPC_LOCK, or
// an unlimited RLIMIT_MEMLOCK: under a finite limit MCL_FUTURE would make later
// allocations fail), then `stack_bytes` of the calling thread's stack touched. Returns
// "" when memory is locked, else why not (the stack is touched either way).
std::string prepare_cyclic_memory(size_t stack_bytes = 256 * 1024);

// The calling thread's scheduling as it is: "SCHED_FIFO 40, memory locked, CPUs 1"
// or "SCHED_OTHER, memory not locked, CPUs 0-1".
std::string describe_scheduling();

// "0-1,3" for {0, 1, 3}.
std::string cpu_list(const std::vector<int>& cpus);

// The cycle timing of one service at the end of its run.
struct LatencyReport {
  std::string service;      // e.g. "cnc-interpolator"; the file is DIR/<service>.json
  std::string loop;         // what was timed, e.g. "interpolation cycle"
  double period_s = 0;      // the loop's period; 0 for an event loop
  int64_t cycles = 0;
  int64_t overruns = 0;
  std::string overruns_what = "deadlines missed by a whole period";
  std::string wake_what = "wake-up latency: time read after the sleep minus the deadline";
  std::string compute_what = "compute: from the wake-up to the end of the cycle's work";
  const LatencyHistogram* wake = nullptr;
  const LatencyHistogram* compute = nullptr;
};

// The directory for the latency files: `option` when set (--latency-dir), else
// $CNC_LATENCY_DIR, else "" (no file).
std::string latency_dir(const std::string& option);

// Logs the two summary lines (min, mean, p99, p99.9, max in µs, cycles, overruns,
// scheduling) and, when dir is not empty, writes DIR/<service>.json (creating DIR).
// Call it from the cyclic thread (the scheduling it reports is the caller's).
void report_latency(const LatencyReport& r, const std::string& dir);

// The same for a loop paced by a PeriodicTimer: its period, cycles, overruns and
// both histograms.
void report_timer_latency(const std::string& service, const std::string& loop, const PeriodicTimer& timer,
                          const std::string& dir);

}  // namespace cnc::util
