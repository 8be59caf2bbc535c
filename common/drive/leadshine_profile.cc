#include "common/drive/leadshine_profile.h"

namespace cnc::drive {
namespace {

constexpr uint16_t kSwReady = 1u << 0;
constexpr uint16_t kSwServoOn = 1u << 1;
constexpr uint16_t kSwAlarm = 1u << 2;

class LeadshineLogic final : public ProfileLogic {
 public:
  const char* name() const override { return "leadshine"; }
  std::vector<Role> required_roles() const override {
    return {Role::kControlword, Role::kStatusword, Role::kFaultReset, Role::kTargetPosition, Role::kActualPosition};
  }

  DriveStatus decode(uint16_t sw) const override {
    DriveStatus s;
    s.fault = (sw & kSwAlarm) != 0;
    s.enabled = !s.fault && (sw & kSwServoOn) != 0;
    s.state = s.fault ? "alarm" : s.enabled ? "servo on" : (sw & kSwReady) ? "ready" : "not ready";
    return s;
  }

  std::optional<ControlWrite> next_write(Goal goal, uint16_t sw, const MasterMemory&,
                                         const DriveProfile&) const override {
    const DriveStatus s = decode(sw);
    if (s.fault) {
      if (goal == Goal::kDisable) return std::nullopt;
      return ControlWrite{Role::kFaultReset, 1};
    }
    if (goal == Goal::kEnable && !s.enabled && (sw & kSwReady)) return ControlWrite{Role::kControlword, 1};
    if (goal != Goal::kEnable && s.enabled) return ControlWrite{Role::kControlword, 0};
    return std::nullopt;
  }

  void drive_power_up(EmulatedDrive& d) const override { d = EmulatedDrive{}; }

  void drive_write(EmulatedDrive& d, Role role, uint16_t v, const DriveProfile&) const override {
    if (role == Role::kFaultReset && v == 1) {
      d.fault = false;
      d.error_code = 0;
      d.state = 0;
    } else if (role == Role::kControlword) {
      d.last_control = v;
      d.state = (v == 1 && !d.fault) ? 1 : 0;
    }
  }

  uint16_t drive_statusword(const EmulatedDrive& d) const override {
    if (d.fault) return kSwAlarm;
    return static_cast<uint16_t>(kSwReady | (d.state == 1 ? kSwServoOn : 0));
  }

  bool drive_follows(const EmulatedDrive& d, const DriveProfile&) const override { return !d.fault && d.state == 1; }

  void drive_fault(EmulatedDrive& d, uint16_t code) const override {
    d.fault = true;
    d.error_code = code;
    d.state = 0;
  }
};

}  // namespace

const ProfileLogic& leadshine_logic() {
  static const LeadshineLogic logic;
  return logic;
}

}  // namespace cnc::drive
