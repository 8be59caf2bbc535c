#include "common/config/machine_config.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <map>
#include <set>

#include "common/config/yaml_reader.h"
#include "common/program/block.h"

namespace cnc::config {
namespace {
constexpr double kInf = std::numeric_limits<double>::max();

DriveConfig read_drive(MapReader r) {
  DriveConfig d;
  d.transport = r.get_choice("transport", d.transport, {"modbus_tcp", "modbus_rtu", "loopback"});
  d.host = r.get_string("host", d.host);
  d.port = static_cast<int>(r.get_int("port", d.port, 1, 65535));
  d.device = r.get_string("device", d.device);
  d.baud = static_cast<int>(r.get_int("baud", d.baud, 1200, 4'000'000));
  d.parity = r.get_choice("parity", d.parity, {"none", "even", "odd"});
  d.stop_bits = static_cast<int>(r.get_int("stop_bits", d.stop_bits, 1, 2));
  d.unit_id = static_cast<int>(r.get_int("unit_id", d.unit_id, 1, 247));
  d.profile = r.get_string("profile", d.profile);
  d.response_timeout_s = r.get_double("response_timeout_s", d.response_timeout_s, 0.001, 5.0);
  if (d.profile.empty()) r.fail("profile", "must not be empty");
  if (d.transport == "modbus_rtu" && d.device.empty()) r.fail("device", "is required for transport modbus_rtu");
  r.finish();
  return d;
}

AxisConfig read_axis(MapReader r) {
  AxisConfig a;
  a.name = r.require_string("name");
  if (a.name.empty()) r.fail("name", "must not be empty");
  a.min_mm = r.require_double("min_mm", -1e5, 1e5);
  a.max_mm = r.require_double("max_mm", -1e5, 1e5);
  if (a.max_mm <= a.min_mm) r.fail("max_mm", "must be greater than min_mm");
  a.max_velocity_mm_s = r.require_double("max_velocity_mm_s", 1e-3, 1e4);
  a.max_accel_mm_s2 = r.require_double("max_accel_mm_s2", 1e-3, 1e6);
  a.max_jerk_mm_s3 = r.require_double("max_jerk_mm_s3", 1e-3, 1e9);
  a.max_following_error_mm = r.get_double("max_following_error_mm", a.max_following_error_mm, 1e-4, 1e3);
  if (!r.has("home_mm") && (a.min_mm > 0 || a.max_mm < 0))
    r.fail("home_mm", "is required when 0 is outside [min_mm, max_mm]");
  a.home_mm = r.get_double("home_mm", 0.0, a.min_mm, a.max_mm);
  a.drive = read_drive(r.map("drive"));
  MapReader s = r.map("sim");
  a.sim.bandwidth_hz = s.get_double("bandwidth_hz", a.sim.bandwidth_hz, 0.1, 1000);
  a.sim.damping = s.get_double("damping", a.sim.damping, 0.05, 10);
  a.sim.max_velocity_mm_s = s.get_double("max_velocity_mm_s", 0.0, 0.0, 1e4);
  a.sim.comm_timeout_s = s.get_double("comm_timeout_s", 0.0, 0.0, 60.0);
  a.sim.comm_stop_decel_mm_s2 = s.get_double("comm_stop_decel_mm_s2", 0.0, 0.0, 1e6);
  a.sim.has_home_switch = s.has("home_switch_mm");
  a.sim.home_switch_mm = s.get_double("home_switch_mm", 0.0, -1e5, 1e5);
  a.sim.home_switch_sigma_mm = s.get_double("home_switch_sigma_mm", a.sim.home_switch_sigma_mm, 0.0, 10.0);
  a.sim.home_switch_hysteresis_mm = s.get_double("home_switch_hysteresis_mm", a.sim.home_switch_hysteresis_mm, 0.0, 100.0);
  a.sim.home_switch_seed = static_cast<uint64_t>(s.get_int("home_switch_seed", 1, 0, INT64_MAX));
  s.finish();
  if (r.has("home")) {
    MapReader h = r.map("home");
    HomeConfig& k = a.home;
    k.method = h.get_choice("method", "switch", {"none", "switch", "absolute"});
    k.search_velocity_mm_s = h.get_double("search_velocity_mm_s", k.search_velocity_mm_s, 1e-3, a.max_velocity_mm_s);
    k.latch_velocity_mm_s = h.get_double("latch_velocity_mm_s", k.latch_velocity_mm_s, 1e-3, a.max_velocity_mm_s);
    k.direction = static_cast<int>(h.get_int("direction", k.direction, -1, 1));
    if (k.direction == 0) h.fail("direction", "must be -1 or 1");
    k.switch_position_mm = h.get_double("switch_position_mm", k.direction < 0 ? a.min_mm : a.max_mm, -1e5, 1e5);
    k.position_mm = h.get_double("position_mm", a.home_mm, a.min_mm, a.max_mm);
    k.backoff_mm = h.get_double("backoff_mm", k.backoff_mm, 1e-3, 1e3);
    k.order = static_cast<int>(h.get_int("order", 0, 0, 64));
    h.finish();
  }
  a.jog_velocity_mm_s = r.get_double("jog_velocity_mm_s", 0.1 * a.max_velocity_mm_s, 1e-3, a.max_velocity_mm_s);
  r.finish();
  return a;
}

MachineConfig read_machine(MapReader top) {
  MachineConfig c;
  {
    MapReader r = top.map("cell");
    c.name = r.require_string("name");
    c.channel_prefix = r.get_string("channel_prefix", c.name.empty() ? "" : c.name + ".");
    c.lcm_url = r.get_string("lcm_url", "");
    r.finish();
  }
  {
    MapReader r = top.map("timing");
    c.ipo_period_s = r.get_double("ipo_period_s", c.ipo_period_s, 1e-4, 0.1);
    c.servo_period_s = r.get_double("servo_period_s", c.servo_period_s, 1e-4, 0.1);
    if (c.servo_period_s > c.ipo_period_s) r.fail("servo_period_s", "must not exceed timing.ipo_period_s");
    const double ratio = c.ipo_period_s / c.servo_period_s;
    if (std::fabs(ratio - std::round(ratio)) > 1e-9)
      r.fail("servo_period_s", "timing.ipo_period_s must be a whole multiple of it");
    c.setpoint_timeout_s = r.get_double("setpoint_timeout_s", c.setpoint_timeout_s, 2 * c.ipo_period_s, 10.0);
    c.stop_decel_mm_s2 = r.get_double("stop_decel_mm_s2", c.stop_decel_mm_s2, 1.0, 1e6);
    c.heartbeat_period_s = r.get_double("heartbeat_period_s", c.heartbeat_period_s, 0.05, 60.0);
    c.heartbeat_timeout_s = r.get_double("heartbeat_timeout_s", 4 * c.heartbeat_period_s, 2 * c.heartbeat_period_s, 600.0);
    c.realtime_priority = static_cast<int>(r.get_int("realtime_priority", 0, 0, 98));
    const YAML::Node cpus = r.sequence("realtime_cpus");
    for (size_t i = 0; i < cpus.size(); ++i) {
      const std::string path = r.item_path("realtime_cpus", i);
      int64_t cpu = -1;
      try {
        if (cpus[i].IsScalar()) cpu = cpus[i].as<int64_t>();
      } catch (const YAML::Exception&) {
        cpu = -1;
      }
      if (cpu < 0 || cpu > 1023)
        throw ConfigError(top.file(), path, "expected a CPU number 0..1023, got '" + YAML::Dump(cpus[i]) + "'");
      if (std::find(c.realtime_cpus.begin(), c.realtime_cpus.end(), cpu) != c.realtime_cpus.end())
        throw ConfigError(top.file(), path, "CPU " + std::to_string(cpu) + " is listed twice");
      c.realtime_cpus.push_back(static_cast<int>(cpu));
    }
    r.finish();
  }
  {
    MapReader r = top.map("motion");
    c.default_feed_mm_per_min = r.get_double("default_feed_mm_per_min", c.default_feed_mm_per_min, 1e-3, 1e6);
    c.chord_tolerance_mm = r.get_double("chord_tolerance_mm", c.chord_tolerance_mm, 1e-8, 1.0);
    c.path_accel_mm_s2 = r.get_double("path_accel_mm_s2", c.path_accel_mm_s2, 1e-3, 1e6);
    c.path_jerk_mm_s3 = r.get_double("path_jerk_mm_s3", c.path_jerk_mm_s3, 1e-3, 1e9);
    c.block_window = static_cast<int>(r.get_int("block_window", c.block_window, 1, 4096));
    c.plan_budget_samples = static_cast<int>(r.get_int("plan_budget_samples", c.plan_budget_samples, 2, 10'000'000));
    c.param_update = r.get_choice("param_update", c.param_update, {"first_order", "taylor2", "corrected"});
    r.finish();
  }
  if (top.has("operator")) {
    MapReader r = top.map("operator");
    c.operator_.homing_required = r.get_bool("homing_required", false);
    c.operator_.jog_keepalive_timeout_s = r.get_double("jog_keepalive_timeout_s", 0.2, 0.01, 10.0);
    c.operator_.mdi_directory = r.get_string("mdi_directory", "");
    if (r.has("safe_z_mm")) c.operator_.safe_z_mm = r.get_double("safe_z_mm", 0.0, -1e6, 1e6);
    r.finish();
  }
  {
    MapReader r = top.map("hmi");
    const std::filesystem::path base = std::filesystem::path(top.file()).parent_path();
    const auto resolve = [&](const std::string& v) {
      if (v.empty() || v[0] == '/') return v;
      return (base / v).lexically_normal().string();
    };
    c.hmi.listen = r.get_string("listen", c.hmi.listen);
    c.hmi.port = static_cast<int>(r.get_int("port", c.hmi.port, 1, 65535));
    c.hmi.users_file = resolve(r.get_string("users_file", ""));
    c.hmi.read_only_without_login = r.get_bool("read_only_without_login", false);
    c.hmi.program_dir = resolve(r.get_string("program_dir", "../programs"));
    c.hmi.status_rate_hz = r.get_double("status_rate_hz", c.hmi.status_rate_hz, 20.0, 100.0);
    c.hmi.runs_dir = resolve(r.get_string("runs_dir", ""));
    const bool local = c.hmi.listen == "127.0.0.1" || c.hmi.listen == "::1" || c.hmi.listen == "localhost";
    if (!local && c.hmi.users_file.empty())
      r.fail("users_file", "is required when hmi.listen is not a localhost address ('" + c.hmi.listen +
                               "'): a shop network needs passwords (cnc-hmi --hash-password makes a line)");
    r.finish();
  }
  {
    MapReader r = top.map("process");
    c.process.ball_radius_mm = r.get_double("ball_radius_mm", 0.0, 0.0, 100.0);
    c.process.flutes = static_cast<int>(r.get_int("flutes", 0, 0, program::kMaxFlutes));
    c.process.pick_feed_mm = r.get_double("pick_feed_mm", 0.0, 0.0, 100.0);
    c.process.target_rmax_um = r.get_double("target_rmax_um", 0.0, 0.0, 1000.0);
    c.process.spindle_rpm = r.get_double("spindle_rpm", 0.0, 0.0, 200000.0);
    r.finish();
  }
  if (top.has("cutting")) {
    MapReader r = top.map("cutting");
    CuttingConfig& k = c.cutting;
    k.enabled = true;
    const std::string base = std::filesystem::path(top.file()).parent_path().string();
    const auto file = [&](const char* key) {
      std::string v = r.require_string(key);
      if (!v.empty() && v[0] != '/') v = (std::filesystem::path(base) / v).lexically_normal().string();
      if (!std::filesystem::is_regular_file(v)) r.fail(key, "'" + v + "' is not a file");
      return v;
    };
    k.tool_file = file("tool");
    k.material_file = file("material");
    k.model = r.get_choice("model", "", {"", "linear_edge", "chip_thickness_law"});
    MapReader s = r.map("stock");
    k.stock_x_min_mm = s.require_double("x_min_mm", -1e5, 1e5);
    k.stock_y_min_mm = s.require_double("y_min_mm", -1e5, 1e5);
    k.stock_x_max_mm = s.require_double("x_max_mm", -1e5, 1e5);
    k.stock_y_max_mm = s.require_double("y_max_mm", -1e5, 1e5);
    k.stock_top_z_mm = s.require_double("top_z_mm", -1e5, 1e5);
    k.stock_pitch_mm = s.get_double("pitch_mm", k.stock_pitch_mm, 0.001, 10.0);
    if (!(k.stock_x_max_mm > k.stock_x_min_mm)) s.fail("x_max_mm", "must be greater than x_min_mm");
    if (!(k.stock_y_max_mm > k.stock_y_min_mm)) s.fail("y_max_mm", "must be greater than y_min_mm");
    // The monitor and the planner each hold the stock: at most 2^24 columns (64 MB).
    const double cells = std::ceil((k.stock_x_max_mm - k.stock_x_min_mm) / k.stock_pitch_mm) *
                         std::ceil((k.stock_y_max_mm - k.stock_y_min_mm) / k.stock_pitch_mm);
    if (cells > 16777216.0)
      s.fail("pitch_mm", "the stock would have " + std::to_string(static_cast<long long>(cells)) +
                             " columns, more than 16777216: a coarser pitch or a smaller box");
    s.finish();
    k.deflection_tolerance_mm = r.require_double("deflection_tolerance_mm", 1e-6, 100.0);
    k.max_force_n = r.get_double("max_force_n", 0.0, 0.0, 1e7);
    k.feed_limit = r.get_bool("feed_limit", k.feed_limit);
    k.station_mm = r.get_double("station_mm", k.station_mm, 0.001, 10.0);
    k.disc_height_mm = r.get_double("disc_height_mm", k.disc_height_mm, 0.001, 10.0);
    k.angles_per_tooth = static_cast<int>(r.get_int("angles_per_tooth", k.angles_per_tooth, 1, 360));
    r.finish();
  }
  {
    MapReader r = top.map("program");
    ProgramConfig& p = c.program;
    const std::string base = std::filesystem::path(top.file()).parent_path().string();
    const auto resolve = [&](const std::string& v) {
      if (v.empty() || v[0] == '/') return v;
      return (std::filesystem::path(base) / v).lexically_normal().string();
    };
    const std::string sub = r.get_string("subroutine_path", "");
    for (size_t b = 0; b < sub.size();) {
      size_t e = sub.find(':', b);
      if (e == std::string::npos) e = sub.size();
      if (e > b) p.subroutine_path.push_back(resolve(sub.substr(b, e - b)));
      b = e + 1;
    }
    for (const std::string& d : p.subroutine_path)
      if (!std::filesystem::is_directory(d)) r.fail("subroutine_path", "'" + d + "' is not a folder");
    p.tool_table = resolve(r.get_string("tool_table", ""));
    if (!p.tool_table.empty() && !std::filesystem::is_regular_file(p.tool_table))
      r.fail("tool_table", "'" + p.tool_table + "' is not a file");
    p.var_file = resolve(r.get_string("var_file", ""));
    p.probe = r.get_bool("probe", p.probe);
    p.digital_inputs = static_cast<int>(r.get_int("digital_inputs", p.digital_inputs, 0, 64));
    p.analog_inputs = static_cast<int>(r.get_int("analog_inputs", p.analog_inputs, 0, 64));
    p.digital_outputs = static_cast<int>(r.get_int("digital_outputs", p.digital_outputs, 0, 64));
    p.analog_outputs = static_cast<int>(r.get_int("analog_outputs", p.analog_outputs, 0, 64));
    p.block_delete = r.get_bool("block_delete", p.block_delete);
    p.optional_stop = r.get_bool("optional_stop", p.optional_stop);
    p.max_validation_lines = r.get_int("max_validation_lines", p.max_validation_lines, 1000, int64_t{1} << 40);
    p.g64_fit = r.get_bool("g64_fit", p.g64_fit);
    p.g64_fit_max_segment_mm = r.get_double("g64_fit_max_segment_mm", p.g64_fit_max_segment_mm, 0.001, 1000.0);
    p.g64_fit_max_turn_deg = r.get_double("g64_fit_max_turn_deg", p.g64_fit_max_turn_deg, 0.0, 90.0);
    r.finish();
  }
  {
    YAML::Node axes = top.sequence("axes");
    if (axes.size() == 0) top.fail("axes", "at least one axis is required");
    if (axes.size() > 9) top.fail("axes", "at most 9 axes are supported");
    std::set<std::string> names;
    std::set<std::tuple<std::string, std::string, int, std::string, int>> addresses;
    for (size_t i = 0; i < axes.size(); ++i) {
      const std::string path = top.item_path("axes", i);
      AxisConfig a = read_axis(MapReader(axes[i], path, top.file()));
      if (!names.insert(a.name).second) throw ConfigError(top.file(), path + ".name", "duplicate axis '" + a.name + "'");
      const auto addr = std::make_tuple(a.drive.transport, a.drive.host, a.drive.port, a.drive.device, a.drive.unit_id);
      if (!addresses.insert(addr).second)
        throw ConfigError(top.file(), path + ".drive.unit_id", "another axis already uses this drive address");
      for (const auto& other : c.axes) {
        if (other.drive.link_key() != a.drive.link_key()) continue;
        if (other.drive.baud != a.drive.baud || other.drive.parity != a.drive.parity ||
            other.drive.stop_bits != a.drive.stop_bits)
          throw ConfigError(top.file(), path + ".drive.baud",
                            "axis " + other.name + " is on the same serial line with other line settings");
      }
      c.axes.push_back(std::move(a));
    }
  }
  {
    MapReader r = top.map("drive_bridge");
    DriveBridgeConfig& b = c.drive_bridge;
    b.enable_on_start = r.get_bool("enable_on_start", b.enable_on_start);
    c.drive_profile_dir = r.get_string("profile_dir", c.drive_profile_dir);
    b.enable_timeout_s = r.get_double("enable_timeout_s", b.enable_timeout_s, 0.01, 60.0);
    b.link_loss_timeout_s = r.get_double("link_loss_timeout_s", b.link_loss_timeout_s, 0.001, 60.0);
    b.reconnect_min_s = r.get_double("reconnect_min_s", b.reconnect_min_s, 0.001, 60.0);
    b.reconnect_max_s = r.get_double("reconnect_max_s", b.reconnect_max_s, b.reconnect_min_s, 600.0);
    b.lead_cycles = r.get_double("lead_cycles", b.lead_cycles, 1.5, 16.0);
    for (const auto& a : c.axes) {
      if (b.link_loss_timeout_s < a.drive.response_timeout_s)
        r.fail("link_loss_timeout_s", "must not be shorter than axis " + a.name + "'s drive.response_timeout_s");
    }
    r.finish();
  }
  {
    MapReader r = top.map("logger");
    c.log_directory = r.get_string("directory", c.log_directory);
    c.log_rotate_mb = r.get_double("rotate_mb", c.log_rotate_mb, 1.0, 1e6);
    c.log_flush_period_s = r.get_double("flush_period_s", c.log_flush_period_s, 0.01, 60.0);
    r.finish();
  }
  {
    MapReader r = top.map("security");
    SecurityConfig& sec = c.security;
    sec.signing = r.get_bool("signing", sec.signing);
    const std::string key = r.get_string("key_file", "");
    if (!key.empty() && key[0] != '/') {
      const std::string base = std::filesystem::path(top.file()).parent_path().string();
      sec.key_file = (std::filesystem::path(base) / key).lexically_normal().string();
    } else {
      sec.key_file = key;
    }
    if (sec.signing && sec.key_file.empty()) r.fail("key_file", "is required when security.signing is true");
    sec.max_age_s = r.get_double("max_age_s", sec.max_age_s, 0.01, 3600.0);
    r.finish();
  }
  {
    MapReader r = top.map("monitor");
    c.monitor_rmax_margin = r.get_double("rmax_margin", c.monitor_rmax_margin, 0.0, 10.0);
    r.finish();
  }
  top.finish();
  return c;
}
}  // namespace

std::string DriveConfig::link_key() const {
  if (transport == "modbus_tcp") return "tcp://" + host + ":" + std::to_string(port);
  if (transport == "modbus_rtu") return "rtu://" + device;
  return "loopback";
}

int MachineConfig::axis_index(const std::string& axis_name) const {
  for (size_t i = 0; i < axes.size(); ++i)
    if (axes[i].name == axis_name) return static_cast<int>(i);
  return -1;
}

MachineConfig load_machine_config(const std::string& file) {
  // Read once and parse that text, so source_text is exactly what was loaded.
  std::ifstream in(file, std::ios::binary);
  if (!in) throw ConfigError(file, "", "cannot open the file");
  std::ostringstream text;
  text << in.rdbuf();
  return parse_machine_config(text.str(), file);
}

MachineConfig parse_machine_config(const std::string& yaml_text, const std::string& file_label) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::ParserException& e) {
    throw ConfigError(file_label, "", "YAML syntax error at line " + std::to_string(e.mark.line + 1) + ", column " +
                                          std::to_string(e.mark.column + 1) + ": " + e.msg);
  }
  MachineConfig c = read_machine(MapReader(root, "", file_label));
  c.source_file = file_label;
  c.source_text = yaml_text;
  return c;
}

}  // namespace cnc::config
