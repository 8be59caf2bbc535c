#include "common/drive/drive_emulator.h"

#include <stdexcept>

namespace cnc::drive {

DriveEmulator::DriveEmulator(const DriveProfile& profile, double start_mm)
    : profile_(profile), logic_(profile_logic(profile)), base_(profile.first_address()),
      count_(profile.end_address() - profile.first_address()) {
  map_ = modbus_mapping_new_start_address(0, 0, 0, 0, static_cast<unsigned>(base_), static_cast<unsigned>(count_), 0, 0);
  if (map_ == nullptr) throw std::runtime_error("modbus_mapping_new_start_address failed");
  power_up();
  profile_.field(Role::kTargetPosition).encode(start_mm, reg(profile_.field(Role::kTargetPosition).address));
  set_actual(start_mm, 0.0);
}

DriveEmulator::~DriveEmulator() { modbus_mapping_free(map_); }

void DriveEmulator::power_up() {
  logic_.drive_power_up(drive_);
  for (int i = 0; i < count_; ++i) map_->tab_registers[i] = 0;
  refresh_status();
}

int DriveEmulator::read(int addr, int n, uint16_t* dest) const {
  if (n < 1 || n > MODBUS_MAX_READ_REGISTERS) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
  if (addr < base_ || addr + n > base_ + count_) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
  for (int i = 0; i < n; ++i) dest[i] = *reg(addr + i);
  return 0;
}

int DriveEmulator::write(int addr, int n, const uint16_t* src) {
  if (n < 1 || n > MODBUS_MAX_WRITE_REGISTERS) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
  if (addr < base_ || addr + n > base_ + count_) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
  for (int i = 0; i < n; ++i) *reg(addr + i) = src[i];
  after_write(addr, n);
  return 0;
}

void DriveEmulator::after_write(int addr, int n) {
  for (int i = 0; i < kRoleCount; ++i) {
    const Role role = static_cast<Role>(i);
    const Field& f = profile_.fields[i];
    if (!f.present() || f.address >= addr + n || f.end() <= addr) continue;
    if (role == Role::kTargetPosition) {
      ++target_writes_;
    } else if (role == Role::kControlword || role == Role::kMode || role == Role::kFaultReset) {
      logic_.drive_write(drive_, role, *reg(f.address), profile_);
      // An alarm-clear register reads back 0 once the drive has acted on it.
      if (role == Role::kFaultReset) *reg(f.address) = 0;
    }
  }
  refresh_status();
}

bool DriveEmulator::follows() const { return logic_.drive_follows(drive_, profile_); }

double DriveEmulator::target_mm() const {
  const Field& f = profile_.field(Role::kTargetPosition);
  return f.decode(reg(f.address));
}

void DriveEmulator::set_actual(double position_mm, double velocity_mm_s) {
  const Field& p = profile_.field(Role::kActualPosition);
  p.encode(position_mm, reg(p.address));
  if (profile_.has(Role::kActualVelocity)) {
    const Field& v = profile_.field(Role::kActualVelocity);
    v.encode(velocity_mm_s, reg(v.address));
  }
  refresh_status();
}

void DriveEmulator::set_following_error(double fe_mm) {
  if (!profile_.has(Role::kFollowingError)) return;
  const Field& f = profile_.field(Role::kFollowingError);
  f.encode(fe_mm, reg(f.address));
}

void DriveEmulator::set_home_latch(double position_mm, int64_t count) {
  if (profile_.has(Role::kHomeLatchPosition)) {
    const Field& f = profile_.field(Role::kHomeLatchPosition);
    f.encode(position_mm, reg(f.address));
  }
  if (profile_.has(Role::kHomeLatchCount)) {
    const Field& f = profile_.field(Role::kHomeLatchCount);
    f.encode_raw(count & 0xFFFF, reg(f.address));
  }
}

void DriveEmulator::set_probe_latch(bool rising, double position_mm, int64_t count) {
  // A drive whose touch probe is switched by a function register latches only when armed
  // for that edge (CiA 402 0x60B8: bit 0 on, bit 4 rising, bit 5 falling).
  if (profile_.has(Role::kProbeFunction)) {
    const uint16_t f = *reg(profile_.field(Role::kProbeFunction).address);
    if (!(f & 0x01) || !(f & (rising ? 0x10 : 0x20))) return;
  }
  const Role pos = rising ? Role::kProbeRisePosition : Role::kProbeFallPosition;
  const Role cnt = rising ? Role::kProbeRiseCount : Role::kProbeFallCount;
  if (profile_.has(pos)) profile_.field(pos).encode(position_mm, reg(profile_.field(pos).address));
  if (profile_.has(cnt)) profile_.field(cnt).encode_raw(count & 0xFFFF, reg(profile_.field(cnt).address));
}

void DriveEmulator::inject_fault(uint16_t code) {
  logic_.drive_fault(drive_, code);
  refresh_status();
}

const char* DriveEmulator::state_name() const { return logic_.decode(logic_.drive_statusword(drive_)).state; }

void DriveEmulator::refresh_status() {
  *reg(profile_.field(Role::kStatusword).address) = logic_.drive_statusword(drive_);
  if (profile_.has(Role::kModeDisplay)) {
    const Field& f = profile_.field(Role::kModeDisplay);
    f.encode_raw(drive_.mode, reg(f.address));
  }
  if (profile_.has(Role::kErrorCode)) *reg(profile_.field(Role::kErrorCode).address) = drive_.error_code;
}

}  // namespace cnc::drive
