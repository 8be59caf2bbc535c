#include "common/drive/sim_profile.h"

namespace cnc::drive {
namespace {

constexpr uint16_t kCwEnable = 1u << 0;
constexpr uint16_t kCwFaultReset = 1u << 7;
constexpr uint16_t kSwEnabled = 1u << 0;
constexpr uint16_t kSwFault = 1u << 3;

class SimLogic final : public ProfileLogic {
 public:
  const char* name() const override { return "sim"; }
  std::vector<Role> required_roles() const override {
    return {Role::kControlword, Role::kStatusword, Role::kTargetPosition, Role::kActualPosition};
  }

  DriveStatus decode(uint16_t sw) const override {
    DriveStatus s;
    s.fault = (sw & kSwFault) != 0;
    s.enabled = !s.fault && (sw & kSwEnabled) != 0;
    s.state = s.fault ? "fault" : s.enabled ? "enabled" : "disabled";
    return s;
  }

  std::optional<ControlWrite> next_write(Goal goal, uint16_t sw, const MasterMemory& m,
                                         const DriveProfile&) const override {
    const DriveStatus s = decode(sw);
    if (s.fault && goal != Goal::kDisable) {
      // A rising edge of bit 7: clear it first if the last write left it set.
      return ControlWrite{Role::kControlword, (m.last_control & kCwFaultReset) ? uint16_t{0} : kCwFaultReset};
    }
    if (goal == Goal::kEnable && !s.enabled) return ControlWrite{Role::kControlword, kCwEnable};
    if (goal != Goal::kEnable && (s.enabled || (m.last_control & kCwEnable)))
      return ControlWrite{Role::kControlword, 0};
    return std::nullopt;
  }

  void drive_power_up(EmulatedDrive& d) const override { d = EmulatedDrive{}; }

  void drive_write(EmulatedDrive& d, Role role, uint16_t v, const DriveProfile&) const override {
    if (role != Role::kControlword) return;
    if ((v & kCwFaultReset) && !(d.last_control & kCwFaultReset)) {
      d.fault = false;
      d.error_code = 0;
    }
    d.last_control = v;
  }

  uint16_t drive_statusword(const EmulatedDrive& d) const override {
    if (d.fault) return kSwFault;
    return (d.last_control & kCwEnable) ? kSwEnabled : 0;
  }

  bool drive_follows(const EmulatedDrive& d, const DriveProfile&) const override {
    return !d.fault && (d.last_control & kCwEnable);
  }

  void drive_fault(EmulatedDrive& d, uint16_t code) const override {
    d.fault = true;
    d.error_code = code;
  }
};

}  // namespace

const ProfileLogic& sim_logic() {
  static const SimLogic logic;
  return logic;
}

}  // namespace cnc::drive
