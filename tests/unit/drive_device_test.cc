// Devices as slices of a cyclic process image (common/drive/device.h): the slices of
// an image do not overlap; an axis drive behind the device interface puts the same
// register transactions on the wire, in the same order, as the register-level
// DriveIo it wraps; and a device that is no axis (a loopback I/O module,
// loopback_io_device.h) shares the image and the cycle with it. A spindle VFD
// (spindle_device.h, profile delta_vfd) against its emulator: the command and the
// first-order speed response through the image, a drive fault and its reset, a lost link.
// A Huanyang VFD (huanyang_frame.h, huanyang_device.h): its frames with their CRC, the
// replies a master must refuse (short, malformed, none) named, the device against the
// same emulator speaking the Huanyang protocol, its PD parameters checked. The
// encoder's 32-bit counter unwrapped (encoder_counter.h), signed and not, both ways; a
// servo spindle (profile cia402_spindle) enabled through the CiA-402 state machine,
// turning at its signed target velocity, its encoder counting across the wrap, its
// fault reset; the encoder's sample dated on a serial line.
#include <gtest/gtest.h>

#include <cerrno>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "common/drive/axis_drive.h"
#include "common/drive/delta_vfd_profile.h"
#include "common/drive/device.h"
#include "common/drive/drive_io.h"
#include "common/drive/encoder_counter.h"
#include "common/drive/huanyang_device.h"
#include "common/drive/huanyang_frame.h"
#include "common/drive/io_module_device.h"
#include "common/drive/loopback_io_device.h"
#include "common/drive/loopback_link.h"
#include "common/config/machine_config.h"
#include "common/config/yaml_reader.h"
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

TEST(EncoderCounter, RunsOnAcrossThe32BitCountersWrapBothWays) {
  EncoderCounter u;  // an unsigned field: 0 .. 2^32 - 1
  EXPECT_FALSE(u.known());
  EXPECT_EQ(u.update(0xFFFFFF00), 0xFFFFFF00) << "the first read is the counter as its field reads it";
  EXPECT_EQ(u.update(0x00000100), int64_t{0xFFFFFF00} + 512);
  EXPECT_EQ(u.update(0xFFFFFF00), int64_t{0xFFFFFF00}) << "and back";
  EncoderCounter s;  // a signed field: -2^31 .. 2^31 - 1
  EXPECT_EQ(s.update(-5), -5);
  EXPECT_EQ(s.update(0x7FFFFF00), int64_t{0x7FFFFF00} - 5 + 5);
  EXPECT_EQ(s.update(-0x7FFFFF00), int64_t{0x7FFFFF00} + 512) << "past +2^31 the signed counter reads negative";
  EXPECT_EQ(s.update(0x7FFFFF00), int64_t{0x7FFFFF00});
  // Many wraps at speed: 10,000 rpm at 2^24 counts per revolution read every 1 ms
  // (2.8e6 counts a read, the counter wraps every 1.5 s) for 10 s.
  EncoderCounter f;
  const int64_t step = 2796203;
  int64_t truth = 0;
  for (int k = 0; k < 10000; ++k, truth += step)
    ASSERT_EQ(f.update(static_cast<int32_t>(static_cast<uint32_t>(static_cast<uint64_t>(truth)))), truth);
}

// A servo spindle (config/drives/cia402_spindle.yaml) on the loopback link, its
// transactions written down (TapLink), its encoder counting on the test's clock.
struct ServoSpindle {
  explicit ServoSpindle(double tau_s = 0.05) : profile(load_drive_profile(kDrives + "cia402_spindle.yaml")) {
    config::SpindleSimConfig sim;
    sim.time_constant_s = tau_s;
    link.inner.add_vfd(kUnit, profile, sim, 100.0, 60.0, 131072);
    link.inner.set_clock([this] { return t; });
    EXPECT_TRUE(link.ensure_open(0.0));
    dev = std::make_unique<SpindleDevice>(profile, kUnit, link);
    slot = image.add(dev->layout());
  }
  static constexpr int kUnit = 4;
  // One cycle of 1 ms: the command out, the answer in, a state machine step.
  SpindleInputs cycle(int direction, double hz, Goal goal = Goal::kEnable) {
    const auto last = get_pdo<SpindleInputs>(image.inputs(slot));
    put_pdo(image.outputs(slot), SpindleOutputs{last.valid, static_cast<int8_t>(direction), hz});
    EXPECT_EQ(dev->exchange(image.outputs(slot), image.inputs(slot), c), TxResult::kOk);
    EXPECT_EQ(dev->control(goal, c), TxResult::kOk);
    t += 0.001;
    return get_pdo<SpindleInputs>(image.inputs(slot));
  }
  VfdEmulator& drive() { return *link.inner.vfd(kUnit); }
  DriveProfile profile;
  TapLink link;
  std::unique_ptr<SpindleDevice> dev;
  ProcessImage image;
  std::size_t slot = 0;
  LinkCounters c;
  double t = 0;
};

TEST(SpindleDevice, AServoSpindleEnablesThroughTheCia402StateMachineAndTurnsAtItsTargetVelocity) {
  ServoSpindle sp;
  EXPECT_TRUE(is_spindle_profile(sp.profile));
  EXPECT_EQ(sp.dev->reads(), 2) << "error code and statusword; position to velocity (read_gap_max 6)";
  SpindleInputs in = sp.cycle(0, 0, Goal::kDisable);
  EXPECT_TRUE(in.valid);
  EXPECT_FALSE(in.running) << "switch on disabled";
  EXPECT_EQ(sp.link.wire.size(), 2u) << "the first exchange only reads";
  for (int k = 0; k < 6; ++k) in = sp.cycle(0, 0);
  EXPECT_TRUE(in.running) << "operation enabled in profile velocity mode";
  // Mode 3 first, then shutdown, switch on, enable operation: one write per cycle.
  std::vector<std::string> steps;
  for (const auto& w : sp.link.wire)
    if (w.rfind("W1", 0) == 0) steps.push_back(w);
  ASSERT_EQ(steps.size(), 4u);
  EXPECT_EQ(steps[0], "W1 u4 @24672 n1 3");   // 0x6060 = 3
  EXPECT_EQ(steps[1], "W1 u4 @24640 n1 6");   // 0x6040: shutdown
  EXPECT_EQ(steps[2], "W1 u4 @24640 n1 7");   // switch on
  EXPECT_EQ(steps[3], "W1 u4 @24640 n1 15");  // enable operation
  // Each cycle: the target velocity written with the first read (function 23), then one read.
  sp.link.wire.clear();
  in = sp.cycle(1, 10.0);
  ASSERT_EQ(sp.link.wire.size(), 3u);
  EXPECT_EQ(sp.link.wire[0], "WR u4 @24831 n2 0 20");  // 0x60FF = 10 x 131072 = 0x140000, low word first
  EXPECT_EQ(sp.link.wire[1], "  R u4 @24639 n3");
  EXPECT_EQ(sp.link.wire[2], "R u4 @24676 n10");
  // 600 rpm clockwise: the velocity actual value and the encoder counting up.
  for (int k = 0; k < 1000; ++k) in = sp.cycle(1, 10.0);
  EXPECT_NEAR(in.output_hz, 10.0, 1e-5);
  EXPECT_FALSE(in.reverse);
  EXPECT_TRUE(in.has_position);
  EXPECT_NEAR(static_cast<double>(in.position_counts) / 131072, sp.drive().revolutions(), 1e-4);
  EXPECT_NEAR(sp.drive().revolutions(), 10.0 * 1.0, 0.02) << "1 s at 10 rev/s on the link's clock";
  EXPECT_EQ(in.sample_age_s, 0.0) << "no serial line";
  // Counterclockwise: a negative target velocity, the counter counting down.
  const int64_t before = in.position_counts;
  for (int k = 0; k < 500; ++k) in = sp.cycle(-1, 5.0);
  EXPECT_NEAR(in.output_hz, -5.0, 1e-5);
  EXPECT_TRUE(in.reverse);
  EXPECT_LT(in.position_counts, before);
  // Stopped: at velocity 0, still enabled (it holds).
  for (int k = 0; k < 10; ++k) in = sp.cycle(0, 0);
  EXPECT_TRUE(in.running);
  EXPECT_NEAR(in.output_hz, 0.0, 1e-9);
  // Disabled: shutdown.
  sp.link.wire.clear();
  in = sp.cycle(0, 0, Goal::kDisable);
  EXPECT_EQ(sp.link.wire.back(), "W1 u4 @24640 n1 6");
  in = sp.cycle(0, 0, Goal::kDisable);
  EXPECT_FALSE(in.running);
}

TEST(SpindleDevice, AServoSpindlesFaultIsResetByTheControlwordsEdge) {
  ServoSpindle sp;
  SpindleInputs in;
  for (int k = 0; k < 20; ++k) in = sp.cycle(1, 10.0);
  ASSERT_TRUE(in.running);
  sp.drive().inject_fault(0x7310);
  sp.link.wire.clear();
  in = sp.cycle(0, 0, Goal::kDisable);  // the bridge's goal for a drive at fault, until a reset is asked for
  EXPECT_TRUE(in.fault);
  EXPECT_FALSE(in.running);
  EXPECT_EQ(in.error_code, 0x7310);
  in = sp.cycle(0, 0, Goal::kDisable);
  for (const auto& w : sp.link.wire) EXPECT_NE(w.rfind("W1", 0), 0u) << "nothing resets it unasked: " << w;
  sp.link.wire.clear();
  in = sp.cycle(1, 10.0, Goal::kFaultReset);
  EXPECT_EQ(sp.link.wire.back(), "W1 u4 @24640 n1 128");
  in = sp.cycle(1, 10.0, Goal::kFaultReset);
  EXPECT_FALSE(in.fault);
  EXPECT_EQ(in.error_code, 0) << "not at fault: its last code is not reported";
  for (int k = 0; k < 6; ++k) in = sp.cycle(1, 10.0);
  EXPECT_TRUE(in.running) << "enabled again";
}

TEST(SpindleDevice, TheEncoderRunsOnAcrossTheCountersWrap) {
  ServoSpindle sp;
  // 2^31 counts are 16384 revolutions of a 17-bit encoder: start 5 revolutions short of
  // the signed counter's wrap and turn 10 at 600 rpm.
  sp.drive().set_revolutions(16384.0 - 5);
  SpindleInputs in = sp.cycle(0, 0);
  const int64_t start = in.position_counts;
  EXPECT_EQ(start, (int64_t{16384} - 5) * 131072);
  for (int k = 0; k < 1000; ++k) in = sp.cycle(1, 10.0);
  EXPECT_GT(sp.drive().revolutions(), 16384.0 + 4) << "past the wrap";
  EXPECT_NEAR(static_cast<double>(in.position_counts) / 131072, sp.drive().revolutions(), 1e-4);
  uint16_t regs[2];
  ASSERT_EQ(sp.drive().read(0x6064, 2, regs), 0);
  EXPECT_LT(static_cast<int32_t>(regs[0] | (uint32_t{regs[1]} << 16)), 0) << "the counter itself has wrapped";
}

TEST(SpindleDevice, OnASerialLineTheEncodersSampleIsDatedBeforeTheReply) {
  ServoSpindle sp;
  sp.link.set_byte_time_s(10.0 / 115200);  // 8N1 at 115200 baud
  const SpindleInputs in = sp.cycle(0, 0);
  // The counter's read (0x6064-0x606D, 10 registers): 3.5 characters of silence and a
  // reply of 5 + 20 bytes after the drive sampled it.
  EXPECT_NEAR(in.sample_age_s, (3.5 + 5 + 20) * 10.0 / 115200, 1e-12);
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

// Analog outputs (M67/M68): a holding register that is an output is written (function
// 6) only when its read-back differs; one that is not (an analog input) never is.
TEST(IoModuleDevice, WritesTheOutputRegistersThatDiffer) {
  config::IoConfig io;
  io.enabled = true;
  io.modules.push_back({"m", config::DriveConfig{}});
  io.modules[0].link.unit_id = 5;
  for (const auto& [name, addr] : {std::pair{"valve", 2}, std::pair{"speed", 3}, std::pair{"gauge", 6}}) {
    config::IoPointConfig p;
    p.name = name;
    p.kind = config::IoKind::kHoldingRegister;
    p.address = addr;
    io.points.push_back(p);
  }
  LoopbackLink link;
  link.add_io_module(5, io, 0);
  ASSERT_TRUE(link.ensure_open(0.0));
  IoModuleDevice dev(io, 0, link);
  ProcessImage image;
  const size_t s = image.add(dev.layout());
  LinkCounters c;
  IoEmulator& m = *link.io_module(5);
  m.set_point("gauge", 77);
  IoModuleOutputs out;
  out.holding_write = 0b011;  // valve and speed are outputs, gauge is not
  out.holding = {425, 65535, 9};
  put_pdo(image.outputs(s), out);
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  EXPECT_EQ(dev.last_transactions(), 1) << "the first exchange only reads";
  out.write = true;
  put_pdo(image.outputs(s), out);
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  EXPECT_EQ(dev.last_transactions(), 3) << "two registers written, one read";
  int raw = 0;
  ASSERT_TRUE(m.point("valve", &raw));
  EXPECT_EQ(raw, 425);
  ASSERT_TRUE(m.point("speed", &raw));
  EXPECT_EQ(raw, 65535);
  ASSERT_TRUE(m.point("gauge", &raw));
  EXPECT_EQ(raw, 77) << "not an output: never written";
  const IoModuleInputs in = get_pdo<IoModuleInputs>(image.inputs(s));
  EXPECT_EQ(in.holding_registers[0], 425) << "read back in the same exchange";
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  EXPECT_EQ(dev.last_transactions(), 1) << "nothing differs: no write";
  m.set_point("valve", 0);  // behind the master's back
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  ASSERT_TRUE(m.point("valve", &raw));
  EXPECT_EQ(raw, 425) << "written again";
  EXPECT_EQ(c.exceptions + c.timeouts + c.other_errors, 0);
}

namespace hy = huanyang;

TEST(HuanyangFrame, EncodesWithModbusCrcLowByteFirstAndFramesByItsLengthByte) {
  // Modbus RTU's CRC on its textbook request 01 03 00 00 00 01: 0x0A84, on the wire 84 0A.
  const uint8_t modbus[] = {0x01, 0x03, 0x00, 0x00, 0x00, 0x01};
  EXPECT_EQ(cnc::drive::rtu_crc16(modbus, 6), 0x0A84);
  uint8_t f[hy::kMaxFrame];
  const uint8_t freq[] = {0x5D, 0xC0};  // 240.00 Hz in 0.01 Hz
  ASSERT_EQ(hy::encode(0x01, hy::kWriteFrequency, freq, 2, f), 7);
  EXPECT_EQ(f[0], 0x01);
  EXPECT_EQ(f[1], 0x05);
  EXPECT_EQ(f[2], 0x02);
  EXPECT_EQ(f[3], 0x5D);
  EXPECT_EQ(f[4], 0xC0);
  const uint16_t crc = cnc::drive::rtu_crc16(f, 5);
  EXPECT_EQ(f[5], crc & 0xFF);
  EXPECT_EQ(f[6], crc >> 8);
  EXPECT_TRUE(hy::crc_ok(f, 7));
  f[4] ^= 1;
  EXPECT_FALSE(hy::crc_ok(f, 7));
  EXPECT_EQ(hy::frame_length(f, 2), 0);
  EXPECT_EQ(hy::frame_length(f, 3), 7);
  const uint8_t bad_len[] = {0x01, 0x04, 0x00};
  EXPECT_EQ(hy::frame_length(bad_len, 3), -1);
  EXPECT_EQ(hy::be16(freq), 24000);
}

TEST(HuanyangFrame, RefusesShortMalformedAndForeignRepliesAndNamesThem) {
  uint8_t req[hy::kMaxFrame], rep[hy::kMaxFrame];
  const uint8_t index = 1;
  const int req_n = hy::encode(4, hy::kReadControlStatus, &index, 1, req);
  EXPECT_EQ(req_n, 6);
  const uint8_t good[] = {1, 0x27, 0x10};  // index 1: 100.00 Hz
  const int n = hy::encode(4, hy::kReadControlStatus, good, 3, rep);
  EXPECT_EQ(n, 8);
  EXPECT_EQ(hy::check_reply(req, rep, n), hy::Check::kOk);
  EXPECT_EQ(hy::check_reply(req, rep, 0), hy::Check::kNone);
  EXPECT_EQ(hy::check_reply(req, rep, 2), hy::Check::kShort);
  EXPECT_EQ(hy::check_reply(req, rep, 5), hy::Check::kShort);
  char text[96];
  hy::describe(hy::Check::kShort, req, rep, 5, text, sizeof text);
  EXPECT_STREQ(text, "short reply from unit 4 to function 0x04: 5 of 8 bytes");
  hy::describe(hy::Check::kNone, req, rep, 0, text, sizeof text);
  EXPECT_STREQ(text, "no reply from unit 4 to function 0x04");
  rep[5] ^= 0xFF;
  EXPECT_EQ(hy::check_reply(req, rep, n), hy::Check::kCrc);
  const uint8_t other_index[] = {2, 0, 15};
  hy::encode(4, hy::kReadControlStatus, other_index, 3, rep);
  EXPECT_EQ(hy::check_reply(req, rep, n), hy::Check::kEcho);
  hy::encode(5, hy::kReadControlStatus, good, 3, rep);
  EXPECT_EQ(hy::check_reply(req, rep, n), hy::Check::kUnit);
  hy::encode(4, hy::kReadFunctionData, good, 3, rep);
  EXPECT_EQ(hy::check_reply(req, rep, n), hy::Check::kFunction);
  const uint8_t two[] = {1, 0x27};
  const int m = hy::encode(4, hy::kReadControlStatus, two, 2, rep);
  EXPECT_EQ(hy::check_reply(req, rep, m), hy::Check::kLength);
  hy::describe(hy::Check::kLength, req, rep, m, text, sizeof text);
  EXPECT_STREQ(text, "malformed reply from unit 4 to function 0x04: 2 data bytes");
}

// A serial line with one Huanyang VFD (unit 4) on it: each frame goes to the
// emulator, its function code is written down; a reply can be cut short, its CRC
// spoiled or withheld.
class HyLink final : public Link {
 public:
  HyLink(const DriveProfile& p, const config::SpindleSimConfig& sim) : Link("hy"), vfd(p, sim, 400.0, 60.0) {}
  VfdEmulator vfd;
  static constexpr int kUnit = 4;
  std::vector<int> functions;
  enum class Damage { kNone, kShort, kCrc, kSilent } damage = Damage::kNone;

 private:
  int do_open(std::string&) override { return 0; }
  void do_close() override {}
  int do_read(int, int, int, uint16_t*) override { return EIO; }
  int do_write1(int, int, uint16_t) override { return EIO; }
  int do_write(int, int, int, const uint16_t*) override { return EIO; }
  int do_write_read(int, int, int, const uint16_t*, int, int, uint16_t*) override { return EIO; }
  int do_frame(const uint8_t* request, int n, uint8_t* reply, int, int* got) override {
    functions.push_back(request[1]);
    *got = request[0] == kUnit ? vfd.answer_frame(request, n, reply) : 0;
    if (damage == Damage::kShort) *got -= 3;
    if (damage == Damage::kCrc) reply[*got - 1] ^= 0x5A;
    if (damage == Damage::kSilent) *got = 0;
    return 0;
  }
};

TEST(HuanyangSpindle, ReadsItsSetupThenCommandsAndFollowsTheFirstOrderResponse) {
  const DriveProfile p = load_drive_profile(kDrives + "huanyang.yaml");
  EXPECT_TRUE(is_spindle_profile(p));
  LoopbackLink loopback;
  EXPECT_THROW(SpindleDevice(p, 4, loopback), std::invalid_argument);
  config::SpindleSimConfig sim;
  sim.time_constant_s = 0.5;
  HyLink link(p, sim);
  ASSERT_TRUE(link.ensure_open(0.0));
  std::unique_ptr<Device> dev = make_spindle_device(p, HyLink::kUnit, link, 400.0, 60.0);
  ProcessImage image;
  const std::size_t s = image.add(dev->layout());
  LinkCounters c;
  // The first exchange only reads: PD001, PD002, PD005, PD144, then output frequency and current.
  put_pdo(image.outputs(s), SpindleOutputs{false, 0, 0.0});
  ASSERT_EQ(dev->exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  EXPECT_EQ(link.functions, (std::vector<int>{1, 1, 1, 1, 4, 4}));
  EXPECT_STREQ(get_pdo<SpindleInputs>(image.inputs(s)).setup_error.data(), "");
  // 200 Hz forward (12000 rpm at 60 rpm/Hz), 1 ms cycles for 2 s: the frequency once, then command and reads.
  double hz_at_tau = 0;
  for (int k = 0; k < 2000; ++k) {
    link.functions.clear();
    put_pdo(image.outputs(s), SpindleOutputs{true, 1, 200.0});
    ASSERT_EQ(dev->exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
    if (k == 0) {
      EXPECT_EQ(link.functions, (std::vector<int>{5, 3, 4, 4}));
    }
    link.vfd.step(0.001);
    if (k == 500) hz_at_tau = get_pdo<SpindleInputs>(image.inputs(s)).output_hz;
  }
  EXPECT_EQ(link.functions, (std::vector<int>{3, 4, 4}));
  EXPECT_NEAR(link.vfd.command_hz(), 200.0, 1e-9);
  const auto in = get_pdo<SpindleInputs>(image.inputs(s));
  EXPECT_TRUE(in.valid);
  EXPECT_TRUE(in.running);
  EXPECT_FALSE(in.reverse);
  EXPECT_EQ(in.error_code, 0);
  EXPECT_NEAR(hz_at_tau, 200.0 * (1 - std::exp(-1.0)), 0.6);  // 63.2 % after one time constant (0.01 Hz counts)
  EXPECT_NEAR(in.output_hz, 200.0 * (1 - std::exp(-4.0)), 0.6);
  EXPECT_TRUE(in.has_current);
  EXPECT_GT(in.current_a, 0.9);
  // Reverse at 100 Hz: the output passes through zero and turns negative, its sign from the status byte.
  for (int k = 0; k < 4000; ++k) {
    put_pdo(image.outputs(s), SpindleOutputs{true, -1, 100.0});
    ASSERT_EQ(dev->exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
    link.vfd.step(0.001);
  }
  EXPECT_TRUE(get_pdo<SpindleInputs>(image.inputs(s)).reverse);
  EXPECT_NEAR(get_pdo<SpindleInputs>(image.inputs(s)).output_hz, -100.0, 0.6);
  // Stop: the command byte 0x08, the drive runs down.
  for (int k = 0; k < 4000; ++k) {
    put_pdo(image.outputs(s), SpindleOutputs{true, 0, 0.0});
    ASSERT_EQ(dev->exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
    link.vfd.step(0.001);
  }
  EXPECT_FALSE(link.vfd.running());
  EXPECT_FALSE(get_pdo<SpindleInputs>(image.inputs(s)).running);
  EXPECT_NEAR(get_pdo<SpindleInputs>(image.inputs(s)).output_hz, 0.0, 0.6);
}

TEST(HuanyangSpindle, NamesThePdParameterThatIsNotSetForTheLink) {
  const DriveProfile p = load_drive_profile(kDrives + "huanyang.yaml");
  auto setup = [&](int pd, uint16_t value) {
    HyLink link(p, config::SpindleSimConfig{});
    link.vfd.set_pd(pd, value);
    EXPECT_TRUE(link.ensure_open(0.0));
    HuanyangSpindleDevice dev(p, HyLink::kUnit, link, 400.0, 60.0);
    ProcessImage image;
    const std::size_t s = image.add(dev.layout());
    LinkCounters c;
    put_pdo(image.outputs(s), SpindleOutputs{false, 0, 0.0});
    EXPECT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
    return std::string(get_pdo<SpindleInputs>(image.inputs(s)).setup_error.data());
  };
  EXPECT_EQ(setup(1, 0), "the VFD takes its run command (PD001 = 0) or frequency (PD002 = 2) elsewhere: both must be 2 "
                         "(the communication port)");
  EXPECT_EQ(setup(5, 30000), "spindle.max_rpm needs 400.00 Hz, the VFD's max frequency (PD005) is 300.00 Hz");
  EXPECT_EQ(setup(144, 2880), "the VFD's rated speed (PD144) is 2880 rpm at 50 Hz, 57.60 rpm/Hz; spindle.rpm_per_hz is 60");
  EXPECT_EQ(setup(144, 3000), "");
}

TEST(HuanyangSpindle, AShortMalformedOrMissingReplyFailsTheExchangeNamingIt) {
  const DriveProfile p = load_drive_profile(kDrives + "huanyang.yaml");
  HyLink link(p, config::SpindleSimConfig{});
  ASSERT_TRUE(link.ensure_open(0.0));
  HuanyangSpindleDevice dev(p, HyLink::kUnit, link, 400.0, 60.0);
  ProcessImage image;
  const std::size_t s = image.add(dev.layout());
  LinkCounters c;
  put_pdo(image.outputs(s), SpindleOutputs{false, 0, 0.0});
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  put_pdo(image.outputs(s), SpindleOutputs{true, 1, 100.0});
  ASSERT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
  const auto good = get_pdo<SpindleInputs>(image.inputs(s));
  link.damage = HyLink::Damage::kShort;
  EXPECT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOther);
  EXPECT_EQ(link.last_error(), "Invalid data: short reply from unit 4 to function 0x03: 3 of 6 bytes");
  link.damage = HyLink::Damage::kCrc;
  EXPECT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kCrc);
  EXPECT_EQ(c.crc_errors, 1);
  EXPECT_NE(link.last_error().find("reply from unit 4 to function 0x03: 6 bytes, CRC wrong"), std::string::npos)
      << link.last_error();
  link.damage = HyLink::Damage::kSilent;
  EXPECT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kTimeout);
  EXPECT_EQ(c.timeouts, 1);
  EXPECT_NE(link.last_error().find("no reply from unit 4 to function 0x03"), std::string::npos) << link.last_error();
  // The inputs keep the last good cycle.
  EXPECT_EQ(get_pdo<SpindleInputs>(image.inputs(s)).output_hz, good.output_hz);
  link.damage = HyLink::Damage::kNone;
  EXPECT_EQ(dev.exchange(image.outputs(s), image.inputs(s), c), TxResult::kOk);
}

TEST(HuanyangSpindle, AProfileWithoutItsSectionOrWithItForAnotherMachineIsRefused) {
  const std::string head = "name: hy\nstate_machine: huanyang\n";
  try {
    parse_drive_profile(head, "hy.yaml");
    ADD_FAILURE() << "no huanyang: section accepted";
  } catch (const config::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("huanyang"), std::string::npos) << e.what();
  }
  try {
    parse_drive_profile(head + "huanyang: {output_frequency_index: 1}\n", "hy.yaml");
    ADD_FAILURE() << "a section without its keys accepted";
  } catch (const config::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("huanyang.output_current_index"), std::string::npos) << e.what();
  }
  EXPECT_THROW(parse_drive_profile("name: d\nstate_machine: sim\nhuanyang: {}\n", "d.yaml"), config::ConfigError);
}

}  // namespace
}  // namespace cnc::drive
