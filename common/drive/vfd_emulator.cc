#include "common/drive/vfd_emulator.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/drive/delta_vfd_profile.h"
#include "common/drive/huanyang_frame.h"
#include "common/drive/huanyang_profile.h"

namespace cnc::drive {

VfdEmulator::VfdEmulator(const DriveProfile& profile, const config::SpindleSimConfig& sim, double max_hz,
                         double rpm_per_hz, int64_t counts_per_rev)
    : profile_(profile), logic_(profile_logic(profile)), sim_(sim), max_hz_(max_hz),
      base_(profile.first_address()), count_(profile.end_address() - profile.first_address()),
      counts_per_rev_(counts_per_rev), cia402_(profile.state_machine == "cia402_velocity"),
      hy_(profile.huanyang.present), rpm_per_hz_(rpm_per_hz) {
  map_ = modbus_mapping_new_start_address(0, 0, 0, 0, static_cast<unsigned>(base_), static_cast<unsigned>(count_), 0, 0);
  if (map_ == nullptr) throw std::runtime_error("modbus_mapping_new_start_address failed");
  logic_.drive_power_up(drive_);
  for (int i = 0; i < count_; ++i) map_->tab_registers[i] = 0;
  if (hy_) {
    // Set up for the link (LinuxCNC's hy_vfd documents the same): run and frequency
    // from the communication port, the max frequency and the rated rpm of the motor.
    const HuanyangMap& h = profile_.huanyang;
    const auto at = [&](int pd) -> uint16_t& { return pd_[static_cast<size_t>(pd)]; };
    at(h.run_source_pd) = static_cast<uint16_t>(h.source_link);
    at(h.frequency_source_pd) = static_cast<uint16_t>(h.source_link);
    at(h.max_frequency_pd) = static_cast<uint16_t>(std::lround(max_hz * h.frequency_scale));
    at(h.rated_rpm_pd) = static_cast<uint16_t>(std::lround(rpm_per_hz * h.rated_rpm_hz));
  }
  refresh();
}

VfdEmulator::~VfdEmulator() { modbus_mapping_free(map_); }

int VfdEmulator::read(int addr, int n, uint16_t* dest) const {
  if (n < 1 || n > MODBUS_MAX_READ_REGISTERS) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
  if (addr < base_ || addr + n > base_ + count_) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
  for (int i = 0; i < n; ++i) dest[i] = *reg(addr + i);
  return 0;
}

int VfdEmulator::write(int addr, int n, const uint16_t* src) {
  if (n < 1 || n > MODBUS_MAX_WRITE_REGISTERS) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
  if (addr < base_ || addr + n > base_ + count_) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
  for (int i = 0; i < n; ++i) *reg(addr + i) = src[i];
  after_write(addr, n);
  return 0;
}

void VfdEmulator::after_write(int addr, int n) {
  for (Role role : {Role::kMode, Role::kControlword, Role::kFaultReset}) {
    const Field& f = profile_.field(role);
    if (!f.present() || f.address >= addr + n || f.end() <= addr) continue;
    logic_.drive_write(drive_, role, *reg(f.address), profile_);
    if (role == Role::kFaultReset) *reg(f.address) = 0;  // the drive clears the reset bit
    if (role == Role::kMode && profile_.has(Role::kModeDisplay))
      *reg(profile_.field(Role::kModeDisplay).address) = *reg(f.address);  // the mode display follows the mode
  }
  refresh();
}

bool VfdEmulator::running() const { return logic_.drive_follows(drive_, profile_); }

double VfdEmulator::command_hz() const {
  if (!running()) return 0.0;
  if (hy_) {
    // The drive limits the frequency to its PD005.
    const HuanyangMap& h = profile_.huanyang;
    const double hz = std::min(hy_frequency_, pd_[static_cast<size_t>(h.max_frequency_pd)]) / h.frequency_scale;
    return (logic_.drive_statusword(drive_) & kHyReverseCommanded) ? -hz : hz;
  }
  const Field& f = profile_.field(Role::kSpeedSetpoint);
  if (cia402_) return f.decode(reg(f.address));  // the target velocity, signed
  const double hz = std::fabs(f.decode(reg(f.address)));
  return (logic_.drive_statusword(drive_) & kDeltaVfdCommandedReverse) ? -hz : hz;
}

void VfdEmulator::step(double dt_s) {
  if (!(dt_s > 0)) return;
  const double before = hz_;
  // First order, exact over the step: a 1 ms grid and a 10 ms one give the same curve;
  // so is the encoder's integral of it.
  const double target = command_hz();
  const double decay = std::exp(-dt_s / sim_.time_constant_s);
  revs_ += (target * dt_s + (hz_ - target) * sim_.time_constant_s * (1 - decay)) * rpm_per_hz_ / 60.0;
  hz_ = target + (hz_ - target) * decay;
  const double accel_hz_s = (hz_ - before) / dt_s;
  const double full_accel = max_hz_ / sim_.time_constant_s;
  current_a_ = sim_.load_current_a * std::fabs(hz_) / max_hz_ + sim_.inertia_current_a * std::fabs(accel_hz_s) / full_accel;
  refresh();
}

void VfdEmulator::advance(double dt_s) {
  if (!(dt_s > 0)) return;
  revs_ += hz_ * dt_s * rpm_per_hz_ / 60.0;
  refresh();
}

void VfdEmulator::set_revolutions(double revs) {
  revs_ = revs;
  refresh();
}

void VfdEmulator::settle() {
  hz_ = command_hz();
  current_a_ = sim_.load_current_a * std::fabs(hz_) / max_hz_;
  refresh();
}

void VfdEmulator::inject_fault(uint16_t code) {
  logic_.drive_fault(drive_, code);
  refresh();
}

int VfdEmulator::answer_frame(const uint8_t* request, int n, uint8_t* reply) {
  namespace hy = huanyang;
  if (!hy_ || hy::frame_length(request, n) != n || !hy::crc_ok(request, n)) return 0;
  const HuanyangMap& h = profile_.huanyang;
  const uint8_t* d = request + 3;
  const int len = request[2];
  uint8_t out[hy::kMaxData];
  int out_n = 0;
  const auto value = [&](uint8_t first, double v) {
    const long raw = std::lround(std::fabs(v));
    const auto u = static_cast<uint16_t>(std::min(raw, 65535L));
    out[0] = first;
    out[1] = static_cast<uint8_t>(u >> 8);
    out[2] = static_cast<uint8_t>(u & 0xFF);
    out_n = 3;
  };
  switch (request[1]) {
    case hy::kReadFunctionData:
      if (len != 3) return 0;
      value(d[0], pd_[d[0]]);
      break;
    case hy::kWriteFunctionData:
      if (len != 3) return 0;
      pd_[d[0]] = hy::be16(d + 1);
      value(d[0], pd_[d[0]]);
      break;
    case hy::kWriteControlData: {
      if (len != 1) return 0;
      logic_.drive_write(drive_, Role::kControlword, d[0], profile_);
      uint16_t cnst = logic_.drive_statusword(drive_);
      if (hz_ < 0) cnst |= kHyTurnsReverse;
      out[0] = static_cast<uint8_t>(cnst);
      out_n = 1;
      break;
    }
    case hy::kReadControlStatus: {
      if (len != 1) return 0;
      const int index = d[0];
      double v = 0;
      if (index == h.output_frequency_index) v = hz_ * h.frequency_scale;
      else if (index == h.output_current_index) v = current_a_ * h.current_scale;
      else if (index == 0) v = hy_frequency_;                      // the set frequency
      else if (index == 3) v = hz_ * rpm_per_hz_;                   // rpm
      value(d[0], v);
      break;
    }
    case hy::kWriteFrequency:
      if (len != 2) return 0;
      hy_frequency_ = hy::be16(d);
      out[0] = d[0];
      out[1] = d[1];
      out_n = 2;
      break;
    default: return 0;
  }
  return hy::encode(request[0], request[1], out, out_n, reply);
}

void VfdEmulator::refresh() {
  if (hy_) return;  // answer_frame reads the motor as it is
  uint16_t sw = logic_.drive_statusword(drive_);
  if (!cia402_) sw = static_cast<uint16_t>((sw & ~kDeltaVfdTurnsReverse) | (hz_ < 0 ? kDeltaVfdTurnsReverse : 0));
  *reg(profile_.field(Role::kStatusword).address) = sw;
  if (profile_.has(Role::kErrorCode)) *reg(profile_.field(Role::kErrorCode).address) = drive_.error_code;
  if (profile_.has(Role::kEncoderPosition) && counts_per_rev_ > 0) {
    // The counter's 32 bits of the count (a signed field reads them as two's complement).
    const Field& e = profile_.field(Role::kEncoderPosition);
    const int64_t counts = std::llround(std::floor(revs_ * static_cast<double>(counts_per_rev_)));
    const auto bits = static_cast<uint32_t>(static_cast<uint64_t>(counts));
    e.encode_raw(e.is_signed ? int64_t{static_cast<int32_t>(bits)} : int64_t{bits}, reg(e.address));
  }
  // The output frequency: a Delta's as a magnitude (the direction is in the status
  // word), a signed field's (a servo drive's velocity actual value) with its sign.
  const Field& a = profile_.field(Role::kActualSpeed);
  a.encode(a.is_signed ? hz_ : std::fabs(hz_), reg(a.address));
  if (profile_.has(Role::kOutputCurrent)) {
    const Field& c = profile_.field(Role::kOutputCurrent);
    c.encode(current_a_, reg(c.address));
  }
}

}  // namespace cnc::drive
