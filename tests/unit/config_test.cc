// Strict loading of the cell configuration: sim3.yaml loads, and every kind of
// fault is refused with the exact key path and the file label in the message.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>

#include "common/config/machine_config.h"
#include "common/config/yaml_reader.h"

namespace cnc::config {
namespace {

const std::string kSim3Path = std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml";
const std::string kLabel = "test.yaml";

std::string sim3_text() {
  std::ifstream in(kSim3Path);
  EXPECT_TRUE(in.good()) << "cannot open " << kSim3Path;
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Replaces the `nth` (0-based) occurrence of `from`; fails the test when there is none,
// so a change to sim3.yaml cannot silently turn a variant into the original text.
std::string replace_nth(std::string text, const std::string& from, const std::string& to, int nth = 0) {
  size_t at = text.find(from);
  for (int i = 0; i < nth && at != std::string::npos; ++i) at = text.find(from, at + 1);
  EXPECT_NE(at, std::string::npos) << "'" << from << "' (occurrence " << nth << ") not in the sim3 text";
  if (at == std::string::npos) return text;
  return text.replace(at, from.size(), to);
}

// Parses `yaml` and returns the ConfigError it must raise.
ConfigError expect_error(const std::string& yaml) {
  try {
    parse_machine_config(yaml, kLabel);
  } catch (const ConfigError& e) {
    return e;
  }
  ADD_FAILURE() << "parse_machine_config accepted the text";
  return ConfigError("", "", "");
}

void expect_error_at(const std::string& yaml, const std::string& key_path, const std::string& detail) {
  const ConfigError e = expect_error(yaml);
  EXPECT_EQ(e.key_path(), key_path) << e.what();
  const std::string what = e.what();
  EXPECT_EQ(what.rfind(kLabel + ": " + key_path + ": ", 0), 0u) << what;
  EXPECT_NE(what.find(detail), std::string::npos) << "'" << detail << "' not in: " << what;
}

TEST(MachineConfig, LoadsSim3) {
  const MachineConfig c = load_machine_config(kSim3Path);
  EXPECT_EQ(c.source_file, kSim3Path);
  EXPECT_EQ(c.name, "sim3");
  EXPECT_EQ(c.channel_prefix, "SIM3.");
  EXPECT_EQ(c.channel(channels::kSetpoints), "SIM3.SETPOINTS");
  EXPECT_DOUBLE_EQ(c.ipo_period_s, 0.004);
  EXPECT_DOUBLE_EQ(c.servo_period_s, 0.001);
  EXPECT_DOUBLE_EQ(c.path_accel_mm_s2, 3000.0);
  EXPECT_DOUBLE_EQ(c.path_jerk_mm_s3, 60000.0);
  ASSERT_EQ(c.axes.size(), 3u);
  EXPECT_EQ(c.axes[0].name, "X");
  EXPECT_EQ(c.axes[1].name, "Y");
  EXPECT_EQ(c.axes[2].name, "Z");
  EXPECT_DOUBLE_EQ(c.axes[2].max_velocity_mm_s, 150.0);
  EXPECT_DOUBLE_EQ(c.axes[2].max_accel_mm_s2, 2000.0);
  EXPECT_DOUBLE_EQ(c.axes[2].min_mm, -150.0);
  EXPECT_EQ(c.axes[1].drive.unit_id, 2);
  EXPECT_EQ(c.axes[2].drive.transport, "modbus_tcp");
  EXPECT_DOUBLE_EQ(c.axes[2].sim.bandwidth_hz, 30.0);
  EXPECT_EQ(c.axis_index("Z"), 2);
  EXPECT_EQ(c.axis_index("A"), -1);
  EXPECT_EQ(c.process.flutes, 2);
}

TEST(MachineConfig, ParseOfTheSameTextMatchesLoad) {
  const MachineConfig c = parse_machine_config(sim3_text(), kLabel);
  EXPECT_EQ(c.source_file, kLabel);
  ASSERT_EQ(c.axes.size(), 3u);
  EXPECT_EQ(c.channel_prefix, "SIM3.");
  EXPECT_DOUBLE_EQ(c.ipo_period_s, 0.004);
}

TEST(MachineConfig, DefaultsApplyToOmittedSections) {
  const std::string yaml =
      "cell: {name: mini}\n"
      "axes:\n"
      "  - {name: X, min_mm: 0, max_mm: 10, max_velocity_mm_s: 5, max_accel_mm_s2: 50, max_jerk_mm_s3: 500}\n";
  const MachineConfig c = parse_machine_config(yaml, kLabel);
  EXPECT_EQ(c.channel_prefix, "mini.");
  EXPECT_DOUBLE_EQ(c.ipo_period_s, MachineConfig{}.ipo_period_s);
  EXPECT_EQ(c.block_window, MachineConfig{}.block_window);
  ASSERT_EQ(c.axes.size(), 1u);
  EXPECT_EQ(c.axes[0].drive.port, DriveConfig{}.port);
}

TEST(MachineConfig, KinematicsTypeIsOneTheFactoryKnows) {
  EXPECT_EQ(parse_machine_config(sim3_text(), kLabel).kinematics.type, "identity");
  EXPECT_EQ(parse_machine_config(sim3_text() + "kinematics: {type: identity}\n", kLabel).kinematics.type, "identity");
  expect_error_at(sim3_text() + "kinematics: {type: xyzab-tdr}\n", "kinematics.type", "identity, xyzac-head");
  expect_error_at(sim3_text() + "kinematics: {type: identity, pivot_mm: 1}\n", "kinematics.pivot_mm",
                  "is no key of kinematics.type identity");
  expect_error_at(sim3_text() + "kinematics: {type: identity, solution: nearest}\n", "kinematics.solution",
                  "is no key of kinematics.type identity: it has no rotary axes");
  expect_error_at(sim3_text() + "kinematics: {type: identity, conventional_directions: true}\n",
                  "kinematics.conventional_directions", "is no key of kinematics.type identity: it has no rotary axes");
  expect_error_at(sim3_text() + "kinematics: {type: identity, swivel: 1}\n", "kinematics.swivel", "unknown key");
  // sim3 is X, Y, Z only
  expect_error_at(sim3_text() + "kinematics: {type: xyzac-trt}\n", "kinematics.type", "xyzac-trt needs an axis A in axes[]");
}

// The example five-axis machines (tests/unit/kinematics_machines/TYPE.yaml).
std::string five_axis_text(const std::string& type) {
  std::ifstream in(std::string(CNC_SOURCE_DIR) + "/tests/unit/kinematics_machines/" + type + ".yaml");
  EXPECT_TRUE(in.good()) << type;
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(MachineConfig, FiveAxisKinematicsKeys) {
  const KinematicsConfig trt = parse_machine_config(five_axis_text("xyzac-trt"), kLabel).kinematics;
  EXPECT_EQ(trt.type, "xyzac-trt");
  EXPECT_EQ(trt.x_rot_point_mm, 12.5);
  EXPECT_EQ(trt.y_rot_point_mm, -7.5);
  EXPECT_EQ(trt.z_rot_point_mm, -180.0);
  EXPECT_EQ(trt.x_offset_mm, 0.0);
  EXPECT_EQ(trt.y_offset_mm, 20.0);
  EXPECT_EQ(trt.z_offset_mm, 10.0);
  EXPECT_FALSE(trt.conventional_directions);
  EXPECT_EQ(trt.pivot_mm, 0.0);
  EXPECT_EQ(trt.solution, "nearest");
  EXPECT_EQ(trt.pole_tolerance_deg, 1e-6);
  const KinematicsConfig bc = parse_machine_config(five_axis_text("xyzbc-trt"), kLabel).kinematics;
  EXPECT_EQ(bc.x_offset_mm, -25.0);
  EXPECT_EQ(bc.z_offset_mm, 40.0);
  const KinematicsConfig head = parse_machine_config(five_axis_text("xyzbc-head"), kLabel).kinematics;
  EXPECT_EQ(head.pivot_mm, 150.0);
  EXPECT_EQ(head.solution, "positive_tilt");
  const KinematicsConfig mixed = parse_machine_config(five_axis_text("xyzbc-head-table"), kLabel).kinematics;
  EXPECT_EQ(mixed.pivot_mm, 120.0);
  EXPECT_EQ(mixed.x_rot_point_mm, 150.0);
  EXPECT_TRUE(mixed.conventional_directions);
  const std::string head_text = replace_nth(five_axis_text("xyzac-head"), "  pivot_mm: 180",
                                            "  pivot_mm: 180\n  pole_tolerance_deg: 0.01\n  solution: negative_tilt");
  const KinematicsConfig a = parse_machine_config(head_text, kLabel).kinematics;
  EXPECT_EQ(a.pole_tolerance_deg, 0.01);
  EXPECT_EQ(a.solution, "negative_tilt");
}

// A key of another geometry, a missing or out-of-range value, a missing or linear axis:
// each refused with its key path.
TEST(MachineConfig, FiveAxisKinematicsErrorsNameTheKey) {
  const std::string ac = five_axis_text("xyzac-trt"), bc = five_axis_text("xyzbc-trt");
  const std::string head = five_axis_text("xyzbc-head"), mixed = five_axis_text("xyzac-head-table");
  auto add = [](const std::string& text, const std::string& after, const std::string& line) {
    return replace_nth(text, after, after + "\n" + line);
  };
  expect_error_at(add(ac, "  z_offset_mm: 10", "  x_offset_mm: 1"), "kinematics.x_offset_mm",
                  "is no key of kinematics.type xyzac-trt: its A axis is parallel to X");
  expect_error_at(add(bc, "  z_offset_mm: 40", "  y_offset_mm: 1"), "kinematics.y_offset_mm",
                  "its B axis is parallel to Y");
  expect_error_at(add(ac, "  z_offset_mm: 10", "  pivot_mm: 100"), "kinematics.pivot_mm", "it has no tilting head");
  expect_error_at(replace_nth(ac, "  y_offset_mm: 20", "  y_offset_mm: 2e5"), "kinematics.y_offset_mm", "out of range");
  expect_error_at(replace_nth(ac, "  x_rot_point_mm: 12.5", "  x_rot_point_mm: -1e6"), "kinematics.x_rot_point_mm",
                  "out of range");
  expect_error_at(add(ac, "  z_offset_mm: 10", "  solution: closest"), "kinematics.solution",
                  "'closest' is not one of: nearest, negative_tilt, positive_tilt");
  expect_error_at(add(ac, "  z_offset_mm: 10", "  pole_tolerance_deg: 2"), "kinematics.pole_tolerance_deg",
                  "out of range");
  expect_error_at(add(ac, "  z_offset_mm: 10", "  pole_tolerance_deg: -1e-9"), "kinematics.pole_tolerance_deg",
                  "out of range");
  expect_error_at(add(ac, "  z_offset_mm: 10", "  conventional_directions: maybe"),
                  "kinematics.conventional_directions", "expected true or false");
  // heads
  expect_error_at(replace_nth(head, "  pivot_mm: 150", ""), "kinematics.pivot_mm", "is required");
  expect_error_at(replace_nth(head, "  pivot_mm: 150", "  pivot_mm: -1"), "kinematics.pivot_mm", "out of range");
  expect_error_at(add(head, "  pivot_mm: 150", "  conventional_directions: true"), "kinematics.conventional_directions",
                  "is no key of kinematics.type xyzbc-head: its rotary axes turn the head");
  expect_error_at(add(head, "  pivot_mm: 150", "  x_rot_point_mm: 1"), "kinematics.x_rot_point_mm",
                  "it has no rotary table");
  expect_error_at(add(head, "  pivot_mm: 150", "  z_offset_mm: 1"), "kinematics.z_offset_mm", "it has no tilting table");
  expect_error_at(add(mixed, "  pivot_mm: 220", "  z_rot_point_mm: 5"), "kinematics.z_rot_point_mm",
                  "its only table axis, C, is vertical");
  expect_error_at(add(mixed, "  pivot_mm: 220", "  y_offset_mm: 5"), "kinematics.y_offset_mm", "it has no tilting table");
  // the axes the type needs
  expect_error_at(replace_nth(mixed, "type: xyzac-head-table", "type: xyzbc-head-table"), "kinematics.type",
                  "xyzbc-head-table needs an axis B in axes[]");
  expect_error_at(replace_nth(five_axis_text("xyzac-head"), "    type: rotary\n", ""), "kinematics.type",
                  "xyzac-head needs axis A of type: rotary");
  expect_error_at(replace_nth(head, "    type: rotary\n    wrapped: true\n", "    min_mm: -10\n    max_mm: 10\n"),
                  "kinematics.type", "xyzbc-head needs axis C of type: rotary");
}

// axes[].type (rotary: A, B, C only, in degrees) and axes[].wrapped (rotary only).
TEST(MachineConfig, RotaryAxes) {
  const MachineConfig c = load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim4_rotary.yaml");
  ASSERT_EQ(c.axes.size(), 4u);
  EXPECT_FALSE(c.axes[0].rotary);
  EXPECT_TRUE(c.axes[3].rotary);
  EXPECT_FALSE(c.axes[3].wrapped);
  EXPECT_DOUBLE_EQ(c.axes[3].max_velocity_mm_s, 180.0);  // deg/s
  const std::string four = replace_nth(sim3_text(), "axes:\n",
                                       "axes:\n  - {name: A, type: rotary, wrapped: true, "
                                       "max_velocity_mm_s: 90, max_accel_mm_s2: 900, max_jerk_mm_s3: 9000, "
                                       "drive: {unit_id: 9}}\n");
  const MachineConfig w = parse_machine_config(four, kLabel);
  EXPECT_TRUE(w.axes[0].rotary);
  EXPECT_TRUE(w.axes[0].wrapped);
  expect_error_at(replace_nth(sim3_text(), "  - name: X\n", "  - name: X\n    type: rotary\n"), "axes[0].type",
                  "A, B and C only");
  expect_error_at(replace_nth(sim3_text(), "  - name: X\n", "  - name: X\n    type: angular\n"), "axes[0].type",
                  "'angular' is not one of: linear, rotary");
  expect_error_at(replace_nth(four, "type: rotary, ", ""), "axes[0].wrapped", "needs type: rotary");
  expect_error_at(replace_nth(four, "wrapped: true, ", "wrapped: true, min_mm: -1, "), "axes[0].min_mm",
                  "a wrapped axis has no travel limits");
}

const std::string kGantryPath = std::string(CNC_SOURCE_DIR) + "/config/machines/sim3_gantry.yaml";

std::string gantry_text() {
  std::ifstream in(kGantryPath);
  EXPECT_TRUE(in.good()) << "cannot open " << kGantryPath;
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(MachineConfig, GantrySection) {
  const MachineConfig c = load_machine_config(kGantryPath);
  ASSERT_EQ(c.axes.size(), 3u);
  EXPECT_FALSE(c.axes[0].gantry.enabled);
  EXPECT_FALSE(c.axes[2].gantry.enabled);
  const GantryConfig& g = c.axes[1].gantry;
  ASSERT_TRUE(g.enabled);
  EXPECT_EQ(g.name, "Y2");
  EXPECT_EQ(g.drive.unit_id, 4);
  EXPECT_EQ(g.drive.link_key(), c.axes[1].drive.link_key());
  EXPECT_DOUBLE_EQ(g.switch_position_mm, -4.0);
  EXPECT_DOUBLE_EQ(g.skew_limit_mm, 0.5);
  EXPECT_DOUBLE_EQ(g.home_max_difference_mm, 2.0);
  // The second simulated drive has its own switch, 0.8 mm nearer than Y's.
  EXPECT_TRUE(g.sim.has_home_switch);
  EXPECT_DOUBLE_EQ(g.sim.home_switch_mm - c.axes[1].sim.home_switch_mm, 0.8);
  // Defaults: the axis's switch position, and the axis's simulator without gantry.sim.
  const std::string minimal = replace_nth(
      replace_nth(gantry_text(), "      switch_position_mm: -4\n", ""),
      "      sim: {bandwidth_hz: 40, damping: 1.0, home_switch_mm: -3.2, home_switch_sigma_mm: 0.002, "
      "home_switch_seed: 14}\n",
      "");
  const MachineConfig d = parse_machine_config(minimal, kLabel);
  EXPECT_DOUBLE_EQ(d.axes[1].gantry.switch_position_mm, d.axes[1].home.switch_position_mm);
  EXPECT_DOUBLE_EQ(d.axes[1].gantry.sim.home_switch_mm, d.axes[1].sim.home_switch_mm);
}

TEST(MachineConfig, GantryErrorsNameTheKey) {
  const std::string g = gantry_text();
  expect_error_at(replace_nth(g, "      name: Y2\n", ""), "axes[1].gantry.name", "is required");
  expect_error_at(replace_nth(g, "      name: Y2\n", "      name: X\n"), "axes[1].gantry.name",
                  "already the name of an axis");
  expect_error_at(replace_nth(g, "skew_limit_mm: 0.5", "skew_limit_mm: 0"), "axes[1].gantry.skew_limit_mm", "");
  expect_error_at(replace_nth(g, "home_max_difference_mm: 2", "home_max_difference_mm: -1"),
                  "axes[1].gantry.home_max_difference_mm", "");
  expect_error_at(replace_nth(g, "unit_id: 4", "unit_id: 2"), "axes[1].gantry.drive.unit_id",
                  "another axis already uses this drive address");
  expect_error_at(replace_nth(g, "unit_id: 4", "unit_id: 4, baud: 9600"), "axes[1].gantry.drive.baud", "");
  expect_error_at(replace_nth(g, "      name: Y2\n", "      name: Y2\n      colour: red\n"),
                  "axes[1].gantry.colour", "unknown key");
  expect_error_at(replace_nth(g, "home: {method: switch,", "home: {method: absolute,"), "axes[1].gantry",
                  "not absolute");
  expect_error_at(replace_nth(g, "      drive: {transport: modbus_tcp, host: 127.0.0.1, port: 1502, unit_id: 4, profile: sim}\n",
                              ""),
                  "axes[1].gantry.drive", "is required");
}

TEST(MachineConfig, UnknownKeyAtTopLevel) {
  expect_error_at(sim3_text() + "bogus: 1\n", "bogus", "unknown key");
}

// Found by fuzz_config: a complex key ("? ...") threw yaml-cpp's bad conversion out of the loader.
TEST(MachineConfig, ComplexKeyIsRefusedWithItsPlace) {
  expect_error_at(replace_nth(sim3_text(), "timing:\n", "timing:\n  ? [a, b]\n  : 1\n"), "timing",
                  "a key must be a plain name (line");
  const std::string top = expect_error(sim3_text() + "? {x: 1}\n: 2\n").what();
  EXPECT_NE(top.find("(top level): a key must be a plain name"), std::string::npos) << top;
}

TEST(MachineConfig, UnknownKeyInTiming) {
  expect_error_at(replace_nth(sim3_text(), "timing:\n", "timing:\n  ipo_period: 0.004\n"), "timing.ipo_period",
                  "unknown key");
}

TEST(MachineConfig, UnknownKeyInAxisDrive) {
  expect_error_at(replace_nth(sim3_text(), "unit_id: 2, profile: sim}", "unit_id: 2, profile: sim, bogus: 1}"),
                  "axes[1].drive.bogus", "unknown key");
}

TEST(MachineConfig, WrongType) {
  expect_error_at(replace_nth(sim3_text(), "ipo_period_s: 0.004", "ipo_period_s: fast"), "timing.ipo_period_s",
                  "expected a number, got 'fast'");
}

TEST(MachineConfig, OutOfRange) {
  expect_error_at(replace_nth(sim3_text(), "max_velocity_mm_s: 250", "max_velocity_mm_s: -3"),
                  "axes[0].max_velocity_mm_s", "out of range");
}

TEST(MachineConfig, MissingRequiredKey) {
  expect_error_at(replace_nth(sim3_text(), "    max_accel_mm_s2: 2000\n", ""), "axes[2].max_accel_mm_s2",
                  "is required");
}

TEST(MachineConfig, DuplicateAxisName) {
  expect_error_at(replace_nth(sim3_text(), "- name: Y", "- name: X"), "axes[1].name", "duplicate axis 'X'");
}

TEST(MachineConfig, DuplicateDriveAddress) {
  expect_error_at(replace_nth(sim3_text(), "unit_id: 3", "unit_id: 1"), "axes[2].drive.unit_id",
                  "another axis already uses this drive address");
}

// The spindle section (optional): its VFD configured like a drive, ranges and relations.
const char* const kSpindle =
    "spindle:\n"
    "  drive: {transport: modbus_tcp, host: 127.0.0.1, port: 1502, unit_id: 4, profile: delta_vfd}\n"
    "  at_speed_tolerance: 0.02\n"
    "  at_speed_timeout_s: 5\n"
    "  sim: {time_constant_s: 0.4}\n";

TEST(MachineConfig, SpindleSection) {
  EXPECT_FALSE(parse_machine_config(sim3_text(), kLabel).spindle.enabled) << "no section, no spindle";
  const MachineConfig c = parse_machine_config(sim3_text() + kSpindle, kLabel);
  EXPECT_TRUE(c.spindle.enabled);
  EXPECT_EQ(c.spindle.drive.unit_id, 4);
  EXPECT_EQ(c.spindle.drive.profile, "delta_vfd");
  EXPECT_EQ(c.spindle.drive.link_key(), c.axes[0].drive.link_key());
  EXPECT_DOUBLE_EQ(c.spindle.at_speed_tolerance, 0.02);
  EXPECT_DOUBLE_EQ(c.spindle.at_speed_timeout_s, 5);
  EXPECT_DOUBLE_EQ(c.spindle.max_rpm, 24000);
  EXPECT_DOUBLE_EQ(c.spindle.rpm_per_hz, 60);
  EXPECT_DOUBLE_EQ(c.spindle.sim.time_constant_s, 0.4);
  EXPECT_DOUBLE_EQ(c.spindle.min_override, 0.5);  // LinuxCNC's MIN/MAX_SPINDLE_OVERRIDE defaults
  EXPECT_DOUBLE_EQ(c.spindle.max_override, 1.0);
  EXPECT_EQ(c.spindle.encoder_counts_per_rev, 0);
  EXPECT_FALSE(c.spindle.measured_position());
  EXPECT_DOUBLE_EQ(c.spindle.orient_tolerance_deg, 0.5);
  EXPECT_DOUBLE_EQ(c.spindle.orient_timeout_s, 10);
  EXPECT_DOUBLE_EQ(c.spindle.orient_rpm, 60);
  EXPECT_DOUBLE_EQ(c.spindle.orient_gain_per_s, 2);
  EXPECT_TRUE(load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3_spindle.yaml").spindle.enabled);
  const MachineConfig servo =
      load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3_servo_spindle.yaml");
  EXPECT_EQ(servo.spindle.drive.profile, "cia402_spindle");
  EXPECT_EQ(servo.spindle.encoder_counts_per_rev, 131072);
  EXPECT_TRUE(servo.spindle.measured_position());
  EXPECT_DOUBLE_EQ(servo.spindle.orient_tolerance_deg, 0.2);
}

TEST(MachineConfig, SpindleErrors) {
  const std::string with = sim3_text() + kSpindle;
  expect_error_at(sim3_text() + "spindle: {max_rpm: 1000}\n", "spindle.drive", "is required");
  expect_error_at(replace_nth(with, "unit_id: 4", "unit_id: 2"), "spindle.drive", "axis Y's drive on the same link");
  expect_error_at(replace_nth(with, "transport: modbus_tcp, host: 127.0.0.1, port: 1502, unit_id: 4",
                              "transport: modbus_rtu, unit_id: 4"),
                  "spindle.drive.device", "is required for transport modbus_rtu");
  expect_error_at(replace_nth(with, "at_speed_tolerance: 0.02", "at_speed_tolerance: 0.9"),
                  "spindle.at_speed_tolerance", "out of range");
  expect_error_at(replace_nth(with, "at_speed_timeout_s: 5", "at_speed_timeout_s: 0"),
                  "spindle.at_speed_timeout_s", "out of range");
  expect_error_at(replace_nth(with, "time_constant_s: 0.4", "time_constant_s: -1"), "spindle.sim.time_constant_s",
                  "out of range");
  expect_error_at(with + "  max_rpm: 0\n", "spindle.max_rpm", "out of range");
  expect_error_at(with + "  rpm_per_hz: 5000\n", "spindle.rpm_per_hz", "out of range");
  expect_error_at(with + "  min_override: 1.2\n", "spindle.min_override", "out of range");
  expect_error_at(with + "  max_override: 0.9\n", "spindle.max_override", "out of range");
  const MachineConfig wide = parse_machine_config(with + "  min_override: 0.2\n  max_override: 1.5\n", kLabel);
  EXPECT_DOUBLE_EQ(wide.spindle.min_override, 0.2);
  EXPECT_DOUBLE_EQ(wide.spindle.max_override, 1.5);
  expect_error_at(with + "  colour: red\n", "spindle.colour", "unknown key");
  expect_error_at(with + "  encoder_counts_per_rev: -1\n", "spindle.encoder_counts_per_rev", "out of range");
  expect_error_at(with + "  orient_tolerance_deg: 0\n", "spindle.orient_tolerance_deg", "out of range");
  expect_error_at(with + "  orient_tolerance_deg: 90\n", "spindle.orient_tolerance_deg", "out of range");
  expect_error_at(with + "  orient_timeout_s: 0.01\n", "spindle.orient_timeout_s", "out of range");
  expect_error_at(with + "  orient_gain_per_s: 0\n", "spindle.orient_gain_per_s", "out of range");
  expect_error_at(with + "  orient_rpm: 0\n", "spindle.orient_rpm", "out of range");
  expect_error_at(with + "  max_rpm: 100\n  orient_rpm: 200\n", "spindle.orient_rpm", "must not exceed spindle.max_rpm");
  expect_error_at(replace_nth(with, "profile: delta_vfd}", "profile: delta_vfd, response_timeout_s: 1}"),
                  "spindle.drive", "must not exceed drive_bridge.link_loss_timeout_s");
}

const char* const kIo =
    "io:\n"
    "  modules:\n"
    "    - {name: io1, transport: modbus_tcp, host: 127.0.0.1, port: 1502, unit_id: 5}\n"
    "  points:\n"
    "    - {name: coolant_mist, kind: coil, address: 0}\n"
    "    - {name: coolant_flood, kind: coil, address: 1}\n"
    "    - {name: clamp, kind: coil, address: 4}\n"
    "    - {name: air, kind: coil, address: 5}\n"
    "    - {name: door_closed, kind: discrete_input, address: 0}\n"
    "    - {name: pressure, kind: input_register, address: 2, scale: 0.01}\n"
    "    - {name: valve, kind: holding_register, address: 0, scale: 0.1, signed: true}\n"
    "  coolant: {mist: coolant_mist, flood: coolant_flood}\n"
    "  digital_outputs: [clamp, air]\n"
    "  digital_inputs: [door_closed]\n"
    "  analog_inputs: [pressure]\n"
    "  analog_outputs: [valve]\n";

TEST(MachineConfig, IoSection) {
  EXPECT_FALSE(parse_machine_config(sim3_text(), kLabel).io.enabled) << "no section, no I/O";
  EXPECT_EQ(parse_machine_config(sim3_text(), kLabel).program.digital_outputs, 8) << "as before without io:";
  const MachineConfig c = parse_machine_config(sim3_text() + kIo, kLabel);
  ASSERT_TRUE(c.io.enabled);
  ASSERT_EQ(c.io.modules.size(), 1u);
  EXPECT_EQ(c.io.modules[0].link.unit_id, 5);
  EXPECT_EQ(c.io.modules[0].link.link_key(), c.axes[0].drive.link_key());
  ASSERT_EQ(c.io.points.size(), 7u);
  EXPECT_EQ(c.io.points[c.io.coolant_flood].name, "coolant_flood");
  EXPECT_EQ(c.io.points[c.io.coolant_mist].address, 0);
  ASSERT_EQ(c.io.digital_outputs.size(), 2u);
  EXPECT_EQ(c.io.points[c.io.digital_outputs[1]].name, "air");
  EXPECT_EQ(c.program.digital_outputs, 2) << "M62-M65 P: the listed outputs";
  const IoPointConfig& valve = c.io.points[c.io.analog_outputs[0]];
  EXPECT_EQ(valve.kind, IoKind::kHoldingRegister);
  EXPECT_DOUBLE_EQ(valve.scale, 0.1);
  EXPECT_TRUE(valve.is_signed);
  EXPECT_EQ(c.io.points[c.io.digital_inputs[0]].kind, IoKind::kDiscreteInput);
  EXPECT_EQ(c.io.points[c.io.analog_inputs[0]].kind, IoKind::kInputRegister);
  EXPECT_TRUE(load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3_io.yaml").io.enabled);
}

TEST(MachineConfig, IoErrors) {
  const std::string with = sim3_text() + kIo;
  expect_error_at(sim3_text() + "io: {coolant: {flood: x}}\n", "io.modules", "at least one module");
  expect_error_at(replace_nth(with, "unit_id: 5", "unit_id: 2"), "io.modules[0].unit_id", "axis Y's drive on the same link");
  expect_error_at(replace_nth(with, "unit_id: 5}", "}"), "io.modules[0].unit_id", "required");
  expect_error_at(replace_nth(with, "name: io1, transport: modbus_tcp", "name: io1, transport: modbus_rtu"),
                  "io.modules[0].device", "is required for transport modbus_rtu");
  expect_error_at(replace_nth(with, "kind: coil, address: 4", "kind: relay, address: 4"), "io.points[2].kind",
                  "is not one of");
  expect_error_at(replace_nth(with, "kind: coil, address: 4", "kind: coil, address: 1"), "io.points[2].address",
                  "is point coolant_flood already");
  expect_error_at(replace_nth(with, "{name: air,", "{name: clamp,"), "io.points[3].name", "duplicate point");
  expect_error_at(replace_nth(with, "{name: air, kind: coil,", "{name: air, module: io2, kind: coil,"),
                  "io.points[3].module", "no module 'io2'");
  expect_error_at(replace_nth(with, "address: 5}", "address: 70000}"), "io.points[3].address", "out of range");
  expect_error_at(replace_nth(with, "address: 5}", "address: 5, scale: 2}"), "io.points[3].scale", "only a register");
  expect_error_at(replace_nth(with, "scale: 0.01}", "scale: 0}"), "io.points[5].scale", "must not be 0");
  expect_error_at(replace_nth(with, "flood: coolant_flood}", "flood: pressure}"), "io.coolant.flood",
                  "is of kind input_register, not coil");
  expect_error_at(replace_nth(with, "flood: coolant_flood}", "flood: nothing}"), "io.coolant.flood",
                  "no point 'nothing'");
  expect_error_at(replace_nth(with, "[clamp, air]", "[clamp, coolant_mist]"), "io.digital_outputs[1]",
                  "has a role already");
  expect_error_at(replace_nth(with, "[door_closed]", "[clamp]"), "io.digital_inputs[0]", "not discrete_input");
  expect_error_at(replace_nth(with, "analog_outputs: [valve]", "analog_outputs: [pressure]"), "io.analog_outputs[0]",
                  "not holding_register");
  expect_error_at(with + "  colour: red\n", "io.colour", "unknown key");
  std::string many = with;
  for (int a = 100; a < 165; ++a)
    many = replace_nth(many, "  coolant: {", "    - {name: c" + std::to_string(a) + ", kind: coil, address: " +
                                                 std::to_string(a) + "}\n  coolant: {");
  expect_error_at(many, "io.points", "module io1 has 69 coil points, at most 64");
  expect_error_at(replace_nth(with, "unit_id: 5}", "unit_id: 5, response_timeout_s: 1}"),
                  "io.modules[0].response_timeout_s", "must not exceed drive_bridge.link_loss_timeout_s");
}

// The E-stop: a normally closed discrete input of an I/O module.
TEST(MachineConfig, SafetySection) {
  const std::string io = replace_nth(std::string(kIo), "  coolant: {",
                                     "    - {name: estop_ok, kind: discrete_input, address: 3}\n  coolant: {");
  EXPECT_FALSE(parse_machine_config(sim3_text() + io, kLabel).safety.enabled()) << "no section, no E-stop";
  const MachineConfig c = parse_machine_config(sim3_text() + io + "safety: {estop: {input: estop_ok}}\n", kLabel);
  ASSERT_TRUE(c.safety.enabled());
  EXPECT_EQ(c.io.points[static_cast<size_t>(c.safety.estop_input)].name, "estop_ok");
  // How alarms name it: the point and its module, both by their config names.
  EXPECT_EQ(c.io.point_label(c.safety.estop_input), "estop_ok on module " + c.io.modules[0].name);
  EXPECT_EQ(c.io.point_label(-1), "(no such point)");
  EXPECT_FALSE(parse_machine_config(sim3_text() + io + "safety: {}\n", kLabel).safety.enabled());
  EXPECT_TRUE(load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3_safety.yaml").safety.enabled());
  const MachineConfig g = load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3_guarded.yaml");
  EXPECT_EQ(g.safety.hard_limits.size(), 3u);
  EXPECT_GE(g.safety.door_input, 0);
  EXPECT_GT(g.axes[0].sim.limit_max_mm, g.axes[0].max_mm) << "the switches beyond the travel";
}

TEST(MachineConfig, SimulatedLimitSwitches) {
  std::string y = sim3_text();
  y = replace_nth(y, "sim: {bandwidth_hz: 40, damping: 1.0}", "sim: {bandwidth_hz: 40, limit_min_mm: -6, limit_max_mm: 401}");
  const MachineConfig c = parse_machine_config(y, kLabel);
  EXPECT_EQ(c.axes[0].sim.limit_min_mm, -6);
  EXPECT_EQ(c.axes[0].sim.limit_max_mm, 401);
  EXPECT_TRUE(std::isnan(c.axes[1].sim.limit_max_mm));
  expect_error_at(replace_nth(sim3_text(), "sim: {bandwidth_hz: 40, damping: 1.0}", "sim: {limit_min_mm: 5, limit_max_mm: 4}"),
                  "axes[0].sim.limit_max_mm", "must be above limit_min_mm");
}

TEST(MachineConfig, SafetyErrors) {
  const std::string io = replace_nth(std::string(kIo), "  coolant: {",
                                     "    - {name: estop_ok, kind: discrete_input, address: 3}\n  coolant: {");
  const std::string with = sim3_text() + io;
  expect_error_at(sim3_text() + "safety: {estop: {input: estop_ok}}\n", "safety.estop.input",
                  "needs an io: section with the point 'estop_ok'");
  expect_error_at(with + "safety: {estop: {input: nothing}}\n", "safety.estop.input", "no point 'nothing'");
  expect_error_at(with + "safety: {estop: {input: clamp}}\n", "safety.estop.input",
                  "is of kind coil, not discrete_input");
  expect_error_at(with + "safety: {estop: {input: door_closed}}\n", "safety.estop.input", "has a role already");
  expect_error_at(with + "safety: {estop: {}}\n", "safety.estop.input", "required");
  expect_error_at(with + "safety: {estop: {input: estop_ok, delay: 1}}\n", "safety.estop.delay", "unknown key");
  expect_error_at(with + "safety: {door: x}\n", "safety.door", "a map");
  expect_error_at(with + "safety: {door: {}}\n", "safety.door.input", "required");
  expect_error_at(with + "safety: {door: {input: clamp}}\n", "safety.door.input", "not discrete_input");
  expect_error_at(with + "safety: {estop: {input: estop_ok}, door: {input: estop_ok}}\n", "safety.door.input",
                  "has a role already");
  {
    const MachineConfig d = parse_machine_config(with + "safety: {door: {input: estop_ok}}\n", kLabel);
    EXPECT_EQ(d.io.points[static_cast<size_t>(d.safety.door_input)].name, "estop_ok");
    EXPECT_TRUE(d.safety.enabled());
  }
  expect_error_at(with + "safety: {hard_limits: [{axis: Q, max: estop_ok}]}\n", "safety.hard_limits[0].axis", "no axis Q");
  expect_error_at(with + "safety: {hard_limits: [{axis: X}]}\n", "safety.hard_limits[0].max", "a min or a max input");
  expect_error_at(with + "safety: {hard_limits: [{axis: X, min: clamp}]}\n", "safety.hard_limits[0].min",
                  "not discrete_input");
  expect_error_at(with + "safety: {estop: {input: estop_ok}, hard_limits: [{axis: X, max: estop_ok}]}\n",
                  "safety.hard_limits[0].max", "has a role already");
  const MachineConfig c = parse_machine_config(with + "safety: {hard_limits: [{axis: Y, max: estop_ok}]}\n", kLabel);
  ASSERT_EQ(c.safety.hard_limits.size(), 1u);
  EXPECT_EQ(c.safety.hard_limits[0].axis, 1);
  EXPECT_EQ(c.safety.hard_limits[0].min_input, -1);
  EXPECT_EQ(c.io.points[static_cast<size_t>(c.safety.hard_limits[0].max_input)].name, "estop_ok");
}

TEST(MachineConfig, OpcuaSection) {
  const std::string id = "  identification: {manufacturer: ACME, model: M3, serial_number: SN-1}\n";
  EXPECT_FALSE(parse_machine_config(sim3_text(), kLabel).opcua.enabled);
  const MachineConfig c = parse_machine_config(
      sim3_text() + "hmi: {users_file: users}\nopcua:\n  port: 4841\n  hmi_user: opcua\n  hmi_password_file: pw\n" + id,
      "/etc/cnc/cell.yaml");
  EXPECT_TRUE(c.opcua.enabled);
  EXPECT_EQ(c.opcua.port, 4841);
  EXPECT_EQ(c.opcua.listen, "127.0.0.1");
  EXPECT_FALSE(c.opcua.anonymous);
  EXPECT_FALSE(c.opcua.allow_security_none);
  EXPECT_FALSE(c.opcua.trust_unknown_clients);
  EXPECT_EQ(c.opcua.hmi_password_file, "/etc/cnc/pw");
  EXPECT_EQ(c.opcua.manufacturer, "ACME");
  EXPECT_EQ(c.opcua.product_instance_uri, "urn:cnc:sim3:SN-1");
  EXPECT_EQ(c.opcua.year_of_construction, 0);
}

TEST(MachineConfig, OpcuaErrors) {
  const std::string id = "  identification: {manufacturer: ACME, model: M3, serial_number: SN-1}\n";
  // No users (no hmi.users_file) and no anonymous access: nobody could log in.
  expect_error_at(sim3_text() + "opcua:\n" + id, "opcua.anonymous", "nobody could log in");
  // The HMI asks for a login: cnc-opcua needs a user of its own.
  expect_error_at(sim3_text() + "hmi: {users_file: users}\nopcua:\n" + id, "opcua.hmi_user", "is required");
  expect_error_at(sim3_text() + "hmi: {users_file: users}\nopcua:\n  hmi_user: o\n" + id, "opcua.hmi_password_file",
                  "is required with hmi_user");
  expect_error_at(sim3_text() + "opcua:\n  anonymous: true\n  identification: {model: M3, serial_number: SN-1}\n",
                  "opcua.identification.manufacturer", "is required");
  expect_error_at(sim3_text() + "opcua:\n  anonymous: true\n  identification: {manufacturer: '', model: M, serial_number: S}\n",
                  "opcua.identification.manufacturer", "must not be empty");
  expect_error_at(sim3_text() + "opcua:\n  anonymous: true\n  port: 0\n" + id, "opcua.port", "out of range");
  expect_error_at(sim3_text() + "opcua:\n  anonymous: true\n  policy: None\n" + id, "opcua.policy", "unknown key");
}

TEST(MachineConfig, MqttSection) {
  EXPECT_FALSE(parse_machine_config(sim3_text(), kLabel).mqtt.enabled);
  const MachineConfig plain = parse_machine_config(sim3_text() + "mqtt: {}\n", kLabel);
  EXPECT_TRUE(plain.mqtt.enabled);
  EXPECT_EQ(plain.mqtt.port, 1883);
  EXPECT_EQ(plain.mqtt.client_id, "cnc-sim3");
  EXPECT_EQ(plain.mqtt.topic_prefix, "cnc");
  const MachineConfig c = parse_machine_config(
      sim3_text() + "mqtt:\n  host: broker.plant\n  topic_prefix: plant/hall2\n  username: sim3\n"
                    "  password_file: mqtt.pw\n  ca_file: ca.crt\n",
      "/etc/cnc/cell.yaml");
  EXPECT_EQ(c.mqtt.port, 8883);  // TLS's port when a CA is given
  EXPECT_EQ(c.mqtt.password_file, "/etc/cnc/mqtt.pw");
  EXPECT_EQ(c.mqtt.ca_file, "/etc/cnc/ca.crt");
  EXPECT_EQ(c.mqtt.topic_prefix, "plant/hall2");
}

TEST(MachineConfig, MqttErrors) {
  // A password in clear to a broker on another PC.
  expect_error_at(sim3_text() + "mqtt: {host: broker.plant, username: u, password_file: pw}\n", "mqtt.ca_file",
                  "not sent in clear");
  expect_error_at(sim3_text() + "mqtt: {password_file: pw}\n", "mqtt.password_file", "needs mqtt.username");
  expect_error_at(sim3_text() + "mqtt: {ca_file: ca, cert_file: c}\n", "mqtt.key_file", "go together");
  expect_error_at(sim3_text() + "mqtt: {cert_file: c, key_file: k}\n", "mqtt.ca_file", "is required with cert_file");
  for (const char* bad : {"'a/+/b'", "'a//b'", "'/a'", "'a/'", "'#'", "'$SYS'"})
    expect_error_at(sim3_text() + "mqtt: {topic_prefix: " + bad + "}\n", "mqtt.topic_prefix", "is not a topic");
  expect_error_at(sim3_text() + "mqtt: {keepalive_s: 4}\n", "mqtt.keepalive_s", "out of range");
  expect_error_at(sim3_text() + "mqtt: {qos: 2}\n", "mqtt.qos", "unknown key");
}

TEST(MachineConfig, DuplicateKey) {
  expect_error_at(replace_nth(sim3_text(), "timing:\n", "timing:\n  stop_decel_mm_s2: 100\n"),
                  "timing.stop_decel_mm_s2", "duplicate key");
}

TEST(MachineConfig, ServoPeriodMustDivideIpoPeriod) {
  expect_error_at(replace_nth(sim3_text(), "servo_period_s: 0.001", "servo_period_s: 0.0015"),
                  "timing.servo_period_s", "whole multiple");
}

TEST(MachineConfig, ServoPeriodMustNotExceedIpoPeriod) {
  expect_error_at(replace_nth(sim3_text(), "servo_period_s: 0.001", "servo_period_s: 0.008"),
                  "timing.servo_period_s", "must not exceed");
}

TEST(MachineConfig, SectionThatIsNotAMapping) {
  expect_error_at(replace_nth(sim3_text(), "monitor:\n  rmax_margin: 0.1\n", "monitor: 5\n"), "monitor",
                  "expected a mapping");
}

TEST(MachineConfig, ChoiceListsTheAlternatives) {
  expect_error_at(replace_nth(sim3_text(), "transport: modbus_tcp", "transport: canopen"), "axes[0].drive.transport",
                  "'canopen' is not one of: loopback, modbus_rtu, modbus_tcp");
}

TEST(MachineConfig, YamlSyntaxErrorNamesLineAndColumn) {
  // Line 3 opens a flow sequence that line 4 does not close.
  const std::string yaml =
      "cell:\n"
      "  name: sim3\n"
      "  lcm_url: [a, b\n"
      "timing: {}\n";
  const ConfigError e = expect_error(yaml);
  EXPECT_EQ(e.key_path(), "");
  const std::string what = e.what();
  EXPECT_EQ(what.rfind(kLabel + ": (top level): YAML syntax error at line ", 0), 0u) << what;
  EXPECT_NE(what.find("at line 4, column 7"), std::string::npos) << what;
}

TEST(MachineConfig, EmptyFileNeedsCellName) { expect_error_at("", "cell.name", "is required"); }

TEST(MachineConfig, MissingFileIsReported) {
  try {
    load_machine_config(kSim3Path + ".missing");
    FAIL() << "a missing file loaded";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("cannot open the file"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(".missing"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace cnc::config
