// Devices as slices of a cyclic process image (common/drive/device.h): the slices of
// an image do not overlap; an axis drive behind the device interface puts the same
// register transactions on the wire, in the same order, as the register-level
// DriveIo it wraps; and a device that is no axis (a loopback I/O module,
// loopback_io_device.h) shares the image and the cycle with it.
#include <gtest/gtest.h>

#include <cerrno>
#include <string>
#include <vector>

#include "common/drive/axis_drive.h"
#include "common/drive/device.h"
#include "common/drive/drive_io.h"
#include "common/drive/loopback_io_device.h"
#include "common/drive/loopback_link.h"

namespace cnc::drive {
namespace {

const std::string kDrives = std::string(CNC_SOURCE_DIR) + "/config/drives/";

// A loopback link that writes down every transaction it carries.
class TapLink final : public Link {
 public:
  TapLink() : Link("tap") {}
  LoopbackLink inner;
  std::vector<std::string> wire;

 private:
  static int err(TxResult r) { return r == TxResult::kOk ? 0 : EIO; }
  void log(const char* op, int unit, int addr, int n, const uint16_t* v) {
    std::string s = std::string(op) + " u" + std::to_string(unit) + " @" + std::to_string(addr) + " n" + std::to_string(n);
    for (int i = 0; v != nullptr && i < n; ++i) s += " " + std::to_string(v[i]);
    wire.push_back(s);
  }
  int do_open(std::string&) override { return inner.ensure_open(0.0) ? 0 : EIO; }
  void do_close() override {}
  int do_read(int unit, int addr, int n, uint16_t* dest) override {
    log("R", unit, addr, n, nullptr);
    return err(inner.read_registers(unit, addr, n, dest, c_));
  }
  int do_write1(int unit, int addr, uint16_t value) override {
    log("W1", unit, addr, 1, &value);
    return err(inner.write_register(unit, addr, value, c_));
  }
  int do_write(int unit, int addr, int n, const uint16_t* src) override {
    log("W", unit, addr, n, src);
    return err(inner.write_registers(unit, addr, n, src, c_));
  }
  int do_write_read(int unit, int waddr, int wn, const uint16_t* src, int raddr, int rn, uint16_t* dest) override {
    log("WR", unit, waddr, wn, src);
    log("  R", unit, raddr, rn, nullptr);
    return err(inner.write_and_read(unit, waddr, wn, src, raddr, rn, dest, c_));
  }
  LinkCounters c_;
};

TEST(ProcessImage, SlicesOfTheDevicesLieSideBySide) {
  ProcessImage image;
  EXPECT_EQ(image.add(kAxisLayout), 0u);
  EXPECT_EQ(image.add(LoopbackIoDevice::kLayout), 1u);
  EXPECT_EQ(image.add(kAxisLayout), 2u);
  EXPECT_EQ(image.devices(), 3u);
  EXPECT_EQ(image.input_bytes(), 2 * sizeof(AxisInputs) + 4);
  EXPECT_EQ(image.output_bytes(), 2 * sizeof(AxisOutputs) + 4);
  EXPECT_EQ(image.inputs(1).data(), image.inputs(0).data() + sizeof(AxisInputs));
  EXPECT_EQ(image.outputs(2).data(), image.outputs(1).data() + 4);
  EXPECT_EQ(image.inputs(2).size(), sizeof(AxisInputs));
  EXPECT_THROW(put_pdo<AxisInputs>(image.inputs(1), AxisInputs{}), std::logic_error);
}

// The bridge's cyclic round on one drive, at the register level (DriveIo) and
// through the device interface: enable, follow a ramp, a fault and its reset.
class EveryProfile : public ::testing::TestWithParam<std::string> {};

TEST_P(EveryProfile, AxisDriveDeviceIsTheSameOnTheWireAsDriveIo) {
  const DriveProfile profile = load_drive_profile(kDrives + GetParam() + ".yaml");
  auto script = [](int k) {
    if (k < 12) return Goal::kEnable;
    if (k < 16) return Goal::kDisable;
    return Goal::kEnable;
  };
  TapLink a;
  a.inner.add_drive(3, profile, 12.5);
  ASSERT_TRUE(a.ensure_open(0.0));
  DriveIo io(profile, 3, a);
  LinkCounters ca;
  for (int k = 0; k < 24; ++k) {
    if (k == 8) a.inner.drive(3)->inject_fault(0x7305);
    double target = io.have_status() ? io.actual_mm() + 0.1 * k : 0.0;
    ASSERT_EQ(io.exchange(io.have_status() ? &target : nullptr, ca), TxResult::kOk);
    ASSERT_EQ(io.control(script(k), ca), TxResult::kOk);
  }

  TapLink b;
  b.inner.add_drive(3, profile, 12.5);
  ASSERT_TRUE(b.ensure_open(0.0));
  ModbusAxisDrive dev(profile, 3, b);
  ProcessImage image;
  const std::size_t slot = image.add(dev.layout());
  LinkCounters cb;
  for (int k = 0; k < 24; ++k) {
    if (k == 8) b.inner.drive(3)->inject_fault(0x7305);
    const auto last = get_pdo<AxisInputs>(image.inputs(slot));
    AxisOutputs out;
    out.write = last.valid;
    out.target_mm = last.valid ? last.actual_mm + 0.1 * k : 0.0;
    put_pdo(image.outputs(slot), out);
    ASSERT_EQ(dev.exchange(image.outputs(slot), image.inputs(slot), cb), TxResult::kOk);
    ASSERT_EQ(dev.control(script(k), cb), TxResult::kOk);
    const auto in = get_pdo<AxisInputs>(image.inputs(slot));
    EXPECT_EQ(in.statusword, dev.io().statusword());
    EXPECT_EQ(in.actual_mm, dev.io().actual_mm());
  }
  EXPECT_EQ(a.wire, b.wire);
  EXPECT_EQ(ca.transactions, cb.transactions);
  EXPECT_GT(a.wire.size(), 40u);
  EXPECT_TRUE(b.inner.drive(3)->follows());
  // Forgotten after a lost link: no status until the next good cycle.
  dev.forget(image.inputs(slot));
  EXPECT_FALSE(get_pdo<AxisInputs>(image.inputs(slot)).valid);
  EXPECT_FALSE(dev.io().have_status());
}

INSTANTIATE_TEST_SUITE_P(Shipped, EveryProfile, ::testing::Values("sim", "cia402_modbus", "leadshine_el"));

TEST(Device, AnAxisDriveAndAnIoModuleShareOneImageAndCycle) {
  const DriveProfile profile = load_drive_profile(kDrives + "sim.yaml");
  LoopbackLink link;
  link.add_drive(1, profile, 5.0);
  ASSERT_TRUE(link.ensure_open(0.0));
  ModbusAxisDrive axis(profile, 1, link);
  LoopbackIoDevice io;
  std::vector<Device*> devices{&axis, &io};
  ProcessImage image;
  for (Device* d : devices) image.add(d->layout());
  LinkCounters c;
  for (uint32_t k = 0; k < 10; ++k) {
    // The master's side of the cycle: each device's outputs into its slice.
    const auto a = get_pdo<AxisInputs>(image.inputs(0));
    put_pdo(image.outputs(0), AxisOutputs{a.valid, a.valid ? a.actual_mm + 0.5 : 0.0});
    put_pdo(image.outputs(1), 0xA0u + k);
    for (std::size_t i = 0; i < devices.size(); ++i) {
      ASSERT_EQ(devices[i]->exchange(image.outputs(i), image.inputs(i), c), TxResult::kOk);
      ASSERT_EQ(devices[i]->control(Goal::kEnable, c), TxResult::kOk);
    }
    if (k >= 1) {
      EXPECT_EQ(get_pdo<uint32_t>(image.inputs(1)), 0xA0u + k);
    }
  }
  EXPECT_TRUE(link.drive(1)->follows());
  EXPECT_GT(get_pdo<AxisInputs>(image.inputs(0)).actual_mm, 5.0);
  io.forget(image.inputs(1));
  EXPECT_EQ(get_pdo<uint32_t>(image.inputs(1)), 0u);
}

}  // namespace
}  // namespace cnc::drive
