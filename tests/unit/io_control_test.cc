// The drive bridge's I/O core (io_control.h) for the analog outputs (M67/M68): a
// value becomes the holding register's raw count, value / scale rounded, held to the
// register's range (and counted); only the analog-output slots of a module are
// written, once a command has given them a value; they keep their values through the bridge's stop; a repeated or older
// command changes nothing.
#include <gtest/gtest.h>

#include <array>
#include <vector>

#include "common/config/machine_config.h"
#include "services/drive_bridge/io_control.h"

namespace cnc::bridge {
namespace {

config::IoConfig io_config() {
  config::IoConfig io;
  io.enabled = true;
  io.modules.push_back({"m", config::DriveConfig{}});
  auto point = [&](const char* name, config::IoKind k, int addr, double scale, bool is_signed) {
    config::IoPointConfig p;
    p.name = name;
    p.kind = k;
    p.address = addr;
    p.scale = scale;
    p.is_signed = is_signed;
    io.points.push_back(p);
  };
  point("valve_pct", config::IoKind::kHoldingRegister, 0, 0.1, false);  // point 0
  point("gauge", config::IoKind::kHoldingRegister, 1, 1, false);        // point 1: an analog input
  point("trim_mm", config::IoKind::kHoldingRegister, 2, 0.001, true);   // point 2
  io.analog_outputs = {0, 2};
  io.analog_inputs = {1};
  return io;
}

TEST(IoControl, AnalogOutputsToRawCountsHeldToTheRegistersRange) {
  const config::IoConfig io = io_config();
  IoControl ctl(io, {{}}, {{0, 1, 2}});
  std::array<uint16_t, 64> raw{};
  EXPECT_EQ(ctl.module_holding(0, raw.data()), 0u) << "no value given yet: the module keeps its own";
  ASSERT_TRUE(ctl.on_command(1, 0, 0, {42.54, -1.2345}, true));
  EXPECT_EQ(ctl.module_holding(0, raw.data()), 0b101u) << "slots 0 and 2 are outputs, 1 is not";
  EXPECT_EQ(raw[0], 425) << "42.54 / 0.1 rounded";
  EXPECT_EQ(static_cast<int16_t>(raw[2]), -1235) << "signed, two's complement; -1234.5 rounds away from 0";
  EXPECT_EQ(ctl.clamped(), 0);
  EXPECT_FALSE(ctl.on_command(1, 0, 0, {1.0, 1.0}, true)) << "a repeat changes nothing";
  ctl.module_holding(0, raw.data());
  EXPECT_EQ(raw[0], 425);
  ASSERT_TRUE(ctl.on_command(2, 0, 0, {7000.0, 40.0}, true));  // 70000 counts; 40000 > 32767
  ctl.module_holding(0, raw.data());
  EXPECT_EQ(raw[0], 65535);
  EXPECT_EQ(raw[2], 32767);
  EXPECT_EQ(ctl.clamped(), 2);
  ASSERT_TRUE(ctl.on_command(3, 0, 0, {-5.0, -40.0}, true));
  ctl.module_holding(0, raw.data());
  EXPECT_EQ(raw[0], 0);
  EXPECT_EQ(static_cast<int16_t>(raw[2]), -32768);
  ctl.stop();
  ctl.module_holding(0, raw.data());
  EXPECT_EQ(static_cast<int16_t>(raw[2]), -32768) << "a stop keeps the analog outputs";
  // A command without analog values keeps them too.
  ASSERT_TRUE(ctl.on_command(4, 0, 0, true));
  EXPECT_EQ(ctl.analog(1), -40.0);
}

}  // namespace
}  // namespace cnc::bridge
