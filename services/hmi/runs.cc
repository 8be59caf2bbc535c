#include "services/hmi/runs.h"

#include <lcm/eventlog.h>

#include <algorithm>
#include <cstring>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_program_state.hpp"

namespace cnc::hmi {

namespace {
bool ends_with(const char* s, const char* tail) {
  const size_t n = std::strlen(s), m = std::strlen(tail);
  return n >= m && std::strcmp(s + n - m, tail) == 0;
}
}  // namespace

RunSummary summarize_log(const std::string& path) {
  RunSummary r;
  lcm_eventlog_t* log = lcm_eventlog_create(path.c_str(), "r");
  if (log == nullptr) {
    r.error = "cannot read " + path;
    return r;
  }
  int64_t first = -1, last = -1;
  int64_t last_token = 0;
  while (lcm_eventlog_event_t* e = lcm_eventlog_read_next_event(log)) {
    ++r.events;
    if (first < 0) first = e->timestamp;
    last = e->timestamp;
    // Decoded from the bytes before a signature trailer: LCM's decode reads only its fields.
    const int len = static_cast<int>(e->datalen);
    if (ends_with(e->channel, "ALARM")) {
      cnc::lcmt_alarm a;
      try {
        if (a.decode(e->data, 0, len) >= 0) {
          ++r.alarms;
          if (a.severity == cnc::lcmt_alarm::FAULT) ++r.faults;
        }
      } catch (...) {
      }
    } else if (ends_with(e->channel, "PROGRAM_STATE")) {
      cnc::lcmt_program_state s;
      try {
        if (s.decode(e->data, 0, len) >= 0 && s.state == cnc::lcmt_program_state::LOADED &&
            s.program_token != last_token) {
          last_token = s.program_token;
          const size_t slash = s.program_path.rfind('/');
          const std::string name = slash == std::string::npos ? s.program_path : s.program_path.substr(slash + 1);
          if (name.rfind("mdi-", 0) == 0) {
            ++r.mdi_lines;
          } else if (r.programs.empty() || r.programs.back() != s.program_path) {
            r.programs.push_back(s.program_path);
          }
        }
      } catch (...) {
      }
    }
    lcm_eventlog_free_event(e);
  }
  lcm_eventlog_destroy(log);
  r.ok = true;
  if (first >= 0) {
    r.start_utime_s = static_cast<double>(first) * 1e-6;
    r.duration_s = static_cast<double>(last - first) * 1e-6;
  }
  return r;
}

}  // namespace cnc::hmi
