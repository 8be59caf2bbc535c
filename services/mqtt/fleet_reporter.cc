#include "services/mqtt/fleet_reporter.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <utility>

namespace cnc::mqtt {
namespace {

using json = nlohmann::json;

constexpr int kRunning = 2, kHeld = 3, kDone = 4, kRefused = 5, kStopped = 6, kFault = 7;

// Every number published is finite: anything else goes out as null.
json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

std::string file_name(const std::string& path) {
  const size_t slash = path.rfind('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

// An MDI line or a touch-off runs as a one-line program of the server's own: no job.
bool operator_line(const std::string& path) { return file_name(path).rfind("mdi-", 0) == 0; }

const char* severity_name(int s) {
  static const char* const k[] = {"info", "warning", "fault"};
  return s >= 0 && s < 3 ? k[s] : "?";
}

json alarm_json(const AlarmIn& a) {
  return {{"utime", a.utime}, {"source", a.source}, {"severity", severity_name(a.severity)}, {"code", a.code},
          {"text", a.text}};
}

}  // namespace

const char* program_state_name(int s) {
  static const char* const k[] = {"idle", "loaded", "running", "held", "done", "refused", "stopped", "fault"};
  return s >= 0 && s < 8 ? k[s] : "?";
}

const char* interp_state_name(int s) {
  static const char* const k[] = {"idle", "running", "held", "done", "starved", "fault"};
  return s >= 0 && s < 6 ? k[s] : "?";
}

FleetReporter::FleetReporter(std::string root, std::string cell, std::vector<std::string> axes, double state_period_s,
                             std::string version, bool spindle)
    : root_(std::move(root)),
      cell_(std::move(cell)),
      version_(std::move(version)),
      axes_(std::move(axes)),
      state_period_s_(state_period_s),
      spindle_(spindle) {}

Record FleetReporter::birth(int64_t utime) const {
  return {root_ + "/status", json{{"status", "online"}, {"cell", cell_}, {"version", version_}, {"utime", utime}}.dump(),
          true, false};
}

Record FleetReporter::will() const {
  return {root_ + "/status", json{{"status", "offline"}, {"cell", cell_}, {"reason", "connection lost"}}.dump(), true,
          false};
}

Record FleetReporter::stopped(int64_t utime) const {
  return {root_ + "/status",
          json{{"status", "offline"}, {"cell", cell_}, {"reason", "stopped"}, {"utime", utime}}.dump(), true, false};
}

void FleetReporter::on_program_state(const ProgramStateIn& m, std::vector<Record>* out) {
  if (!program_seen_ || m.state != program_.state || m.token != program_.token || m.path != program_.path)
    program_changed_ = true;
  program_seen_ = true;
  program_ = m;
  const bool in_run = m.state == kRunning || m.state == kHeld;
  // Another program's token while a run is open: the run was left (a new load).
  if (run_.active && (m.token != run_.token || !in_run)) {
    switch (m.state) {
      case kDone: end_run(m.utime, m.token == run_.token ? "done" : "aborted", "", out); break;
      case kStopped: end_run(m.utime, m.token == run_.token ? "stopped" : "aborted", "", out); break;
      case kFault: end_run(m.utime, "fault", m.error, out); break;
      case kRefused: end_run(m.utime, "refused", m.error, out); break;
      default: end_run(m.utime, "aborted", "", out); break;
    }
  }
  if (in_run && !run_.active && !operator_line(m.path)) start_run(m, out);
}

void FleetReporter::start_run(const ProgramStateIn& m, std::vector<Record>* out) {
  run_ = Run{};
  run_.active = true;
  run_.program = file_name(m.path);
  run_.path = m.path;
  run_.token = m.token;
  run_.start_utime = m.utime;
  run_.log = log_path_;
  // Unique across restarts of cnc-mqtt and of the program server: the start's time.
  run_.id = run_.program + "#" + std::to_string(m.token) + "." + std::to_string(m.utime);
  ++jobs_started_;
  json j = {{"job", run_.id},       {"cell", cell_},           {"program", run_.program}, {"path", run_.path},
            {"token", run_.token},  {"start_utime", m.utime},  {"log", log_path_.empty() ? json(nullptr) : json(log_path_)}};
  out->push_back({root_ + "/job/start", j.dump(), false, true});
}

void FleetReporter::end_run(int64_t utime, const char* outcome, const std::string& error, std::vector<Record>* out) {
  ++jobs_ended_;
  json alarms = json::array();
  for (const AlarmIn& a : run_.first_alarms) alarms.push_back(alarm_json(a));
  const bool same = interp_seen_ && interp_.program_token == run_.token;
  const std::string log = run_.log.empty() ? log_path_ : run_.log;
  json j = {{"job", run_.id},
            {"cell", cell_},
            {"program", run_.program},
            {"path", run_.path},
            {"token", run_.token},
            {"outcome", outcome},
            {"error", error},
            {"start_utime", run_.start_utime},
            {"end_utime", utime},
            {"duration_s", num(static_cast<double>(utime - run_.start_utime) * 1e-6)},
            {"program_time_s", same ? num(interp_.program_time_s) : json(nullptr)},
            {"blocks_done", same ? json(interp_.blocks_done) : json(nullptr)},
            {"alarms", run_.alarms},
            {"alarm_list", alarms},
            {"max_following_error_mm", num(run_.max_following_error_mm)},
            {"log", log.empty() ? json(nullptr) : json(log)}};
  const std::string payload = j.dump();
  out->push_back({root_ + "/job/end", payload, false, true});
  // The last job, retained: what a dashboard that connects later shows.
  out->push_back({root_ + "/job/last", payload, true, true});
  run_.active = false;
}

void FleetReporter::on_interp_state(const InterpStateIn& m) {
  interp_ = m;
  interp_seen_ = true;
}

void FleetReporter::on_axis_status(const double* actual_mm, const double* following_error_mm, int n) {
  actual_mm_.assign(actual_mm, actual_mm + n);
  double worst = 0;
  for (int i = 0; i < n; ++i)
    if (std::isfinite(following_error_mm[i])) worst = std::max(worst, std::fabs(following_error_mm[i]));
  following_error_mm_ = worst;
  if (run_.active) run_.max_following_error_mm = std::max(run_.max_following_error_mm, worst);
}

void FleetReporter::on_spindle(const SpindleIn& m) {
  spindle_in_ = m;
  spindle_seen_ = true;
}

void FleetReporter::on_alarm(const AlarmIn& m, std::vector<Record>* out) {
  ++alarms_;
  json j = alarm_json(m);
  j["cell"] = cell_;
  j["job"] = run_.active ? json(run_.id) : json(nullptr);
  out->push_back({root_ + "/alarm", j.dump(), false, true});
  if (!run_.active) return;
  ++run_.alarms;
  if (run_.first_alarms.size() < kMaxListedAlarms) run_.first_alarms.push_back(m);
}

void FleetReporter::tick(double now_s, int64_t utime, bool force, std::vector<Record>* out) {
  if (!force && !program_changed_ && now_s - last_state_s_ < state_period_s_) return;
  last_state_s_ = now_s;
  program_changed_ = false;
  ++states_;
  json j = {{"cell", cell_}, {"utime", utime}};
  j["program"] = program_seen_ ? json{{"state", program_state_name(program_.state)},
                                      {"name", file_name(program_.path)},
                                      {"token", program_.token}}
                               : json(nullptr);
  if (interp_seen_) {
    static const char* const modes[] = {"program", "jog", "home"};
    j["interp"] = {{"state", interp_state_name(interp_.state)},
                   {"mode", interp_.mode >= 0 && interp_.mode < 3 ? modes[interp_.mode] : "?"},
                   {"mode_text", interp_.mode_text},
                   {"program_time_s", num(interp_.program_time_s)}};
    j["overrides"] = {{"feed", num(interp_.feed_override)},
                      {"rapid", num(interp_.rapid_override)},
                      {"spindle", num(interp_.spindle_override)}};
  } else {
    j["interp"] = nullptr;
    j["overrides"] = nullptr;
  }
  json pos = json::object(), act = json::object();
  for (size_t i = 0; i < axes_.size(); ++i) {
    if (interp_seen_ && i < interp_.position_mm.size()) pos[axes_[i]] = num(interp_.position_mm[i]);
    if (i < actual_mm_.size()) act[axes_[i]] = num(actual_mm_[i]);
  }
  j["position_mm"] = pos;
  j["actual_mm"] = act;
  j["following_error_mm"] = num(following_error_mm_);
  if (spindle_) {
    static const char* const states[] = {"starting", "stopped", "running", "fault"};
    j["spindle"] = spindle_seen_ ? json{{"state", spindle_in_.state >= 0 && spindle_in_.state < 4 ? states[spindle_in_.state] : "?"},
                                        {"commanded_rpm", num(spindle_in_.commanded_rpm)},
                                        {"actual_rpm", num(spindle_in_.actual_rpm)}}
                                 : json(nullptr);
  }
  j["job"] = run_.active ? json(run_.id) : json(nullptr);
  out->push_back({root_ + "/state", j.dump(), true, false});
}

}  // namespace cnc::mqtt
