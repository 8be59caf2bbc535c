#pragma once
// State machine `cia402`: the CiA 402 power drive system state machine over Modbus
// registers. Enable: shutdown 0x06 -> switch on 0x07 -> enable operation 0x0F, with
// the mode of operation written first; fault reset: a rising edge of controlword
// bit 7 (0x80). States from the statusword (CiA 402 masks 0x4F / 0x6F).
//
// State machine `cia402_velocity`: the same, for a spindle drive in a velocity mode
// (mode_of_operation 3, profile velocity; config/drives/cia402_spindle.yaml): it
// needs the target velocity (speed_setpoint, 0x60FF) and the velocity actual value
// (actual_speed, 0x606C) instead of the positions; the drive follows its target
// velocity while operation is enabled in that mode.
#include "common/drive/profile_logic.h"

namespace cnc::drive {

const ProfileLogic& cia402_logic();
const ProfileLogic& cia402_velocity_logic();

// CiA 402 controlword commands and drive states.
namespace cia402 {
inline constexpr uint16_t kCwDisableVoltage = 0x00;
inline constexpr uint16_t kCwShutdown = 0x06;
inline constexpr uint16_t kCwSwitchOn = 0x07;
inline constexpr uint16_t kCwEnableOperation = 0x0F;
inline constexpr uint16_t kCwFaultReset = 0x80;
enum State : int {
  kNotReadyToSwitchOn,
  kSwitchOnDisabled,
  kReadyToSwitchOn,
  kSwitchedOn,
  kOperationEnabled,
  kQuickStopActive,
  kFaultReactionActive,
  kFault
};
State state_of(uint16_t statusword);
}  // namespace cia402

}  // namespace cnc::drive
