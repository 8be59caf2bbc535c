#include "common/util/realtime.h"

#include <sched.h>
#include <sys/mman.h>

#include <cerrno>
#include <cstring>

namespace cnc::util {

std::string make_realtime(int priority) {
  if (priority <= 0) return "";
  sched_param sp{};
  sp.sched_priority = priority;
  if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0) return std::string("SCHED_FIFO: ") + std::strerror(errno);
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) return std::string("mlockall: ") + std::strerror(errno);
  return "";
}

}  // namespace cnc::util
