#pragma once
// State machine `sim`: the simulator's own drive (config/drives/sim.yaml).
//   controlword bit 0 enable operation, bit 7 fault reset (rising edge)
//   statusword  bit 0 operation enabled, bit 3 fault
#include "common/drive/profile_logic.h"

namespace cnc::drive {

const ProfileLogic& sim_logic();

}  // namespace cnc::drive
