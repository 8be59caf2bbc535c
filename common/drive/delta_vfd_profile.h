#pragma once
// State machine `delta_vfd`: a spindle VFD of the Delta VFD-E / VFD-EL / VFD-M
// family's Modbus map (config/drives/delta_vfd.yaml; LinuxCNC's vfdb_vfd drives the
// same family). Run and direction are a command word written every cycle, not a
// sequence of states:
//   controlword (0x2000)  bits 0-1: 01 stop, 10 run; bits 4-5: 01 forward, 10 reverse
//   speed_setpoint (0x2001)  frequency command, 0.01 Hz
//   fault_reset (0x2002)  bit 1: reset (the drive clears it)
//   error_code (0x2100)   the fault code, 0 when none: the drive stops while it is set
//   statusword (0x2101)   bits 0-1: 00 stopped, 01 decelerating, 11 in operation;
//                         bits 3-4: 00 forward, 11 reverse, 10 forward to reverse,
//                         01 reverse to forward (bit 3: the output turns in reverse,
//                         bit 4: reverse is commanded)
//   actual_speed (0x2103) output frequency, 0.01 Hz; output_current (0x2104), 0.1 A
// Its fault is the error code (the status word has no fault bit), which the spindle
// device reads with every cycle; decode() cannot see it and never reports a fault.
#include <cstdint>

#include "common/drive/profile_logic.h"

namespace cnc::drive {

const ProfileLogic& delta_vfd_logic();
// The command word that runs the drive in `direction` (1 forward, -1 reverse; 0 stop).
uint16_t delta_vfd_command(int direction);
inline constexpr uint16_t kDeltaVfdFaultReset = 1u << 1;
// Whether the status word says the output turns in reverse (bit 3), and whether
// reverse is commanded (bit 4): the two differ while the drive reverses.
inline constexpr uint16_t kDeltaVfdTurnsReverse = 1u << 3;
inline constexpr uint16_t kDeltaVfdCommandedReverse = 1u << 4;
inline bool delta_vfd_reverse(uint16_t statusword) { return (statusword & kDeltaVfdTurnsReverse) != 0; }
// Whether a profile is a spindle drive's (its state machine is delta_vfd, huanyang or
// cia402_velocity, a servo drive in a velocity mode).
bool is_spindle_profile(const DriveProfile& p);

}  // namespace cnc::drive
