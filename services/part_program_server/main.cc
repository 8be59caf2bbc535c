// cnc-program-server: parses part programs and serves their blocks on request.
#include "cnc/lcmt_heartbeat.hpp"
#include "common/service/heartbeat.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/signals.h"
#include "services/part_program_server/program_server_node.h"

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-program-server", "parses part programs and serves their blocks", {}, {}};
  return cnc::service::run(spec, argc, argv, [](const cnc::config::MachineConfig& cfg, const cnc::service::Args&) {
    cnc::bus::Bus bus(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-program-server"));
    cnc::pps::ProgramServerNode node(cfg, bus);
    cnc::service::Heartbeat hb(bus, cfg, "cnc-program-server");
    while (!cnc::util::stop_requested()) {
      bus.handle(20);
      node.publish_state(false);
      node.poll(cnc::util::monotonic_s());
      hb.tick(cnc::lcmt_heartbeat::RUNNING, 0);
    }
    hb.tick(cnc::lcmt_heartbeat::STOPPING, 0, "", true);
    return cnc::service::kExitOk;
  });
}
