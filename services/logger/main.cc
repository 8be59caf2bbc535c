// cnc-logger: records every channel of the cell into standard LCM log files.
#include <spdlog/spdlog.h>
#include <sys/stat.h>

#include <ctime>
#include <filesystem>

#include "cnc/lcmt_heartbeat.hpp"
#include "common/service/heartbeat.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/signals.h"
#include "services/logger/log_writer.h"

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-logger", "records every channel of the cell into LCM log files", {"out"}, {}};
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
    cnc::bus::Bus bus(cfg.lcm_url);
    cnc::logger::LogWriter writer(base, cfg.log_rotate_mb * 1024 * 1024);
    spdlog::info("cnc-logger: writing {}", writer.current_path());
    bus.subscribe_raw(cnc::bus::exact_channel(cfg.channel_prefix) + ".*",
                      [&](const std::string& channel, const void* data, size_t size, int64_t recv_utime) {
                        writer.write(channel, data, size, recv_utime);
                      });
    cnc::service::Heartbeat hb(bus, cfg, "cnc-logger");
    double last_flush = cnc::util::monotonic_s();
    while (!cnc::util::stop_requested()) {
      bus.handle(20);
      const double now = cnc::util::monotonic_s();
      if (now - last_flush >= cfg.log_flush_period_s) {
        writer.flush();
        last_flush = now;
      }
      hb.tick(cnc::lcmt_heartbeat::RUNNING, writer.dropped(), writer.current_path());
    }
    // Take what is already queued, then close cleanly.
    bus.drain();
    hb.tick(cnc::lcmt_heartbeat::STOPPING, writer.dropped(), writer.current_path(), true);
    bus.drain();
    writer.close();
    spdlog::info("cnc-logger: {} events in {} file(s), last {}", writer.events(), writer.files(), writer.current_path());
    return cnc::service::kExitOk;
  });
}
