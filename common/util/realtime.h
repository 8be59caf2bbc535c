#pragma once
// Real-time scheduling for the cyclic services (interpolator, drive bridge, servo
// simulator): SCHED_FIFO at the given priority and locked memory, so a busy
// shop-floor PC does not stall the servo loop. Needs root or CAP_SYS_NICE.
#include <string>

namespace cnc::util {

// priority 1..98; 0 does nothing. Returns "" on success, else why it failed (the
// service then runs with normal scheduling and says so).
std::string make_realtime(int priority);

}  // namespace cnc::util
