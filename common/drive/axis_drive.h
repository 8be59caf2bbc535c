#pragma once
// An axis drive as a device (device.h): its process data are a position target
// out and status, position, following error and home latch in. ModbusAxisDrive is
// today's register transactions (DriveIo, planned from the drive's profile) behind
// that interface: the same reads and writes in the same order.
#include <cstdint>
#include <memory>
#include <span>

#include "common/drive/device.h"
#include "common/drive/drive_io.h"

namespace cnc::drive {

// Master to drive, each cycle.
struct AxisOutputs {
  bool write = false;  // write target_mm; otherwise only read (no status yet)
  double target_mm = 0;
};

// Drive to master: the last good cycle's answer.
struct AxisInputs {
  bool valid = false;  // the drive has answered since the link was (re)opened
  uint16_t statusword = 0;
  DriveStatus status;
  uint16_t error_code = 0;
  double actual_mm = 0;
  double written_mm = 0;  // the last target written, as the drive has it (rounded to its counts)
  bool reports_following_error = false;  // the profile maps the drive's own following error
  double following_error_mm = 0;
  bool has_home_latch = false;  // the profile maps a home switch latch
  double home_latch_mm = 0;
  int64_t home_latch_count = 0;
  bool has_probe_latch = false;  // the profile maps the touch probe's latches
  ProbeLatches probe;
};

inline constexpr PdoLayout kAxisLayout{sizeof(AxisInputs), sizeof(AxisOutputs)};

class ModbusAxisDrive final : public Device {
 public:
  ModbusAxisDrive(const DriveProfile& profile, int unit, Link& link) : io_(profile, unit, link) {}
  PdoLayout layout() const override { return kAxisLayout; }
  TxResult exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs, LinkCounters& c) override;
  TxResult control(Goal goal, LinkCounters& c) override { return io_.control(goal, c); }
  void forget(std::span<std::byte> inputs) override;
  const DriveIo& io() const { return io_; }

 private:
  DriveIo io_;
};

}  // namespace cnc::drive
