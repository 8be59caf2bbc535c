#include "common/service/machine_status.h"

#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <vector>

#include "common/program/block.h"

namespace cnc::service {

namespace {

void add(std::string* out, const char* fmt, ...) __attribute__((format(printf, 2, 3)));
void add(std::string* out, const char* fmt, ...) {
  char buf[512];
  va_list ap;
  va_start(ap, fmt);
  std::vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  *out += buf;
}

const char* kind_text(int8_t kind) {
  switch (kind) {
    case cnc::lcmt_io_status::COIL: return "digital out";
    case cnc::lcmt_io_status::DISCRETE_INPUT: return "digital in";
    case cnc::lcmt_io_status::INPUT_REGISTER: return "analog in";
    case cnc::lcmt_io_status::HOLDING_REGISTER: return "analog out";
    default: return "?";
  }
}

// A point's value as read ("?" while its module has not answered), by its index in
// io.points (IO_STATUS lists them in the same order).
std::string point_value(const cnc::lcmt_io_status* io, int point) {
  if (io == nullptr || point < 0 || point >= io->num_points) return "?";
  const size_t p = static_cast<size_t>(point);
  if (!io->valid[p]) return "?";
  char buf[32];
  if (io->kind[p] == cnc::lcmt_io_status::COIL || io->kind[p] == cnc::lcmt_io_status::DISCRETE_INPUT)
    std::snprintf(buf, sizeof buf, "%d", io->value[p] != 0 ? 1 : 0);
  else
    std::snprintf(buf, sizeof buf, "%.4g", io->value[p]);
  return buf;
}

const std::string& point_name(const cnc::config::MachineConfig& cfg, int point) {
  static const std::string none = "(none)";
  return point >= 0 && static_cast<size_t>(point) < cfg.io.points.size() ? cfg.io.points[static_cast<size_t>(point)].name
                                                                         : none;
}

}  // namespace

std::vector<std::string> point_roles(const cnc::config::MachineConfig& cfg) {
  std::vector<std::string> roles(cfg.io.points.size());
  auto role = [&](int point, const std::string& r) {
    if (point < 0 || static_cast<size_t>(point) >= roles.size()) return;
    std::string& s = roles[static_cast<size_t>(point)];
    s += (s.empty() ? "" : ", ") + r;
  };
  role(cfg.io.coolant_mist, "M7 mist");
  role(cfg.io.coolant_flood, "M8 flood");
  for (size_t n = 0; n < cfg.io.digital_outputs.size(); ++n) role(cfg.io.digital_outputs[n], "M62-M65 P" + std::to_string(n));
  for (size_t n = 0; n < cfg.io.digital_inputs.size(); ++n) role(cfg.io.digital_inputs[n], "M66 P" + std::to_string(n));
  for (size_t n = 0; n < cfg.io.analog_inputs.size(); ++n) role(cfg.io.analog_inputs[n], "M66 E" + std::to_string(n));
  for (size_t n = 0; n < cfg.io.analog_outputs.size(); ++n) role(cfg.io.analog_outputs[n], "M67/M68 E" + std::to_string(n));
  role(cfg.safety.estop_input, "E-stop");
  for (const auto& l : cfg.safety.hard_limits) {
    const std::string& axis = cfg.axes[static_cast<size_t>(l.axis)].name;
    role(l.min_input, axis + " min limit");
    role(l.max_input, axis + " max limit");
  }
  role(cfg.safety.door_input, "door");
  role(cfg.probe.input, "probe");
  return roles;
}

namespace {

void spindle_lines(const cnc::config::MachineConfig& cfg, const MachineView& v, std::string* out) {
  if (!cfg.spindle.enabled) return;
  const cnc::lcmt_spindle_status* s = v.spindle;
  if (s == nullptr) {
    *out += "spindle: no SPINDLE_STATUS heard\n";
    return;
  }
  static const char* const kStates[] = {"starting", "stopped", "running", "FAULT"};
  const char* state = s->state >= 0 && s->state <= 3 ? kStates[s->state] : "?";
  const char* dir = s->direction > 0 ? "forward (M3)" : s->direction < 0 ? "reverse (M4)" : "off (M5)";
  add(out, "spindle: %s, %s, commanded %.0f rpm, actual %.0f rpm, %s, load %.2f A", state, dir, s->commanded_rpm,
      s->actual_rpm, s->command_seq > 0 && s->at_speed_seq == s->command_seq ? "at speed" : "not at speed",
      s->current_a);
  if (v.interp != nullptr)
    add(out, ", override %.2f %s", v.interp->spindle_override,
        v.interp->spindle_override_enabled ? "(enabled)" : "(disabled: M51 P0)");
  if (s->error_code != 0) add(out, ", drive error code %d", s->error_code);
  if (!s->fault.empty()) add(out, ": %s", s->fault.c_str());
  *out += "\n";
  if (!cfg.spindle.measured_position()) return;
  // The encoder's position and the orientation (M19) of the command it follows.
  static const char* const kOrient[] = {"", ", orienting", ", oriented", ", orientation failed"};
  const char* orient = s->orient_state >= 0 && s->orient_state <= 3 ? kOrient[s->orient_state] : "";
  if (s->position_valid)
    add(out, "spindle position: %.4f rev (%.2f deg)%s\n", s->position_rev,
        (s->position_rev - std::floor(s->position_rev)) * 360.0, orient);
  else
    add(out, "spindle position: not read%s\n", orient);
}

void io_lines(const cnc::config::MachineConfig& cfg, const MachineView& v, std::string* out) {
  if (!cfg.io.enabled) return;
  const cnc::lcmt_io_status* io = v.io;
  if (io == nullptr) {
    *out += "io: no IO_STATUS heard\n";
    return;
  }
  if (cfg.io.coolant_mist >= 0 || cfg.io.coolant_flood >= 0) {
    *out += "coolant:";
    if (cfg.io.coolant_mist >= 0)
      add(out, " mist %s (%s reads %s)", io->coolant & 1 ? "on" : "off", point_name(cfg, cfg.io.coolant_mist).c_str(),
          point_value(io, cfg.io.coolant_mist).c_str());
    if (cfg.io.coolant_flood >= 0)
      add(out, "%s flood %s (%s reads %s)", cfg.io.coolant_mist >= 0 ? "," : "", io->coolant & 2 ? "on" : "off",
          point_name(cfg, cfg.io.coolant_flood).c_str(), point_value(io, cfg.io.coolant_flood).c_str());
    *out += "\n";
  }
  for (int m = 0; m < io->num_modules; ++m) {
    const size_t i = static_cast<size_t>(m);
    add(out, "io module %s: %s, %lld transactions, %lld timeouts, %lld exceptions%s%s\n", io->module[i].c_str(),
        io->answering[i] ? "answering" : "NOT ANSWERING", static_cast<long long>(io->transactions[i]),
        static_cast<long long>(io->timeouts[i]), static_cast<long long>(io->exceptions[i]),
        io->last_error[i].empty() ? "" : ", last error: ", io->last_error[i].c_str());
  }
  const std::vector<std::string> roles = point_roles(cfg);
  for (size_t p = 0; p < cfg.io.points.size(); ++p) {
    const auto& pc = cfg.io.points[p];
    const std::string module =
        static_cast<size_t>(pc.module) < cfg.io.modules.size() ? cfg.io.modules[static_cast<size_t>(pc.module)].name : "?";
    add(out, "io %-16s %-11s %-8s %s%s%s%s\n", pc.name.c_str(), kind_text(static_cast<int8_t>(pc.kind)),
        point_value(io, static_cast<int>(p)).c_str(), module.c_str(), roles[p].empty() ? "" : " (", roles[p].c_str(),
        roles[p].empty() ? "" : ")");
  }
}

void safety_lines(const cnc::config::MachineConfig& cfg, const MachineView& v, std::string* out) {
  if (!cfg.safety.enabled()) return;
  const cnc::lcmt_io_status* io = v.io;
  if (io == nullptr) return;  // io_lines said so
  if (cfg.safety.estop_input >= 0) {
    static const char* const kEstop[] = {"none", "OK", "TRIPPED (the axes brake)", "TRIPPED, drives disabled",
                                         "RELEASED (waits for fault-reset and enable)"};
    add(out, "E-stop: %s, input %s reads %s", io->estop >= 0 && io->estop <= 4 ? kEstop[io->estop] : "?",
        point_name(cfg, cfg.safety.estop_input).c_str(), point_value(io, cfg.safety.estop_input).c_str());
    if (io->estop_utime != 0 && io->estop_stop_ms >= 0) add(out, ", last trip stood in %.1f ms", io->estop_stop_ms);
    *out += "\n";
  }
  if (cfg.safety.door_input >= 0)
    add(out, "door: %s, input %s reads %s\n",
        io->door == cnc::lcmt_io_status::DOOR_OPEN     ? "OPEN (feed held, motion refused)"
        : io->door == cnc::lcmt_io_status::DOOR_CLOSED ? "shut"
                                                       : "?",
        point_name(cfg, cfg.safety.door_input).c_str(), point_value(io, cfg.safety.door_input).c_str());
  if (!cfg.safety.hard_limits.empty()) {
    static const char* const kLimit[] = {"none", "OK", "TRIPPED (the axes brake)", "TRIPPED, drives disabled",
                                         "ON SWITCH (moves only away from it)"};
    add(out, "limits: %s", io->limit >= 0 && io->limit <= 4 ? kLimit[io->limit] : "?");
    if (!io->limit_input.empty()) add(out, " (%s)", io->limit_input.c_str());
    if (io->limit_utime != 0 && io->limit_stop_ms >= 0) add(out, ", last trip stood in %.1f ms", io->limit_stop_ms);
    *out += ";";
    for (const auto& l : cfg.safety.hard_limits) {
      const std::string& axis = cfg.axes[static_cast<size_t>(l.axis)].name;
      if (l.min_input >= 0)
        add(out, " %s min %s %s", axis.c_str(), point_name(cfg, l.min_input).c_str(), point_value(io, l.min_input).c_str());
      if (l.max_input >= 0)
        add(out, " %s max %s %s", axis.c_str(), point_name(cfg, l.max_input).c_str(), point_value(io, l.max_input).c_str());
    }
    *out += "\n";
  }
}

void axes_mm(const cnc::config::MachineConfig& cfg, const std::vector<double>& mm, std::string* out) {
  for (size_t a = 0; a < mm.size() && a < cfg.axes.size(); ++a) add(out, " %s %.4f", cfg.axes[a].name.c_str(), mm[a]);
}

void probe_lines(const cnc::config::MachineConfig& cfg, const MachineView& v, std::string* out) {
  if (!cfg.probe.enabled()) return;
  const int8_t probe = v.axes != nullptr ? v.axes->probe : -1;
  add(out, "probe: input %s %s", point_name(cfg, cfg.probe.input).c_str(),
      probe == 1 ? "1 (touching)" : probe == 0 ? "0" : "? (not read)");
  const cnc::lcmt_interp_state* in = v.interp;
  if (in == nullptr || in->probe_results == 0) {
    *out += "; no probing result in this program\n";
    return;
  }
  add(out, "; %d probing moves, the last (block %lld) ", in->probe_results, static_cast<long long>(in->probe_block));
  if (in->probe_tripped) {
    *out += "tripped at";
    axes_mm(cfg, in->probe_trip_mm, out);
    *out += ", rest at";
  } else {
    *out += "did not trip, rest at";
  }
  axes_mm(cfg, in->probe_rest_mm, out);
  *out += "\n";
}

void input_wait_lines(const cnc::config::MachineConfig& cfg, const MachineView& v, std::string* out) {
  const cnc::lcmt_interp_state* in = v.interp;
  if (in == nullptr || (!in->input_waiting && in->input_results == 0)) return;
  if (in->input_waiting) {
    const program::InputWait w = program::InputWait::of(in->input_wait);
    static const char* const kModes[] = {"immediate", "rise", "fall", "high", "low"};
    const std::vector<int>& inputs = w.analog ? cfg.io.analog_inputs : cfg.io.digital_inputs;
    const int point = static_cast<size_t>(w.index) < inputs.size() ? inputs[static_cast<size_t>(w.index)] : -1;
    add(out, "M66: waiting on %s%d (%s, reads %s), mode %s, ", w.analog ? "E" : "P", w.index,
        point_name(cfg, point).c_str(), point_value(v.io, point).c_str(),
        w.mode >= 0 && w.mode <= 4 ? kModes[w.mode] : "?");
    if (in->input_wait_left_s >= 0)
      add(out, "%.1f s left of its timeout\n", in->input_wait_left_s);
    else
      *out += "no timeout\n";
    return;
  }
  if (in->input_value == -1.0)
    add(out, "M66: last wait (block %lld) timed out (#5399 = -1)\n", static_cast<long long>(in->input_block));
  else
    add(out, "M66: last wait (block %lld) read %.4g (#5399)\n", static_cast<long long>(in->input_block), in->input_value);
}

}  // namespace

void gantry_lines(const cnc::config::MachineConfig& cfg, const MachineView& v, std::string* out) {
  for (size_t i = 0; i < cfg.axes.size(); ++i) {
    const cnc::config::AxisConfig& a = cfg.axes[i];
    if (!a.gantry.enabled) continue;
    add(out, "gantry %s: ", a.name.c_str());
    const cnc::lcmt_joint_status* j = v.joints;
    size_t k = 0;
    while (j != nullptr && k < j->axis.size() && j->axis[k] != static_cast<int32_t>(i)) ++k;
    if (j == nullptr || k >= j->axis.size() || j->skew_mm.size() != j->axis.size()) {
      add(out, "%s not heard (JOINT_STATUS)\n", a.gantry.name.c_str());
      continue;
    }
    add(out, "%s at %.4f mm, squaring %.4f mm (to %.4f), skew %.4f mm (limit %g, largest since enable %.4f)\n",
        a.gantry.name.c_str(), j->actual_mm[k], j->squaring_mm[k], j->squaring_target_mm[k], j->skew_mm[k],
        a.gantry.skew_limit_mm, j->max_skew_mm[k]);
  }
}

std::string machine_status(const cnc::config::MachineConfig& cfg, const MachineView& v) {
  std::string out;
  gantry_lines(cfg, v, &out);
  spindle_lines(cfg, v, &out);
  io_lines(cfg, v, &out);
  safety_lines(cfg, v, &out);
  probe_lines(cfg, v, &out);
  input_wait_lines(cfg, v, &out);
  return out;
}

}  // namespace cnc::service
