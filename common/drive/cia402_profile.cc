#include "common/drive/cia402_profile.h"

#include <utility>

namespace cnc::drive {
namespace cia402 {

State state_of(uint16_t sw) {
  if ((sw & 0x4F) == 0x00) return kNotReadyToSwitchOn;
  if ((sw & 0x4F) == 0x40) return kSwitchOnDisabled;
  if ((sw & 0x6F) == 0x21) return kReadyToSwitchOn;
  if ((sw & 0x6F) == 0x23) return kSwitchedOn;
  if ((sw & 0x6F) == 0x27) return kOperationEnabled;
  if ((sw & 0x6F) == 0x07) return kQuickStopActive;
  if ((sw & 0x4F) == 0x0F) return kFaultReactionActive;
  if ((sw & 0x4F) == 0x08) return kFault;
  return kNotReadyToSwitchOn;
}

}  // namespace cia402

namespace {
using namespace cia402;

constexpr const char* kStateNames[] = {"not ready to switch on", "switch on disabled", "ready to switch on",
                                       "switched on", "operation enabled", "quick stop active",
                                       "fault reaction active", "fault"};
constexpr uint16_t kSwRemote = 1u << 9;
// 0x60B8: bit 0 TP1 on, bit 1 continuous (every edge, not the first only), bits 2-3 the
// TP1 input as trigger (0), bit 4 latch at the rising edge, bit 5 at the falling edge.
constexpr uint16_t kTouchProbeBothEdges = 0x0033;

// One state machine, two uses: an axis drive in a position mode (`cia402`) and a
// spindle drive in a velocity mode (`cia402_velocity`); only their name and the
// registers their cyclic data needs differ.
class Cia402Logic final : public ProfileLogic {
 public:
  Cia402Logic(const char* name, std::vector<Role> required) : name_(name), required_(std::move(required)) {}
  const char* name() const override { return name_; }
  std::vector<Role> required_roles() const override { return required_; }

  DriveStatus decode(uint16_t sw) const override {
    const State st = state_of(sw);
    DriveStatus s;
    s.fault = st == kFault || st == kFaultReactionActive;
    s.enabled = st == kOperationEnabled;
    s.state = kStateNames[st];
    return s;
  }

  std::optional<ControlWrite> next_write(Goal goal, uint16_t sw, const MasterMemory& m,
                                         const DriveProfile& p) const override {
    const State st = state_of(sw);
    if (st == kFaultReactionActive || st == kNotReadyToSwitchOn) return std::nullopt;  // the drive moves on by itself
    if (st == kFault) {
      if (goal == Goal::kDisable) return std::nullopt;
      return ControlWrite{Role::kControlword, (m.last_control & kCwFaultReset) ? kCwDisableVoltage : kCwFaultReset};
    }
    if (goal != Goal::kEnable) {
      if (st == kOperationEnabled || st == kSwitchedOn) return ControlWrite{Role::kControlword, kCwShutdown};
      if (st == kQuickStopActive) return ControlWrite{Role::kControlword, kCwDisableVoltage};
      return std::nullopt;
    }
    if (!m.mode_written) return ControlWrite{Role::kMode, static_cast<uint16_t>(static_cast<int16_t>(p.mode_of_operation))};
    if (p.has(Role::kProbeFunction) && !m.probe_armed) return ControlWrite{Role::kProbeFunction, kTouchProbeBothEdges};
    switch (st) {
      case kSwitchOnDisabled: return ControlWrite{Role::kControlword, kCwShutdown};
      case kReadyToSwitchOn: return ControlWrite{Role::kControlword, kCwSwitchOn};
      case kSwitchedOn: return ControlWrite{Role::kControlword, kCwEnableOperation};
      case kQuickStopActive: return ControlWrite{Role::kControlword, kCwDisableVoltage};
      default: return std::nullopt;
    }
  }

  void drive_power_up(EmulatedDrive& d) const override {
    d = EmulatedDrive{};
    d.state = kSwitchOnDisabled;  // not ready to switch on passes at power-up
  }

  void drive_write(EmulatedDrive& d, Role role, uint16_t v, const DriveProfile&) const override {
    if (role == Role::kMode) {
      d.mode = static_cast<int16_t>(v);
      return;
    }
    if (role != Role::kControlword) return;
    const bool reset_edge = (v & kCwFaultReset) && !(d.last_control & kCwFaultReset);
    d.last_control = v;
    if (d.state == kFault) {
      if (reset_edge) {
        d.state = kSwitchOnDisabled;
        d.fault = false;
        d.error_code = 0;
      }
      return;
    }
    if ((v & 0x02) == 0) {  // disable voltage
      d.state = kSwitchOnDisabled;
    } else if ((v & 0x06) == 0x02) {  // quick stop
      d.state = d.state == kOperationEnabled ? kQuickStopActive : kSwitchOnDisabled;
    } else if ((v & 0x0F) == 0x06) {  // shutdown
      d.state = kReadyToSwitchOn;
    } else if ((v & 0x0F) == 0x07) {  // switch on / disable operation
      if (d.state == kReadyToSwitchOn || d.state == kOperationEnabled) d.state = kSwitchedOn;
    } else if ((v & 0x0F) == 0x0F) {  // enable operation
      if (d.state == kSwitchedOn || d.state == kQuickStopActive) d.state = kOperationEnabled;
    }
  }

  uint16_t drive_statusword(const EmulatedDrive& d) const override {
    static constexpr uint16_t kBits[] = {0x0000, 0x0040, 0x0031, 0x0033, 0x0037, 0x0017, 0x001F, 0x0008};
    return static_cast<uint16_t>(kBits[d.state] | kSwRemote);
  }

  bool drive_follows(const EmulatedDrive& d, const DriveProfile& p) const override {
    return d.state == kOperationEnabled && d.mode == p.mode_of_operation;
  }

  void drive_fault(EmulatedDrive& d, uint16_t code) const override {
    d.state = kFault;
    d.fault = true;
    d.error_code = code;
  }

 private:
  const char* name_;
  std::vector<Role> required_;
};

}  // namespace

const ProfileLogic& cia402_logic() {
  static const Cia402Logic logic("cia402", {Role::kControlword, Role::kStatusword, Role::kMode, Role::kTargetPosition,
                                            Role::kActualPosition});
  return logic;
}

const ProfileLogic& cia402_velocity_logic() {
  static const Cia402Logic logic("cia402_velocity", {Role::kControlword, Role::kStatusword, Role::kMode,
                                                     Role::kSpeedSetpoint, Role::kActualSpeed});
  return logic;
}

}  // namespace cnc::drive
