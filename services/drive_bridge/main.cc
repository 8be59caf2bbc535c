// cnc-drive-bridge: fine interpolation, safety, and Modbus I/O to the servo drives.
#include <spdlog/spdlog.h>

#include <algorithm>

#include "cnc/lcmt_heartbeat.hpp"
#include "common/service/heartbeat.h"
#include "common/service/peer_watch.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/realtime.h"
#include "common/util/signals.h"
#include "services/drive_bridge/drive_bridge_node.h"

int main(int argc, char** argv) {
  // --latency-dir DIR (or $CNC_LATENCY_DIR): where the servo loop's timing goes at the end (cnc-drive-bridge.json).
  cnc::service::Spec spec{"cnc-drive-bridge", "fine interpolation, safety and Modbus I/O to the servo drives",
                          {{"latency-dir", "DIR", "where the servo loop's timing goes at the end (cnc-drive-bridge.json; default $CNC_LATENCY_DIR)"}}, {}};
  return cnc::service::run(spec, argc, argv, [](const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
    // First, so the threads LCM starts (its receive thread) inherit the scheduling,
    // and the Modbus I/O threads too. One priority above the other cyclic services:
    // neither the interpolator's planning nor the simulator may hold up the servo
    // loop or the delivery of setpoints to it.
    const int priority = cfg.realtime_priority > 0 ? std::min(cfg.realtime_priority + 1, 98) : 0;
    cnc::util::apply_realtime("cnc-drive-bridge", priority, cfg.realtime_cpus);
    cnc::bus::Bus bus(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-drive-bridge"));
    cnc::bridge::DriveBridgeNode node(cfg, bus);
    cnc::service::Heartbeat hb(bus, cfg, "cnc-drive-bridge");
    // The interpolator's heartbeat: an ALARM naming it when it is lost (the setpoint
    // watchdog has stopped the axes long before: timing.setpoint_timeout_s).
    cnc::service::PeerWatch peers(bus, cfg, "cnc-drive-bridge", {"cnc-interpolator"});
    node.start();
    cnc::util::PeriodicTimer timer(cfg.servo_period_s);
    while (!cnc::util::stop_requested()) {
      timer.wait();
      if (cnc::util::stop_requested()) break;
      node.servo_tick(cnc::util::monotonic_s());
      node.publish_status(timer.overruns());
      hb.tick(node.ready() ? cnc::lcmt_heartbeat::RUNNING : cnc::lcmt_heartbeat::STARTING, timer.overruns(),
              node.detail());
      peers.check(cnc::util::monotonic_s());
    }
    node.shut_down();
    hb.tick(cnc::lcmt_heartbeat::STOPPING, timer.overruns(), node.detail(), true);
    cnc::util::report_timer_latency("cnc-drive-bridge", "servo cycle (T_servo)", timer, cnc::util::latency_dir(args.option("latency-dir")));
    return cnc::service::kExitOk;
  });
}
