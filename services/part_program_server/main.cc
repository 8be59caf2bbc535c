// cnc-program-server: parses part programs and serves their blocks on request.
#include <cstdio>
#include <string>

#include "cnc/lcmt_heartbeat.hpp"
#include "common/service/heartbeat.h"
#include "common/service/peer_watch.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/signals.h"
#include "services/part_program_server/program_server_node.h"

int main(int argc, char** argv) {
  // --state FILE: the loaded program's path, token and start, so that a restarted
  // server serves the same blocks to the interpolator that still runs them.
  cnc::service::Spec spec{"cnc-program-server", "parses part programs and serves their blocks", 
                          {{"state", "FILE",
                            "keeps the loaded program's path, token and start, so that a restarted server resumes it"}},
                          {{"show-setup", "", "print the settings programs are interpreted with, then exit"}}};
  return cnc::service::run(spec, argc, argv, [](const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
    if (args.flags.count("show-setup") > 0) {  // what cnc-plan --show-setup prints for the dry run
      std::fputs(cnc::pps::describe(cnc::pps::program_setup(cfg)).c_str(), stdout);
      return cnc::service::kExitOk;
    }
    cnc::bus::Bus bus(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-program-server"));
    cnc::pps::ProgramServerNode node(cfg, bus);
    node.use_state_file(args.option("state"));
    cnc::service::Heartbeat hb(bus, cfg, "cnc-program-server");
    // A program of millions of lines validates for seconds: the heartbeat goes on,
    // saying so (cnc-ctl waits for the load's answer while it does).
    node.on_validation_progress([&hb](int64_t blocks) {
      hb.tick(cnc::lcmt_heartbeat::RUNNING, 0, std::string(cnc::service::kValidatingDetail) + std::to_string(blocks) + " blocks");
    });
    // The interpolator requests the blocks: an ALARM naming it when it is lost.
    cnc::service::PeerWatch peers(bus, cfg, "cnc-program-server", {"cnc-interpolator"});
    while (!cnc::util::stop_requested()) {
      if (bus.handle(20) > 0) bus.drain();  // all that is queued before the peers are judged
      node.publish_state(false);
      node.poll(cnc::util::monotonic_s());
      hb.tick(cnc::lcmt_heartbeat::RUNNING, 0);
      peers.check(cnc::util::monotonic_s());
      if (peers.lost(0)) node.interpolator_lost();
    }
    hb.tick(cnc::lcmt_heartbeat::STOPPING, 0, "", true);
    return cnc::service::kExitOk;
  });
}
