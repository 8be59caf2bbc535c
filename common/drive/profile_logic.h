#pragma once
// The part of a drive profile that is code: how a drive is enabled, disabled and
// reset from its faults, seen from both ends of the wire. The master side (the
// bridge) turns the drive's statusword and a goal into at most one register write
// per cycle; the drive side (the simulator and the loopback link) reacts to those
// writes and produces the statusword. One implementation per `state_machine`:
// sim_profile.cc, cia402_profile.cc, leadshine_profile.cc.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "common/drive/drive_profile.h"

namespace cnc::drive {

enum class Goal : int8_t { kDisable, kEnable, kFaultReset };

struct DriveStatus {
  bool enabled = false;  // following its target
  bool fault = false;
  const char* state = "unknown";  // the drive state by its profile's name for it
};

struct ControlWrite {
  Role role;
  uint16_t value;
};

// What the master remembers between steps (edges, the mode written once).
struct MasterMemory {
  uint16_t last_control = 0;
  bool mode_written = false;
  bool probe_armed = false;  // the touch probe's function written (kProbeFunction)
};

// The emulated drive's internal state.
struct EmulatedDrive {
  int state = 0;  // profile-specific
  bool fault = false;
  uint16_t error_code = 0;
  uint16_t last_control = 0;
  int mode = 0;
};

class ProfileLogic {
 public:
  virtual ~ProfileLogic() = default;
  virtual const char* name() const = 0;
  virtual std::vector<Role> required_roles() const = 0;

  // Master side.
  virtual DriveStatus decode(uint16_t statusword) const = 0;
  // The next write toward `goal`; nullopt when there is nothing to do (goal reached,
  // or the drive is in a transient state the master waits out).
  virtual std::optional<ControlWrite> next_write(Goal goal, uint16_t statusword, const MasterMemory& m,
                                                 const DriveProfile& p) const = 0;

  // Drive side.
  virtual void drive_power_up(EmulatedDrive& d) const = 0;
  virtual void drive_write(EmulatedDrive& d, Role role, uint16_t value, const DriveProfile& p) const = 0;
  virtual uint16_t drive_statusword(const EmulatedDrive& d) const = 0;
  virtual bool drive_follows(const EmulatedDrive& d, const DriveProfile& p) const = 0;
  // A fault raised inside the drive (fault injection): it stops following.
  virtual void drive_fault(EmulatedDrive& d, uint16_t code) const = 0;
};

// The drive side every VFD's logic shares: EmulatedDrive::state bit 0 is run
// commanded, bit 1 reverse; the output runs while commanded and not faulted, and a
// fault stops it.
class VfdLogic : public ProfileLogic {
 public:
  static constexpr int kStRun = 1;
  static constexpr int kStReverse = 2;
  void drive_power_up(EmulatedDrive& d) const override { d = EmulatedDrive{}; }
  bool drive_follows(const EmulatedDrive& d, const DriveProfile&) const override {
    return !d.fault && (d.state & kStRun) != 0;
  }
  void drive_fault(EmulatedDrive& d, uint16_t code) const override {
    d.fault = true;
    d.error_code = code;
    d.state &= ~kStRun;
  }
};

// The logic of a state machine by name; nullptr when there is none of that name.
const ProfileLogic* find_profile_logic(const std::string& state_machine);
const ProfileLogic& profile_logic(const DriveProfile& p);
std::vector<std::string> profile_logic_names();

}  // namespace cnc::drive
