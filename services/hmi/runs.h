#pragma once
// Run analysis beside the HMI: what a recorded run was, read from
// its LCM log without touching the machine.
#include <cstdint>
#include <string>
#include <vector>

namespace cnc::hmi {

struct RunSummary {
  bool ok = false;
  std::string error;                  // the log could not be read
  double start_utime_s = 0;           // the first event (Unix seconds)
  double duration_s = 0;              // the first event to the last
  std::vector<std::string> programs;  // the programs loaded (PROGRAM_STATE LOADED), in order, MDI lines left out
  int64_t mdi_lines = 0;              // MDI and touch-off lines run
  int64_t alarms = 0;                 // ALARM messages
  int64_t faults = 0;                 // ... of severity FAULT
  int64_t events = 0;
};

// Reads the whole log once (its events' channels and times; PROGRAM_STATE and ALARM decoded).
RunSummary summarize_log(const std::string& path);

// The commanded path of a run for playing it back in the preview: the SETPOINTS of
// the log, thinned to a point where the path moved `tol_mm` or `max_gap_s` passed (at
// most `max_points`; halved and the tolerance doubled when more), with each point's
// time from the run's first setpoint (cycle x period) and source line.
struct RunPath {
  bool ok = false;
  std::string error;
  std::vector<double> xyz;     // 3 per point
  std::vector<double> t_s;
  std::vector<int> lines;
  double duration_s = 0;
  int64_t setpoints = 0;
};
RunPath log_path(const std::string& path, double tol_mm = 0.05, double max_gap_s = 0.25, size_t max_points = 40000);

}  // namespace cnc::hmi
