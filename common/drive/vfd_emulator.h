#pragma once
// The drive end of a spindle VFD profile: a motor whose output frequency follows the
// command with a first-order response, with a load figure (output current) of a
// steady part proportional to speed and an inertial part proportional to the
// acceleration, behind either of two protocols: a register image (state_machine
// delta_vfd; the servo simulator serves it with modbus_reply on mapping()) or the
// Huanyang frames (state_machine huanyang; answer_frame, with the PD parameters the
// master checks set as a drive set up for the link has them). One VFD model, two
// protocols; and a third: a servo drive in profile velocity mode (state_machine
// cia402_velocity, a register image like the Delta's), the same motor model behind
// the CiA-402 state machine: it follows its signed target velocity while operation
// is enabled in mode 3, and coasts down otherwise.
// The encoder (`counts_per_rev` > 0, and the profile maps encoder_position): the
// spindle's revolutions (output frequency x rpm_per_hz / 60, integrated exactly over
// each step) times counts_per_rev, counted up in the forward (M3) direction, as a
// 32-bit counter that wraps. The simulator steps it on its 1 ms grid and before each
// request it answers; tests drive it through a link of their own.
#include <modbus.h>

#include <array>
#include <cstdint>

#include "common/config/machine_config.h"
#include "common/drive/drive_profile.h"
#include "common/drive/profile_logic.h"

namespace cnc::drive {

class VfdEmulator {
 public:
  // `max_hz`: the frequency at the spindle's max_rpm (the load figure's scale; a
  // Huanyang's PD005); `rpm_per_hz`: the motor's (a Huanyang's PD144 follows from it).
  // `counts_per_rev`: the encoder's (spindle.encoder_counts_per_rev), 0 none.
  VfdEmulator(const DriveProfile& profile, const config::SpindleSimConfig& sim, double max_hz, double rpm_per_hz = 60,
              int64_t counts_per_rev = 0);
  ~VfdEmulator();
  VfdEmulator(const VfdEmulator&) = delete;
  VfdEmulator& operator=(const VfdEmulator&) = delete;

  modbus_mapping_t* mapping() { return map_; }
  // Direct access: 0 or a Modbus exception code.
  int read(int addr, int n, uint16_t* dest) const;
  int write(int addr, int n, const uint16_t* src);
  // After the registers [addr, addr + n) were written through mapping().
  void after_write(int addr, int n);
  // A Huanyang request (a whole frame, its CRC checked); its reply into `reply`
  // (huanyang::kMaxFrame bytes). Returns the reply's length, 0 for no reply (a bad
  // CRC or a function the drive does not have: a real one stays silent).
  int answer_frame(const uint8_t* request, int n, uint8_t* reply);
  // A Huanyang's PD parameter (function 0x01 reads it), to set up a drive wrongly.
  void set_pd(int number, uint16_t value) { pd_[static_cast<size_t>(number & 0xFF)] = value; }
  // The motor over dt_s seconds; refreshes the read registers.
  void step(double dt_s);
  // An ideal motor (the loopback link): at the commanded frequency at once.
  void settle();
  // The ideal motor's encoder: dt_s seconds at the output frequency it has (the loopback link).
  void advance(double dt_s);
  // A fault inside the drive: it coasts down and reports `code` until a fault reset.
  void inject_fault(uint16_t code);

  bool running() const;
  // Signed: negative in reverse.
  double command_hz() const;
  double output_hz() const { return hz_; }
  // The spindle's revolutions since start (the encoder's position before its counts and wrap).
  double revolutions() const { return revs_; }
  // Sets them (tests: the counter near its wrap).
  void set_revolutions(double revs);
  double current_a() const { return current_a_; }
  const DriveProfile& profile() const { return profile_; }

 private:
  uint16_t* reg(int addr) { return &map_->tab_registers[addr - base_]; }
  const uint16_t* reg(int addr) const { return &map_->tab_registers[addr - base_]; }
  void refresh();

  DriveProfile profile_;
  const ProfileLogic& logic_;
  config::SpindleSimConfig sim_;
  double max_hz_;
  modbus_mapping_t* map_ = nullptr;
  int base_;
  int count_;
  EmulatedDrive drive_;
  double hz_ = 0;
  double current_a_ = 0;
  double revs_ = 0;
  int64_t counts_per_rev_;
  bool cia402_;                  // the servo drive's protocol (cia402_velocity)
  bool hy_ = false;              // the Huanyang protocol
  uint16_t hy_frequency_ = 0;    // function 0x05's value
  std::array<uint16_t, 256> pd_{};
  double rpm_per_hz_;
};

}  // namespace cnc::drive
