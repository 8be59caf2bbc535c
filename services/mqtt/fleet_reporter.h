#pragma once
// cnc-mqtt's core: the cell's state, alarms and program runs as MQTT records (topic,
// JSON payload, retained or not) from plain structs. No LCM, no broker, no clock: the
// node hands it the bus's messages and the time, and publishes what it returns.
// docs/mqtt.md has the topics and payloads.
#include <cstdint>
#include <string>
#include <vector>

namespace cnc::mqtt {

struct Record {
  std::string topic;    // the whole topic: PREFIX/CELL/...
  std::string payload;  // JSON
  bool retained = false;
  // A job or alarm record: kept by the client while the broker is away and sent once
  // it is back (QoS 1, persistent session). The state is not: the next one replaces it.
  bool durable = false;
};

// lcmt_program_state's and lcmt_setpoint's (interpolator) state numbers.
struct ProgramStateIn {
  int64_t utime = 0;
  int state = 0;  // IDLE 0, LOADED 1, RUNNING 2, HELD 3, DONE 4, REFUSED 5, STOPPED 6, FAULT 7
  int64_t token = 0;
  std::string path;
  std::string error;
};

struct InterpStateIn {
  int64_t utime = 0;
  int state = 0;  // IDLE 0, RUNNING 1, HELD 2, DONE 3, STARVED 4, FAULT 5
  int mode = 0;   // PROGRAM 0, JOG 1, HOME 2
  std::string mode_text;
  int64_t program_token = 0;
  int64_t blocks_done = 0;
  double program_time_s = 0;
  double feed_override = 1, rapid_override = 1, spindle_override = 1;
  std::vector<double> position_mm;  // commanded, one per axis
};

struct AlarmIn {
  int64_t utime = 0;
  std::string source;
  int severity = 0;  // INFO 0, WARNING 1, FAULT 2
  std::string code;
  std::string text;
};

struct SpindleIn {
  int state = 0;  // STARTING 0, STOPPED 1, RUNNING 2, FAULT 3
  double commanded_rpm = 0, actual_rpm = 0;
};

class FleetReporter {
 public:
  // root: PREFIX/CELL; axes: the axes' names in the bus's order.
  FleetReporter(std::string root, std::string cell, std::vector<std::string> axes, double state_period_s,
                std::string version, bool spindle);

  // The status topic's records: online (published at every connection), the last will
  // (the broker publishes it when the connection is lost), offline at a clean stop.
  Record birth(int64_t utime) const;
  Record will() const;
  Record stopped(int64_t utime) const;

  void on_program_state(const ProgramStateIn& m, std::vector<Record>* out);
  void on_interp_state(const InterpStateIn& m);
  // The drive bridge's actual positions and following errors (AXIS_STATUS), n axes.
  void on_axis_status(const double* actual_mm, const double* following_error_mm, int n);
  void on_spindle(const SpindleIn& m);
  void on_alarm(const AlarmIn& m, std::vector<Record>* out);
  // The logger's current file (LOGGER_STATS): the run's log.
  void on_log_path(const std::string& path) { log_path_ = path; }
  // The retained state when a period has passed since the last one, the program's
  // state changed, or `force` (after a (re)connection).
  void tick(double now_s, int64_t utime, bool force, std::vector<Record>* out);

  int64_t jobs_started() const { return jobs_started_; }
  int64_t jobs_ended() const { return jobs_ended_; }
  int64_t alarms() const { return alarms_; }
  int64_t states() const { return states_; }

 private:
  struct Run {
    bool active = false;
    std::string id, program, path, log;
    int64_t token = 0, start_utime = 0;
    double max_following_error_mm = 0;
    int64_t alarms = 0;
    std::vector<AlarmIn> first_alarms;  // the first kMaxListedAlarms
  };
  static constexpr size_t kMaxListedAlarms = 20;

  void start_run(const ProgramStateIn& m, std::vector<Record>* out);
  void end_run(int64_t utime, const char* outcome, const std::string& error, std::vector<Record>* out);

  std::string root_, cell_, version_;
  std::vector<std::string> axes_;
  double state_period_s_;
  bool spindle_;

  ProgramStateIn program_;
  bool program_seen_ = false, program_changed_ = false;
  InterpStateIn interp_;
  bool interp_seen_ = false;
  std::vector<double> actual_mm_;
  double following_error_mm_ = 0;  // the largest of the axes', now
  SpindleIn spindle_in_;
  bool spindle_seen_ = false;
  std::string log_path_;
  Run run_;
  double last_state_s_ = -1e18;
  int64_t jobs_started_ = 0, jobs_ended_ = 0, alarms_ = 0, states_ = 0;
};

// "running", "done", ... (lcmt_program_state); "?" outside the range.
const char* program_state_name(int state);
// "idle", "running", ... (lcmt_setpoint's interpolator states).
const char* interp_state_name(int state);

}  // namespace cnc::mqtt
