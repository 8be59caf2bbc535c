// cnc-monitor: live feed and following error; alarms on stream gaps.
#include <spdlog/spdlog.h>

#include <cmath>
#include <limits>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_monitor_report.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/service/heartbeat.h"
#include "common/service/service.h"
#include "common/util/signals.h"
#include "services/monitor/monitor.h"

namespace ch = cnc::config::channels;

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-monitor", "live feed and following-error monitor with alarms", {}, {}};
  return cnc::service::run(spec, argc, argv, [](const cnc::config::MachineConfig& cfg, const cnc::service::Args&) {
    cnc::bus::Bus bus(cfg.lcm_url);
    cnc::monitor::FeedMonitor core(cfg.ipo_period_s);
    const std::string ch_report = cfg.channel(ch::kMonitor), ch_alarm = cfg.channel(ch::kAlarm);
    double spindle = cfg.process.spindle_rpm;
    bus.subscribe<cnc::lcmt_setpoint>(cfg.channel(ch::kSetpoints),
                                      [&](const cnc::lcmt_setpoint& m) { core.on_commanded_feed(m.feed_mm_per_min); });
    bus.subscribe<cnc::lcmt_axis_status>(cfg.channel(ch::kAxisStatus), [&](const cnc::lcmt_axis_status& m) {
      const auto s = core.on_status(m.setpoint_cycle, m.actual_mm, m.following_error_mm);
      cnc::lcmt_monitor_report r{};
      r.setpoint_cycle = m.setpoint_cycle;
      r.commanded_feed_mm_per_min = s.commanded_feed_mm_per_min;
      r.actual_feed_mm_per_min = s.actual_feed_mm_per_min;
      // Chord error and R_max need the block geometry and the roughness model: not known here yet.
      r.chord_error_mm = std::numeric_limits<double>::quiet_NaN();
      r.predicted_rmax_um = std::numeric_limits<double>::quiet_NaN();
      r.spindle_rpm = spindle;
      r.num_axes = m.num_axes;
      r.following_error_mm = m.following_error_mm;
      r.max_following_error_mm = s.max_following_error_mm;
      bus.publish(ch_report, r);
    });
    cnc::service::Heartbeat hb(bus, cfg, "cnc-monitor");
    std::map<std::string, int64_t> gaps_reported;
    while (!cnc::util::stop_requested()) {
      bus.handle(20);
      for (const auto& [channel, st] : bus.stats()) {
        int64_t& seen = gaps_reported[channel];
        if (st.seq_gaps > seen) {
          cnc::lcmt_alarm al{};
          al.source = "cnc-monitor";
          al.severity = cnc::lcmt_alarm::WARNING;
          al.code = "seq_gap";
          al.text = channel + ": " + std::to_string(st.seq_gaps - seen) + " message(s) lost (total " +
                    std::to_string(st.seq_gaps) + ")";
          spdlog::warn("{}", al.text);
          seen = st.seq_gaps;
          bus.publish(ch_alarm, al);
        }
      }
      hb.tick(cnc::lcmt_heartbeat::RUNNING, 0);
    }
    hb.tick(cnc::lcmt_heartbeat::STOPPING, 0, "", true);
    return cnc::service::kExitOk;
  });
}
