#pragma once
// The hard-limit switch a jog must not move towards: the one IO_STATUS names while a
// limit reads 0 (on it, tripped, or the chain disabled). The program server's interlock
// refuses such a jog, and the interpolator refuses it too: it reads PROGRAM_CMD itself,
// and a jog it began before the refusal reached the operator was the bridge's to stop,
// with a fault (integration.limits, 1 run in a fresh clone: exit 5 instead of 3).
#include <string>

#include "cnc/lcmt_io_status.hpp"
#include "common/config/machine_config.h"

namespace cnc::service {

struct OpenLimit {
  int axis = -1;   // -1: none
  int side = 0;    // +1 the max end, -1 the min end
  std::string name;  // the input's label
};

inline OpenLimit open_limit(const config::MachineConfig& cfg, const cnc::lcmt_io_status& m) {
  using I = cnc::lcmt_io_status;
  OpenLimit o;
  if (m.limit != I::LIMIT_ON_SWITCH && m.limit != I::LIMIT_TRIPPED && m.limit != I::LIMIT_DISABLED) return o;
  const int point = cfg.io.point_index(m.limit_input);
  for (const auto& h : cfg.safety.hard_limits) {
    if (point < 0 || (point != h.min_input && point != h.max_input)) continue;
    o.axis = h.axis;
    o.side = point == h.max_input ? 1 : -1;
    o.name = m.limit_input;
  }
  return o;
}

}  // namespace cnc::service
