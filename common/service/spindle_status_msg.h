#pragma once
// SPINDLE_STATUS across log formats (common/bus/log_format.h): format 4 added the
// encoder's position and the orientation's state; logs of formats 1 to 3 hold the
// message without them (lcmt_spindle_status_v1, the same fields as then, so the same
// fingerprint). A reader of logs takes either.
#include <cstddef>

#include "cnc/lcmt_spindle_status.hpp"
#include "cnc/lcmt_spindle_status_v1.hpp"

namespace cnc::service {

// The fields a v1 message has; of the others, position_valid false,
// sample_playback_cycle -1 and orient_state ORIENT_NONE.
cnc::lcmt_spindle_status from_v1(const cnc::lcmt_spindle_status_v1& v);
// A SPINDLE_STATUS datagram of any format (a signed cell's trailer after the message);
// false when it is neither.
bool decode_spindle_status(const void* data, size_t size, cnc::lcmt_spindle_status* out);

}  // namespace cnc::service
