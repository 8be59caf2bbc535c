#include "common/drive/vfd_emulator.h"

#include <cmath>
#include <stdexcept>

#include "common/drive/delta_vfd_profile.h"

namespace cnc::drive {

VfdEmulator::VfdEmulator(const DriveProfile& profile, const config::SpindleSimConfig& sim, double max_hz)
    : profile_(profile), logic_(profile_logic(profile)), sim_(sim), max_hz_(max_hz),
      base_(profile.first_address()), count_(profile.end_address() - profile.first_address()) {
  map_ = modbus_mapping_new_start_address(0, 0, 0, 0, static_cast<unsigned>(base_), static_cast<unsigned>(count_), 0, 0);
  if (map_ == nullptr) throw std::runtime_error("modbus_mapping_new_start_address failed");
  logic_.drive_power_up(drive_);
  for (int i = 0; i < count_; ++i) map_->tab_registers[i] = 0;
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
  for (Role role : {Role::kControlword, Role::kFaultReset}) {
    const Field& f = profile_.field(role);
    if (!f.present() || f.address >= addr + n || f.end() <= addr) continue;
    logic_.drive_write(drive_, role, *reg(f.address), profile_);
    if (role == Role::kFaultReset) *reg(f.address) = 0;  // the drive clears the reset bit
  }
  refresh();
}

bool VfdEmulator::running() const { return logic_.drive_follows(drive_, profile_); }

double VfdEmulator::command_hz() const {
  if (!running()) return 0.0;
  const Field& f = profile_.field(Role::kSpeedSetpoint);
  const double hz = std::fabs(f.decode(reg(f.address)));
  return (logic_.drive_statusword(drive_) & kDeltaVfdCommandedReverse) ? -hz : hz;
}

void VfdEmulator::step(double dt_s) {
  if (!(dt_s > 0)) return;
  const double before = hz_;
  // First order, exact over the step: a 1 ms grid and a 10 ms one give the same curve.
  hz_ = command_hz() + (hz_ - command_hz()) * std::exp(-dt_s / sim_.time_constant_s);
  const double accel_hz_s = (hz_ - before) / dt_s;
  const double full_accel = max_hz_ / sim_.time_constant_s;
  current_a_ = sim_.load_current_a * std::fabs(hz_) / max_hz_ + sim_.inertia_current_a * std::fabs(accel_hz_s) / full_accel;
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

void VfdEmulator::refresh() {
  uint16_t sw = logic_.drive_statusword(drive_);
  sw = static_cast<uint16_t>((sw & ~kDeltaVfdTurnsReverse) | (hz_ < 0 ? kDeltaVfdTurnsReverse : 0));
  *reg(profile_.field(Role::kStatusword).address) = sw;
  *reg(profile_.field(Role::kErrorCode).address) = drive_.error_code;
  // The output frequency as a magnitude: the direction is in the status word.
  const Field& a = profile_.field(Role::kActualSpeed);
  a.encode(a.is_signed ? hz_ : std::fabs(hz_), reg(a.address));
  if (profile_.has(Role::kOutputCurrent)) {
    const Field& c = profile_.field(Role::kOutputCurrent);
    c.encode(current_a_, reg(c.address));
  }
}

}  // namespace cnc::drive
