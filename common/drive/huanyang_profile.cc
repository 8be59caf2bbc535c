#include "common/drive/huanyang_profile.h"

namespace cnc::drive {
namespace {

constexpr uint8_t kCmdRunForward = 0x01;
constexpr uint8_t kCmdRunReverse = 0x11;
constexpr uint8_t kCmdStop = 0x08;

class HuanyangLogic final : public VfdLogic {
 public:
  const char* name() const override { return "huanyang"; }
  // No registers: the profile's huanyang: section is its map (drive_profile.cc requires it).
  std::vector<Role> required_roles() const override { return {}; }

  DriveStatus decode(uint16_t cnst) const override {
    DriveStatus s;
    s.enabled = (cnst & kHyRunning) != 0;
    s.state = s.enabled ? "running" : "stopped";
    return s;
  }

  // Nothing acyclic: run and stop are the cyclic command byte, and the protocol has no fault reset.
  std::optional<ControlWrite> next_write(Goal, uint16_t, const MasterMemory&, const DriveProfile&) const override {
    return std::nullopt;
  }

  void drive_write(EmulatedDrive& d, Role role, uint16_t v, const DriveProfile&) const override {
    if (role != Role::kControlword) return;
    d.last_control = v;
    if (v == kCmdStop) d.state &= ~kStRun;
    if ((v == kCmdRunForward || v == kCmdRunReverse) && !d.fault) {
      d.state |= kStRun;
      d.state = v == kCmdRunReverse ? (d.state | kStReverse) : (d.state & ~kStReverse);
    }
  }

  // Bit 5 (the output's own direction) is the emulator's (vfd_emulator.h).
  uint16_t drive_statusword(const EmulatedDrive& d) const override {
    uint16_t s = (d.state & kStRun) ? (kHyRunCommanded | kHyRunning) : 0;
    if (d.state & kStReverse) s |= kHyReverseCommanded;
    return s;
  }
};

}  // namespace

const ProfileLogic& huanyang_logic() {
  static const HuanyangLogic logic;
  return logic;
}

uint8_t huanyang_command(int direction) {
  if (direction == 0) return kCmdStop;
  return direction > 0 ? kCmdRunForward : kCmdRunReverse;
}

}  // namespace cnc::drive
