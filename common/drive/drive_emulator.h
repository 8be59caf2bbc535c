#pragma once
// The drive end of a profile: the register image of one emulated drive and its
// side of the profile's state machine. The servo simulator serves it over Modbus
// (modbus_reply on mapping()) and moves the axis with its servo dynamics; the
// loopback link serves it in-process with an ideal axis.
#include <modbus.h>

#include <cstdint>
#include <memory>

#include "common/drive/drive_profile.h"
#include "common/drive/profile_logic.h"

namespace cnc::drive {

class DriveEmulator {
 public:
  DriveEmulator(const DriveProfile& profile, double start_mm);
  ~DriveEmulator();
  DriveEmulator(const DriveEmulator&) = delete;
  DriveEmulator& operator=(const DriveEmulator&) = delete;

  // The holding registers, starting at the profile's first address.
  modbus_mapping_t* mapping() { return map_; }
  // Direct access (loopback): 0 or a Modbus exception code.
  int read(int addr, int n, uint16_t* dest) const;
  int write(int addr, int n, const uint16_t* src);
  // After the registers [addr, addr + n) were written through mapping(): the drive
  // reacts to control writes and counts target writes.
  void after_write(int addr, int n);

  bool follows() const;
  double target_mm() const;
  // Target writes so far: the simulator times them for its interpolation.
  int64_t target_writes() const { return target_writes_; }
  // The axis state, into the registers; refreshes the status registers too.
  void set_actual(double position_mm, double velocity_mm_s);
  // Where the profile maps it: the drive's position demand minus actual.
  void set_following_error(double fe_mm);
  // Where the profile maps them: the home switch latch (position and edge count).
  void set_home_latch(double position_mm, int64_t count);
  // The touch probe's latch of an edge (rising: true) at `position_mm`, its counter at `count`.
  void set_probe_latch(bool rising, double position_mm, int64_t count);
  void inject_fault(uint16_t code);
  void power_up();  // back to the power-up state (the simulator restarted)
  const DriveProfile& profile() const { return profile_; }
  const EmulatedDrive& state() const { return drive_; }
  const char* state_name() const;

 private:
  uint16_t* reg(int addr) { return &map_->tab_registers[addr - base_]; }
  const uint16_t* reg(int addr) const { return &map_->tab_registers[addr - base_]; }
  void refresh_status();

  DriveProfile profile_;
  const ProfileLogic& logic_;
  modbus_mapping_t* map_ = nullptr;
  int base_;
  int count_;
  EmulatedDrive drive_;
  int64_t target_writes_ = 0;
};

}  // namespace cnc::drive
