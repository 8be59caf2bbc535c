#pragma once
// A spindle drive on Modbus registers as a device (device.h): its process data are
// run, direction and a speed command out, and status, error code, output speed,
// output current and, where the profile maps it, the encoder's position counter in.
// The register map is the profile's (data, e.g. config/drives/delta_vfd.yaml); the
// meaning of the command and status is its state machine's:
//  * delta_vfd (delta_vfd_profile.h): each cycle writes the command word and the
//    frequency (one transaction where they are adjacent);
//  * cia402_velocity (cia402_profile.h, a servo drive in profile velocity mode): each
//    cycle writes the signed target velocity; enabling is the CiA-402 state machine's
//    steps in control(), one write per cycle, as an axis drive's.
// Then it reads its input fields, merged into as few reads as the profile's
// read_gap_max allows (with function 23 where the profile has write_and_read). No
// allocation after construction: it runs on the bridge's link workers.
#include <array>
#include <cstdint>
#include <memory>
#include <span>

#include "common/drive/device.h"
#include "common/drive/drive_profile.h"
#include "common/drive/encoder_counter.h"
#include "common/drive/link.h"

namespace cnc::drive {

// Master to drive, each cycle.
struct SpindleOutputs {
  bool write = false;  // write the command; otherwise only read
  int8_t direction = 0;  // 1 forward, -1 reverse, 0 stop
  double hz = 0;         // frequency command, >= 0
};

// Drive to master: the last good cycle's answer.
// (cia402_velocity: running is "operation enabled", the drive following its target
// velocity, also at 0; reverse is the sign of its velocity.)
struct SpindleInputs {
  bool valid = false;  // the drive has answered since the link was (re)opened
  uint16_t statusword = 0;
  bool running = false;
  bool reverse = false;
  uint16_t error_code = 0;  // the drive's fault, 0 none
  double output_hz = 0;     // signed: negative in reverse
  bool has_current = false;
  double current_a = 0;
  // The drive reports a fault: delta_vfd, its error code is not 0; cia402_velocity, its
  // state is fault (error_code then the drive's 0x603F).
  bool fault = false;
  // The encoder (the profile maps encoder_position): its counter unwrapped
  // (encoder_counter.h), and how long before the exchange returned the drive sampled
  // it: a serial line's reply on its way (3.5 characters of silence and the reply's
  // bytes), 0 on TCP (whose delay, tens of microseconds, is not counted).
  bool has_position = false;
  int64_t position_counts = 0;
  double sample_age_s = 0;
  // What is wrong with the drive's own settings for the link, read when the link
  // opened (Huanyang: its PD parameters); empty when nothing is, or not known.
  std::array<char, 160> setup_error{};
};

class SpindleDevice final : public Device {
 public:
  static constexpr PdoLayout kLayout{sizeof(SpindleInputs), sizeof(SpindleOutputs)};
  // Throws std::invalid_argument when the profile is no register-mapped spindle drive's.
  SpindleDevice(const DriveProfile& profile, int unit, Link& link);
  PdoLayout layout() const override { return kLayout; }
  TxResult exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs, LinkCounters& c) override;
  // delta_vfd: kFaultReset is one write of the fault-reset register while the drive
  // reports a fault; enable and disable are the command word's. cia402_velocity: one
  // step of the CiA-402 state machine toward `goal` (mode, shutdown, switch on,
  // enable operation; the fault reset's edge).
  TxResult control(Goal goal, LinkCounters& c) override;
  void forget(std::span<std::byte> inputs) override;
  // The cyclic reads' register ranges (tests, the bench).
  int reads() const { return n_reads_; }

 private:
  struct Range {
    int addr = 0;
    int n = 0;
  };
  const uint16_t* at(Role role) const { return values_[static_cast<size_t>(role)].data(); }
  void take(const Range& g);

  const DriveProfile& profile_;
  const ProfileLogic& logic_;
  bool cia402_;
  int unit_;
  Link& link_;
  std::array<Range, 5> reads_{};  // one per input role at most
  int n_reads_ = 0;
  bool command_adjacent_ = false;  // delta_vfd: speed_setpoint directly follows controlword
  std::array<uint16_t, 125> buf_{};
  std::array<std::array<uint16_t, 2>, kRoleCount> values_{};
  uint16_t last_error_ = 0;
  // cia402_velocity: what the state machine's master side remembers, and the last statusword.
  MasterMemory memory_;
  bool have_status_ = false;
  uint16_t statusword_ = 0;
  EncoderCounter encoder_;  // kept across a lost link: the position runs on where the counter does
};

// The spindle device of a spindle drive's profile: SpindleDevice (delta_vfd,
// cia402_velocity) or HuanyangSpindleDevice (huanyang). `max_hz` and `rpm_per_hz` from spindle: (the
// Huanyang checks its drive's settings against them). Throws std::invalid_argument
// for a profile that is no spindle drive's.
std::unique_ptr<Device> make_spindle_device(const DriveProfile& profile, int unit, Link& link, double max_hz,
                                            double rpm_per_hz);

}  // namespace cnc::drive
