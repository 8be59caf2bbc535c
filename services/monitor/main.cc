// cnc-monitor: live feed, chord error against the exact block geometry, predicted
// R_max (Choi et al. 2005), following error and, with `cutting:`, cutting force and tool
// deflection (VMCS 1999); alarms on R_max over target, chord error over ε, deflection
// over its tolerance, and sequence gaps in any stream it reads.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_joint_status.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_interp_input.hpp"
#include "cnc/lcmt_monitor_report.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/program/block_msg.h"
#include "common/service/heartbeat.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/realtime.h"
#include "common/util/signals.h"
#include "services/monitor/monitor.h"

namespace ch = cnc::config::channels;

int main(int argc, char** argv) {
  // --latency-dir DIR (or $CNC_LATENCY_DIR): where the timing of its status handling goes at the end (cnc-monitor.json).
  cnc::service::Spec spec{"cnc-monitor", "feed, chord error, predicted roughness and following error, with alarms",
                          {{"latency-dir", "DIR", "where the status handling's timing goes at the end (cnc-monitor.json; default $CNC_LATENCY_DIR)"}}, {}};
  return cnc::service::run(spec, argc, argv, [](const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
    // Below the cyclic services, above ordinary load: a starved monitor loses messages.
    // Not pinned: it is event-driven, and may use whatever CPU the cyclic services leave.
    cnc::util::apply_realtime("cnc-monitor", std::max(0, cfg.realtime_priority - 10), {});
    // The monitor has no timer: its cycle is one AXIS_STATUS (every T_ipo). "Wake-up" is
    // that message's delivery latency (its utime, stamped by the bridge, to the handler's
    // start, on the wall clock: exact on one host, offset by clock skew across hosts),
    // compute the handler's time.
    cnc::util::LatencyHistogram delivery, handling;
    cnc::bus::Bus bus(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-monitor"));
    cnc::monitor::Monitor core(cfg);
    const std::string ch_report = cfg.channel(ch::kMonitor), ch_alarm = cfg.channel(ch::kAlarm);
    const int naxes = static_cast<int>(cfg.axes.size());
    auto raise = [&](const std::string& code, const std::string& text, int8_t severity) {
      cnc::lcmt_alarm al{};
      al.source = "cnc-monitor";
      al.severity = severity;
      al.code = code;
      al.text = text;
      spdlog::warn("{}: {}", code, text);
      bus.publish(ch_alarm, al);
    };
    bus.subscribe<cnc::lcmt_interp_input>(cfg.channel(ch::kInterpInput), [&](const cnc::lcmt_interp_input& m) {
      if (m.kind == cnc::lcmt_interp_input::COMMAND && m.command.command == cnc::lcmt_program_command::RESET)
        core.on_reset();
      if (m.kind == cnc::lcmt_interp_input::COMMAND && m.command.command == cnc::lcmt_program_command::HOMED)
        core.on_homed(m.command.axis, m.command.value);
      if (m.kind != cnc::lcmt_interp_input::BLOCK) return;
      cnc::program::Block b;
      if (cnc::program::from_msg(m.block, naxes, &b).empty()) core.on_block(b, m.block.program_token);
    });
    double stale_report_s = -1e9;
    bus.subscribe<cnc::lcmt_setpoint>(cfg.channel(ch::kSetpoints), [&](const cnc::lcmt_setpoint& m) {
      if (m.num_axes != naxes) return;
      cnc::monitor::SetpointIn sp;
      sp.stream = m.stream;
      sp.cycle = m.cycle;
      sp.program_token = m.program_token;
      sp.block_index = m.block_index;
      sp.source_line = m.source_line;
      sp.u = m.u;
      sp.feed_mm_per_min = m.feed_mm_per_min;
      for (int a = 0; a < naxes; ++a) sp.position_mm[a] = m.position_mm[a];
      const int64_t stale = core.stale_setpoints();
      core.on_setpoint(sp);
      if (core.stale_setpoints() > stale && cnc::util::monotonic_s() - stale_report_s >= 1.0) {
        stale_report_s = cnc::util::monotonic_s();
        spdlog::warn("setpoint seq {} cycle {} of stream {} dropped: a newer stream runs; {} stale so far", m.seq,
                     m.cycle, m.stream, core.stale_setpoints());
      }
    });
    // Reused every cycle (the report's vector keeps its size, the alarm list its
    // capacity): handling a status allocates nothing unless an alarm is raised.
    cnc::lcmt_monitor_report r{};
    std::vector<cnc::monitor::Alarm> alarms;
    alarms.reserve(4);
    bus.subscribe<cnc::lcmt_axis_status>(cfg.channel(ch::kAxisStatus), [&](const cnc::lcmt_axis_status& m) {
      delivery.record_ns((cnc::util::wall_utime() - m.utime) * 1000);
      const double t_in = cnc::util::monotonic_s();
      alarms.clear();
      const auto s =
          core.on_status(m.utime, m.setpoint_cycle, m.actual_mm, m.following_error_mm, &alarms, m.playback_cycle);
      r.setpoint_cycle = s.setpoint_cycle;
      r.commanded_feed_mm_per_min = s.commanded_feed_mm_per_min;
      r.actual_feed_mm_per_min = s.actual_feed_mm_per_min;
      r.chord_error_mm = s.chord_error_mm;
      r.predicted_rmax_um = s.predicted_rmax_um;
      r.spindle_rpm = s.spindle_rpm;
      r.num_axes = m.num_axes;
      r.following_error_mm.resize(m.following_error_mm.size());
      std::copy(m.following_error_mm.begin(), m.following_error_mm.end(), r.following_error_mm.begin());
      r.max_following_error_mm = s.max_following_error_mm;
      r.target_rmax_um = s.target_rmax_um;
      r.chord_tolerance_mm = cfg.chord_tolerance_mm;
      r.block_index = s.block_index;
      r.source_line = s.source_line;
      r.force_x_n = s.force_x_n;
      r.force_y_n = s.force_y_n;
      r.force_z_n = s.force_z_n;
      r.force_peak_n = s.force_peak_n;
      r.deflection_mm = s.deflection_mm;
      r.deflection_tolerance_mm = s.deflection_tolerance_mm;
      bus.publish(ch_report, r);
      for (const auto& a : alarms) raise(a.code, a.text, cnc::lcmt_alarm::WARNING);
      handling.record_s(cnc::util::monotonic_s() - t_in);
    });
    // A gantry's second drives (JOINT_STATUS): a skew over half its limit while enabled
    // is a warning (at most one a second per joint) before the bridge's fault at the
    // limit; the largest skew and following error go to the summary.
    struct JointSeen {
      double max_skew_mm = 0, max_fe_mm = 0;
      double warned_s = -1e9;
    };
    std::vector<JointSeen> joints_seen;
    if (std::any_of(cfg.axes.begin(), cfg.axes.end(), [](const cnc::config::AxisConfig& a) { return a.gantry.enabled; }))
      bus.subscribe<cnc::lcmt_joint_status>(cfg.channel(ch::kJointStatus), [&](const cnc::lcmt_joint_status& m) {
        const auto n = static_cast<size_t>(m.num_joints);
        if (m.axis.size() != n || m.skew_mm.size() != n || m.drive_state.size() != n) return;
        if (joints_seen.size() != n) joints_seen.assign(n, JointSeen{});
        for (size_t k = 0; k < n; ++k) {
          if (m.axis[k] < 0 || m.axis[k] >= naxes || m.drive_state[k] != cnc::lcmt_axis_status::ENABLED) continue;
          const auto& ax = cfg.axes[static_cast<size_t>(m.axis[k])];
          JointSeen& j = joints_seen[k];
          const double skew = std::fabs(m.skew_mm[k]);
          j.max_skew_mm = std::max(j.max_skew_mm, skew);
          j.max_fe_mm = std::max(j.max_fe_mm, std::fabs(m.following_error_mm[k]));
          const double now_s = cnc::util::monotonic_s();
          if (skew > 0.5 * ax.gantry.skew_limit_mm && now_s - j.warned_s >= 1.0) {
            j.warned_s = now_s;
            char b[200];
            std::snprintf(b, sizeof b, "gantry %s: %s's skew %.4f mm is over half its limit %g mm", ax.name.c_str(),
                          m.name[k].c_str(), m.skew_mm[k], ax.gantry.skew_limit_mm);
            raise("gantry_skew_warning", b, cnc::lcmt_alarm::WARNING);
          }
        }
      });
    cnc::service::Heartbeat hb(bus, cfg, "cnc-monitor");
    // Sequence gaps: one alarm per channel and second at most, with the count since
    // the last one (a lossy network loses a few datagrams a second: a line each
    // would flood the alarm channel and the operator).
    struct GapReport {
      int64_t seen = 0;
      double last_s = -1e9;
    };
    std::map<std::string, GapReport> gaps_reported;
    while (!cnc::util::stop_requested()) {
      bus.handle(20);
      const double now_s = cnc::util::monotonic_s();
      for (const auto& [channel, st] : bus.stats()) {
        GapReport& g = gaps_reported[channel];
        if (st.seq_gaps > g.seen && now_s - g.last_s >= 1.0) {
          const bool first = g.last_s < -1e8;
          raise("seq_gap",
                channel + ": " + std::to_string(st.seq_gaps - g.seen) + " message(s) lost" +
                    (first ? "" : " in the last " + std::to_string(static_cast<int>(std::lround(now_s - g.last_s))) + " s") +
                    " (total " + std::to_string(st.seq_gaps) + ")",
                cnc::lcmt_alarm::WARNING);
          g.seen = st.seq_gaps;
          g.last_s = now_s;
        }
      }
      hb.tick(cnc::lcmt_heartbeat::RUNNING, 0);
    }
    for (size_t k = 0, j = 0; k < cfg.axes.size(); ++k)
      if (cfg.axes[k].gantry.enabled && j < joints_seen.size()) {
        spdlog::info("cnc-monitor: gantry {}: largest skew {:.4f} mm, {}'s largest following error {:.4f} mm",
                     cfg.axes[k].name, joints_seen[j].max_skew_mm, cfg.axes[k].gantry.name, joints_seen[j].max_fe_mm);
        ++j;
      }
    spdlog::info("cnc-monitor: largest chord error {:.4f} um, largest following error {:.4f} mm",
                 core.largest_chord_error_mm() * 1e3, core.largest_following_error_mm());
    hb.tick(cnc::lcmt_heartbeat::STOPPING, 0, "", true);
    cnc::util::LatencyReport lat;
    lat.service = "cnc-monitor";
    lat.loop = "AXIS_STATUS handler (event-driven, one per T_ipo)";
    lat.period_s = cfg.ipo_period_s;
    lat.cycles = delivery.count();
    const auto st = bus.stats().find(cfg.channel(ch::kAxisStatus));
    lat.overruns = st == bus.stats().end() ? 0 : st->second.seq_gaps;
    lat.overruns_what = "AXIS_STATUS messages lost (sequence gaps)";
    lat.wake_what = "delivery latency: AXIS_STATUS utime (bridge, wall clock) to the handler's start";
    lat.compute_what = "compute: the AXIS_STATUS handler (core update, report, alarms)";
    lat.wake = &delivery;
    lat.compute = &handling;
    cnc::util::report_latency(lat, cnc::util::latency_dir(args.option("latency-dir")));
    return cnc::service::kExitOk;
  });
}
