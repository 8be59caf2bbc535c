// cnc-logger: records every channel of the cell into standard LCM log files, with
// its own counts (lcmt_logger_stats on PREFIX + "LOGGER_STATS") written into them.
#include <spdlog/spdlog.h>

#include <algorithm>

#include <ctime>
#include <filesystem>

#include "cnc/lcmt_heartbeat.hpp"
#include "common/bus/log_format.h"
#include "common/service/heartbeat.h"
#include "common/service/service.h"
#include "common/util/realtime.h"
#include "common/util/clock.h"
#include "common/util/signals.h"
#include "services/logger/log_writer.h"
#include "services/logger/logger_node.h"

namespace {
constexpr int64_t kReceiveBufferBytes = 8 * 1024 * 1024;
}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-logger", "records every channel of the cell into LCM log files", 
                          {{"out", "BASE", "the log's path without .lcmlog (default: the config's DIR/CELL-YYYYmmdd-HHMMSS)"}},
                          {}};
  return cnc::service::run(spec, argc, argv, [](const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
    // --out BASE (without .lcmlog) overrides DIR/CELL-YYYYmmdd-HHMMSS from the config.
    std::string base = args.option("out");
    if (base.empty()) {
      char stamp[32];
      const std::time_t t = std::time(nullptr);
      std::tm tm{};
      gmtime_r(&t, &tm);
      std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", &tm);
      base = cfg.log_directory + "/" + cfg.name + "-" + stamp;
    }
    const auto dir = std::filesystem::path(base).parent_path();
    if (!dir.empty()) std::filesystem::create_directories(dir);
    // Above ordinary load, below the cyclic services; first, so LCM's receive thread inherits it.
    if (const std::string why = cnc::util::make_realtime(std::max(0, cfg.realtime_priority - 5)); !why.empty())
      spdlog::warn("real-time scheduling not available ({}): running with normal scheduling", why);
    // A deep queue: the logger must ride out a stalled write without dropping (~10 s at 2 kHz).
    cnc::bus::Bus bus(cnc::logger::receive_url(cfg.lcm_url, kReceiveBufferBytes), 0, 20000,
                      cnc::service::bus_security(cfg, "cnc-logger"));
    cnc::logger::LogWriter writer(base, cfg.log_rotate_mb * 1024 * 1024, cnc::logger::LogWriter::kDefaultBufferBytes,
                                  cnc::bus::log_format_record());
    cnc::logger::LoggerNode node(cfg, bus, writer);
    spdlog::info("cnc-logger: writing {}", writer.current_path());
    cnc::service::Heartbeat hb(bus, cfg, "cnc-logger");
    while (!cnc::util::stop_requested()) {
      bus.handle(20);
      node.tick(cnc::util::monotonic_s());
      hb.tick(cnc::lcmt_heartbeat::RUNNING, writer.dropped(), writer.current_path());
    }
    // Take what is already queued, then close cleanly with the stats as the last event.
    bus.drain();
    hb.tick(cnc::lcmt_heartbeat::STOPPING, writer.dropped(), writer.current_path(), true);
    bus.drain();
    node.close();
    spdlog::info("cnc-logger: {} events in {} file(s), {} dropped, last {}", writer.events(), writer.files(),
                 writer.dropped(), writer.current_path());
    return cnc::service::kExitOk;
  });
}
