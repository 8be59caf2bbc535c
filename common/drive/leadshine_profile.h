#pragma once
// State machine `leadshine`: a servo-on register and a separate alarm-clear
// register, in the style of Leadshine's EL-series Modbus drives.
//   controlword (servo on)  1 on, 0 off
//   fault_reset (alarm clear)  write 1; the drive clears the alarm and the register
//   statusword  bit 0 ready (no alarm), bit 1 servo on, bit 2 alarm
#include "common/drive/profile_logic.h"

namespace cnc::drive {

const ProfileLogic& leadshine_logic();

}  // namespace cnc::drive
