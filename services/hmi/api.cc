#include "services/hmi/api.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_drive_command.hpp"
#include "cnc/lcmt_program_block.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "common/motion/feed_override.h"
#include "common/rs274/parameters.h"
#include "common/rs274/tool_table.h"
#include "common/service/machine_status.h"
#include "common/util/clock.h"
#include "common/util/install.h"
#include "services/hmi/programs.h"

namespace cnc::hmi {

namespace ch = config::channels;
using json = nlohmann::json;

namespace {

constexpr size_t kAlarmsKept = 200;

const char* program_state_name(int8_t s) {
  static const char* const k[] = {"idle", "loaded", "running", "held", "done", "refused", "stopped", "fault"};
  return s >= 0 && s <= 7 ? k[s] : "?";
}
const char* interp_state_name(int8_t s) {
  static const char* const k[] = {"idle", "running", "held", "done", "starved", "fault"};
  return s >= 0 && s <= 5 ? k[s] : "?";
}
const char* drive_state_name(int8_t s) {
  static const char* const k[] = {"disabled", "enabling", "enabled", "stopping", "fault"};
  return s >= 0 && s <= 4 ? k[s] : "?";
}

// A finite number for JSON (NaN and infinities are not JSON).
double fin(double v) { return std::isfinite(v) ? v : 0.0; }

std::string read_text(const std::string& path, size_t limit) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return "";
  std::string s(limit, '\0');
  f.read(s.data(), static_cast<std::streamsize>(limit));
  s.resize(static_cast<size_t>(f.gcount()));
  return s;
}

// A field as a number (a number, or a string that is one whole); invalid_argument naming it otherwise.
double number(const json& j, const char* key, double fallback) {
  if (!j.contains(key)) return fallback;
  if (j[key].is_number()) return j[key].get<double>();
  if (j[key].is_string()) {
    const std::string s = j[key].get<std::string>();
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (end != s.c_str() && *end == '\0' && std::isfinite(v)) return v;
  }
  throw std::invalid_argument(std::string("'") + key + "' must be a number");
}

}  // namespace

// ---- the actions ----

const std::vector<Api::Action>& Api::actions() {
  static const std::vector<Action> k = {
      {"load", "`path` (relative to `program_dir`), `from_line` (optional: run from line N)",
       "PROGRAM_CMD LOAD (absolute path, `from_line`)",
       "`loaded P: N blocks`, or the parser's `file:line:col` refusal, or the interlock's", false, &Api::load},
      {"start", "", "PROGRAM_CMD START", "`start sent`, then the interlock's refusal if one comes (before `confirm`)",
       false, &Api::program_command},
      {"hold", "", "PROGRAM_CMD HOLD", "`hold sent`, then the interlock's refusal if one comes", false,
       &Api::program_command},
      {"resume", "", "PROGRAM_CMD RESUME", "`resume sent`, then the interlock's refusal if one comes", false,
       &Api::program_command},
      {"stop", "", "PROGRAM_CMD STOP", "`stop sent`, then the interlock's refusal if one comes", false,
       &Api::program_command},
      {"confirm", "", "PROGRAM_CMD CONFIRM (the approach of a run from line N)",
       "`confirm sent`, then the interlock's refusal if one comes", false, &Api::program_command},
      {"override", "`value` (0 .. 1.5)", "PROGRAM_CMD OVERRIDE", "`override sent` / refusal", false,
       &Api::override_command},
      {"rapid_override", "`value` (0 .. 1)", "PROGRAM_CMD RAPID_OVERRIDE", "`rapid_override sent` / refusal", false,
       &Api::override_command},
      {"spindle_override", "`value` (`spindle.min_override` .. `max_override`)", "PROGRAM_CMD SPINDLE_OVERRIDE",
       "`spindle_override sent` / refusal", false, &Api::override_command},
      {"single_block", "`value` (bool)", "PROGRAM_CMD SINGLE_BLOCK",
       "`single-block on sent` / `… off sent`, then the interlock's refusal", false, &Api::program_switch},
      {"optional_stop", "`value` (bool)", "PROGRAM_CMD OPTIONAL_STOP",
       "`optional-stop on sent` / `… off sent`, then the interlock's refusal", false, &Api::program_switch},
      {"block_delete", "`value` (bool)", "PROGRAM_CMD BLOCK_DELETE",
       "`block-delete on sent` / `… off sent`, then the interlock's refusal (block delete while running)", false,
       &Api::program_switch},
      {"reset", "",
       "DRIVE_CMD ENABLE (every 1 s until enabled), then PROGRAM_CMD RESET (every 0.5 s until the `reset` alarm)",
       "`reset: …` or why not (30 s)", false, &Api::reset},
      {"enable", "", "DRIVE_CMD ENABLE", "`enable sent`", false, &Api::drive_command},
      {"disable", "", "DRIVE_CMD DISABLE", "`disable sent`", false, &Api::drive_command},
      {"home", "`axis` (name or index; none: all in `home.order`)", "PROGRAM_CMD HOME",
       "`home sent`, then `home_refused` / interlock refusal", false, &Api::home},
      {"jog", "`axis`, `value` (mm; continuous: the sign), `feed` (mm/min, 0: the axis's jog feed), `continuous` (bool)",
       "PROGRAM_CMD JOG", "`jog sent`, then `jog_refused` / interlock refusal", false, &Api::jog},
      {"jog_keepalive", "`axis`",
       "PROGRAM_CMD JOG_KEEPALIVE, only while this client's continuous jog of that axis runs (send every 50 ms)",
       "none", false, &Api::jog_keepalive},
      {"jog_stop", "`axis`", "PROGRAM_CMD STOP", "`jog stopped`", false, &Api::jog_stop},
      {"touch_off", "`axis`, `value` (the reading wanted, mm)",
       "PROGRAM_CMD TOUCH_OFF, then START of its line once loaded (as cnc-ctl)",
       "`touch_off started` / refusal with its place", false, &Api::touch_off},
      {"mdi", "`line`", "PROGRAM_CMD MDI, then START", "`mdi started` / refusal (`mdi-…ngc:1:7: …`)", false,
       &Api::mdi},
      {"offsets", "", "nothing (reads `program.var_file` and `program.tool_table`)",
       "an `offsets` message {coord, systems [{name, p, values, rotation}], g92 {active, values}, tools [{number, "
       "pocket, offset, diameter, comment}], locked}",
       true, &Api::send_offsets},
      {"set_offset", "`system` (`G54` .. `G59.3`), `values` {axis: mm}",
       "PROGRAM_CMD MDI `G10 L2 P<n> X.. Y..`, then START (as `mdi`)",
       "`set_offset started`, refused while a program runs (`set_offset refused: a program runs ...`), or the MDI "
       "line's refusal",
       false, &Api::set_offset},
      {"clear_g92", "", "PROGRAM_CMD MDI `G92.1`, then START", "`clear_g92 started` / refused as `set_offset`", false,
       &Api::clear_g92},
      {"set_tool", "`tool` (T number), `length` (Z offset, mm), `diameter` (mm, optional)",
       "PROGRAM_CMD MDI `G10 L1 P<t> Z.. R..`, then START (the tool table written back)",
       "`set_tool started` / refused as `set_offset`", false, &Api::set_tool},
      {"upload", "`name` (a file name), `text` (the program), `replace` (bool)",
       "nothing to the cell: the file written into `program_dir`",
       "`uploaded NAME (N bytes)` and a new `programs`; refused (naming why) without a logged-in user, over "
       "`hmi.upload_max_bytes`, for a name with a folder, a hidden or non-program name, or an existing file "
       "without `replace`",
       false, &Api::upload},
      {"programs", "", "nothing (lists the program directory)", "a `programs` message", true, &Api::send_programs},
      {"runs", "", "nothing (lists the runs directory)",
       "a `runs` message ([{name, log, start, duration_s, programs, mdi_lines, alarms, faults, report_url}])", true,
       &Api::post_runs},
      {"playback", "`log` (as listed)", "nothing to the cell: the log's setpoints read",
       "a `playback` message {log, points [x,y,z,...], times, lines, duration_s, setpoints} (the page animates it)",
       false, &Api::playback},
      {"report", "`log` (as listed)", "nothing to the cell: `cnc-logexport` and `make_report.py` on the log",
       "`report of L ready` with `report_url`, then a new `runs`", false, &Api::report},
      {"ping", "", "nothing", "`pong`", true, &Api::ping},
  };
  return k;
}

const Api::Action* Api::find_action(const std::string& name) {
  for (const Action& a : actions())
    if (name == a.name) return &a;
  return nullptr;
}

void Api::message(uint64_t client, bool may_control, const std::string& text, const std::string& user) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& ex) {
    // The parser's message quotes the bytes it last read, which need not be UTF-8
    // (fuzz_hmi_api: a message that is not JSON could not be answered).
    const std::string why = json(std::string(ex.what())).dump(-1, ' ', false, json::error_handler_t::replace);
    out_.send_to(client, {{"t", "result"}, {"id", nullptr}, {"ok", false},
                          {"text", "not JSON: " + json::parse(why).get<std::string>()}});
    return;
  }
  if (!j.is_object() || (j.contains("action") && !j["action"].is_string())) {
    const json id = j.is_object() && j.contains("id") ? j["id"] : json(nullptr);
    out_.send_to(client, {{"t", "result"}, {"id", id}, {"ok", false},
                          {"text", "expected an object {\"action\": \"NAME\", ...}"}});
    return;
  }
  const json id = j.contains("id") ? j["id"] : json(nullptr);
  const std::string action = j.value("action", "");
  try {
    const Action* a = find_action(action);
    if ((a == nullptr || !a->view_only) && !may_control) {
      result(client, id, false, "view only: log in to operate the machine");
      return;
    }
    if (a == nullptr) {
      result(client, id, false, "unknown action '" + action + "'");
      return;
    }
    (this->*(a->handler))(Request{client, id, j, action, user});
  } catch (const std::exception& ex) {
    result(client, id, false, action + ": " + ex.what());
  }
}

void Api::send_programs(const Request& r) {
  out_.send_to(r.client, {{"t", "programs"}, {"programs", list_programs(cfg_.hmi.program_dir)}});
}

void Api::post_runs(const Request& r) {
  if (!runs_.post({r.client, r.id, "list", ""})) result(r.client, r.id, false, "runs: busy, try again");
}

void Api::ping(const Request& r) { out_.send_to(r.client, {{"t", "pong"}, {"id", r.id}}); }

void Api::playback(const Request& r) {
  if (!runs_.post({r.client, r.id, "playback", r.message.value("log", "")}))
    result(r.client, r.id, false, "playback: busy, try again");
}

void Api::report(const Request& r) {
  if (!runs_.post({r.client, r.id, "report", r.message.value("log", "")}))
    result(r.client, r.id, false, "report: busy, try again");
}

void Api::load(const Request& r) {
  std::string why;
  const std::string path = resolve_program(cfg_.hmi.program_dir, r.message.value("path", ""), &why);
  if (path.empty()) {
    result(r.client, r.id, false, "load refused: " + why);
    return;
  }
  service::OperatorCommand c;
  c.command = lcmt_program_command::LOAD;
  c.program_path = path;
  // Run from line N (0: from the start): the cell shows the approach and waits for a confirm.
  const double from = number(r.message, "from_line", 0.0);
  if (!(from >= 0 && from <= 1e7 && from == std::floor(from))) {
    result(r.client, r.id, false, "load refused: from_line must be a line number >= 1");
    return;
  }
  c.from_line = static_cast<int32_t>(from);
  if (Pending* p = send_cmd(r.client, r.id, r.action, c)) {
    p->path = path;
    p->old_token = have_program_ ? program_.program_token : 0;
    p->deadline_s = p->sent_s + 10.0;
  }
}

void Api::program_command(const Request& r) {
  service::OperatorCommand c;
  c.command = *service::program_command_by_name(r.action);
  if (r.action == "stop") jogging_.erase(r.client);
  if (send_cmd(r.client, r.id, r.action, c)) result(r.client, r.id, true, r.action + " sent");
}

void Api::program_switch(const Request& r) {
  // The switches (1 on, 0 off): the interlock answers as for cnc-ctl --do single-block ...
  std::string name = r.action;
  std::replace(name.begin(), name.end(), '_', '-');
  service::OperatorCommand c;
  c.command = *service::program_command_by_name(name);
  const bool on = r.message.value("value", false);
  c.value = on ? 1 : 0;
  c.axis = -1;
  c.feed_override = 0;
  if (send_cmd(r.client, r.id, r.action, c)) result(r.client, r.id, true, name + (on ? " on" : " off") + " sent");
}

void Api::override_command(const Request& r) {
  service::OperatorCommand c;
  c.command = r.action == "rapid_override"     ? lcmt_program_command::RAPID_OVERRIDE
              : r.action == "spindle_override" ? lcmt_program_command::SPINDLE_OVERRIDE
                                               : lcmt_program_command::OVERRIDE;
  c.feed_override = number(r.message, "value", 1.0);
  if (send_cmd(r.client, r.id, r.action, c)) result(r.client, r.id, true, r.action + " sent");
}

void Api::drive_command(const Request& r) {
  const int8_t d = r.action == "enable" ? lcmt_drive_command::ENABLE : lcmt_drive_command::DISABLE;
  if (!service::send_drive_command(bus_, cfg_, d))
    result(r.client, r.id, false, std::string("not sent: ") + bus_.last_publish_error());
  else
    result(r.client, r.id, true, r.action + " sent");
}

void Api::reset(const Request& r) {
  // As cnc-ctl --do reset: the drives enabled first (ENABLE every second until they
  // are), then RESET every 0.5 s until the interpolator's `reset` alarm.
  Pending p;
  p.client = r.client;
  p.id = r.id;
  p.action = "reset";
  p.command = lcmt_program_command::RESET;
  p.sent_s = util::monotonic_s();
  p.alarms_at = alarms_total_;
  p.deadline_s = p.sent_s + 30;
  pending_.push_back(p);
}

void Api::home(const Request& r) {
  service::OperatorCommand c;
  c.command = lcmt_program_command::HOME;
  c.axis = axis_index(r.message);
  c.feed_override = 0;
  if (r.message.contains("axis") && !r.message["axis"].is_null() && c.axis < 0) {
    result(r.client, r.id, false, "home: the machine has no axis " + r.message["axis"].dump());
    return;
  }
  if (send_cmd(r.client, r.id, r.action, c)) result(r.client, r.id, true, "home sent");
}

int Api::jog_axis(const Request& r) {
  const int a = axis_index(r.message);
  if (a < 0 || a >= naxes_) {
    result(r.client, r.id, false, r.action + ": the machine has no axis " + r.message.value("axis", json()).dump());
    return -1;
  }
  return a;
}

void Api::jog(const Request& r) {
  const int a = jog_axis(r);
  if (a < 0) return;
  service::OperatorCommand c;
  c.axis = a;
  c.feed_override = 0;
  c.command = lcmt_program_command::JOG;
  c.value = number(r.message, "value", 0);
  c.feed_mm_per_min = number(r.message, "feed", 0);
  c.jog_continuous = r.message.value("continuous", false) ? 1 : 0;
  if (c.jog_continuous) jogging_[r.client] = a;
  if (send_cmd(r.client, r.id, r.action, c)) result(r.client, r.id, true, "jog sent");
}

void Api::jog_keepalive(const Request& r) {
  const int a = jog_axis(r);
  if (a < 0) return;
  // Only for the jog this client holds: a late keepalive never restarts anything.
  const auto it = jogging_.find(r.client);
  if (it == jogging_.end() || it->second != a) return;
  service::OperatorCommand c;
  c.axis = a;
  c.feed_override = 0;
  c.command = lcmt_program_command::JOG_KEEPALIVE;
  service::send_program_command(bus_, cfg_, c);
}

void Api::jog_stop(const Request& r) {
  if (jog_axis(r) < 0) return;
  jogging_.erase(r.client);
  service::OperatorCommand c;
  c.command = lcmt_program_command::STOP;
  c.axis = -1;
  c.feed_override = 1.0;
  if (send_cmd(r.client, r.id, r.action, c)) result(r.client, r.id, true, "jog stopped");
}

void Api::touch_off(const Request& r) {
  service::OperatorCommand c;
  c.command = lcmt_program_command::TOUCH_OFF;
  c.axis = axis_index(r.message);
  if (c.axis < 0 || c.axis >= naxes_) {
    result(r.client, r.id, false, "touch_off: the machine has no axis " + r.message.value("axis", json()).dump());
    return;
  }
  c.value = number(r.message, "value", 0);
  send_line(r, c);
}

void Api::mdi(const Request& r) {
  service::OperatorCommand c;
  c.command = lcmt_program_command::MDI;
  c.text = r.message.value("line", "");
  if (c.text.empty()) {
    result(r.client, r.id, false, "mdi: no line");
    return;
  }
  send_line(r, c);
}

// ---- work offsets, tools, upload ----

namespace {

const char* const kSystems[] = {"G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"};
constexpr char kPoseLetters[] = "XYZABCUVW";

double file_stamp(const std::string& path) {
  std::error_code ec;
  if (path.empty()) return 0;
  const auto t = std::filesystem::last_write_time(path, ec);
  if (ec) return 0;
  return std::chrono::duration<double>(t.time_since_epoch()).count();
}

std::string format_mm(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4f", v);
  std::string s = buf;
  while (s.back() == '0') s.pop_back();
  if (s.back() == '.') s.pop_back();
  return s == "-0" ? "0" : s;
}

}  // namespace

std::string Api::offsets_locked() const {
  const bool running = have_program_ && (program_.state == lcmt_program_state::RUNNING ||
                                         program_.state == lcmt_program_state::HELD);
  const bool moving = have_interp_ && (interp_.state == lcmt_setpoint::RUNNING || interp_.state == lcmt_setpoint::HELD);
  if (!running && !moving) return "";
  return std::string("a program runs (program ") + program_state_name(have_program_ ? program_.state : 0) +
         ", interpolator " + interp_state_name(have_interp_ ? interp_.state : 0) +
         "): offsets and tools are changed between programs";
}

json Api::offsets() const {
  json m = {{"t", "offsets"}, {"var_file", cfg_.program.var_file}, {"tool_table", cfg_.program.tool_table}};
  // The machine's axes on the interpreter's pose (X Y Z A B C U V W).
  std::vector<int> pose;
  json names = json::array();
  for (const auto& a : cfg_.axes) {
    const char* at = std::strchr(kPoseLetters, a.name.empty() ? '?' : a.name[0]);
    pose.push_back(at == nullptr ? -1 : static_cast<int>(at - kPoseLetters));
    names.push_back(a.name);
  }
  m["axes"] = names;
  rs274::Parameters params;
  std::string error;
  if (!cfg_.program.var_file.empty() && std::filesystem::exists(cfg_.program.var_file)) {
    try {
      params.read_var_file(cfg_.program.var_file);
    } catch (const std::exception& ex) {
      error = ex.what();
    }
  }
  auto values = [&](int base) {
    json v = json::array();
    for (int p : pose) v.push_back(p < 0 ? 0.0 : fin(params.get(base + p)));
    return v;
  };
  const int coord = static_cast<int>(std::lround(params.get(5220)));
  m["coord"] = coord >= 1 && coord <= 9 ? coord : 1;
  json systems = json::array();
  for (int n = 1; n <= 9; ++n)
    systems.push_back({{"name", kSystems[n - 1]}, {"p", n}, {"values", values(5201 + 20 * n)},
                       {"rotation", fin(params.get(5210 + 20 * n))}});
  m["systems"] = systems;
  m["g92"] = {{"active", params.get(5210) != 0}, {"values", values(5211)}};
  json tools = json::array();
  if (!cfg_.program.tool_table.empty()) {
    try {
      rs274::ToolTable table;
      table.read(cfg_.program.tool_table);
      for (const rs274::Tool& t : table.tools()) {
        json off = json::array();
        for (int p : pose) off.push_back(p < 0 ? 0.0 : fin(t.offset[static_cast<size_t>(p)]));
        tools.push_back({{"number", t.number}, {"pocket", t.pocket}, {"offset", off},
                         {"diameter", fin(t.diameter)}, {"comment", t.comment}});
      }
    } catch (const std::exception& ex) {
      error += (error.empty() ? "" : "; ") + std::string(ex.what());
    }
  }
  m["tools"] = tools;
  m["error"] = error;
  m["locked"] = offsets_locked();
  return m;
}

void Api::send_offsets(const Request& r) { out_.send_to(r.client, offsets()); }

void Api::send_mdi_line(const Request& r, const std::string& line) {
  if (const std::string why = offsets_locked(); !why.empty()) {
    result(r.client, r.id, false, r.action + " refused: " + why);
    return;
  }
  service::OperatorCommand c;
  c.command = lcmt_program_command::MDI;
  c.text = line;
  spdlog::info("cnc-hmi: client {}: {} as MDI '{}'", r.client, r.action, line);
  send_line(r, c);
}

void Api::set_offset(const Request& r) {
  const std::string sys = r.message.value("system", "");
  int p = 0;
  for (int n = 1; n <= 9; ++n)
    if (sys == kSystems[n - 1]) p = n;
  if (p == 0) {
    result(r.client, r.id, false, "set_offset: 'system' must be one of G54 .. G59.3 (G92: clear_g92), not '" + sys + "'");
    return;
  }
  const json& v = r.message.contains("values") ? r.message["values"] : json::object();
  if (!v.is_object() || v.empty()) {
    result(r.client, r.id, false, "set_offset: 'values' must name at least one axis, {\"X\": 10.5}");
    return;
  }
  std::string line = "G10 L2 P" + std::to_string(p);
  for (const auto& [axis, value] : v.items()) {
    if (cfg_.axis_index(axis) < 0) {
      result(r.client, r.id, false, "set_offset: the machine has no axis '" + axis + "'");
      return;
    }
    const double mm = number(v, axis.c_str(), 0.0);
    if (std::fabs(mm) > 1e6) {
      result(r.client, r.id, false, "set_offset: " + axis + " " + format_mm(mm) + " mm is not an offset");
      return;
    }
    line += " " + axis + format_mm(mm);
  }
  send_mdi_line(r, line);
}

void Api::clear_g92(const Request& r) { send_mdi_line(r, "G92.1"); }

void Api::set_tool(const Request& r) {
  const double t = number(r.message, "tool", -1);
  if (!(t >= 1 && t <= 99999 && t == std::floor(t))) {
    result(r.client, r.id, false, "set_tool: 'tool' must be a tool number >= 1");
    return;
  }
  if (!r.message.contains("length") && !r.message.contains("diameter")) {
    result(r.client, r.id, false, "set_tool: give 'length' (Z offset, mm) or 'diameter' (mm)");
    return;
  }
  std::string line = "G10 L1 P" + std::to_string(static_cast<int>(t));
  if (r.message.contains("length")) {
    const double z = number(r.message, "length", 0);
    if (std::fabs(z) > 1e5) {
      result(r.client, r.id, false, "set_tool: length " + format_mm(z) + " mm is not a tool length");
      return;
    }
    line += " Z" + format_mm(z);
  }
  if (r.message.contains("diameter")) {
    const double d = number(r.message, "diameter", 0);
    if (!(d >= 0 && d <= 1e4)) {
      result(r.client, r.id, false, "set_tool: diameter " + format_mm(d) + " mm is not a tool diameter (>= 0)");
      return;
    }
    line += " R" + format_mm(d / 2);
  }
  send_mdi_line(r, line);
}

void Api::upload(const Request& r) {
  const std::string name = r.message.value("name", "");
  if (r.user.empty()) {
    result(r.client, r.id, false, "upload refused: uploading needs a logged-in user (hmi.users_file)");
    return;
  }
  if (!r.message.contains("text") || !r.message["text"].is_string()) {
    result(r.client, r.id, false, "upload refused: 'text' (the program) must be a string");
    return;
  }
  const std::string& text = r.message["text"].get_ref<const std::string&>();
  const bool replace = r.message.value("replace", false);
  std::string why = check_upload(cfg_.hmi.program_dir, name, text, cfg_.hmi.upload_max_bytes, replace);
  if (why.empty()) why = write_upload(cfg_.hmi.program_dir, name, text);
  if (!why.empty()) {
    result(r.client, r.id, false, "upload refused: " + why);
    return;
  }
  spdlog::info("cnc-hmi: {} uploaded {} ({} bytes) into {}", r.user, name, text.size(), cfg_.hmi.program_dir);
  result(r.client, r.id, true, "uploaded " + name + " (" + std::to_string(text.size()) + " bytes)");
  out_.broadcast({{"t", "programs"}, {"programs", list_programs(cfg_.hmi.program_dir)}}, false);
}

// MDI and touch-off: the server writes the line to a program of its own and loads
// it; follow() starts it once the interpolator has taken it.
void Api::send_line(const Request& r, service::OperatorCommand& c) {
  c.feed_override = 0;
  if (Pending* p = send_cmd(r.client, r.id, r.action, c)) {
    p->suffix = service::mdi_program_suffix(bus_.sender(), p->seq);
    p->old_token = have_program_ ? program_.program_token : 0;
    p->deadline_s = p->sent_s + 10.0;
  }
}

// ---- the cell's state ----

Api::Api(const config::MachineConfig& cfg, bus::Bus& bus, ApiOptions options, Outbox out)
    : cfg_(cfg),
      bus_(bus),
      options_(std::move(options)),
      out_(std::move(out)),
      naxes_(static_cast<int>(cfg.axes.size())),
      dry_(options_.machine_file, options_.plan_exe),
      runs_(options_.runs_dir, options_.logexport_exe, options_.make_report) {
  subscribe();
}

void Api::subscribe() {
  bus_.subscribe<lcmt_axis_status>(cfg_.channel(ch::kAxisStatus), [this](const auto& m) {
    axes_ = m;
    have_axes_ = true;
  });
  bus_.subscribe<lcmt_interp_state>(cfg_.channel(ch::kInterpState), [this](const auto& m) {
    interp_ = m;
    have_interp_ = true;
  });
  bus_.subscribe<lcmt_program_state>(cfg_.channel(ch::kProgramState), [this](const auto& m) {
    program_ = m;
    have_program_ = true;
  });
  bus_.subscribe<lcmt_setpoint>(cfg_.channel(ch::kSetpoints), [this](const auto& m) {
    setpoint_ = m;
    have_setpoint_ = true;
  });
  if (cfg_.spindle.enabled)
    bus_.subscribe<lcmt_spindle_status>(cfg_.channel(ch::kSpindleStatus), [this](const auto& m) {
      spindle_ = m;
      have_spindle_ = true;
    });
  if (cfg_.io.enabled)
    bus_.subscribe<lcmt_io_status>(cfg_.channel(ch::kIoStatus), [this](const auto& m) {
      io_ = m;
      have_io_ = true;
    });
  bus_.subscribe<lcmt_heartbeat>(cfg_.channel(ch::kHeartbeat),
                                 [this](const auto& m) { services_[m.service] = Seen{m, util::monotonic_s()}; });
  bus_.subscribe<lcmt_program_block>(cfg_.channel(ch::kProgramBlocks), [this](const auto& m) {
    if (!have_program_ || m.program_token != program_.program_token) return;
    if (blocks_token_ != m.program_token) {
      blocks_.clear();
      blocks_token_ = m.program_token;
    }
    BlockInfo b{};
    b.line = m.source_line;
    b.in_program = m.source_file == program_.program_path || m.source_file.empty();
    for (int a = 0; a < naxes_ && a < m.num_axes; ++a) b.end[a] = m.end[static_cast<size_t>(a)];
    blocks_[m.block_index] = b;
    // Bounded: the blocks well behind the path are dropped.
    while (blocks_.size() > 4096) blocks_.erase(blocks_.begin());
  });
  bus_.subscribe<lcmt_alarm>(cfg_.channel(ch::kAlarm), [this](const auto& m) {
    static const char* const kSeverity[] = {"info", "warning", "fault"};
    on_alarm({{"utime", m.utime},
              {"source", m.source},
              {"severity", m.severity >= 0 && m.severity <= 2 ? kSeverity[m.severity] : "?"},
              {"code", m.code},
              {"text", m.text},
              {"n", alarms_total_}});
  });
}

void Api::on_alarm(const json& a) {
  ++alarms_total_;
  alarm_history_.push_back(a);
  if (alarm_history_.size() > 4 * kAlarmsKept)
    alarm_history_.erase(alarm_history_.begin(), alarm_history_.begin() + kAlarmsKept);
  alarms_shown_.push_back(a);
  if (alarms_shown_.size() > kAlarmsKept) alarms_shown_.pop_front();
  json msg = a;
  msg["t"] = "alarm";
  out_.broadcast(msg, false);
}

// The alarms since a pending action was sent, by code (its index in the total count).
std::string Api::alarm_since(size_t from, std::initializer_list<const char*> codes) const {
  for (const json& a : alarm_history_) {
    if (a["n"].get<size_t>() < from) continue;
    for (const char* c : codes)
      if (a["code"] == c) return a["text"].get<std::string>();
  }
  return "";
}

void Api::open(uint64_t client, bool may_control, const std::string& user) {
  json ax = json::array();
  for (const auto& a : cfg_.axes)
    ax.push_back({{"name", a.name}, {"min", a.min_mm}, {"max", a.max_mm}, {"rotary", a.rotary}, {"wrapped", a.wrapped}});
  out_.send_to(client, {{"t", "hello"},
                        {"machine", cfg_.name},
                        {"version", util::version()},
                        {"axes", ax},
                        {"may_control", may_control},
                        {"user", user},
                        {"login", options_.login_required},
                        {"program_dir", cfg_.hmi.program_dir},
                        {"programs", list_programs(cfg_.hmi.program_dir)},
                        // Commands the cell does not have yet: their controls stay disabled.
                        {"unavailable", json::array()},
                        {"status_rate_hz", cfg_.hmi.status_rate_hz},
                        // The feed slider's top: the largest override the cell accepts.
                        {"max_feed_override", motion::kMaxFeedOverride},
                        // The largest upload (the page refuses a larger file before sending it).
                        {"upload_max_bytes", cfg_.hmi.upload_max_bytes},
                        {"devices", devices()}});
  out_.send_to(client, program_msg_);
  out_.send_to(client, offsets());
  if (!preview_msg_.is_null()) out_.send_to(client, preview_msg_);
  json list = json::array();
  for (const auto& a : alarms_shown_) list.push_back(a);
  out_.send_to(client, {{"t", "alarms"}, {"alarms", list}});
}

void Api::close(uint64_t client) {
  // A client that held a continuous jog and went away: stopped now, not only
  // by the interpolator's keepalive timeout.
  if (jogging_.count(client)) {
    service::OperatorCommand c;
    c.command = lcmt_program_command::STOP;
    service::send_program_command(bus_, cfg_, c);
    jogging_.erase(client);
    spdlog::warn("cnc-hmi: client {} left during a continuous jog: STOP sent", client);
  }
}

void Api::stop() {
  // Leaving with a jog held by a browser: stopped.
  if (!jogging_.empty()) {
    service::OperatorCommand c;
    c.command = lcmt_program_command::STOP;
    service::send_program_command(bus_, cfg_, c);
  }
  dry_.cancel();
}

void Api::result(uint64_t client, const json& id, bool ok, const std::string& text) {
  out_.send_to(client, {{"t", "result"}, {"id", id}, {"ok", ok}, {"text", text}});
  if (!ok) spdlog::info("cnc-hmi: client {}: {}", client, text);
}

int Api::axis_index(const json& j) const {
  if (!j.contains("axis") || j["axis"].is_null()) return -1;
  if (j["axis"].is_string()) return cfg_.axis_index(j["axis"].get<std::string>());
  return j["axis"].get<int>();
}

Api::Pending* Api::send_cmd(uint64_t client, const json& id, const std::string& action,
                            const service::OperatorCommand& c) {
  const int64_t seq = service::send_program_command(bus_, cfg_, c);
  if (seq < 0) {
    result(client, id, false, std::string("not sent: ") + bus_.last_publish_error());
    return nullptr;
  }
  Pending p;
  p.client = client;
  p.id = id;
  p.action = action;
  p.command = c.command;
  p.seq = seq;
  p.sent_s = util::monotonic_s();
  p.alarms_at = alarms_total_;
  p.deadline_s = p.sent_s + 2.0;
  pending_.push_back(p);
  return &pending_.back();
}

bool Api::all_enabled() const {
  if (!have_axes_ || axes_.num_axes == 0) return false;
  for (int8_t s : axes_.drive_state)
    if (s != lcmt_axis_status::ENABLED) return false;
  return true;
}

void Api::update(double now) {
  follow(now);

  // The var file and the tool table, written at each program's (and MDI line's) end:
  // a change is sent to every client (looked at twice a second).
  if (now - offsets_checked_s_ >= 0.5) {
    offsets_checked_s_ = now;
    const double stamp = file_stamp(cfg_.program.var_file) + 1e-3 * file_stamp(cfg_.program.tool_table);
    const bool was_locked = offsets_locked_;
    offsets_locked_ = !offsets_locked().empty();
    if (stamp != offsets_stamp_ || was_locked != offsets_locked_) {
      offsets_stamp_ = stamp;
      out_.broadcast(offsets(), false);
    }
  }

  // The loaded program: its text and its dry run for the preview, once per load.
  if (have_program_ && !program_.program_path.empty() && program_.program_path != program_text_path_) {
    program_text_path_ = program_.program_path;
    std::string text = read_text(program_text_path_, 4 << 20);
    program_msg_ = {{"t", "program"},
                    {"path", program_text_path_},
                    {"name", std::filesystem::path(program_text_path_).filename().string()},
                    {"text", text}};
    out_.broadcast(program_msg_, false);
  }
  if (have_program_ && program_.state == lcmt_program_state::LOADED && program_.program_token != preview_token_ &&
      !program_.program_path.empty()) {
    preview_token_ = program_.program_token;
    // An MDI or touch-off line keeps the program's preview.
    if (std::filesystem::path(program_.program_path).filename().string().rfind("mdi-", 0) != 0)
      dry_.start(preview_token_, program_.program_path, program_.block_delete != 0,
                 have_interp_ ? std::vector<double>(interp_.position_mm.begin(),
                                                    interp_.position_mm.begin() + interp_.num_axes)
                              : std::vector<double>{});
  }
  if (std::string p = dry_.take(); !p.empty()) {
    preview_msg_ = json::parse(p);
    out_.broadcast(preview_msg_, false);
  }

  for (auto& [client, msg] : runs_.take()) out_.send_to(client, msg);
}

// Pending actions: answered by a refusal, a load, a start, or their time running out.
void Api::follow(double now) {
  for (size_t i = 0; i < pending_.size();) {
    Pending& p = pending_[i];
    bool done = false;
    auto finish = [&](bool ok, const std::string& text) {
      result(p.client, p.id, ok, text);
      done = true;
    };
    const std::string why = have_program_ ? service::refusal_of(program_, bus_.sender(), p.seq) : "";
    if (!why.empty()) {
      finish(false, p.action + " refused: " + why);
    } else if (p.command == lcmt_program_command::JOG || p.command == lcmt_program_command::HOME) {
      if (const std::string a = alarm_since(p.alarms_at, {"jog_refused", "home_refused"}); !a.empty()) {
        finish(false, p.action + " refused: " + a);
        jogging_.erase(p.client);
      } else if (now > p.deadline_s) {
        done = true;
      }
    } else if (p.command == lcmt_program_command::LOAD) {
      if (have_program_ && program_.program_path == p.path && program_.state == lcmt_program_state::REFUSED) {
        finish(false, "program refused: " + program_.error);
      } else if (have_program_ && program_.program_path == p.path && program_.program_token != p.old_token &&
                 program_.state == lcmt_program_state::LOADED) {
        finish(true, "loaded " + p.path + ": " + std::to_string(program_.num_blocks) + " blocks");
      } else if (now > p.deadline_s) {
        finish(false, "the program server did not answer the load of " + p.path);
      }
    } else if (p.command == lcmt_program_command::MDI || p.command == lcmt_program_command::TOUCH_OFF) {
      follow_line(p, now, done);
    } else if (p.command == lcmt_program_command::RESET) {
      follow_reset(p, now, done);
    } else if (now > p.deadline_s) {
      done = true;  // answered "sent" already; no refusal came
    }
    if (done) {
      pending_.erase(pending_.begin() + static_cast<std::ptrdiff_t>(i));
    } else {
      ++i;
    }
  }
}

// An MDI or touch-off line: loaded, taken by the interpolator, then started (as cnc-ctl).
void Api::follow_line(Pending& p, double now, bool& done) {
  auto finish = [&](bool ok, const std::string& text) {
    result(p.client, p.id, ok, text);
    done = true;
  };
  if (p.stage == 0 && have_program_ && program_.program_path.ends_with(p.suffix)) {
    if (program_.state == lcmt_program_state::REFUSED) {
      finish(false, p.action + " refused: " + program_.error);
    } else if (program_.state == lcmt_program_state::LOADED && program_.program_token != p.old_token) {
      p.stage = 1;
      p.token = program_.program_token;
      spdlog::info("cnc-hmi: client {}: {} loaded as {} (token {})", p.client, p.action, program_.program_path,
                   p.token);
    }
  }
  if (!done && p.stage == 1 && have_interp_ && interp_.program_token == p.token) {
    // As cnc-ctl: the line's program, once the interpolator took it, is started.
    service::OperatorCommand c;
    c.command = lcmt_program_command::START;
    p.seq = service::send_program_command(bus_, cfg_, c);
    spdlog::info("cnc-hmi: client {}: {}: START sent (seq {})", p.client, p.action, p.seq);
    p.stage = 2;
    p.attempts = 1;
    p.next_s = now + 1.0;
  }
  if (!done && p.stage == 2) {
    if (have_interp_ && interp_.program_token == p.token && interp_.state != lcmt_setpoint::IDLE) {
      finish(true, p.action + " started");
    } else if (now >= p.next_s && p.attempts < 5) {
      service::OperatorCommand c;
      c.command = lcmt_program_command::START;
      p.seq = service::send_program_command(bus_, cfg_, c);
      ++p.attempts;
      p.next_s = now + 1.0;
    }
  }
  if (!done && now > p.deadline_s) finish(false, p.action + ": the cell did not run the line");
}

// RESET: the drives enabled (ENABLE every second), then RESET every 0.5 s until the `reset` alarm.
void Api::follow_reset(Pending& p, double now, bool& done) {
  auto finish = [&](bool ok, const std::string& text) {
    result(p.client, p.id, ok, text);
    done = true;
  };
  if (p.stage == 0) {
    if (all_enabled()) {
      p.stage = 1;
      p.next_s = 0;
    } else if (now >= p.next_s) {
      service::send_drive_command(bus_, cfg_, lcmt_drive_command::ENABLE);
      p.next_s = now + 1.0;
    }
  }
  if (p.stage == 1) {
    if (!alarm_since(p.alarms_at, {"reset"}).empty()) {
      finish(true, "reset: the drives are enabled and the interpolator stands where they are");
    } else if (now >= p.next_s) {
      service::OperatorCommand c;
      c.command = lcmt_program_command::RESET;
      p.seq = service::send_program_command(bus_, cfg_, c);
      p.next_s = now + 0.5;
    }
  }
  if (!done && now > p.deadline_s)
    finish(false, p.stage == 0 ? "reset: the drives did not enable" : "reset: the interpolator did not reset");
}

// The status snapshot, pushed at hmi.status_rate_hz.
json Api::status(double now, int64_t login_refusals, int clients) const {
  json ax = json::array();
  const bool sp_is_program = have_setpoint_ && have_program_ && setpoint_.program_token == program_.program_token;
  const BlockInfo* blk = nullptr;
  if (sp_is_program) {
    const auto it = blocks_.find(setpoint_.block_index);
    if (it != blocks_.end()) blk = &it->second;
  }
  for (int a = 0; a < naxes_; ++a) {
    const size_t i = static_cast<size_t>(a);
    json x = {{"name", cfg_.axes[i].name}};
    if (have_axes_ && a < axes_.num_axes) {
      x["cmd"] = fin(axes_.commanded_mm[i]);
      x["act"] = fin(axes_.actual_mm[i]);
      x["fe"] = fin(axes_.following_error_mm[i]);
      x["drive"] = drive_state_name(axes_.drive_state[i]);
      if (!axes_.fault[i].empty()) x["fault"] = axes_.fault[i];
    }
    if (have_interp_ && a < interp_.num_axes) x["pos"] = fin(interp_.position_mm[i]);
    if (have_interp_ && a < interp_.num_homed) x["homed"] = interp_.homed[i] != 0;
    if (blk != nullptr && have_axes_ && a < axes_.num_axes) x["dtg"] = fin(blk->end[a] - axes_.commanded_mm[i]);
    ax.push_back(x);
  }
  json s = {{"t", "status"}, {"axes", ax}, {"time", util::wall_utime()}};
  if (have_interp_) {
    static const char* const kModes[] = {"program", "jog", "home"};
    s["interp"] = {{"state", interp_state_name(interp_.state)},
                   {"mode", interp_.mode >= 0 && interp_.mode <= 2 ? kModes[interp_.mode] : "?"},
                   {"mode_text", interp_.mode_text},
                   {"feed_override", fin(interp_.feed_override)},
                   {"rapid_override", fin(interp_.rapid_override)},
                   {"spindle_override", fin(interp_.spindle_override)},
                   {"spindle_override_enabled", interp_.spindle_override_enabled != 0},
                   {"token", interp_.program_token},
                   {"blocks_done", interp_.blocks_done},
                   {"program_time_s", fin(interp_.program_time_s)},
                   {"single_block", interp_.single_block != 0},
                   {"optional_stop", interp_.optional_stop != 0},
                   {"source_line", interp_.source_line}};
  }
  if (have_program_) {
    s["program"] = {{"state", program_state_name(program_.state)},
                    {"path", program_.program_path},
                    {"token", program_.program_token},
                    {"blocks", program_.num_blocks},
                    {"error", program_.error},
                    {"refusal", program_.refusal},
                    {"block_delete", program_.block_delete != 0},
                    {"from_line", program_.from_line},
                    {"approach", program_.approach},
                    {"approach_pending", program_.approach_pending != 0}};
  }
  if (have_setpoint_) {
    s["feed"] = fin(setpoint_.feed_mm_per_min);
    if (sp_is_program) {
      // Held (single block, M1, a hold): the line the path stands before, from the interpolator.
      const bool held = have_interp_ && interp_.state == lcmt_setpoint::HELD && interp_.source_line > 0 &&
                        interp_.program_token == setpoint_.program_token;
      s["line"] = held ? interp_.source_line : setpoint_.source_line;
      s["line_in_program"] = blk == nullptr || blk->in_program;
      s["block"] = setpoint_.block_index;
    }
  }
  json sv = json::object();
  static const char* const kHb[] = {"starting", "running", "stopping", "fault"};
  for (const auto& [name, seen] : services_)
    sv[name] = {{"state", seen.hb.state >= 0 && seen.hb.state <= 3 ? kHb[seen.hb.state] : "?"},
                {"age", std::round((now - seen.at_s) * 100) / 100},
                {"lost", now - seen.at_s > cfg_.heartbeat_timeout_s}};
  s["services"] = sv;
  if (cfg_.spindle.enabled || cfg_.io.enabled) s["machine"] = machine();
  s["login_refusals"] = login_refusals;
  s["clients"] = clients;
  return s;
}

// What the machine has, from the config: the spindle's override range, every I/O point
// with its module and role (status sends their values in this order), the safety
// chain's and the probe's inputs.
json Api::devices() const {
  json d = json::object();
  if (cfg_.spindle.enabled)
    d["spindle"] = {{"max_rpm", cfg_.spindle.max_rpm},
                    {"min_override", cfg_.spindle.min_override},
                    {"max_override", cfg_.spindle.max_override}};
  if (!cfg_.io.enabled) return d;
  static const char* const kKinds[] = {"digital out", "digital in", "analog in", "analog out"};
  const std::vector<std::string> roles = service::point_roles(cfg_);
  json points = json::array();
  for (size_t p = 0; p < cfg_.io.points.size(); ++p) {
    const auto& pc = cfg_.io.points[p];
    points.push_back({{"name", pc.name},
                      {"kind", kKinds[static_cast<int>(pc.kind)]},
                      {"module", cfg_.io.modules[static_cast<size_t>(pc.module)].name},
                      {"role", roles[p]}});
  }
  d["points"] = points;
  d["coolant"] = {{"mist", cfg_.io.coolant_mist >= 0}, {"flood", cfg_.io.coolant_flood >= 0}};
  auto label = [&](int point) { return point >= 0 ? json(cfg_.io.point_label(point)) : json(nullptr); };
  d["estop_input"] = label(cfg_.safety.estop_input);
  d["door_input"] = label(cfg_.safety.door_input);
  d["hard_limits"] = !cfg_.safety.hard_limits.empty();
  d["probe_input"] = label(cfg_.probe.input);
  return d;
}

// Where the devices stand: the spindle, the coolant, each point's value (null: not
// read), the safety chain, the probe and its last result, an M66 wait.
json Api::machine() const {
  json m = json::object();
  if (have_spindle_) {
    static const char* const kStates[] = {"starting", "stopped", "running", "fault"};
    m["spindle"] = {{"state", spindle_.state >= 0 && spindle_.state <= 3 ? kStates[spindle_.state] : "?"},
                    {"direction", spindle_.direction},
                    {"commanded_rpm", fin(spindle_.commanded_rpm)},
                    {"actual_rpm", fin(spindle_.actual_rpm)},
                    {"at_speed", spindle_.command_seq > 0 && spindle_.at_speed_seq == spindle_.command_seq},
                    {"load_a", fin(spindle_.current_a)},
                    {"error_code", spindle_.error_code},
                    {"fault", spindle_.fault}};
  }
  if (have_io_) {
    m["coolant"] = {{"mist", (io_.coolant & 1) != 0}, {"flood", (io_.coolant & 2) != 0}};
    json values = json::array();
    for (int p = 0; p < io_.num_points; ++p) {
      const size_t i = static_cast<size_t>(p);
      values.push_back(io_.valid[i] ? json(fin(io_.value[i])) : json(nullptr));
    }
    m["points"] = values;
    json modules = json::array();
    for (int k = 0; k < io_.num_modules; ++k)
      modules.push_back({{"name", io_.module[static_cast<size_t>(k)]}, {"answering", io_.answering[static_cast<size_t>(k)] != 0}});
    m["modules"] = modules;
    static const char* const kEstop[] = {"none", "ok", "tripped", "disabled", "released"};
    static const char* const kLimit[] = {"none", "ok", "tripped", "disabled", "on_switch"};
    static const char* const kDoor[] = {"none", "closed", "open"};
    m["estop"] = io_.estop >= 0 && io_.estop <= 4 ? kEstop[io_.estop] : "?";
    m["estop_stop_ms"] = fin(io_.estop_stop_ms);
    m["limit"] = io_.limit >= 0 && io_.limit <= 4 ? kLimit[io_.limit] : "?";
    m["limit_input"] = io_.limit_input;
    m["door"] = io_.door >= 0 && io_.door <= 2 ? kDoor[io_.door] : "?";
  }
  if (cfg_.probe.enabled() && have_axes_) m["probe"] = axes_.probe;
  if (have_interp_) {
    if (interp_.probe_results > 0) {
      json trip = json::array(), rest = json::array();
      for (int a = 0; a < interp_.num_probe_axes; ++a) {
        trip.push_back(fin(interp_.probe_trip_mm[static_cast<size_t>(a)]));
        rest.push_back(fin(interp_.probe_rest_mm[static_cast<size_t>(a)]));
      }
      m["probe_result"] = {{"results", interp_.probe_results},
                           {"block", interp_.probe_block},
                           {"tripped", interp_.probe_tripped != 0},
                           {"trip", trip},
                           {"rest", rest}};
    }
    if (interp_.input_waiting) {
      const program::InputWait w = program::InputWait::of(interp_.input_wait);
      static const char* const kModes[] = {"immediate", "rise", "fall", "high", "low"};
      const std::vector<int>& list = w.analog ? cfg_.io.analog_inputs : cfg_.io.digital_inputs;
      const int point = static_cast<size_t>(w.index) < list.size() ? list[static_cast<size_t>(w.index)] : -1;
      m["input_wait"] = {{"input", (w.analog ? "E" : "P") + std::to_string(w.index)},
                         {"name", point >= 0 ? cfg_.io.points[static_cast<size_t>(point)].name : "?"},
                         {"mode", w.mode >= 0 && w.mode <= 4 ? kModes[w.mode] : "?"},
                         {"left_s", fin(interp_.input_wait_left_s)}};
    } else if (interp_.input_results > 0) {
      m["input_result"] = {{"block", interp_.input_block}, {"value", fin(interp_.input_value)}};
    }
  }
  return m;
}

}  // namespace cnc::hmi
