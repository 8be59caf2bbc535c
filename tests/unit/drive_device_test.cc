// Devices as slices of a cyclic process image (common/drive/device.h): the slices of
// an image do not overlap; an axis drive behind the device interface puts the same
// register transactions on the wire, in the same order, as the register-level
// DriveIo it wraps; and a device that is no axis (a loopback I/O module,
// loopback_io_device.h) shares the image and the cycle with it. A spindle VFD
// (spindle_device.h, profile delta_vfd) against its emulator: the command and the
// first-order speed response through the image, a drive fault and its reset, a lost link.
#include <gtest/gtest.h>

#include <cerrno>
#include <cmath>
#include <string>
#include <vector>

#include "common/drive/axis_drive.h"
#include "common/drive/delta_vfd_profile.h"
#include "common/drive/device.h"
#include "common/drive/drive_io.h"
#include "common/drive/io_module_device.h"
#include "common/drive/loopback_io_device.h"
#include "common/drive/loopback_link.h"
#include "common/config/machine_config.h"
#include "common/drive/spindle_device.h"
#include "common/drive/vfd_emulator.h"

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
    // Appended piece by piece: GCC 12 sees a false overlap (-Wrestrict) in "..." + std::string&&.
    std::string s(op);
    s.append(" u").append(std::to_string(unit)).append(" @").append(std::to_string(addr));
    s.append(" n").append(std::to_string(n));
    for (int i = 0; v != nullptr && i < n; ++i) s.append(" ").append(std::to_string(v[i]));
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

// A link to one emulated VFD beside a loopback axis drive: requests for its unit go
// to the emulator, every other to the loopback; every transaction is written down.
class VfdLink final : public Link {
 public:
  VfdLink(const DriveProfile& p, const config::SpindleSimConfig& sim) : Link("vfd"), vfd(p, sim, 400.0) {}
  LoopbackLink axes;
  VfdEmulator vfd;
  static constexpr int kUnit = 4;
  std::vector<std::string> wire;
  bool reachable = true;

 private:
  void log(const char* op, int unit, int addr, int n) {
    std::string s(op);
    s.append(" u").append(std::to_string(unit)).append(" @").append(std::to_string(addr));
    s.append(" n").append(std::to_string(n));
    wire.push_back(s);
  }
  static int ex(int code) { return code ? EIO : 0; }
  static int err(TxResult r) { return r == TxResult::kOk ? 0 : EIO; }
  int do_open(std::string&) override { return reachable && axes.ensure_open(0.0) ? 0 : ECONNREFUSED; }
  void do_close() override {}
  int do_read(int unit, int addr, int n, uint16_t* dest) override {
    if (!reachable) return ECONNRESET;
    log("R", unit, addr, n);
    return unit == kUnit ? ex(vfd.read(addr, n, dest)) : err(axes.read_registers(unit, addr, n, dest, c_));
  }
  int do_write1(int unit, int addr, uint16_t value) override { return do_write(unit, addr, 1, &value); }
  int do_write(int unit, int addr, int n, const uint16_t* src) override {
    if (!reachable) return ECONNRESET;
    log("W", unit, addr, n);
    return unit == kUnit ? ex(vfd.write(addr, n, src)) : err(axes.write_registers(unit, addr, n, src, c_));
  }
  int do_write_read(int unit, int waddr, int wn, const uint16_t* src, int raddr, int rn, uint16_t* dest) override {
    if (!reachable) return ECONNRESET;
    log("WR", unit, waddr, wn);
    if (unit == kUnit) return EIO;  // the VFD has no function 23
    return err(axes.write_and_read(unit, waddr, wn, src, raddr, rn, dest, c_));
  }
  LinkCounters c_;
};

TEST(SpindleDevice, RefusesAProfileThatIsNoSpindleDrives) {
  const DriveProfile sim = load_drive_profile(kDrives + "sim.yaml");
  LoopbackLink link;
  EXPECT_THROW(SpindleDevice(sim, 4, link), std::invalid_argument);
  EXPECT_TRUE(is_spindle_profile(load_drive_profile(kDrives + "delta_vfd.yaml")));
  EXPECT_FALSE(is_spindle_profile(sim));
}

TEST(SpindleDevice, RunsBesideAnAxisDriveAndFollowsTheFirstOrderResponse) {
  const DriveProfile axis_profile = load_drive_profile(kDrives + "sim.yaml");
  const DriveProfile vfd_profile = load_drive_profile(kDrives + "delta_vfd.yaml");
  config::SpindleSimConfig sim;
  sim.time_constant_s = 0.5;
  VfdLink link(vfd_profile, sim);
  link.axes.add_drive(1, axis_profile, 0.0);
  ASSERT_TRUE(link.ensure_open(0.0));
  ModbusAxisDrive axis(axis_profile, 1, link);
  SpindleDevice spindle(vfd_profile, VfdLink::kUnit, link);
  EXPECT_EQ(spindle.layout().inputs, sizeof(SpindleInputs));
  ProcessImage image;
  const std::size_t a = image.add(axis.layout());
  const std::size_t s = image.add(spindle.layout());
  LinkCounters c;
  // 200 Hz forward (12000 rpm at 60 rpm/Hz), 1 ms cycles for 2 s.
  const double dt = 0.001;
  double hz_at_tau = 0;
  for (int k = 0; k < 2000; ++k) {
    put_pdo(image.outputs(a), AxisOutputs{});
    const auto last = get_pdo<SpindleInputs>(image.inputs(s));
    put_pdo(image.outputs(s), SpindleOutputs{last.valid, 1, 200.0});
    ASSERT_EQ(axis.exchange(image.outputs(a), image.inputs(a), c), TxResult::kOk);
    ASSERT_EQ(spindle.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
    ASSERT_EQ(spindle.control(Goal::kEnable, c), TxResult::kOk);
    link.vfd.step(dt);
    if (k == 500) hz_at_tau = get_pdo<SpindleInputs>(image.inputs(s)).output_hz;
  }
  // One write of command word and frequency (adjacent) and one read per cycle.
  EXPECT_EQ(link.wire[link.wire.size() - 2], "W u4 @8192 n2");
  EXPECT_EQ(link.wire.back(), "R u4 @8448 n5");
  const auto in = get_pdo<SpindleInputs>(image.inputs(s));
  EXPECT_TRUE(in.valid);
  EXPECT_TRUE(in.running);
  EXPECT_FALSE(in.reverse);
  EXPECT_EQ(in.error_code, 0);
  // After one time constant 63.2 % of the step (registers in 0.01 Hz; the first cycle only read).
  EXPECT_NEAR(hz_at_tau, 200.0 * (1 - std::exp(-1.0)), 0.6);
  EXPECT_NEAR(in.output_hz, 200.0 * (1 - std::exp(-4.0)), 0.6);
  EXPECT_TRUE(in.has_current);
  EXPECT_GT(in.current_a, 0.9);  // the load figure: 2 A at 400 Hz in proportion, plus the inertial part
  // Reverse: the output passes through zero and turns negative.
  bool seen_forward_while_reversing = false;
  for (int k = 0; k < 4000; ++k) {
    put_pdo(image.outputs(s), SpindleOutputs{true, -1, 100.0});
    ASSERT_EQ(spindle.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
    link.vfd.step(dt);
    const auto r = get_pdo<SpindleInputs>(image.inputs(s));
    if (k > 1 && r.output_hz > 50) seen_forward_while_reversing = !r.reverse;
  }
  EXPECT_TRUE(seen_forward_while_reversing) << "the output's own direction, not the commanded one";
  EXPECT_TRUE(get_pdo<SpindleInputs>(image.inputs(s)).reverse);
  EXPECT_NEAR(get_pdo<SpindleInputs>(image.inputs(s)).output_hz, -100.0, 0.6);
}

TEST(SpindleDevice, AFaultStopsTheDriveUntilItsResetAndALostLinkIsForgotten) {
  const DriveProfile vfd_profile = load_drive_profile(kDrives + "delta_vfd.yaml");
  VfdLink link(vfd_profile, config::SpindleSimConfig{});
  ASSERT_TRUE(link.ensure_open(0.0));
  SpindleDevice spindle(vfd_profile, VfdLink::kUnit, link);
  ProcessImage image;
  const std::size_t s = image.add(spindle.layout());
  LinkCounters c;
  auto cycle = [&](Goal goal) {
    put_pdo(image.outputs(s), SpindleOutputs{true, 1, 50.0});
    ASSERT_EQ(spindle.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
    ASSERT_EQ(spindle.control(goal, c), TxResult::kOk);
    link.vfd.step(0.01);
  };
  for (int k = 0; k < 10; ++k) cycle(Goal::kEnable);
  EXPECT_TRUE(link.vfd.running());
  link.vfd.inject_fault(0x0007);
  cycle(Goal::kEnable);
  EXPECT_EQ(get_pdo<SpindleInputs>(image.inputs(s)).error_code, 0x0007);
  EXPECT_FALSE(get_pdo<SpindleInputs>(image.inputs(s)).running);
  cycle(Goal::kEnable);
  EXPECT_FALSE(link.vfd.running()) << "a run command does not clear the fault";
  const size_t before = link.wire.size();
  cycle(Goal::kFaultReset);  // the reset register written once, after the read
  EXPECT_EQ(link.wire.back(), "W u4 @8194 n1");
  EXPECT_EQ(link.wire.size(), before + 3);
  cycle(Goal::kFaultReset);
  EXPECT_EQ(get_pdo<SpindleInputs>(image.inputs(s)).error_code, 0);
  EXPECT_TRUE(link.vfd.running());
  cycle(Goal::kFaultReset);
  EXPECT_EQ(link.wire.back(), "R u4 @8448 n5") << "no reset written without a fault";
  // A lost link: the exchange fails, the inputs keep the last good cycle until forgotten.
  link.reachable = false;
  put_pdo(image.outputs(s), SpindleOutputs{true, 1, 50.0});
  EXPECT_EQ(spindle.exchange(image.outputs(s), image.inputs(s), c), TxResult::kLinkLost);
  EXPECT_TRUE(get_pdo<SpindleInputs>(image.inputs(s)).valid);
  spindle.forget(image.inputs(s));
  EXPECT_FALSE(get_pdo<SpindleInputs>(image.inputs(s)).valid);
}

// An I/O module: three coils (a run of two and a lone one), a discrete input and an
// input register. The first exchange after (re)opening only reads; a coil is written
// only when its read-back differs, a run in one transaction; a coil changed behind
// the master's back is written again.
TEST(IoModuleDevice, WritesOnlyTheCoilsThatDifferAndReadsEachTableOnce) {
  config::IoConfig io;
  io.enabled = true;
  io.modules.push_back({"m", config::DriveConfig{}});
  io.modules[0].link.unit_id = 5;
  auto point = [&](const char* name, config::IoKind k, int addr, double scale = 1) {
    config::IoPointConfig p;
    p.name = name;
    p.kind = k;
    p.address = addr;
    p.scale = scale;
    io.points.push_back(p);
  };
  point("a", config::IoKind::kCoil, 4);
  point("b", config::IoKind::kCoil, 3);
  point("c", config::IoKind::kCoil, 9);
  point("in", config::IoKind::kDiscreteInput, 2);
  point("level", config::IoKind::kInputRegister, 7);
  LoopbackLink link;
  link.add_io_module(5, io, 0);
  ASSERT_TRUE(link.ensure_open(0.0));
  IoModuleDevice dev(io, 0, link);
  ProcessImage image;
  const size_t s = image.add(dev.layout());
  LinkCounters c;
  IoEmulator& m = *link.io_module(5);
  m.set_point("in", 1);
  m.set_point("level", 1234);
  IoModuleOutputs out;
  out.coils = 0b111;
  put_pdo(image.outputs(s), out);  // write false: only reads
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  EXPECT_EQ(dev.last_transactions(), 3) << "coils, discrete inputs, input registers";
  IoModuleInputs in = get_pdo<IoModuleInputs>(image.inputs(s));
  EXPECT_TRUE(in.valid);
  EXPECT_EQ(in.coils, 0u);
  EXPECT_EQ(in.discrete, 1u);
  EXPECT_EQ(in.input_registers[0], 1234);
  out.write = true;
  put_pdo(image.outputs(s), out);
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  EXPECT_EQ(dev.last_transactions(), 5) << "the run 3-4 in one write, coil 9 in another, three reads";
  EXPECT_EQ(m.coil(3), 1);
  EXPECT_EQ(m.coil(4), 1);
  EXPECT_EQ(m.coil(9), 1);
  EXPECT_EQ(get_pdo<IoModuleInputs>(image.inputs(s)).coils, 0b111u) << "read back in the same exchange";
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  EXPECT_EQ(dev.last_transactions(), 3) << "nothing differs: no write";
  m.set_point("c", 0);  // behind the master's back
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  EXPECT_EQ(m.coil(9), 1) << "written again";
  out.coils = 0b001;  // b (address 3) off: the run 3-4 written
  put_pdo(image.outputs(s), out);
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  EXPECT_EQ(m.coil(3), 0);
  EXPECT_EQ(m.coil(4), 1);
  EXPECT_EQ(m.coil(9), 0);
  EXPECT_EQ(c.exceptions + c.timeouts + c.other_errors, 0);
  dev.forget(image.inputs(s));
  EXPECT_FALSE(get_pdo<IoModuleInputs>(image.inputs(s)).valid);
}

}  // namespace
}  // namespace cnc::drive
