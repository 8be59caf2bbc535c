#include "common/config/machine_config.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <map>
#include <set>

#include "common/config/yaml_reader.h"
#include "common/drive/transport.h"
#include "common/program/block.h"

namespace cnc::config {
namespace {
constexpr double kInf = std::numeric_limits<double>::max();
using drive::Transport;

std::set<std::string> transport_names() {
  std::set<std::string> names;
  for (const auto& [t, n] : drive::kTransports) names.emplace(n);
  return names;
}

// The keys of each mapping, in the order the reader reads them. Each reader below is
// given its table: it may read no other key, and the table rejects every other key.
constexpr std::string_view kTopKeys[] = {"cell",    "timing", "motion", "operator",     "hmi",    "process",
                                         "cutting", "program", "axes",  "drive_bridge", "logger", "security",
                                         "monitor", "spindle", "io",  "safety", "kinematics",
                                         "probe", "opcua", "mqtt"};
constexpr std::string_view kCellKeys[] = {"name", "channel_prefix", "lcm_url"};
constexpr std::string_view kTimingKeys[] = {"ipo_period_s",       "servo_period_s",      "setpoint_timeout_s",
                                            "stop_decel_mm_s2",   "heartbeat_period_s",  "heartbeat_timeout_s",
                                            "realtime_priority",  "realtime_cpus"};
constexpr std::string_view kMotionKeys[] = {"default_feed_mm_per_min", "chord_tolerance_mm", "path_accel_mm_s2",
                                            "path_jerk_mm_s3",         "block_window",       "plan_budget_samples",
                                            "param_update"};
constexpr std::string_view kOperatorKeys[] = {"homing_required", "jog_keepalive_timeout_s", "mdi_directory",
                                              "safe_z_mm"};
constexpr std::string_view kHmiKeys[] = {"listen",      "port",           "users_file", "read_only_without_login",
                                         "program_dir", "status_rate_hz", "runs_dir",   "upload_max_bytes"};
constexpr std::string_view kOpcuaKeys[] = {"listen",   "port",          "anonymous",        "allow_security_none",
                                           "trust_unknown_clients", "hmi_user", "hmi_password_file", "identification"};
constexpr std::string_view kOpcuaIdKeys[] = {"manufacturer", "model", "serial_number", "product_instance_uri",
                                             "year_of_construction"};
constexpr std::string_view kMqttKeys[] = {"host",     "port",          "topic_prefix", "client_id", "keepalive_s",
                                          "state_period_s", "username", "password_file", "ca_file", "cert_file",
                                          "key_file"};
constexpr std::string_view kProcessKeys[] = {"ball_radius_mm", "flutes", "pick_feed_mm", "target_rmax_um",
                                             "spindle_rpm"};
constexpr std::string_view kCuttingKeys[] = {"tool",          "material",       "model",          "stock",
                                             "deflection_tolerance_mm", "max_force_n", "feed_limit", "station_mm",
                                             "disc_height_mm", "angles_per_tooth"};
constexpr std::string_view kStockKeys[] = {"x_min_mm", "y_min_mm", "x_max_mm", "y_max_mm", "top_z_mm", "pitch_mm"};
constexpr std::string_view kProgramKeys[] = {
    "subroutine_path", "m6_remap",     "tool_table",    "var_file",      "probe",         "digital_inputs",
    "analog_inputs",   "digital_outputs", "analog_outputs", "block_delete", "optional_stop",
    "max_validation_lines", "dry_run_max_time_s", "g64_fit", "g64_fit_max_segment_mm", "g64_fit_max_segment_per_p", "g64_fit_max_turn_deg",
    "default_path_tolerance_mm"};
constexpr std::string_view kAxisKeys[] = {"name",          "type",    "wrapped",         "min_mm",
                                          "max_mm",        "max_velocity_mm_s", "max_accel_mm_s2", "max_jerk_mm_s3",
                                          "max_following_error_mm", "home_mm", "drive",     "sim",
                                          "home",          "jog_velocity_mm_s", "gantry"};
constexpr std::string_view kGantryKeys[] = {"name", "drive", "switch_position_mm", "skew_limit_mm",
                                            "home_max_difference_mm", "sim"};
constexpr std::string_view kDriveKeys[] = {"transport", "host",      "port",    "device",  "baud",
                                           "parity",    "stop_bits", "unit_id", "profile", "response_timeout_s"};
constexpr std::string_view kSimKeys[] = {"bandwidth_hz",         "damping",          "max_velocity_mm_s",
                                         "comm_timeout_s",       "comm_stop_decel_mm_s2", "home_switch_mm",
                                         "home_switch_sigma_mm", "home_switch_hysteresis_mm", "home_switch_seed",
                                         "limit_min_mm",         "limit_max_mm"};
constexpr std::string_view kHomeKeys[] = {"method",      "search_velocity_mm_s", "latch_velocity_mm_s",
                                          "direction",   "switch_position_mm",   "position_mm",
                                          "backoff_mm",  "order"};
constexpr std::string_view kSpindleKeys[] = {"drive",        "max_rpm",      "rpm_per_hz", "at_speed_tolerance",
                                             "at_speed_timeout_s", "min_override", "max_override", "encoder_counts_per_rev", "sync_lead_s", "orient_offset_deg",
                                             "orient_tolerance_deg", "orient_timeout_s", "orient_rpm",
                                             "orient_gain_per_s", "sim"};
constexpr std::string_view kSpindleSimKeys[] = {"time_constant_s", "load_current_a", "inertia_current_a"};
constexpr std::string_view kIoKeys[] = {"modules",        "points",        "coolant",       "digital_outputs",
                                        "digital_inputs", "analog_inputs", "analog_outputs"};
constexpr std::string_view kIoModuleKeys[] = {"name",   "transport", "host",    "port",
                                              "device", "baud",      "parity",  "stop_bits",
                                              "unit_id", "response_timeout_s"};
constexpr std::string_view kIoPointKeys[] = {"name", "module", "kind", "address", "scale", "signed"};
constexpr std::string_view kIoCoolantKeys[] = {"mist", "flood"};
constexpr std::string_view kSafetyKeys[] = {"estop", "hard_limits", "door"};
constexpr std::string_view kSafetyLimitKeys[] = {"axis", "min", "max"};
constexpr std::string_view kSafetyEstopKeys[] = {"input"};
constexpr std::string_view kSafetyDoorKeys[] = {"input"};
constexpr std::string_view kKinematicsKeys[] = {"type",        "x_rot_point_mm", "y_rot_point_mm", "z_rot_point_mm",
                                                "x_offset_mm", "y_offset_mm",    "z_offset_mm",    "conventional_directions",
                                                "pivot_mm",    "solution",       "pole_tolerance_deg"};
constexpr std::string_view kProbeKeys[] = {"input", "latch", "sim_box"};
constexpr std::string_view kProbeBoxKeys[] = {"x_min_mm", "x_max_mm", "y_min_mm", "y_max_mm", "z_min_mm", "z_max_mm",
                                             "bore_x_mm", "bore_y_mm", "bore_diameter_mm"};
constexpr std::string_view kDriveBridgeKeys[] = {"enable_on_start", "profile_dir",     "enable_timeout_s",
                                                 "link_loss_timeout_s", "reconnect_min_s", "reconnect_max_s",
                                                 "lead_cycles"};
constexpr std::string_view kLoggerKeys[] = {"directory", "rotate_mb", "flush_period_s"};
constexpr std::string_view kSecurityKeys[] = {"signing", "key_file", "max_age_s"};
constexpr std::string_view kMonitorKeys[] = {"rmax_margin"};

constexpr KeySection kSections[] = {
    {"", kTopKeys},
    {"cell", kCellKeys},
    {"timing", kTimingKeys},
    {"motion", kMotionKeys},
    {"operator", kOperatorKeys},
    {"hmi", kHmiKeys},
    {"opcua", kOpcuaKeys},
    {"opcua.identification", kOpcuaIdKeys},
    {"mqtt", kMqttKeys},
    {"process", kProcessKeys},
    {"cutting", kCuttingKeys},
    {"cutting.stock", kStockKeys},
    {"program", kProgramKeys},
    {"axes[]", kAxisKeys},
    {"axes[].drive", kDriveKeys},
    {"axes[].sim", kSimKeys},
    {"axes[].home", kHomeKeys},
    {"axes[].gantry", kGantryKeys},
    {"axes[].gantry.drive", kDriveKeys},
    {"axes[].gantry.sim", kSimKeys},
    {"drive_bridge", kDriveBridgeKeys},
    {"spindle", kSpindleKeys},
    {"spindle.drive", kDriveKeys},
    {"spindle.sim", kSpindleSimKeys},
    {"io", kIoKeys},
    {"io.modules[]", kIoModuleKeys},
    {"io.points[]", kIoPointKeys},
    {"io.coolant", kIoCoolantKeys},
    {"safety", kSafetyKeys},
    {"safety.estop", kSafetyEstopKeys},
    {"safety.hard_limits[]", kSafetyLimitKeys},
    {"safety.door", kSafetyDoorKeys},
    {"probe", kProbeKeys},
    {"probe.sim_box", kProbeBoxKeys},
    {"logger", kLoggerKeys},
    {"security", kSecurityKeys},
    {"monitor", kMonitorKeys},
    {"kinematics", kKinematicsKeys},
};

// A path relative to the config file's folder; "" and absolute paths stay as they are.
std::string beside(const MapReader& r, const std::string& v) {
  if (v.empty() || v[0] == '/') return v;
  return (std::filesystem::path(r.file()).parent_path() / v).lexically_normal().string();
}

// The Modbus link's keys a drive and an I/O module share (the unit id is each one's own).
void read_link(MapReader& r, DriveConfig& d) {
  d.transport = r.get_choice("transport", d.transport, transport_names());
  d.host = r.get_string("host", d.host);
  d.port = static_cast<int>(r.get_int("port", d.port, 1, 65535));
  d.device = r.get_string("device", d.device);
  d.baud = static_cast<int>(r.get_int("baud", d.baud, 1200, 4'000'000));
  d.parity = r.get_choice("parity", d.parity, {"none", "even", "odd"});
  d.stop_bits = static_cast<int>(r.get_int("stop_bits", d.stop_bits, 1, 2));
  d.response_timeout_s = r.get_double("response_timeout_s", d.response_timeout_s, 0.001, 5.0);
  if (drive::transport_named(d.transport) == Transport::kModbusRtu && d.device.empty())
    r.fail("device", "is required for transport modbus_rtu");
}

DriveConfig read_drive(MapReader r) {
  DriveConfig d;
  read_link(r, d);
  d.unit_id = static_cast<int>(r.get_int("unit_id", d.unit_id, 1, 247));
  d.profile = r.get_string("profile", d.profile);
  if (d.profile.empty()) r.fail("profile", "must not be empty");
  r.finish();
  return d;
}

ServoSimAxisConfig read_sim(MapReader s) {
  ServoSimAxisConfig k;
  k.bandwidth_hz = s.get_double("bandwidth_hz", k.bandwidth_hz, 0.1, 1000);
  k.damping = s.get_double("damping", k.damping, 0.05, 10);
  k.max_velocity_mm_s = s.get_double("max_velocity_mm_s", 0.0, 0.0, 1e4);
  k.comm_timeout_s = s.get_double("comm_timeout_s", 0.0, 0.0, 60.0);
  k.comm_stop_decel_mm_s2 = s.get_double("comm_stop_decel_mm_s2", 0.0, 0.0, 1e6);
  k.has_home_switch = s.has("home_switch_mm");
  k.home_switch_mm = s.get_double("home_switch_mm", 0.0, -1e5, 1e5);
  k.home_switch_sigma_mm = s.get_double("home_switch_sigma_mm", k.home_switch_sigma_mm, 0.0, 10.0);
  k.home_switch_hysteresis_mm = s.get_double("home_switch_hysteresis_mm", k.home_switch_hysteresis_mm, 0.0, 100.0);
  k.home_switch_seed = static_cast<uint64_t>(s.get_int("home_switch_seed", 1, 0, INT64_MAX));
  if (s.has("limit_min_mm")) k.limit_min_mm = s.get_double("limit_min_mm", 0.0, -1e5, 1e5);
  if (s.has("limit_max_mm")) k.limit_max_mm = s.get_double("limit_max_mm", 0.0, -1e5, 1e5);
  if (k.limit_min_mm >= k.limit_max_mm) s.fail("limit_max_mm", "must be above limit_min_mm");
  s.finish();
  return k;
}

HomeConfig read_home(MapReader h, const AxisConfig& a) {
  HomeConfig k;
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
  return k;
}

GantryConfig read_gantry(MapReader g, const AxisConfig& a) {
  GantryConfig k;
  k.enabled = true;
  k.name = g.require_string("name");
  if (k.name.empty()) g.fail("name", "must not be empty");
  if (!g.has("drive")) g.fail("drive", "is required: the second side's drive");
  k.drive = read_drive(g.map("drive", kDriveKeys));
  k.switch_position_mm = g.get_double("switch_position_mm", a.home.switch_position_mm, -1e5, 1e5);
  k.skew_limit_mm = g.get_double("skew_limit_mm", k.skew_limit_mm, 1e-3, 100);
  k.home_max_difference_mm = g.get_double("home_max_difference_mm", k.home_max_difference_mm, 1e-3, 1e3);
  // Without its own sim: section the second simulated drive is the first's.
  k.sim = g.has("sim") ? read_sim(g.map("sim", kSimKeys)) : a.sim;
  g.finish();
  return k;
}

AxisConfig read_axis(MapReader r) {
  AxisConfig a;
  a.name = r.require_string("name");
  if (a.name.empty()) r.fail("name", "must not be empty");
  a.rotary = r.get_choice("type", "linear", {"linear", "rotary"}) == "rotary";
  if (a.rotary && a.name != "A" && a.name != "B" && a.name != "C")
    r.fail("type", "rotary is for the axes A, B and C only (this one is " + a.name + ")");
  a.wrapped = r.get_bool("wrapped", false);
  if (a.wrapped && !a.rotary) r.fail("wrapped", "needs type: rotary");
  if (a.wrapped) {
    // LinuxCNC's wrapped rotary axis has no travel limits: a travel far beyond any
    // program (±kWrappedTravelDeg) keeps every check and clamp finite.
    for (const char* k : {"min_mm", "max_mm"})
      if (r.has(k)) r.fail(k, "a wrapped axis has no travel limits");
    a.min_mm = -kWrappedTravelDeg;
    a.max_mm = kWrappedTravelDeg;
  } else {
    a.min_mm = r.require_double("min_mm", -1e5, 1e5);
    a.max_mm = r.require_double("max_mm", -1e5, 1e5);
  }
  if (a.max_mm <= a.min_mm) r.fail("max_mm", "must be greater than min_mm");
  a.max_velocity_mm_s = r.require_double("max_velocity_mm_s", 1e-3, 1e4);
  a.max_accel_mm_s2 = r.require_double("max_accel_mm_s2", 1e-3, 1e6);
  a.max_jerk_mm_s3 = r.require_double("max_jerk_mm_s3", 1e-3, 1e9);
  a.max_following_error_mm = r.get_double("max_following_error_mm", a.max_following_error_mm, 1e-4, 1e3);
  if (!r.has("home_mm") && (a.min_mm > 0 || a.max_mm < 0))
    r.fail("home_mm", "is required when 0 is outside [min_mm, max_mm]");
  a.home_mm = r.get_double("home_mm", 0.0, a.min_mm, a.max_mm);
  a.drive = read_drive(r.map("drive", kDriveKeys));
  a.sim = read_sim(r.map("sim", kSimKeys));
  if (r.has("home")) a.home = read_home(r.map("home", kHomeKeys), a);
  a.jog_velocity_mm_s = r.get_double("jog_velocity_mm_s", 0.1 * a.max_velocity_mm_s, 1e-3, a.max_velocity_mm_s);
  if (r.has("gantry")) {
    if (a.rotary) r.fail("gantry", "a gantry is a linear axis (this one is type: rotary)");
    if (a.home.method == "absolute")
      r.fail("gantry", "a gantry squares on its two switches: home.method switch (or none), not absolute");
    a.gantry = read_gantry(r.map("gantry", kGantryKeys), a);
  }
  r.finish();
  return a;
}

void read_cell(MapReader r, MachineConfig& c) {
  c.name = r.require_string("name");
  c.channel_prefix = r.get_string("channel_prefix", c.name.empty() ? "" : c.name + ".");
  c.lcm_url = r.get_string("lcm_url", "");
  r.finish();
}

void read_timing(MapReader r, MachineConfig& c) {
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
      throw ConfigError(r.file(), path, "expected a CPU number 0..1023, got '" + YAML::Dump(cpus[i]) + "'");
    if (std::find(c.realtime_cpus.begin(), c.realtime_cpus.end(), cpu) != c.realtime_cpus.end())
      throw ConfigError(r.file(), path, "CPU " + std::to_string(cpu) + " is listed twice");
    c.realtime_cpus.push_back(static_cast<int>(cpu));
  }
  r.finish();
}

void read_motion(MapReader r, MachineConfig& c) {
  c.default_feed_mm_per_min = r.get_double("default_feed_mm_per_min", c.default_feed_mm_per_min, 1e-3, 1e6);
  c.chord_tolerance_mm = r.get_double("chord_tolerance_mm", c.chord_tolerance_mm, 1e-8, 1.0);
  c.path_accel_mm_s2 = r.get_double("path_accel_mm_s2", c.path_accel_mm_s2, 1e-3, 1e6);
  c.path_jerk_mm_s3 = r.get_double("path_jerk_mm_s3", c.path_jerk_mm_s3, 1e-3, 1e9);
  c.block_window = static_cast<int>(r.get_int("block_window", c.block_window, 1, 4096));
  c.plan_budget_samples = static_cast<int>(r.get_int("plan_budget_samples", c.plan_budget_samples, 2, 10'000'000));
  c.param_update = r.get_choice("param_update", c.param_update, {"first_order", "taylor2", "corrected"});
  r.finish();
}

void read_operator(MapReader r, OperatorConfig& o) {
  o.homing_required = r.get_bool("homing_required", false);
  o.jog_keepalive_timeout_s = r.get_double("jog_keepalive_timeout_s", 0.2, 0.01, 10.0);
  o.mdi_directory = r.get_string("mdi_directory", "");
  if (r.has("safe_z_mm")) o.safe_z_mm = r.get_double("safe_z_mm", 0.0, -1e6, 1e6);
  r.finish();
}

void read_hmi(MapReader r, HmiConfig& h) {
  h.listen = r.get_string("listen", h.listen);
  h.port = static_cast<int>(r.get_int("port", h.port, 1, 65535));
  h.users_file = beside(r, r.get_string("users_file", ""));
  h.read_only_without_login = r.get_bool("read_only_without_login", false);
  h.program_dir = beside(r, r.get_string("program_dir", "../programs"));
  h.status_rate_hz = r.get_double("status_rate_hz", h.status_rate_hz, 20.0, 100.0);
  h.runs_dir = beside(r, r.get_string("runs_dir", ""));
  h.upload_max_bytes = r.get_int("upload_max_bytes", h.upload_max_bytes, 1024, int64_t{256} << 20);
  const bool local = h.listen == "127.0.0.1" || h.listen == "::1" || h.listen == "localhost";
  if (!local && h.users_file.empty())
    r.fail("users_file", "is required when hmi.listen is not a localhost address ('" + h.listen +
                             "'): a shop network needs passwords (cnc-hmi --hash-password makes a line)");
  r.finish();
}

// After read_hmi: who may log in depends on the HMI's users.
void read_opcua(MapReader r, const HmiConfig& hmi, const std::string& cell, OpcuaConfig& o) {
  o.enabled = true;
  o.listen = r.get_string("listen", o.listen);
  o.port = static_cast<int>(r.get_int("port", o.port, 1, 65535));
  o.anonymous = r.get_bool("anonymous", false);
  o.allow_security_none = r.get_bool("allow_security_none", false);
  o.trust_unknown_clients = r.get_bool("trust_unknown_clients", false);
  o.hmi_user = r.get_string("hmi_user", "");
  o.hmi_password_file = beside(r, r.get_string("hmi_password_file", ""));
  MapReader id = r.map("identification", kOpcuaIdKeys);
  o.manufacturer = id.require_string("manufacturer");
  o.model = id.require_string("model");
  o.serial_number = id.require_string("serial_number");
  o.product_instance_uri = id.get_string("product_instance_uri", "urn:cnc:" + cell + ":" + o.serial_number);
  o.year_of_construction = static_cast<int>(id.get_int("year_of_construction", 0, 0, 9999));
  for (const auto& [k, v] : {std::pair{"manufacturer", &o.manufacturer}, {"model", &o.model},
                              {"serial_number", &o.serial_number}, {"product_instance_uri", &o.product_instance_uri}})
    if (v->empty()) id.fail(k, "must not be empty");
  id.finish();
  if (hmi.users_file.empty() && !o.anonymous)
    r.fail("anonymous", "is false and hmi.users_file is not set: nobody could log in (OPC UA users are the HMI's)");
  const bool hmi_asks = !hmi.users_file.empty() && !hmi.read_only_without_login;
  if (hmi_asks && o.hmi_user.empty())
    r.fail("hmi_user", "is required: the HMI asks for a login (hmi.users_file) and cnc-opcua reads the cell through it");
  if (!o.hmi_user.empty() && o.hmi_password_file.empty())
    r.fail("hmi_password_file", "is required with hmi_user: the file with " + o.hmi_user + "'s password");
  r.finish();
}

// A topic level the cell writes under: no wildcard, no separator, not empty.
bool topic_level_ok(const std::string& s) { return !s.empty() && s.find_first_of("+#/") == std::string::npos; }

void read_mqtt(MapReader r, const std::string& cell, MqttConfig& m) {
  m.enabled = true;
  m.host = r.get_string("host", m.host);
  if (m.host.empty()) r.fail("host", "must not be empty");
  m.ca_file = beside(r, r.get_string("ca_file", ""));
  m.port = static_cast<int>(r.get_int("port", m.ca_file.empty() ? 1883 : 8883, 1, 65535));
  m.topic_prefix = r.get_string("topic_prefix", m.topic_prefix);
  for (size_t from = 0; from <= m.topic_prefix.size();) {
    const size_t end = std::min(m.topic_prefix.find('/', from), m.topic_prefix.size());
    const std::string level = m.topic_prefix.substr(from, end - from);
    if (!topic_level_ok(level) || level.front() == '$')
      r.fail("topic_prefix", "'" + m.topic_prefix +
                                 "' is not a topic: levels separated by '/', none empty, no '+', '#' or leading '$'");
    from = end + 1;
  }
  // The cell's name is its topic level: the broker's ACL gives each cell its own.
  if (!topic_level_ok(cell))
    r.fail("topic_prefix", "cell.name '" + cell + "' cannot be a topic level under it (no '/', '+' or '#')");
  m.client_id = r.get_string("client_id", "cnc-" + cell);
  if (m.client_id.empty() || m.client_id.size() > 65535) r.fail("client_id", "must not be empty");
  // libmosquitto refuses a keepalive under 5 s.
  m.keepalive_s = static_cast<int>(r.get_int("keepalive_s", m.keepalive_s, 5, 3600));
  m.state_period_s = r.get_double("state_period_s", m.state_period_s, 0.1, 60.0);
  m.username = r.get_string("username", "");
  m.password_file = beside(r, r.get_string("password_file", ""));
  m.cert_file = beside(r, r.get_string("cert_file", ""));
  m.key_file = beside(r, r.get_string("key_file", ""));
  if (!m.password_file.empty() && m.username.empty())
    r.fail("password_file", "needs mqtt.username: the broker user the password is for");
  if (m.cert_file.empty() != m.key_file.empty())
    r.fail(m.cert_file.empty() ? "cert_file" : "key_file", "and mqtt." + std::string(m.cert_file.empty() ? "key_file" : "cert_file") +
                                                                " go together (the client certificate and its key)");
  if (!m.cert_file.empty() && m.ca_file.empty())
    r.fail("ca_file", "is required with cert_file: a client certificate is TLS's");
  const bool local = m.host == "127.0.0.1" || m.host == "::1" || m.host == "localhost";
  if (!m.password_file.empty() && m.ca_file.empty() && !local)
    r.fail("ca_file", "is required: a password is not sent in clear to a broker that is not on this PC ('" + m.host + "')");
  r.finish();
}

void read_process(MapReader r, ProcessConfig& p) {
  p.ball_radius_mm = r.get_double("ball_radius_mm", 0.0, 0.0, 100.0);
  p.flutes = static_cast<int>(r.get_int("flutes", 0, 0, program::kMaxFlutes));
  p.pick_feed_mm = r.get_double("pick_feed_mm", 0.0, 0.0, 100.0);
  p.target_rmax_um = r.get_double("target_rmax_um", 0.0, 0.0, 1000.0);
  p.spindle_rpm = r.get_double("spindle_rpm", 0.0, 0.0, 200000.0);
  r.finish();
}

void read_stock(MapReader s, CuttingConfig& k) {
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
}

void read_cutting(MapReader r, CuttingConfig& k) {
  k.enabled = true;
  const auto file = [&](const char* key) {
    const std::string v = beside(r, r.require_string(key));
    if (!std::filesystem::is_regular_file(v)) r.fail(key, "'" + v + "' is not a file");
    return v;
  };
  k.tool_file = file("tool");
  k.material_file = file("material");
  k.model = r.get_choice("model", "", {"", "linear_edge", "chip_thickness_law"});
  read_stock(r.map("stock", kStockKeys), k);
  k.deflection_tolerance_mm = r.require_double("deflection_tolerance_mm", 1e-6, 100.0);
  k.max_force_n = r.get_double("max_force_n", 0.0, 0.0, 1e7);
  k.feed_limit = r.get_bool("feed_limit", k.feed_limit);
  k.station_mm = r.get_double("station_mm", k.station_mm, 0.001, 10.0);
  k.disc_height_mm = r.get_double("disc_height_mm", k.disc_height_mm, 0.001, 10.0);
  k.angles_per_tooth = static_cast<int>(r.get_int("angles_per_tooth", k.angles_per_tooth, 1, 360));
  r.finish();
}

void read_program(MapReader r, ProgramConfig& p) {
  const std::string sub = r.get_string("subroutine_path", "");
  for (size_t b = 0; b < sub.size();) {
    size_t e = sub.find(':', b);
    if (e == std::string::npos) e = sub.size();
    if (e > b) p.subroutine_path.push_back(beside(r, sub.substr(b, e - b)));
    b = e + 1;
  }
  for (const std::string& d : p.subroutine_path)
    if (!std::filesystem::is_directory(d)) r.fail("subroutine_path", "'" + d + "' is not a folder");
  p.m6_remap = r.get_string("m6_remap", "");
  if (!p.m6_remap.empty()) {
    bool found = false;
    for (const std::string& d : p.subroutine_path)
      found = found || std::filesystem::is_regular_file(std::filesystem::path(d) / (p.m6_remap + ".ngc"));
    if (!found)
      r.fail("m6_remap", "no " + p.m6_remap + ".ngc in program.subroutine_path (" +
                             (p.subroutine_path.empty() ? std::string("not set") : sub) + ")");
  }
  p.tool_table = beside(r, r.get_string("tool_table", ""));
  if (!p.tool_table.empty() && !std::filesystem::is_regular_file(p.tool_table))
    r.fail("tool_table", "'" + p.tool_table + "' is not a file");
  p.var_file = beside(r, r.get_string("var_file", ""));
  p.probe = r.get_bool("probe", p.probe);
  p.digital_inputs = static_cast<int>(r.get_int("digital_inputs", p.digital_inputs, 0, 64));
  p.analog_inputs = static_cast<int>(r.get_int("analog_inputs", p.analog_inputs, 0, 64));
  p.digital_outputs = static_cast<int>(r.get_int("digital_outputs", p.digital_outputs, 0, 64));
  p.analog_outputs = static_cast<int>(r.get_int("analog_outputs", p.analog_outputs, 0, 64));
  p.block_delete = r.get_bool("block_delete", p.block_delete);
  p.optional_stop = r.get_bool("optional_stop", p.optional_stop);
  p.max_validation_lines = r.get_int("max_validation_lines", p.max_validation_lines, 1000, int64_t{1} << 40);
  p.dry_run_max_time_s = r.get_double("dry_run_max_time_s", p.dry_run_max_time_s, 1.0, 1e9);
  p.g64_fit = r.get_bool("g64_fit", p.g64_fit);
  p.g64_fit_max_segment_mm = r.get_double("g64_fit_max_segment_mm", p.g64_fit_max_segment_mm, 0.001, 1000.0);
  p.g64_fit_max_segment_per_p = r.get_double("g64_fit_max_segment_per_p", p.g64_fit_max_segment_per_p, 0.0, 1e6);
  p.g64_fit_max_turn_deg = r.get_double("g64_fit_max_turn_deg", p.g64_fit_max_turn_deg, 0.0, 90.0);
  p.default_path_tolerance_mm = r.get_double("default_path_tolerance_mm", p.default_path_tolerance_mm, 0.0, 1.0);
  r.finish();
}

void read_axes(MapReader& top, MachineConfig& c) {
  YAML::Node axes = top.sequence("axes");
  if (axes.size() == 0) top.fail("axes", "at least one axis is required");
  if (axes.size() > 9) top.fail("axes", "at most 9 axes are supported");
  std::set<std::string> names;
  std::set<std::tuple<std::string, std::string, int, std::string, int>> addresses;
  for (size_t i = 0; i < axes.size(); ++i) {
    const std::string path = top.item_path("axes", i);
    AxisConfig a = read_axis(MapReader(axes[i], path, top.file(), kAxisKeys));
    if (!names.insert(a.name).second) throw ConfigError(top.file(), path + ".name", "duplicate axis '" + a.name + "'");
    // Every drive (each axis's, each gantry's second) at an address of its own, and the
    // drives on one serial line with the same line settings.
    const auto check_drive = [&](const DriveConfig& d, const std::string& at) {
      const auto addr = std::make_tuple(d.transport, d.host, d.port, d.device, d.unit_id);
      if (!addresses.insert(addr).second)
        throw ConfigError(top.file(), at + ".unit_id", "another axis already uses this drive address");
      for (const auto& other : c.axes)
        for (const DriveConfig* o : {&other.drive, other.gantry.enabled ? &other.gantry.drive : nullptr}) {
          if (o == nullptr || o->link_key() != d.link_key()) continue;
          if (o->baud != d.baud || o->parity != d.parity || o->stop_bits != d.stop_bits)
            throw ConfigError(top.file(), at + ".baud",
                              "axis " + other.name + " is on the same serial line with other line settings");
        }
    };
    check_drive(a.drive, path + ".drive");
    if (a.gantry.enabled) {
      if (a.gantry.drive.link_key() == a.drive.link_key() &&
          (a.gantry.drive.baud != a.drive.baud || a.gantry.drive.parity != a.drive.parity ||
           a.gantry.drive.stop_bits != a.drive.stop_bits))
        throw ConfigError(top.file(), path + ".gantry.drive.baud",
                            "the axis's own drive is on the same serial line with other line settings");
      check_drive(a.gantry.drive, path + ".gantry.drive");
    }
    c.axes.push_back(std::move(a));
  }
  // A gantry's second joint has a name of its own: no axis's, no other joint's.
  for (size_t i = 0; i < c.axes.size(); ++i) {
    if (!c.axes[i].gantry.enabled) continue;
    if (!names.insert(c.axes[i].gantry.name).second)
      throw ConfigError(top.file(), top.item_path("axes", i) + ".gantry.name",
                        "'" + c.axes[i].gantry.name + "' is already the name of an axis or of another gantry's joint");
  }
}

void read_drive_bridge(MapReader r, MachineConfig& c) {
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

void read_spindle(MapReader r, MachineConfig& c) {
  SpindleConfig& s = c.spindle;
  s.enabled = true;
  if (!r.has("drive")) r.fail("drive", "is required: the spindle's VFD (transport, address, unit_id, profile)");
  s.drive = read_drive(r.map("drive", kDriveKeys));
  for (const auto& a : c.axes) {
    if (a.drive.link_key() == s.drive.link_key() && a.drive.unit_id == s.drive.unit_id)
      r.fail("drive", "unit_id " + std::to_string(s.drive.unit_id) + " is axis " + a.name + "'s drive on the same link");
    if (a.drive.link_key() == s.drive.link_key() &&
        (a.drive.baud != s.drive.baud || a.drive.parity != s.drive.parity || a.drive.stop_bits != s.drive.stop_bits))
      r.fail("drive", "axis " + a.name + " is on the same serial line with other line settings");
  }
  s.max_rpm = r.get_double("max_rpm", s.max_rpm, 1.0, 200000.0);
  s.rpm_per_hz = r.get_double("rpm_per_hz", s.rpm_per_hz, 1.0, 1000.0);
  s.at_speed_tolerance = r.get_double("at_speed_tolerance", s.at_speed_tolerance, 0.001, 0.5);
  s.at_speed_timeout_s = r.get_double("at_speed_timeout_s", s.at_speed_timeout_s, 0.1, 600.0);
  s.min_override = r.get_double("min_override", s.min_override, 0.0, 1.0);
  s.max_override = r.get_double("max_override", s.max_override, 1.0, 10.0);
  s.encoder_counts_per_rev = r.get_int("encoder_counts_per_rev", s.encoder_counts_per_rev, 0, 1 << 24);
  s.sync_lead_s = r.get_double("sync_lead_s", s.sync_lead_s, 0.0, 0.1);
  s.orient_offset_deg = r.get_double("orient_offset_deg", s.orient_offset_deg, -360.0, 360.0);
  s.orient_tolerance_deg = r.get_double("orient_tolerance_deg", s.orient_tolerance_deg, 0.01, 45.0);
  s.orient_timeout_s = r.get_double("orient_timeout_s", s.orient_timeout_s, 0.1, 600.0);
  s.orient_rpm = r.get_double("orient_rpm", s.orient_rpm, 0.1, 10000.0);
  s.orient_gain_per_s = r.get_double("orient_gain_per_s", s.orient_gain_per_s, 0.01, 1000.0);
  if (s.orient_rpm > s.max_rpm) r.fail("orient_rpm", "must not exceed spindle.max_rpm");
  if (c.drive_bridge.link_loss_timeout_s < s.drive.response_timeout_s)
    r.fail("drive", "drive.response_timeout_s must not exceed drive_bridge.link_loss_timeout_s");
  MapReader m = r.map("sim", kSpindleSimKeys);
  s.sim.time_constant_s = m.get_double("time_constant_s", s.sim.time_constant_s, 0.001, 600.0);
  s.sim.load_current_a = m.get_double("load_current_a", s.sim.load_current_a, 0.0, 1000.0);
  s.sim.inertia_current_a = m.get_double("inertia_current_a", s.sim.inertia_current_a, 0.0, 1000.0);
  m.finish();
  r.finish();
}

bool plain_name(const std::string& s) {
  if (s.empty() || !(std::isalpha(static_cast<unsigned char>(s[0])) || s[0] == '_')) return false;
  return std::all_of(s.begin(), s.end(), [](char ch) { return std::isalnum(static_cast<unsigned char>(ch)) || ch == '_'; });
}

IoModuleConfig read_io_module(MapReader r) {
  IoModuleConfig m;
  DriveConfig& d = m.link;
  m.name = r.require_string("name");
  if (!plain_name(m.name)) r.fail("name", "'" + m.name + "' is no name: letters, digits and _");
  read_link(r, d);
  d.unit_id = static_cast<int>(r.require_int("unit_id", 1, 247));
  d.profile = "";
  r.finish();
  return m;
}

// The unit ids and line settings an I/O module shares with the drives on its link.
void check_io_module_link(const MapReader& r, const MachineConfig& c, const IoModuleConfig& m) {
  const DriveConfig& d = m.link;
  auto clash = [&](const DriveConfig& o, const std::string& who) {
    if (o.link_key() != d.link_key()) return;
    if (o.unit_id == d.unit_id) r.fail("unit_id", "unit_id " + std::to_string(d.unit_id) + " is " + who + " on the same link");
    if (o.baud != d.baud || o.parity != d.parity || o.stop_bits != d.stop_bits)
      r.fail("baud", who + " is on the same serial line with other line settings");
  };
  for (const auto& a : c.axes) clash(a.drive, "axis " + a.name + "'s drive");
  if (c.spindle.enabled) clash(c.spindle.drive, "the spindle's drive");
  for (const auto& o : c.io.modules) clash(o.link, "module " + o.name);
}

IoPointConfig read_io_point(MapReader r, const IoConfig& io) {
  IoPointConfig p;
  p.name = r.require_string("name");
  if (!plain_name(p.name)) r.fail("name", "'" + p.name + "' is no name: letters, digits and _");
  if (io.point_index(p.name) >= 0) r.fail("name", "duplicate point '" + p.name + "'");
  const std::string module = io.modules.size() == 1 ? r.get_string("module", io.modules[0].name) : r.require_string("module");
  p.module = -1;
  for (size_t i = 0; i < io.modules.size(); ++i)
    if (io.modules[i].name == module) p.module = static_cast<int>(i);
  if (p.module < 0) r.fail("module", "no module '" + module + "' in io.modules");
  const std::string kind = r.require_string("kind");
  if (kind == "coil") p.kind = IoKind::kCoil;
  else if (kind == "discrete_input") p.kind = IoKind::kDiscreteInput;
  else if (kind == "input_register") p.kind = IoKind::kInputRegister;
  else if (kind == "holding_register") p.kind = IoKind::kHoldingRegister;
  else r.fail("kind", "'" + kind + "' is not one of: coil, discrete_input, input_register, holding_register");
  p.address = static_cast<int>(r.require_int("address", 0, 65535));
  const bool reg = p.kind == IoKind::kInputRegister || p.kind == IoKind::kHoldingRegister;
  if (!reg && (r.has("scale") || r.has("signed"))) r.fail(r.has("scale") ? "scale" : "signed", "only a register has one");
  p.scale = r.get_double("scale", p.scale, -1e9, 1e9);
  if (p.scale == 0) r.fail("scale", "must not be 0");
  p.is_signed = r.get_bool("signed", p.is_signed);
  for (const auto& o : io.points)
    if (o.module == p.module && o.kind == p.kind && o.address == p.address)
      r.fail("address", std::string(to_string(p.kind)) + " " + std::to_string(p.address) + " of module " + module +
                            " is point " + o.name + " already");
  r.finish();
  return p;
}

// A point named by a role (io.coolant.*, io.digital_outputs[n], ...): its index, of one of `kinds`.
int io_role(const MapReader& r, const std::string& path, const std::string& name, const IoConfig& io,
            std::initializer_list<IoKind> kinds, std::set<int>& taken) {
  const int i = io.point_index(name);
  if (i < 0) throw ConfigError(r.file(), path, "no point '" + name + "' in io.points");
  const IoKind k = io.points[static_cast<size_t>(i)].kind;
  if (std::find(kinds.begin(), kinds.end(), k) == kinds.end()) {
    std::string want;
    for (IoKind w : kinds) want += (want.empty() ? "" : " or ") + std::string(to_string(w));
    throw ConfigError(r.file(), path, "point '" + name + "' is of kind " + to_string(k) + ", not " + want);
  }
  if (!taken.insert(i).second) throw ConfigError(r.file(), path, "point '" + name + "' has a role already");
  return i;
}

void read_io(MapReader r, MachineConfig& c) {
  IoConfig& io = c.io;
  io.enabled = true;
  YAML::Node modules = r.sequence("modules");
  if (modules.size() == 0) r.fail("modules", "at least one module is required");
  for (size_t i = 0; i < modules.size(); ++i) {
    MapReader m(modules[i], r.item_path("modules", i), r.file(), kIoModuleKeys);
    IoModuleConfig mod = read_io_module(m);
    for (const auto& o : io.modules)
      if (o.name == mod.name) m.fail("name", "duplicate module '" + mod.name + "'");
    check_io_module_link(m, c, mod);
    if (c.drive_bridge.link_loss_timeout_s < mod.link.response_timeout_s)
      m.fail("response_timeout_s", "must not exceed drive_bridge.link_loss_timeout_s");
    io.modules.push_back(std::move(mod));
  }
  YAML::Node points = r.sequence("points");
  for (size_t i = 0; i < points.size(); ++i)
    io.points.push_back(read_io_point(MapReader(points[i], r.item_path("points", i), r.file(), kIoPointKeys), io));
  for (size_t m = 0; m < io.modules.size(); ++m)
    for (IoKind k : {IoKind::kCoil, IoKind::kDiscreteInput, IoKind::kInputRegister, IoKind::kHoldingRegister}) {
      // Each kind's points are a bit (or a slot) of the module's process data.
      const auto n = std::count_if(io.points.begin(), io.points.end(),
                                   [&](const IoPointConfig& p) { return p.module == static_cast<int>(m) && p.kind == k; });
      if (n > 64)
        r.fail("points", "module " + io.modules[m].name + " has " + std::to_string(n) + " " + to_string(k) +
                             " points, at most 64");
    }
  std::set<int> taken;
  MapReader cool = r.map("coolant", kIoCoolantKeys);
  if (cool.has("mist"))
    io.coolant_mist = io_role(cool, cool.child_path("mist"), cool.require_string("mist"), io, {IoKind::kCoil}, taken);
  if (cool.has("flood"))
    io.coolant_flood = io_role(cool, cool.child_path("flood"), cool.require_string("flood"), io, {IoKind::kCoil}, taken);
  cool.finish();
  auto list = [&](const std::string& key, std::initializer_list<IoKind> kinds, std::vector<int>& out, size_t max) {
    YAML::Node seq = r.sequence(key);
    if (seq.size() > max) r.fail(key, "at most " + std::to_string(max) + " points");
    for (size_t i = 0; i < seq.size(); ++i) {
      const std::string path = r.item_path(key, i);
      if (!seq[i].IsScalar()) throw ConfigError(r.file(), path, "expected a point's name");
      out.push_back(io_role(r, path, seq[i].Scalar(), io, kinds, taken));
    }
  };
  list("digital_outputs", {IoKind::kCoil}, io.digital_outputs, 64);
  list("digital_inputs", {IoKind::kDiscreteInput}, io.digital_inputs, 64);
  list("analog_inputs", {IoKind::kInputRegister, IoKind::kHoldingRegister}, io.analog_inputs, 64);
  list("analog_outputs", {IoKind::kHoldingRegister}, io.analog_outputs, 64);
  // M62-M65, M66 and M67/M68 address exactly the listed points.
  c.program.digital_outputs = static_cast<int>(io.digital_outputs.size());
  c.program.digital_inputs = static_cast<int>(io.digital_inputs.size());
  c.program.analog_inputs = static_cast<int>(io.analog_inputs.size());
  c.program.analog_outputs = static_cast<int>(io.analog_outputs.size());
  r.finish();
}

void read_safety(MapReader r, MachineConfig& c) {
  // A point used by a role of io: may not be a safety input too (an M66 on it).
  std::set<int> taken(c.io.digital_inputs.begin(), c.io.digital_inputs.end());
  auto input = [&](const MapReader& m, const std::string& path, const std::string& name) {
    if (!c.io.enabled) throw ConfigError(r.file(), path, "needs an io: section with the point '" + name + "'");
    return io_role(m, path, name, c.io, {IoKind::kDiscreteInput}, taken);
  };
  MapReader estop = r.map("estop", kSafetyEstopKeys);
  const std::string name = r.has("estop") ? estop.require_string("input") : estop.get_string("input", "");
  if (!name.empty()) c.safety.estop_input = input(estop, estop.child_path("input"), name);
  estop.finish();
  YAML::Node limits = r.sequence("hard_limits");
  for (size_t i = 0; i < limits.size(); ++i) {
    MapReader l(limits[i], r.item_path("hard_limits", i), r.file(), kSafetyLimitKeys);
    SafetyConfig::HardLimit h;
    const std::string axis = l.require_string("axis");
    h.axis = c.axis_index(axis);
    if (h.axis < 0) l.fail("axis", "no axis " + axis);
    for (const auto& o : c.safety.hard_limits)
      if (o.axis == h.axis) l.fail("axis", "axis " + axis + " has its limits already");
    const std::string lo = l.get_string("min", ""), hi = l.get_string("max", "");
    if (lo.empty() && hi.empty()) l.fail("max", "a min or a max input is required");
    if (!lo.empty()) h.min_input = input(l, l.child_path("min"), lo);
    if (!hi.empty()) h.max_input = input(l, l.child_path("max"), hi);
    l.finish();
    c.safety.hard_limits.push_back(h);
  }
  MapReader door = r.map("door", kSafetyDoorKeys);
  const std::string dname = r.has("door") ? door.require_string("input") : door.get_string("input", "");
  if (!dname.empty()) c.safety.door_input = input(door, door.child_path("input"), dname);
  door.finish();
  r.finish();
}

// A five-axis type's axes: X, Y, Z linear, the tilt (A or B, the type's fourth letter) and C rotary.
void check_five_axis_axes(const MapReader& r, const MachineConfig& c, const std::string& type) {
  const std::string tilt(1, static_cast<char>(std::toupper(static_cast<unsigned char>(type[3]))));
  const std::string names[] = {"X", "Y", "Z", tilt, "C"};
  for (const std::string& name : names) {
    const int i = c.axis_index(name);
    const bool rotary = name == tilt || name == "C";
    std::string what = type;
    if (i < 0) {
      what += " needs an axis ";
      what += name;
      r.fail("type", what += " in axes[]");
    }
    if (c.axes[static_cast<size_t>(i)].rotary != rotary) {
      what += " needs axis ";
      what += name;
      r.fail("type", what += rotary ? " of type: rotary" : " linear");
    }
  }
}

void read_kinematics(MapReader r, MachineConfig& c) {
  KinematicsConfig& k = c.kinematics;
  k.type = r.get_choice("type", k.type, std::set<std::string>(std::begin(kKinematicsTypes), std::end(kKinematicsTypes)));
  // Which keys the type has: a key of another geometry is refused, not ignored.
  const bool five = k.type != "identity";
  const bool trt = k.type.ends_with("-trt");
  const bool head_table = k.type.ends_with("-head-table");
  const bool head = five && !trt;                // a tilting head: a pivot
  const bool table_c = trt || head_table;        // a rotary table C: its centre, its direction
  const bool tilt_a = five && k.type[3] == 'a';  // xyzac-*
  auto key = [&](const char* name, bool applies, const std::string& why) {
    if (r.has(name) && !applies) {
      std::string what = "is no key of kinematics.type ";
      what += k.type;
      what += ": ";
      r.fail(name, what += why);
    }
    return r.has(name);
  };
  const std::string no_table = "it has no rotary table";
  if (key("x_rot_point_mm", table_c, no_table)) k.x_rot_point_mm = r.get_double("x_rot_point_mm", 0, -1e5, 1e5);
  if (key("y_rot_point_mm", table_c, no_table)) k.y_rot_point_mm = r.get_double("y_rot_point_mm", 0, -1e5, 1e5);
  if (key("z_rot_point_mm", trt, head_table ? "its only table axis, C, is vertical" : no_table))
    k.z_rot_point_mm = r.get_double("z_rot_point_mm", 0, -1e5, 1e5);
  const std::string no_tilting_table = "it has no tilting table";
  if (key("x_offset_mm", trt && !tilt_a, trt ? "its A axis is parallel to X" : no_tilting_table))
    k.x_offset_mm = r.get_double("x_offset_mm", 0, -1e5, 1e5);
  if (key("y_offset_mm", trt && tilt_a, trt ? "its B axis is parallel to Y" : no_tilting_table))
    k.y_offset_mm = r.get_double("y_offset_mm", 0, -1e5, 1e5);
  if (key("z_offset_mm", trt, no_tilting_table)) k.z_offset_mm = r.get_double("z_offset_mm", 0, -1e5, 1e5);
  if (key("conventional_directions", table_c,
          five ? "its rotary axes turn the head, by the right-hand rule" : "it has no rotary axes"))
    k.conventional_directions = r.get_bool("conventional_directions", false);
  if (head) k.pivot_mm = r.require_double("pivot_mm", 0, 1e4);
  else key("pivot_mm", false, "it has no tilting head");
  if (key("solution", five, "it has no rotary axes"))
    k.solution = r.get_choice("solution", k.solution, {"nearest", "positive_tilt", "negative_tilt"});
  if (key("pole_tolerance_deg", five, "it has no rotary axes"))
    k.pole_tolerance_deg = r.get_double("pole_tolerance_deg", k.pole_tolerance_deg, 0, 1);
  if (five) check_five_axis_axes(r, c, k.type);
  r.finish();
}

void read_probe(MapReader r, MachineConfig& c) {
  const std::string path = r.child_path("input");
  const std::string name = r.require_string("input");
  if (!c.io.enabled) throw ConfigError(r.file(), path, "needs an io: section with the point '" + name + "'");
  // Not a point another role reads (an M66 input, the safety chain's).
  std::set<int> taken(c.io.digital_inputs.begin(), c.io.digital_inputs.end());
  for (const int i : {c.safety.estop_input, c.safety.door_input})
    if (i >= 0) taken.insert(i);
  for (const auto& h : c.safety.hard_limits)
    for (const int i : {h.min_input, h.max_input})
      if (i >= 0) taken.insert(i);
  c.probe.input = io_role(r, path, name, c.io, {IoKind::kDiscreteInput}, taken);
  c.probe.drive_latch = r.get_choice("latch", "input", {"input", "drives"}) == "drives";
  c.program.probe = true;
  if (r.has("sim_box")) {
    MapReader box = r.map("sim_box", kProbeBoxKeys);
    static const char* const kMin[] = {"x_min_mm", "y_min_mm", "z_min_mm"};
    static const char* const kMax[] = {"x_max_mm", "y_max_mm", "z_max_mm"};
    for (int i = 0; i < 3; ++i) {
      c.probe.box_min_mm[i] = box.require_double(kMin[i], -1e6, 1e6);
      c.probe.box_max_mm[i] = box.require_double(kMax[i], -1e6, 1e6);
      if (!(c.probe.box_max_mm[i] > c.probe.box_min_mm[i])) box.fail(kMax[i], std::string("must exceed ") + kMin[i]);
    }
    if (box.has("bore_diameter_mm") || box.has("bore_x_mm") || box.has("bore_y_mm")) {
      c.probe.bore_diameter_mm = box.require_double("bore_diameter_mm", 1e-3, 1e6);
      c.probe.bore_xy_mm[0] = box.require_double("bore_x_mm", -1e6, 1e6);
      c.probe.bore_xy_mm[1] = box.require_double("bore_y_mm", -1e6, 1e6);
    }
    box.finish();
    c.probe.sim_box = true;
  } else {
    r.map("sim_box", kProbeBoxKeys);
  }
  r.finish();
}

void read_logger(MapReader r, MachineConfig& c) {
  c.log_directory = r.get_string("directory", c.log_directory);
  c.log_rotate_mb = r.get_double("rotate_mb", c.log_rotate_mb, 1.0, 1e6);
  c.log_flush_period_s = r.get_double("flush_period_s", c.log_flush_period_s, 0.01, 60.0);
  r.finish();
}

void read_security(MapReader r, SecurityConfig& sec) {
  sec.signing = r.get_bool("signing", sec.signing);
  sec.key_file = beside(r, r.get_string("key_file", ""));
  if (sec.signing && sec.key_file.empty()) r.fail("key_file", "is required when security.signing is true");
  sec.max_age_s = r.get_double("max_age_s", sec.max_age_s, 0.01, 3600.0);
  r.finish();
}

void read_monitor(MapReader r, MachineConfig& c) {
  c.monitor_rmax_margin = r.get_double("rmax_margin", c.monitor_rmax_margin, 0.0, 10.0);
  r.finish();
}

// The sections in the order they were always read, so that of two errors the same one is reported.
MachineConfig read_machine(MapReader top) {
  MachineConfig c;
  read_cell(top.map("cell", kCellKeys), c);
  read_timing(top.map("timing", kTimingKeys), c);
  read_motion(top.map("motion", kMotionKeys), c);
  if (top.has("operator")) read_operator(top.map("operator", kOperatorKeys), c.operator_);
  read_hmi(top.map("hmi", kHmiKeys), c.hmi);
  if (top.has("opcua")) read_opcua(top.map("opcua", kOpcuaKeys), c.hmi, c.name, c.opcua);
  if (top.has("mqtt")) read_mqtt(top.map("mqtt", kMqttKeys), c.name, c.mqtt);
  read_process(top.map("process", kProcessKeys), c.process);
  if (top.has("cutting")) read_cutting(top.map("cutting", kCuttingKeys), c.cutting);
  read_program(top.map("program", kProgramKeys), c.program);
  read_axes(top, c);
  read_drive_bridge(top.map("drive_bridge", kDriveBridgeKeys), c);
  if (top.has("spindle")) read_spindle(top.map("spindle", kSpindleKeys), c);
  if (top.has("io")) read_io(top.map("io", kIoKeys), c);
  if (top.has("safety")) read_safety(top.map("safety", kSafetyKeys), c);
  if (top.has("kinematics")) read_kinematics(top.map("kinematics", kKinematicsKeys), c);
  for (size_t i = 0; i < c.axes.size(); ++i)
    if (c.axes[i].gantry.enabled && c.kinematics.type != "identity")
      throw ConfigError(top.file(), top.item_path("axes", i) + ".gantry",
                        "a gantry needs kinematics.type identity (this machine's is " + c.kinematics.type + ")");
  if (top.has("probe")) read_probe(top.map("probe", kProbeKeys), c);
  read_logger(top.map("logger", kLoggerKeys), c);
  read_security(top.map("security", kSecurityKeys), c.security);
  read_monitor(top.map("monitor", kMonitorKeys), c);
  top.finish();
  return c;
}
}  // namespace

std::string DriveConfig::link_key() const {
  switch (drive::transport_named(transport).value_or(Transport::kLoopback)) {
    case Transport::kModbusTcp: return "tcp://" + host + ":" + std::to_string(port);
    case Transport::kModbusRtu: return "rtu://" + device;
    case Transport::kLoopback: break;
  }
  return "loopback";
}

std::span<const KeySection> machine_config_keys() { return kSections; }

const char* to_string(IoKind k) {
  switch (k) {
    case IoKind::kCoil: return "coil";
    case IoKind::kDiscreteInput: return "discrete_input";
    case IoKind::kInputRegister: return "input_register";
    case IoKind::kHoldingRegister: return "holding_register";
  }
  return "?";
}

int IoConfig::point_index(const std::string& name) const {
  for (size_t i = 0; i < points.size(); ++i)
    if (points[i].name == name) return static_cast<int>(i);
  return -1;
}

std::string IoConfig::point_label(int point) const {
  if (point < 0 || static_cast<size_t>(point) >= points.size()) return "(no such point)";
  const IoPointConfig& p = points[static_cast<size_t>(point)];
  const std::string module =
      p.module >= 0 && static_cast<size_t>(p.module) < modules.size() ? modules[static_cast<size_t>(p.module)].name : "?";
  return p.name + " on module " + module;
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
  MachineConfig c = read_machine(MapReader(root, "", file_label, kTopKeys));
  c.source_file = file_label;
  c.source_text = yaml_text;
  return c;
}

}  // namespace cnc::config
