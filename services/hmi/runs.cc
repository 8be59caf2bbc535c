#include "services/hmi/runs.h"

#include <lcm/eventlog.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"

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

RunPath log_path(const std::string& path, double tol_mm, double max_gap_s, size_t max_points) {
  RunPath r;
  lcm_eventlog_t* log = lcm_eventlog_create(path.c_str(), "r");
  if (log == nullptr) {
    r.error = "cannot read " + path;
    return r;
  }
  int64_t first_cycle = -1, last_cycle = -1;
  double period = 0, lx = 1e300, ly = 1e300, lz = 1e300, lt = -1e300;
  cnc::lcmt_setpoint sp;
  while (lcm_eventlog_event_t* e = lcm_eventlog_read_next_event(log)) {
    if (ends_with(e->channel, "SETPOINTS")) {
      try {
        if (sp.decode(e->data, 0, static_cast<int>(e->datalen)) >= 0 && sp.num_axes >= 2 &&
            sp.cycle > last_cycle) {  // a late or repeated setpoint adds nothing
          ++r.setpoints;
          if (first_cycle < 0) first_cycle = sp.cycle;
          last_cycle = sp.cycle;
          period = sp.period_s;
          const double t = static_cast<double>(sp.cycle - first_cycle) * sp.period_s;
          const double x = sp.position_mm[0], y = sp.position_mm[1], z = sp.num_axes > 2 ? sp.position_mm[2] : 0.0;
          if (std::fabs(x - lx) + std::fabs(y - ly) + std::fabs(z - lz) >= tol_mm || t - lt >= max_gap_s) {
            lx = x, ly = y, lz = z, lt = t;
            r.xyz.insert(r.xyz.end(), {x, y, z});
            r.t_s.push_back(t);
            r.lines.push_back(sp.source_line);
            if (r.t_s.size() > max_points) {
              std::vector<double> xyz, ts;
              std::vector<int> ln;
              for (size_t i = 0; i < r.t_s.size(); i += 2) {
                xyz.insert(xyz.end(), {r.xyz[3 * i], r.xyz[3 * i + 1], r.xyz[3 * i + 2]});
                ts.push_back(r.t_s[i]);
                ln.push_back(r.lines[i]);
              }
              r.xyz.swap(xyz);
              r.t_s.swap(ts);
              r.lines.swap(ln);
              tol_mm *= 2;
              max_gap_s *= 2;
            }
          }
        }
      } catch (...) {
      }
    }
    lcm_eventlog_free_event(e);
  }
  lcm_eventlog_destroy(log);
  r.ok = true;
  if (first_cycle >= 0) r.duration_s = static_cast<double>(last_cycle - first_cycle) * period;
  return r;
}

}  // namespace cnc::hmi
