// cnc-interpolator: turns program blocks into coarse axis setpoints every T_ipo.
#include "cnc/lcmt_heartbeat.hpp"
#include "common/bus/bus.h"
#include "common/service/heartbeat.h"
#include "common/service/service.h"
#include <spdlog/spdlog.h>

#include "common/util/clock.h"
#include "common/util/realtime.h"
#include "common/util/signals.h"
#include "services/interpolator/interpolator_node.h"

int main(int argc, char** argv) {
  // --latency-dir DIR (or $CNC_LATENCY_DIR): where the cycle timing goes at the end (cnc-interpolator.json).
  cnc::service::Spec spec{"cnc-interpolator", "coarse interpolation of program blocks into axis setpoints",
                          {{"latency-dir", "DIR", "where the cycle timing goes at the end (cnc-interpolator.json; default $CNC_LATENCY_DIR)"}}, {}};
  return cnc::service::run(spec, argc, argv, [](const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
    // First, so the threads LCM starts (its receive thread) inherit the scheduling and the CPUs.
    cnc::util::apply_realtime("cnc-interpolator", cfg.realtime_priority, cfg.realtime_cpus);
    cnc::bus::Bus bus(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-interpolator"));
    cnc::interp::InterpolatorNode node(cfg, bus);
    // No page fault in the cycles: memory locked where permitted, the stack touched (the
    // rings are touched when they are made). The bench does the same.
    if (const std::string why = cnc::util::prepare_cyclic_memory(); !why.empty())
      spdlog::info("cnc-interpolator: memory not locked ({}); the stack and the rings are touched", why);
    cnc::service::Heartbeat hb(bus, cfg, "cnc-interpolator");
    cnc::util::PeriodicTimer timer(cfg.ipo_period_s);
    while (!cnc::util::stop_requested()) {
      timer.wait();
      if (cnc::util::stop_requested()) break;
      node.cycle();  // never throws: a fault stops the program and waits for RESET
      hb.tick(cnc::lcmt_heartbeat::RUNNING, timer.overruns(), node.detail());
    }
    node.publish_state(true);
    hb.tick(cnc::lcmt_heartbeat::STOPPING, timer.overruns(), "", true);
    cnc::util::report_timer_latency("cnc-interpolator", "interpolation cycle (T_ipo)", timer, cnc::util::latency_dir(args.option("latency-dir")));
    return cnc::service::kExitOk;
  });
}
