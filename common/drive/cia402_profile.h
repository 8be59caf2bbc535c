#pragma once
// State machine `cia402`: the CiA 402 power drive system state machine over Modbus
// registers. Enable: shutdown 0x06 -> switch on 0x07 -> enable operation 0x0F, with
// the mode of operation written first; fault reset: a rising edge of controlword
// bit 7 (0x80). States from the statusword (CiA 402 masks 0x4F / 0x6F).
#include "common/drive/profile_logic.h"

namespace cnc::drive {

const ProfileLogic& cia402_logic();

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
