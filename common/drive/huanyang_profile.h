#pragma once
// State machine `huanyang`: a spindle VFD of the Huanyang HY series, which speaks
// frames of its own (huanyang_frame.h), not Modbus registers; its data (status
// indices, scales, the PD parameters it must have) are the profile's `huanyang:`
// section (config/drives/huanyang.yaml). Run and direction are one command byte
// (function 0x03) written every cycle, as LinuxCNC's hy_vfd writes them:
//   0x01 run forward, 0x11 run reverse, 0x08 stop
// and its reply is the drive's status byte (CNST):
//   bit 0 run commanded, 1 jog, 2 reverse commanded, 3 running, 4 jogging,
//   5 the output turns in reverse, 6 braking, 7 track start.
// The protocol has no fault code and no fault reset: a tripped drive stops and
// shows its code on its panel; the status byte then says it does not run.
#include <cstdint>

#include "common/drive/profile_logic.h"

namespace cnc::drive {

const ProfileLogic& huanyang_logic();
// The command byte that runs the drive in `direction` (1 forward, -1 reverse; 0 stop).
uint8_t huanyang_command(int direction);
inline constexpr uint8_t kHyRunCommanded = 0x01;
inline constexpr uint8_t kHyReverseCommanded = 0x04;
inline constexpr uint8_t kHyRunning = 0x08;
inline constexpr uint8_t kHyTurnsReverse = 0x20;

}  // namespace cnc::drive
