#include "tools/logexport/log_export.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <stdexcept>

#include <nlohmann/json.hpp>

namespace cnc::logexport {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

const char* limit_name(int8_t limit) {
  switch (limit) {
    case cnc::lcmt_setpoint::LIMIT_PROGRAM: return "program";
    case cnc::lcmt_setpoint::LIMIT_CHORD: return "chord";
    case cnc::lcmt_setpoint::LIMIT_ROUGHNESS: return "roughness";
    case cnc::lcmt_setpoint::LIMIT_AXIS_VELOCITY: return "axis_velocity";
    case cnc::lcmt_setpoint::LIMIT_CURVATURE_ACCEL: return "curvature_accel";
    case cnc::lcmt_setpoint::LIMIT_LOOKAHEAD: return "lookahead";
    case cnc::lcmt_setpoint::LIMIT_FORCE: return "force";
    default: return "none";
  }
}

const char* state_name(int8_t state) {
  switch (state) {
    case cnc::lcmt_setpoint::IDLE: return "idle";
    case cnc::lcmt_setpoint::RUNNING: return "running";
    case cnc::lcmt_setpoint::HELD: return "held";
    case cnc::lcmt_setpoint::DONE: return "done";
    case cnc::lcmt_setpoint::STARVED: return "starved";
    default: return "unknown";
  }
}

const char* drive_state_name(int8_t state) {
  switch (state) {
    case cnc::lcmt_axis_status::DISABLED: return "disabled";
    case cnc::lcmt_axis_status::ENABLING: return "enabling";
    case cnc::lcmt_axis_status::ENABLED: return "enabled";
    case cnc::lcmt_axis_status::STOPPING: return "stopping";
    case cnc::lcmt_axis_status::FAULT: return "fault";
    default: return "unknown";
  }
}

const char* program_state_name(int8_t state) {
  switch (state) {
    case cnc::lcmt_program_state::IDLE: return "idle";
    case cnc::lcmt_program_state::LOADED: return "loaded";
    case cnc::lcmt_program_state::RUNNING: return "running";
    case cnc::lcmt_program_state::HELD: return "held";
    case cnc::lcmt_program_state::DONE: return "done";
    case cnc::lcmt_program_state::REFUSED: return "refused";
    case cnc::lcmt_program_state::STOPPED: return "stopped";
    default: return "unknown";
  }
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Numbers as Python's float() reads them: "nan" for NaN, enough digits for µm.
std::string num(double v) {
  if (std::isnan(v)) return "nan";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

std::string csv_text(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

// A number of summary.json: full precision, null when not finite (JSON has no NaN).
nlohmann::ordered_json json_num(double v) { return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(); }

// A text, null when empty.
nlohmann::ordered_json str_or_null(const std::string& s) {
  return s.empty() ? nlohmann::ordered_json() : nlohmann::ordered_json(s);
}

bool positive(double v) { return std::isfinite(v) && v > 0; }

// One CSV line, field by field (appending, not `"," + s`: GCC 12 warns falsely on that).
class Line {
 public:
  Line& operator<<(const std::string& field) {
    if (!first_) text_ += ',';
    first_ = false;
    text_ += field;
    return *this;
  }
  Line& operator<<(const char* field) { return *this << std::string(field); }
  Line& operator<<(int64_t v) { return *this << std::to_string(v); }
  Line& operator<<(int32_t v) { return *this << std::to_string(v); }
  Line& operator<<(double v) { return *this << num(v); }
  const std::string& str() const { return text_; }

 private:
  std::string text_;
  bool first_ = true;
};

struct File {
  explicit File(const std::string& path) : f(std::fopen(path.c_str(), "w")) {
    if (f == nullptr) throw std::runtime_error("cannot write " + path);
  }
  ~File() {
    if (f != nullptr) std::fclose(f);
  }
  File(const File&) = delete;
  File& operator=(const File&) = delete;
  void line(const std::string& s) {
    std::fputs(s.c_str(), f);
    std::fputc('\n', f);
  }
  void line(const Line& l) { line(l.str()); }
  FILE* f;
};

}  // namespace

void LogExport::on_config(const config::MachineConfig& cfg, const std::string& source_file) {
  config_ = cfg;
  config_source_ = source_file;
}

void LogExport::on_setpoint(const cnc::lcmt_setpoint& m) { setpoints_.push_back(m); }

void LogExport::on_monitor(const cnc::lcmt_monitor_report& m) { monitor_.push_back(m); }

void LogExport::on_axis_status(const cnc::lcmt_axis_status& m) {
  if (status_axis_names_.empty()) status_axis_names_ = m.axis_name;
  axis_status_.push_back(m);
}

void LogExport::on_alarm(const cnc::lcmt_alarm& m) { alarms_.push_back(m); }

void LogExport::on_program_block(const cnc::lcmt_program_block& m) {
  if (m.target_rmax_um > 0) block_target_rmax_um_ = m.target_rmax_um;
}

void LogExport::on_logger_stats(const cnc::lcmt_logger_stats& m) { logger_stats_[m.sender] = m; }

int64_t LogExport::cycle0() const {
  for (const auto& s : setpoints_)
    if (s.state == cnc::lcmt_setpoint::RUNNING) return s.cycle;
  return setpoints_.empty() ? 0 : setpoints_.front().cycle;
}

double LogExport::period_s() const {
  if (!setpoints_.empty() && setpoints_.front().period_s > 0) return setpoints_.front().period_s;
  return config_ ? config_->ipo_period_s : 0.004;
}

std::vector<std::string> LogExport::axis_names(size_t n) const {
  std::vector<std::string> names;
  for (size_t i = 0; i < n; ++i) {
    if (config_ && i < config_->axes.size()) {
      names.push_back(lower(config_->axes[i].name));
    } else if (i < status_axis_names_.size()) {
      names.push_back(lower(status_axis_names_[i]));
    } else {
      std::string name = "a";
      name += std::to_string(i);
      names.push_back(name);
    }
  }
  return names;
}

const cnc::lcmt_logger_stats* LogExport::own_logger_stats(const std::vector<std::string>& log_files) const {
  // The logger that wrote these files names one of them; else the busiest logger.
  const cnc::lcmt_logger_stats* best = nullptr;
  for (const auto& [sender, st] : logger_stats_) {
    const auto name = std::filesystem::path(st.path).filename();
    for (const auto& f : log_files)
      if (std::filesystem::path(f).filename() == name) return &st;
    if (best == nullptr || st.events > best->events) best = &st;
  }
  return best;
}

void LogExport::write(const std::string& dir, const std::vector<std::string>& log_files, const std::string& prefix,
                      const std::map<std::string, ChannelSummary>& channels) const {
  std::filesystem::create_directories(dir);
  const int64_t c0 = cycle0();
  const double T = period_s();
  auto t_of = [&](int64_t cycle) { return static_cast<double>(cycle - c0) * T; };
  size_t naxes = 0;
  for (const auto& s : setpoints_) naxes = std::max(naxes, static_cast<size_t>(s.num_axes));
  for (const auto& s : axis_status_) naxes = std::max(naxes, static_cast<size_t>(s.num_axes));
  const auto names = axis_names(naxes);

  int64_t running = 0;
  {
    File f(dir + "/setpoints.csv");
    Line head;
    head << "cycle" << "t_s";
    for (const auto& n : names) head << n + "_mm";
    f.line(head << "feed_mm_min" << "limit" << "block" << "line" << "u" << "state" << "program_token");
    for (const auto& s : setpoints_) {
      if (s.state == cnc::lcmt_setpoint::RUNNING) ++running;
      Line row;
      row << s.cycle << t_of(s.cycle);
      for (size_t a = 0; a < naxes; ++a) row << (a < s.position_mm.size() ? s.position_mm[a] : kNaN);
      row << s.feed_mm_per_min << limit_name(s.limit) << s.block_index << s.source_line << s.u << state_name(s.state)
          << s.program_token;
      f.line(row);
    }
  }

  double max_chord = kNaN, max_rmax = kNaN, monitor_tolerance = kNaN, monitor_target = kNaN;
  {
    File f(dir + "/monitor.csv");
    Line head;
    head << "setpoint_cycle" << "t_s" << "commanded_feed_mm_min" << "actual_feed_mm_min" << "chord_error_mm"
         << "chord_tolerance_mm" << "predicted_rmax_um" << "target_rmax_um" << "spindle_rpm" << "max_following_error_mm";
    for (const auto& n : names) head << "fe_" + n + "_mm";
    // VMCS 1999 live (machine config `cutting:`; NaN without it).
    f.line(head << "block" << "line" << "force_peak_n" << "deflection_mm" << "deflection_tolerance_mm");
    for (const auto& m : monitor_) {
      if (std::isfinite(m.chord_error_mm))
        max_chord = std::isnan(max_chord) ? m.chord_error_mm : std::max(max_chord, m.chord_error_mm);
      if (std::isfinite(m.predicted_rmax_um))
        max_rmax = std::isnan(max_rmax) ? m.predicted_rmax_um : std::max(max_rmax, m.predicted_rmax_um);
      if (positive(m.chord_tolerance_mm)) monitor_tolerance = m.chord_tolerance_mm;
      if (positive(m.target_rmax_um)) monitor_target = m.target_rmax_um;
      Line row;
      row << m.setpoint_cycle << t_of(m.setpoint_cycle) << m.commanded_feed_mm_per_min << m.actual_feed_mm_per_min
          << m.chord_error_mm << m.chord_tolerance_mm << m.predicted_rmax_um << m.target_rmax_um << m.spindle_rpm
          << m.max_following_error_mm;
      for (size_t a = 0; a < naxes; ++a) row << (a < m.following_error_mm.size() ? m.following_error_mm[a] : kNaN);
      f.line(row << m.block_index << m.source_line << m.force_peak_n << m.deflection_mm << m.deflection_tolerance_mm);
    }
  }

  double largest_fe = 0;
  std::string largest_fe_axis;
  int64_t faults = 0;
  {
    File f(dir + "/axis_status.csv");
    Line head;
    head << "setpoint_cycle" << "t_s";
    for (const auto& n : names)
      head << n + "_commanded_mm" << n + "_actual_mm" << n + "_following_error_mm" << n + "_drive_state";
    // playback_cycle: the bridge's playback clock when the drives were read, the time of
    // the actual positions (setpoint_cycle repeats and skips with the setpoints' jitter).
    f.line(head << "setpoint_gaps" << "servo_overruns" << "playback_cycle");
    for (const auto& m : axis_status_) {
      Line row;
      row << m.setpoint_cycle << t_of(m.setpoint_cycle);
      for (size_t a = 0; a < naxes; ++a) {
        if (a >= static_cast<size_t>(m.num_axes)) {
          row << kNaN << kNaN << kNaN << "unknown";
          continue;
        }
        row << m.commanded_mm[a] << m.actual_mm[a] << m.following_error_mm[a] << drive_state_name(m.drive_state[a]);
        if (std::fabs(m.following_error_mm[a]) > largest_fe) {
          largest_fe = std::fabs(m.following_error_mm[a]);
          largest_fe_axis = m.axis_name[a];
        }
        if (m.drive_state[a] == cnc::lcmt_axis_status::FAULT) ++faults;
      }
      f.line(row << m.setpoint_gaps << m.servo_overruns << m.playback_cycle);
    }
  }

  int64_t utime0 = 0;
  for (const auto& s : setpoints_)
    if (s.cycle == c0) {
      utime0 = s.utime;
      break;
    }
  if (!spindle_.empty()) {
    // The encoder's position is empty (nan) where it was not valid or not recorded (formats 1 to 3).
    File f(dir + "/spindle_status.csv");
    f.line("utime,t_s,state,command_seq,at_speed_seq,direction,commanded_rpm,actual_rpm,current_a,error_code,"
           "position_rev,sample_playback_cycle,orient_state,fault");
    for (const auto& m : spindle_) {
      static constexpr const char* kStates[] = {"starting", "stopped", "running", "fault"};
      static constexpr const char* kOrient[] = {"none", "orienting", "oriented", "fault"};
      Line row;
      row << m.utime << static_cast<double>(m.utime - utime0) * 1e-6
          << (m.state >= 0 && m.state <= 3 ? kStates[m.state] : "unknown") << m.command_seq << m.at_speed_seq
          << static_cast<int32_t>(m.direction) << m.commanded_rpm << m.actual_rpm << m.current_a << m.error_code
          << (m.position_valid ? m.position_rev : kNaN) << (m.position_valid ? m.sample_playback_cycle : kNaN)
          << (m.orient_state >= 0 && m.orient_state <= 3 ? kOrient[m.orient_state] : "unknown") << csv_text(m.fault);
      f.line(row);
    }
  }
  {
    File f(dir + "/alarms.csv");
    f.line("utime,t_s,source,severity,code,text");
    for (const auto& a : alarms_) {
      const char* severity = a.severity == cnc::lcmt_alarm::FAULT     ? "fault"
                             : a.severity == cnc::lcmt_alarm::WARNING ? "warning"
                                                                      : "info";
      Line row;
      f.line(row << a.utime << static_cast<double>(a.utime - utime0) * 1e-6 << csv_text(a.source) << severity
                 << csv_text(a.code) << csv_text(a.text));
    }
  }

  // Where the reference lines come from: the recorded config first, then the
  // monitor's reports, then the program's process parameters.
  double tolerance = kNaN, target = kNaN;
  std::string tolerance_source, target_source;
  if (config_) {
    tolerance = config_->chord_tolerance_mm;
    tolerance_source = "INTERP_CONFIG";
  } else if (positive(monitor_tolerance)) {
    tolerance = monitor_tolerance;
    tolerance_source = "MONITOR";
  }
  if (positive(monitor_target)) {
    target = monitor_target;
    target_source = "MONITOR";
  } else if (block_target_rmax_um_ > 0) {
    target = block_target_rmax_um_;
    target_source = "PROGRAM_BLOCKS";
  } else if (config_ && config_->process.target_rmax_um > 0) {
    target = config_->process.target_rmax_um;
    target_source = "INTERP_CONFIG";
  }

  using Json = nlohmann::ordered_json;  // the keys in the order written
  Json j;
  j["log_files"] = log_files;
  j["prefix"] = prefix;
  j["axes"] = names;
  j["config_file"] = str_or_null(config_source_);
  j["program"] = program_ ? Json(program_->program_path) : Json();
  j["program_state"] = program_ ? Json(program_state_name(program_->state)) : Json();
  j["interpolator_state"] = interp_ ? Json(state_name(interp_->state)) : Json();
  j["program_time_s"] = interp_ ? json_num(interp_->program_time_s) : Json();
  j["blocks_done"] = interp_ ? Json(interp_->blocks_done) : Json();
  j["blocks_total"] = program_ ? Json(program_->num_blocks) : Json();
  j["blocks_resent"] = program_ ? Json(program_->blocks_resent) : Json();
  j["period_s"] = json_num(T);
  j["setpoints"] = setpoints_.size();
  j["running_setpoints"] = running;
  j["monitor_reports"] = monitor_.size();
  j["axis_status_reports"] = axis_status_.size();
  j["largest_following_error_mm"] = largest_fe_axis.empty() ? Json() : json_num(largest_fe);
  j["largest_following_error_axis"] = str_or_null(largest_fe_axis);
  j["drive_fault_reports"] = faults;
  j["max_chord_error_mm"] = json_num(max_chord);
  j["max_predicted_rmax_um"] = json_num(max_rmax);
  j["chord_tolerance_mm"] = json_num(tolerance);
  j["chord_tolerance_source"] = str_or_null(tolerance_source);
  j["target_rmax_um"] = json_num(target);
  j["target_rmax_source"] = str_or_null(target_source);
  j["alarms"] = alarms_.size();
  Json& ch_json = j["channels"] = Json::object();
  for (const auto& [ch, c] : channels)
    ch_json[ch] = {{"events", c.events}, {"senders", c.senders}, {"seq_gaps", c.seq_gaps}, {"seq_restarts", c.seq_restarts}};
  if (const auto* st = own_logger_stats(log_files)) {
    Json lg;
    lg["path"] = st->path;
    lg["files"] = st->files;
    lg["events"] = st->events;
    lg["bytes"] = st->bytes;
    lg["events_dropped"] = st->events_dropped;
    lg["write_errors"] = st->write_errors;
    lg["socket_drops"] = st->socket_drops;
    lg["max_io_s"] = json_num(st->max_io_s);
    lg["max_loop_gap_s"] = json_num(st->max_loop_gap_s);
    lg["closing"] = static_cast<bool>(st->closing);
    Json& lch = lg["channels"] = Json::object();
    for (int k = 0; k < st->num_channels; ++k) {
      const auto u = static_cast<size_t>(k);
      lch[st->channel[u]] = {{"received", st->received[u]}, {"logged", st->logged[u]}, {"seq_gaps", st->seq_gaps[u]},
                             {"dropped", st->dropped[u]}};
    }
    j["logger"] = std::move(lg);
  } else {
    j["logger"] = nullptr;
  }
  // Texts from the log that are not UTF-8 are written with U+FFFD, not refused.
  File f(dir + "/summary.json");
  f.line(j.dump(2, ' ', false, Json::error_handler_t::replace));
}

}  // namespace cnc::logexport
