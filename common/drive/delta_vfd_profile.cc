#include "common/drive/delta_vfd_profile.h"

namespace cnc::drive {
namespace {

constexpr uint16_t kCmdStop = 0x01;
constexpr uint16_t kCmdRun = 0x02;
constexpr uint16_t kCmdForward = 0x10;
constexpr uint16_t kCmdReverse = 0x20;
constexpr uint16_t kSwRunMask = 0x03;
constexpr uint16_t kSwRunning = 0x03;
constexpr uint16_t kSwDecelerating = 0x01;
constexpr uint16_t kSwReverse = kDeltaVfdTurnsReverse | kDeltaVfdCommandedReverse;

class DeltaVfdLogic final : public VfdLogic {
 public:
  const char* name() const override { return "delta_vfd"; }
  std::vector<Role> required_roles() const override {
    return {Role::kControlword, Role::kStatusword, Role::kSpeedSetpoint, Role::kActualSpeed, Role::kErrorCode,
            Role::kFaultReset};
  }

  DriveStatus decode(uint16_t sw) const override {
    DriveStatus s;
    s.enabled = (sw & kSwRunMask) == kSwRunning;
    s.state = s.enabled ? "running" : (sw & kSwRunMask) == kSwDecelerating ? "decelerating" : "stopped";
    return s;
  }

  // Run and stop are the cyclic command word; the only acyclic step is the fault
  // reset, written while the goal asks for it (the drive clears the bit itself).
  std::optional<ControlWrite> next_write(Goal goal, uint16_t, const MasterMemory&, const DriveProfile&) const override {
    if (goal == Goal::kFaultReset) return ControlWrite{Role::kFaultReset, kDeltaVfdFaultReset};
    return std::nullopt;
  }

  void drive_write(EmulatedDrive& d, Role role, uint16_t v, const DriveProfile&) const override {
    if (role == Role::kFaultReset && (v & kDeltaVfdFaultReset)) {
      d.fault = false;
      d.error_code = 0;
      return;
    }
    if (role != Role::kControlword) return;
    d.last_control = v;
    if ((v & 0x03) == kCmdStop) d.state &= ~kStRun;
    if ((v & 0x03) == kCmdRun && !d.fault) d.state |= kStRun;
    if ((v & 0x30) == kCmdForward) d.state &= ~kStReverse;
    if ((v & 0x30) == kCmdReverse) d.state |= kStReverse;
  }

  // Reverse commanded sets both direction bits; the emulator (vfd_emulator.h) clears
  // bit 3 while its output still turns forward, and sets it while a forward command
  // still turns in reverse.
  uint16_t drive_statusword(const EmulatedDrive& d) const override {
    uint16_t sw = (d.state & kStRun) ? kSwRunning : 0;
    if (d.state & kStReverse) sw |= kSwReverse;
    return sw;
  }
};

}  // namespace

const ProfileLogic& delta_vfd_logic() {
  static const DeltaVfdLogic logic;
  return logic;
}

uint16_t delta_vfd_command(int direction) {
  if (direction == 0) return kCmdStop;
  return static_cast<uint16_t>(kCmdRun | (direction > 0 ? kCmdForward : kCmdReverse));
}

bool is_spindle_profile(const DriveProfile& p) {
  return p.state_machine == delta_vfd_logic().name() || p.state_machine == "huanyang" ||
         p.state_machine == "cia402_velocity";
}

}  // namespace cnc::drive
