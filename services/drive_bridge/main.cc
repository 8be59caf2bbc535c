// cnc-drive-bridge: fine interpolation and Modbus I/O to the servo drives.
#include "cnc/lcmt_heartbeat.hpp"
#include "common/service/heartbeat.h"
#include "common/service/service.h"
#include <spdlog/spdlog.h>

#include "common/util/clock.h"
#include "common/util/realtime.h"
#include "common/util/signals.h"
#include "services/drive_bridge/drive_bridge_node.h"

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-drive-bridge", "fine interpolation and Modbus I/O to the servo drives", {}, {}};
  return cnc::service::run(spec, argc, argv, [](const cnc::config::MachineConfig& cfg, const cnc::service::Args&) {
    // First, so the threads LCM starts (its receive thread) inherit the scheduling.
    if (const std::string why = cnc::util::make_realtime(cfg.realtime_priority); !why.empty())
      spdlog::warn("real-time scheduling not available ({}): running with normal scheduling", why);
    cnc::bus::Bus bus(cfg.lcm_url);
    cnc::bridge::DriveBridgeNode node(cfg, bus);
    cnc::service::Heartbeat hb(bus, cfg, "cnc-drive-bridge");
    cnc::util::PeriodicTimer timer(cfg.servo_period_s);
    while (!cnc::util::stop_requested()) {
      timer.wait();
      if (cnc::util::stop_requested()) break;
      const double now = cnc::util::monotonic_s();
      if (!node.up()) node.bring_up(now);
      node.servo_tick(now);
      node.publish_status(timer.overruns());
      hb.tick(node.up() ? cnc::lcmt_heartbeat::RUNNING : cnc::lcmt_heartbeat::STARTING, timer.overruns());
    }
    node.shut_down();
    hb.tick(cnc::lcmt_heartbeat::STOPPING, timer.overruns(), "", true);
    return cnc::service::kExitOk;
  });
}
