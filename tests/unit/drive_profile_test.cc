// Drive profiles as data: the register field codec (16/32 bit, signedness, word
// order, scale), strict loading of config/drives/*.yaml with key paths in the
// errors, and where a machine's profile is found.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>

#include "common/config/yaml_reader.h"
#include "common/drive/drive_profile.h"

namespace cnc::drive {
namespace {

const std::string kDrives = std::string(CNC_SOURCE_DIR) + "/config/drives/";

Field field(int words, bool is_signed, WordOrder order, double scale = 1.0) {
  Field f;
  f.address = 0;
  f.words = words;
  f.is_signed = is_signed;
  f.order = order;
  f.scale = scale;
  return f;
}

TEST(Field, Int32LowWordFirst) {
  const Field f = field(2, true, WordOrder::kLowFirst);
  uint16_t regs[2] = {};
  f.encode_raw(0x12345678, regs);
  EXPECT_EQ(regs[0], 0x5678);
  EXPECT_EQ(regs[1], 0x1234);
  EXPECT_EQ(f.decode_raw(regs), 0x12345678);
  f.encode_raw(-2, regs);
  EXPECT_EQ(regs[0], 0xFFFE);
  EXPECT_EQ(regs[1], 0xFFFF);
  for (int64_t v : {int64_t{0}, int64_t{1}, int64_t{-1}, int64_t{-123456789}, int64_t{std::numeric_limits<int32_t>::min()},
                    int64_t{std::numeric_limits<int32_t>::max()}}) {
    f.encode_raw(v, regs);
    EXPECT_EQ(f.decode_raw(regs), v);
  }
}

TEST(Field, Int32HighWordFirst) {
  const Field f = field(2, true, WordOrder::kHighFirst);
  uint16_t regs[2] = {};
  f.encode_raw(0x12345678, regs);
  EXPECT_EQ(regs[0], 0x1234);
  EXPECT_EQ(regs[1], 0x5678);
  EXPECT_EQ(f.decode_raw(regs), 0x12345678);
  f.encode_raw(-100000, regs);  // 0xFFFE7960
  EXPECT_EQ(regs[0], 0xFFFE);
  EXPECT_EQ(regs[1], 0x7960);
  EXPECT_EQ(f.decode_raw(regs), -100000);
}

TEST(Field, SixteenBitSignedAndUnsigned) {
  uint16_t r = 0;
  const Field s = field(1, true, WordOrder::kLowFirst);
  s.encode_raw(-8, &r);
  EXPECT_EQ(r, 0xFFF8);
  EXPECT_EQ(s.decode_raw(&r), -8);
  s.encode_raw(40000, &r);  // saturates at 32767
  EXPECT_EQ(s.decode_raw(&r), 32767);
  const Field u = field(1, false, WordOrder::kLowFirst);
  r = 0xFFF8;
  EXPECT_EQ(u.decode_raw(&r), 65528);
  u.encode_raw(-5, &r);  // saturates at 0
  EXPECT_EQ(r, 0);
  const Field u32 = field(2, false, WordOrder::kHighFirst);
  uint16_t w[2] = {0xFFFF, 0xFFFF};
  EXPECT_EQ(u32.decode_raw(w), 4294967295LL);
}

TEST(Field, ScaleRoundsAndSaturates) {
  const Field f = field(2, true, WordOrder::kLowFirst, 10000.0);
  uint16_t regs[2] = {};
  auto counts = [&](double mm) {
    f.encode(mm, regs);
    return f.decode_raw(regs);
  };
  EXPECT_EQ(counts(0.0), 0);
  EXPECT_EQ(counts(1.0), 10000);
  EXPECT_EQ(counts(-12.34567), -123457);
  EXPECT_EQ(counts(0.00004), 0);
  EXPECT_EQ(counts(0.00006), 1);
  EXPECT_EQ(counts(1e9), std::numeric_limits<int32_t>::max());
  EXPECT_EQ(counts(-1e9), std::numeric_limits<int32_t>::min());
  EXPECT_EQ(counts(std::numeric_limits<double>::quiet_NaN()), std::numeric_limits<int32_t>::min());
  f.encode_raw(-123457, regs);
  EXPECT_DOUBLE_EQ(f.decode(regs), -12.3457);
  const Field g = field(2, true, WordOrder::kHighFirst, 26214.4);
  for (double mm : {-150.0, -0.0001, 0.0001, 123.4567, 400.0}) {
    g.encode(mm, regs);
    EXPECT_NEAR(g.decode(regs), mm, 0.5 / 26214.4);
  }
}

TEST(DriveProfile, ShippedProfilesLoad) {
  const DriveProfile sim = load_drive_profile(kDrives + "sim.yaml");
  EXPECT_EQ(sim.name, "sim");
  EXPECT_EQ(sim.state_machine, "sim");
  EXPECT_TRUE(sim.write_and_read);
  EXPECT_EQ(sim.field(Role::kTargetPosition).address, 2);
  EXPECT_DOUBLE_EQ(sim.field(Role::kActualPosition).scale, 10000.0);

  const DriveProfile cia = load_drive_profile(kDrives + "cia402_modbus.yaml");
  EXPECT_EQ(cia.state_machine, "cia402");
  EXPECT_EQ(cia.field(Role::kControlword).address, 0x6040);
  EXPECT_EQ(cia.field(Role::kStatusword).address, 0x6041);
  EXPECT_EQ(cia.field(Role::kMode).address, 0x6060);
  EXPECT_EQ(cia.field(Role::kTargetPosition).address, 0x607A);
  EXPECT_EQ(cia.field(Role::kTargetPosition).order, WordOrder::kLowFirst);
  EXPECT_EQ(cia.mode_of_operation, 8);

  const DriveProfile ls = load_drive_profile(kDrives + "leadshine_el.yaml");
  EXPECT_EQ(ls.state_machine, "leadshine");
  EXPECT_FALSE(ls.write_and_read);
  EXPECT_EQ(ls.field(Role::kTargetPosition).order, WordOrder::kHighFirst);
  EXPECT_EQ(ls.field(Role::kActualPosition).order, WordOrder::kHighFirst);
  EXPECT_TRUE(ls.has(Role::kFaultReset));
  EXPECT_DOUBLE_EQ(ls.field(Role::kTargetPosition).scale, 1000.0);

  const DriveProfile vfd = load_drive_profile(kDrives + "delta_vfd.yaml");
  EXPECT_EQ(vfd.state_machine, "delta_vfd");
  EXPECT_EQ(vfd.field(Role::kControlword).address, 0x2000);
  EXPECT_EQ(vfd.field(Role::kSpeedSetpoint).address, 0x2001);
  EXPECT_DOUBLE_EQ(vfd.field(Role::kSpeedSetpoint).scale, 100.0);
  EXPECT_EQ(vfd.field(Role::kActualSpeed).address, 0x2103);
  EXPECT_EQ(vfd.field(Role::kOutputCurrent).address, 0x2104);
  EXPECT_FALSE(vfd.has(Role::kTargetPosition));
  EXPECT_FALSE(vfd.has(Role::kEncoderPosition));

  const DriveProfile enc = load_drive_profile(kDrives + "delta_vfd_encoder.yaml");
  EXPECT_EQ(enc.state_machine, "delta_vfd");
  EXPECT_EQ(enc.field(Role::kEncoderPosition).address, 0x2105);
  EXPECT_EQ(enc.field(Role::kEncoderPosition).words, 2);

  const DriveProfile servo = load_drive_profile(kDrives + "cia402_spindle.yaml");
  EXPECT_EQ(servo.state_machine, "cia402_velocity");
  EXPECT_EQ(servo.mode_of_operation, 3) << "profile velocity";
  EXPECT_EQ(servo.field(Role::kControlword).address, 0x6040);
  EXPECT_EQ(servo.field(Role::kStatusword).address, 0x6041);
  EXPECT_EQ(servo.field(Role::kMode).address, 0x6060);
  EXPECT_EQ(servo.field(Role::kSpeedSetpoint).address, 0x60FF);
  EXPECT_EQ(servo.field(Role::kActualSpeed).address, 0x606C);
  EXPECT_EQ(servo.field(Role::kEncoderPosition).address, 0x6064);
  EXPECT_TRUE(servo.field(Role::kSpeedSetpoint).is_signed);
  EXPECT_DOUBLE_EQ(servo.field(Role::kSpeedSetpoint).scale, 131072.0);
}

const std::string kGood =
    "name: t\n"
    "state_machine: sim\n"
    "registers:\n"
    "  controlword: {address: 0}\n"
    "  statusword: {address: 1}\n"
    "  target_position: {address: 2, words: 2, signed: true}\n"
    "  actual_position: {address: 4, words: 2, signed: true}\n";

void expect_error(const std::string& yaml, const std::string& key_path, const std::string& detail) {
  try {
    parse_drive_profile(yaml, "p.yaml");
    ADD_FAILURE() << "accepted:\n" << yaml;
  } catch (const config::ConfigError& e) {
    EXPECT_EQ(e.key_path(), key_path) << e.what();
    EXPECT_NE(std::string(e.what()).find(detail), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).rfind("p.yaml: " + key_path + ": ", 0), 0u) << e.what();
  }
}

TEST(DriveProfile, HexAddressesAndDefaults) {
  const DriveProfile p = parse_drive_profile(kGood + "  mode: {address: 0x6060}\n", "p.yaml");
  EXPECT_EQ(p.field(Role::kMode).address, 0x6060);
  EXPECT_EQ(p.field(Role::kControlword).words, 1);
  EXPECT_FALSE(p.field(Role::kControlword).is_signed);
  EXPECT_EQ(p.field(Role::kTargetPosition).order, WordOrder::kLowFirst);
  EXPECT_FALSE(p.write_and_read);
  EXPECT_EQ(p.first_address(), 0);
  EXPECT_EQ(p.end_address(), 0x6061);
}

TEST(DriveProfile, ErrorsNameTheKeyPath) {
  expect_error(kGood + "bogus: 1\n", "bogus", "unknown key");
  expect_error(kGood + "  bogus: {address: 9}\n", "registers.bogus", "unknown key");
  expect_error(kGood + "  mode: {address: 9, word: 2}\n", "registers.mode.word", "unknown key");
  expect_error(kGood + "  mode: {address: 70000}\n", "registers.mode.address", "out of range");
  expect_error(kGood + "  mode: {address: 9, words: 3}\n", "registers.mode.words", "out of range");
  expect_error(kGood + "  mode: {address: 9, word_order: middle_first}\n", "registers.mode.word_order",
               "'middle_first' is not one of: high_first, low_first");
  expect_error(kGood + "  mode: {address: 9, scale: 0}\n", "registers.mode.scale", "out of range");
  expect_error(kGood + "  mode: {address: 3}\n", "registers.target_position", "overlaps mode");
  expect_error("name: t\nstate_machine: canopen\n", "state_machine",
               "is not one of: cia402, cia402_velocity, delta_vfd, huanyang, leadshine, sim");
  std::string no_status = kGood;
  no_status.replace(no_status.find("  statusword: {address: 1}\n"), 27, "");
  expect_error(no_status, "registers.statusword", "is required by state_machine sim");
  std::string short_pos = kGood;
  short_pos.replace(short_pos.find("{address: 4, words: 2"), 21, "{address: 4, words: 1");
  expect_error(short_pos, "registers.actual_position.words", "must be 2 for a position");
  expect_error("state_machine: sim\n", "name", "is required");
  // The CiA 402 state machine needs the mode register.
  std::string cia = kGood;
  cia.replace(cia.find("state_machine: sim"), 18, "state_machine: cia402");
  expect_error(cia, "registers.mode", "is required by state_machine cia402");
  // A spindle VFD needs its frequency command and output frequency.
  expect_error("name: v\nstate_machine: delta_vfd\nregisters:\n  controlword: {address: 0x2000}\n"
               "  statusword: {address: 0x2101}\n  error_code: {address: 0x2100}\n  fault_reset: {address: 0x2002}\n"
               "  actual_speed: {address: 0x2103, scale: 100}\n",
               "registers.speed_setpoint", "is required by state_machine delta_vfd");
  // The servo spindle needs its target velocity and velocity actual value.
  expect_error("name: s\nstate_machine: cia402_velocity\nregisters:\n  controlword: {address: 0x6040}\n"
               "  statusword: {address: 0x6041}\n  mode: {address: 0x6060}\n"
               "  speed_setpoint: {address: 0x60FF, words: 2, signed: true}\n",
               "registers.actual_speed", "is required by state_machine cia402_velocity");
  // The encoder's counter: 32 bits, raw counts.
  expect_error(kGood + "  encoder_position: {address: 10}\n", "registers.encoder_position",
               "must be two registers (a 32-bit counter) with scale 1");
  expect_error(kGood + "  encoder_position: {address: 10, words: 2, scale: 4096}\n", "registers.encoder_position",
               "must be two registers (a 32-bit counter) with scale 1");
}

TEST(DriveProfile, FoundBesideTheMachineOrInTheSourceTree) {
  const std::string machine = std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml";
  EXPECT_TRUE(std::filesystem::equivalent(find_drive_profile("sim", machine, ""), kDrives + "sim.yaml"));
  // A machine file elsewhere (a test's copy) falls back to the source tree.
  EXPECT_TRUE(std::filesystem::equivalent(find_drive_profile("leadshine_el", "/tmp/x/machine.yaml", ""),
                                          kDrives + "leadshine_el.yaml"));
  EXPECT_EQ(find_drive_profile("sim", "/a/b/m.yaml", "../profiles"), "/a/b/../profiles/sim.yaml");
  EXPECT_EQ(find_drive_profile("my/drive.yaml", "/a/b/m.yaml", ""), "/a/b/my/drive.yaml");
  EXPECT_EQ(find_drive_profile("/abs/drive.yaml", "/a/b/m.yaml", ""), "/abs/drive.yaml");
}

}  // namespace
}  // namespace cnc::drive
