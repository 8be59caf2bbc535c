#pragma once
// The tables of a recorded run, for plotting: fed with the decoded messages of a
// log (in log order), it writes setpoints.csv, monitor.csv, axis_status.csv,
// alarms.csv, summary.json and, for a cell with a spindle, spindle_status.csv. No LCM
// here; main.cc reads the log.
//
// One time axis for every table: t_s = (cycle - cycle0) * T_ipo, where cycle0 is
// the first RUNNING setpoint (the first setpoint when none ran). Monitor and axis
// rows are placed by their setpoint_cycle, alarms by their utime against cycle0's.
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_logger_stats.hpp"
#include "cnc/lcmt_monitor_report.hpp"
#include "cnc/lcmt_program_block.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "cnc/lcmt_spindle_status.hpp"
#include "common/config/machine_config.h"

namespace cnc::logexport {

struct ChannelSummary {
  int64_t events = 0;
  int64_t senders = 0;
  int64_t seq_gaps = 0;
  int64_t seq_restarts = 0;
};

class LogExport {
 public:
  // The config the interpolator recorded (INTERP_CONFIG): axis names, ε, process.
  void on_config(const config::MachineConfig& cfg, const std::string& source_file);
  void on_setpoint(const cnc::lcmt_setpoint& m);
  void on_monitor(const cnc::lcmt_monitor_report& m);
  void on_axis_status(const cnc::lcmt_axis_status& m);
  void on_alarm(const cnc::lcmt_alarm& m);
  void on_program_state(const cnc::lcmt_program_state& m) { program_ = m; }
  void on_interp_state(const cnc::lcmt_interp_state& m) { interp_ = m; }
  void on_program_block(const cnc::lcmt_program_block& m);
  void on_logger_stats(const cnc::lcmt_logger_stats& m);
  // Of any log format (common/service/spindle_status_msg.h).
  void on_spindle_status(const cnc::lcmt_spindle_status& m) { spindle_.push_back(m); }

  // Writes the tables and summary.json into `dir` (created). `log_files`: the files
  // read; `channels`: per-channel counts as the reader's bus saw them.
  void write(const std::string& dir, const std::vector<std::string>& log_files, const std::string& prefix,
             const std::map<std::string, ChannelSummary>& channels) const;

  size_t setpoints() const { return setpoints_.size(); }

 private:
  int64_t cycle0() const;
  double period_s() const;
  std::vector<std::string> axis_names(size_t n) const;
  const cnc::lcmt_logger_stats* own_logger_stats(const std::vector<std::string>& log_files) const;

  std::optional<config::MachineConfig> config_;
  std::string config_source_;
  std::vector<cnc::lcmt_setpoint> setpoints_;
  std::vector<cnc::lcmt_monitor_report> monitor_;
  std::vector<cnc::lcmt_axis_status> axis_status_;
  std::vector<cnc::lcmt_alarm> alarms_;
  std::vector<cnc::lcmt_spindle_status> spindle_;
  std::optional<cnc::lcmt_program_state> program_;
  std::optional<cnc::lcmt_interp_state> interp_;
  std::map<int32_t, cnc::lcmt_logger_stats> logger_stats_;  // the last report of each logger
  std::vector<std::string> status_axis_names_;
  double block_target_rmax_um_ = 0;  // the process parameters of the program's blocks
};

}  // namespace cnc::logexport
