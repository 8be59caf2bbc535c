#pragma once
// Publishes a service's heartbeat with the bus's per-channel counters.
#include <string>

#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/service/bus_health.h"

namespace cnc::service {

// The program server's heartbeat detail while a load validates: "validating: N blocks".
inline constexpr const char* kValidatingDetail = "validating: ";

class Heartbeat {
 public:
  Heartbeat(bus::Bus& bus, const config::MachineConfig& cfg, std::string service_name);
  // Publishes when a heartbeat period has passed since the last one (or `force`).
  // Every call also raises the rate-limited ALARMs of messages the bus dropped
  // (signed channels; see RejectAlarms): every service ticks its heartbeat.
  void tick(int8_t state, int64_t loop_overruns, const std::string& detail = "", bool force = false);

 private:
  bus::Bus& bus_;
  std::string channel_;
  std::string name_;
  std::string host_;  // gethostname(), once
  double period_s_;
  double last_s_ = -1e9;
  RejectAlarms rejects_;
};

}  // namespace cnc::service
