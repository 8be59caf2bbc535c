// cnc-logstat: reads a cell's LCM log through the bus's file back end and prints,
// per channel, the events, senders and sequence gaps; with --summary, the run's
// summary (program time, blocks, setpoints published/received, gaps per channel
// and receiver, largest following error).
//
//   cnc-logstat --log FILE [--summary] [--require-no-gaps CHANNEL] [--key KEYFILE | --machine FILE]
//   cnc-logstat --log FILE --compare-monitor OTHER_LOG
//   cnc-logstat --log FILE --delivery [--stall-ms MS]
//
// --key (or the key file of --machine's config, when it signs) verifies the MAC of
// every logged message (the logger keeps them) and prints, per channel, how many
// verify and how many are unsigned, under an unknown key, forged or repeated. The
// summary also lists the messages each service dropped unverified (heartbeats).
//
// --compare-monitor checks that the monitor reports of OTHER_LOG (e.g. a monitor
// driven by lcm-logplayer playing FILE) equal FILE's, field by field, cycle by
// cycle (see compare_monitor for which cycles).
//
// --delivery tells a stalled publisher from a stalled delivery (common/bus/delivery.h):
// per channel, the time from each message's stamp to the logger's kernel receive
// stamp, and every silence of the receive side over --stall-ms (default 20) with
// what was published inside it. The live tests print it when they fail.
//
// Exit codes: 0 fine; 1 a required channel is empty or has gaps, the monitor
// reports differ, or a message fails verification; 2 bad flags or key file.
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <set>
#include <vector>

#include <lcm/lcm-cpp.hpp>

#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_monitor_report.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "common/bus/bus.h"
#include "common/bus/delivery.h"
#include "common/bus/log_format.h"
#include "common/service/service.h"
#include "common/util/signals.h"

namespace {

// A message of the log, with or without a signature trailer (signed cells).
template <class Msg>
bool decodes(Msg& m, const void* data, size_t size) {
  const size_t n = cnc::bus::payload_size(data, size);
  try {
    return m.decode(data, 0, static_cast<int>(n)) == static_cast<int>(n);
  } catch (...) {
    return false;
  }
}

struct Senders {
  std::set<int32_t> ids;
};

std::vector<cnc::lcmt_monitor_report> monitor_reports(const std::string& log) {
  std::vector<cnc::lcmt_monitor_report> out;
  cnc::bus::Bus bus("file://" + log + "?speed=0");
  bus.subscribe_raw(".*MONITOR", [&](const std::string&, const void* data, size_t size, int64_t) {
    cnc::lcmt_monitor_report m;
    if (decodes(m, data, size)) out.push_back(std::move(m));
  });
  while (bus.handle(1000) > 0) {
  }
  return out;
}

bool same_double(double a, double b) { return (std::isnan(a) && std::isnan(b)) || a == b; }

// "" when equal, else the first differing field.
std::string report_diff(const cnc::lcmt_monitor_report& a, const cnc::lcmt_monitor_report& b) {
  auto d = [](const char* name, double x, double y) {
    return same_double(x, y) ? std::string() : std::string(name) + ": " + std::to_string(x) + " vs " + std::to_string(y);
  };
  if (a.setpoint_cycle != b.setpoint_cycle) return "setpoint_cycle";
  for (const std::string& s : {d("commanded_feed", a.commanded_feed_mm_per_min, b.commanded_feed_mm_per_min),
                               d("actual_feed", a.actual_feed_mm_per_min, b.actual_feed_mm_per_min),
                               d("chord_error", a.chord_error_mm, b.chord_error_mm),
                               d("predicted_rmax", a.predicted_rmax_um, b.predicted_rmax_um),
                               d("target_rmax", a.target_rmax_um, b.target_rmax_um),
                               d("max_following_error", a.max_following_error_mm, b.max_following_error_mm),
                               d("deflection", a.deflection_mm, b.deflection_mm)})
    if (!s.empty()) return s;
  if (a.block_index != b.block_index) return "block_index";
  return "";
}

int compare_monitor(const std::string& log, const std::string& other) {
  const auto a = monitor_reports(log);
  const auto b = monitor_reports(other);
  // Key by setpoint cycle; compare the cycles that have exactly one report in each
  // log, and whose previous cycle does too (the actual feed is measured over the
  // statuses before). The bridge reports twice on a cycle whose successor was late,
  // and idle cycles before a program repeat. The original's first report is left
  // out: its feed depends on statuses before the monitor started.
  std::map<int64_t, std::vector<const cnc::lcmt_monitor_report*>> ka, kb;
  for (size_t i = 1; i < a.size(); ++i) ka[a[i].setpoint_cycle].push_back(&a[i]);
  for (const auto& r : b) kb[r.setpoint_cycle].push_back(&r);
  auto single = [](const auto& m, int64_t c) {
    auto it = m.find(c);
    return it != m.end() && it->second.size() == 1;
  };
  size_t compared = 0, unique = 0, missing = 0;
  for (const auto& [cycle, ra] : ka) {
    if (ra.size() != 1) continue;
    ++unique;
    if (kb.find(cycle) == kb.end()) {
      ++missing;
      continue;
    }
    if (!single(kb, cycle) || !single(ka, cycle - 1) || !single(kb, cycle - 1)) continue;
    const std::string diff = report_diff(*ra.front(), *kb.at(cycle).front());
    if (!diff.empty()) {
      std::fprintf(stderr, "cnc-logstat: monitor report of cycle %lld differs: %s\n", static_cast<long long>(cycle),
                   diff.c_str());
      return 1;
    }
    ++compared;
  }
  std::printf("monitor reports identical: %zu compared (of %zu cycles with one report in %s; %zu reports there, "
              "%zu in %s); %zu of those cycles without a report in the other, the rest reported twice there or "
              "next to a cycle reported twice\n",
              compared, unique, log.c_str(), a.size(), b.size(), other.c_str(), missing);
  // Every cycle reported must be reported in the other log too. A cycle reported twice
  // (the bridge's status after a late setpoint; more of them the more the machine is
  // loaded) cannot be compared one to one: most cycles must still be.
  return missing == 0 && compared > 0 && compared >= unique / 2 ? 0 : 1;
}

int delivery(const std::string& log, double stall_ms) {
  // The log's own receive stamps (LCM's file provider hands the time of reading).
  std::vector<cnc::bus::DeliveryEvent> events;
  lcm::LogFile file(log, "r");
  if (!file.good()) {
    std::fprintf(stderr, "cnc-logstat: cannot read %s\n", log.c_str());
    return 1;
  }
  while (const lcm::LogEvent* e = file.readNextEvent()) {
    if (e->channel == cnc::bus::kLogFormatChannel) continue;  // the logger's own record
    const auto h = cnc::bus::peek_header(e->data, static_cast<size_t>(e->datalen));
    if (!h) continue;
    events.push_back({e->channel, h->sender, h->utime, e->timestamp});
  }
  if (events.empty()) {
    std::fprintf(stderr, "cnc-logstat: %s holds no cell messages\n", log.c_str());
    return 1;
  }
  const int64_t t0 = events.front().received_us;
  std::fputs(cnc::bus::format_delivery(cnc::bus::analyse_delivery(std::move(events), stall_ms), t0, stall_ms).c_str(),
             stdout);
  return 0;
}

int run_logstat(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
  cnc::util::end_at_once_on_stop_signals();  // no loop here polls the stop flag
  const std::string log = args.option("log");
  if (log.empty()) {
    std::fprintf(stderr, "cnc-logstat: --log FILE is required\n");
    return cnc::service::kExitBadInput;
  }
  if (!args.option("compare-monitor").empty()) return compare_monitor(log, args.option("compare-monitor"));
  if (args.flags.count("delivery")) {
    const double stall_ms = args.number("stall-ms", 20.0);
    if (!(stall_ms > 0)) throw cnc::service::FlagError("--stall-ms: " + args.option("stall-ms") + " is not above 0");
    return delivery(log, stall_ms);
  }
  std::string key_file = args.option("key");
  if (key_file.empty() && cfg.security.signing) key_file = cfg.security.key_file;
  std::optional<cnc::bus::LogVerifier> verifier;
  if (!key_file.empty()) verifier.emplace(cnc::bus::read_key_file(key_file));
  cnc::bus::Bus bus("file://" + log + "?speed=0");
  std::map<std::string, Senders> senders;
  int64_t signed_events = 0;
  bus.subscribe_raw(".*", [&](const std::string& ch, const void* data, size_t size, int64_t) {
    if (auto h = cnc::bus::peek_header(data, size)) senders[ch].ids.insert(h->sender);
    if (cnc::bus::has_trailer(data, size)) ++signed_events;
    if (verifier && ch != cnc::bus::kLogFormatChannel) verifier->check(ch, data, size);  // the logger's own, unsigned
  });
  // The last heartbeat of each service (its final one when it stopped cleanly).
  std::map<std::string, cnc::lcmt_heartbeat> last_hb;
  cnc::lcmt_interp_state interp{};
  cnc::lcmt_program_state program{};
  double largest_fe = 0;
  std::string largest_fe_axis;
  int64_t axis_faults = 0;
  std::string prefix;
  bus.subscribe_raw(".*HEARTBEAT", [&](const std::string& ch, const void* data, size_t size, int64_t) {
    cnc::lcmt_heartbeat hb;
    if (decodes(hb, data, size)) {
      last_hb[hb.service] = hb;
      prefix = ch.substr(0, ch.size() - std::string("HEARTBEAT").size());
    }
  });
  bus.subscribe_raw(".*INTERP_STATE", [&](const std::string&, const void* data, size_t size, int64_t) {
    cnc::lcmt_interp_state m;
    if (decodes(m, data, size)) interp = m;
  });
  bus.subscribe_raw(".*PROGRAM_STATE", [&](const std::string&, const void* data, size_t size, int64_t) {
    cnc::lcmt_program_state m;
    if (decodes(m, data, size)) program = m;
  });
  bus.subscribe_raw(".*AXIS_STATUS", [&](const std::string&, const void* data, size_t size, int64_t) {
    cnc::lcmt_axis_status m;
    if (!decodes(m, data, size)) return;
    for (int i = 0; i < m.num_axes; ++i) {
      if (std::fabs(m.following_error_mm[i]) > largest_fe) {
        largest_fe = std::fabs(m.following_error_mm[i]);
        largest_fe_axis = m.axis_name[i];
      }
      if (m.drive_state[i] == cnc::lcmt_axis_status::FAULT) ++axis_faults;
    }
  });
  int64_t events = 0;
  while (bus.handle(1000) > 0) ++events;

  std::printf("%-28s %10s %8s %10s %10s\n", "channel", "events", "senders", "seq_gaps", "restarts");
  for (const auto& [ch, st] : bus.stats()) {
    std::printf("%-28s %10lld %8zu %10lld %10lld\n", ch.c_str(), static_cast<long long>(st.received),
                senders[ch].ids.size(), static_cast<long long>(st.seq_gaps), static_cast<long long>(st.seq_restarts));
  }
  std::printf("%lld events in %s (%lld signed)\n", static_cast<long long>(events), log.c_str(),
              static_cast<long long>(signed_events));
  if (verifier) {
    std::printf("\nsignatures (key file %s)\n", key_file.c_str());
    std::printf("%-28s %10s %10s %10s %10s %10s\n", "channel", "verified", "unsigned", "unknown_key", "forged",
                "replayed");
    for (const auto& [ch, c] : verifier->counts()) {
      using R = cnc::bus::Reject;
      auto b = [&](R r) { return static_cast<long long>(c.bad[static_cast<size_t>(r)]); };
      std::printf("%-28s %10lld %10lld %10lld %10lld %10lld\n", ch.c_str(), static_cast<long long>(c.verified),
                  b(R::kUnsigned), b(R::kUnknownKey), b(R::kForged), b(R::kReplayed));
    }
    std::printf("signatures: %lld verified, %lld bad\n", static_cast<long long>(verifier->verified()),
                static_cast<long long>(verifier->bad()));
  }

  if (args.flags.count("summary")) {
    auto hb_count = [&](const std::string& service, const std::string& channel, const char* what) -> long long {
      auto it = last_hb.find(service);
      if (it == last_hb.end()) return -1;
      const auto& hb = it->second;
      for (int i = 0; i < hb.num_channels; ++i) {
        if (hb.channel[i] != channel) continue;
        if (std::string(what) == "published") return hb.published[i];
        if (std::string(what) == "received") return hb.received[i];
        return hb.seq_gaps[i];
      }
      return 0;
    };
    const std::string sp = prefix + "SETPOINTS";
    std::printf("\nrun summary\n");
    std::printf("  program             %s\n", program.program_path.c_str());
    std::printf("  program time        %.3f s\n", interp.program_time_s);
    std::printf("  blocks              %lld of %lld done (sent %lld, re-sent %lld)\n",
                static_cast<long long>(interp.blocks_done), static_cast<long long>(program.num_blocks),
                static_cast<long long>(program.blocks_sent), static_cast<long long>(program.blocks_resent));
    std::printf("  setpoints           published %lld (interpolator), received %lld (drive bridge), %lld (monitor), "
                "%lld (logger)\n",
                hb_count("cnc-interpolator", sp, "published"), hb_count("cnc-drive-bridge", sp, "received"),
                hb_count("cnc-monitor", sp, "received"), static_cast<long long>(bus.stats(sp).received));
    // Which build of each service ran, and where (its heartbeats carry both).
    std::printf("  services            ");
    bool first = true;
    for (const auto& [service, hb] : last_hb) {
      std::printf("%s%s %s on %s", first ? "" : "\n                      ", service.c_str(),
                  hb.version.empty() ? "(no version)" : hb.version.c_str(), hb.host.empty() ? "?" : hb.host.c_str());
      first = false;
    }
    std::printf("\n");
    std::printf("  sequence gaps       per channel, as each receiver counted them:\n");
    std::map<std::string, std::string> per_channel;
    for (const auto& [service, hb] : last_hb) {
      for (int i = 0; i < hb.num_channels; ++i) {
        if (hb.received[i] == 0) continue;
        std::string& line = per_channel[hb.channel[i]];
        line += (line.empty() ? "" : ", ") + service.substr(service.rfind("cnc-", 0) == 0 ? 4 : 0) + " " +
                std::to_string(hb.seq_gaps[i]);
      }
    }
    for (const auto& [channel, line] : per_channel) std::printf("      %-26s %s\n", channel.c_str(), line.c_str());
    // Signed cells: what each receiver dropped unverified (its last heartbeat).
    std::map<std::string, std::string> dropped;
    for (const auto& [service, hb] : last_hb) {
      if (static_cast<int>(hb.rejected_unsigned.size()) != hb.num_channels) continue;
      for (size_t i = 0; i < static_cast<size_t>(hb.num_channels); ++i) {
        const int64_t u = hb.rejected_unsigned[i], k = hb.rejected_unknown_key[i], f = hb.rejected_forged[i],
                      st = hb.rejected_stale[i], r = hb.rejected_replayed[i];
        if (u + k + f + st + r == 0) continue;
        char b[200];
        std::snprintf(b, sizeof b, "%s unsigned %lld, unknown_key %lld, forged %lld, stale %lld, replayed %lld",
                      service.substr(service.rfind("cnc-", 0) == 0 ? 4 : 0).c_str(), static_cast<long long>(u),
                      static_cast<long long>(k), static_cast<long long>(f), static_cast<long long>(st),
                      static_cast<long long>(r));
        std::string& line = dropped[hb.channel[i]];
        line += (line.empty() ? "" : "; ") + std::string(b);
      }
    }
    std::printf("  dropped unverified  %s\n", dropped.empty() ? "none" : "per channel, as each receiver counted them:");
    for (const auto& [channel, line] : dropped) std::printf("      %-26s %s\n", channel.c_str(), line.c_str());
    std::printf("  largest foll. error %.4f mm (axis %s)%s\n", largest_fe, largest_fe_axis.c_str(),
                axis_faults ? "  -- drive FAULT reported" : "");
  }

  const std::string required = args.option("require-no-gaps");
  if (!required.empty()) {
    const auto st = bus.stats(required);
    if (st.received == 0 || st.seq_gaps != 0) {
      std::fprintf(stderr, "cnc-logstat: %s has %lld events and %lld sequence gaps\n", required.c_str(),
                   static_cast<long long>(st.received), static_cast<long long>(st.seq_gaps));
      return 1;
    }
  }
  if (verifier && verifier->bad() > 0) {
    std::fprintf(stderr, "cnc-logstat: %lld message(s) of the log fail verification\n",
                 static_cast<long long>(verifier->bad()));
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-logstat", "per-channel statistics and run summary of a cell log",
                          
                          {{"log", "FILE", "the cell's log"},
                           {"require-no-gaps", "CHANNEL", "exit 1 when CHANNEL is empty or has sequence gaps"},
                           {"compare-monitor", "OTHER_LOG", "check that OTHER_LOG's monitor reports equal the log's"},
                           {"key", "KEYFILE", "verify every message's MAC (or the key of --machine's config)"},
                           {"stall-ms", "MS", "with --delivery: the receive-side silence that counts as a stall (default 20)", true}},
                          {{"summary", "", "the run's summary: program time, blocks, setpoints, gaps, versions"},
                           {"delivery", "", "publish-to-receive times per channel, and who stalled: publishers or the delivery"}},
                          false};
  return cnc::service::run(spec, argc, argv, run_logstat);
}
