#pragma once
// A spindle drive (a VFD on Modbus) as a device (device.h): its process data are
// run, direction and a frequency command out, and status, error code, output
// frequency and output current in. The register map is the profile's (data, e.g.
// config/drives/delta_vfd.yaml); the command word's bits are its state machine's
// (delta_vfd_profile.h). Each cycle writes the command word and the frequency (one
// transaction where they are adjacent) and reads every input field in one read.
// No allocation after construction: it runs on the bridge's link workers.
#include <array>
#include <cstdint>
#include <memory>
#include <span>

#include "common/drive/device.h"
#include "common/drive/drive_profile.h"
#include "common/drive/link.h"

namespace cnc::drive {

// Master to drive, each cycle.
struct SpindleOutputs {
  bool write = false;  // write the command; otherwise only read
  int8_t direction = 0;  // 1 forward, -1 reverse, 0 stop
  double hz = 0;         // frequency command, >= 0
};

// Drive to master: the last good cycle's answer.
struct SpindleInputs {
  bool valid = false;  // the drive has answered since the link was (re)opened
  uint16_t statusword = 0;
  bool running = false;
  bool reverse = false;
  uint16_t error_code = 0;  // the drive's fault, 0 none
  double output_hz = 0;     // signed: negative in reverse
  bool has_current = false;
  double current_a = 0;
  // What is wrong with the drive's own settings for the link, read when the link
  // opened (Huanyang: its PD parameters); empty when nothing is, or not known.
  std::array<char, 160> setup_error{};
};

class SpindleDevice final : public Device {
 public:
  static constexpr PdoLayout kLayout{sizeof(SpindleInputs), sizeof(SpindleOutputs)};
  // Throws std::invalid_argument when the profile is no spindle drive's or its input
  // fields do not fit one read.
  SpindleDevice(const DriveProfile& profile, int unit, Link& link);
  PdoLayout layout() const override { return kLayout; }
  TxResult exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs, LinkCounters& c) override;
  // kFaultReset: one write of the fault-reset register while the drive reports a fault.
  TxResult control(Goal goal, LinkCounters& c) override;
  void forget(std::span<std::byte> inputs) override;

 private:
  const DriveProfile& profile_;
  int unit_;
  Link& link_;
  int read_addr_ = 0;
  int read_n_ = 0;
  bool command_adjacent_ = false;  // speed_setpoint directly follows controlword
  std::array<uint16_t, 125> buf_{};
  uint16_t last_error_ = 0;
};

// The spindle device of a spindle drive's profile: SpindleDevice (delta_vfd) or
// HuanyangSpindleDevice (huanyang). `max_hz` and `rpm_per_hz` from spindle: (the
// Huanyang checks its drive's settings against them). Throws std::invalid_argument
// for a profile that is no spindle drive's.
std::unique_ptr<Device> make_spindle_device(const DriveProfile& profile, int unit, Link& link, double max_hz,
                                            double rpm_per_hz);

}  // namespace cnc::drive
