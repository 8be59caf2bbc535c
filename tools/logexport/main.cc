// cnc-logexport: the tables of a recorded run for plotting and for people. Reads a
// cell's log through the bus's file back end (every rotated part: NAME.lcmlog,
// NAME.1.lcmlog, ...) and writes into DIR: setpoints.csv, monitor.csv,
// axis_status.csv, alarms.csv, summary.json and spindle_status.csv (see log_export.h).
//
//   cnc-logexport --log LOG --out DIR [--prefix P]
// --prefix: the cell's channel prefix when a log holds several cells (default: the
// prefix of the first SETPOINTS channel). Exit codes: 0 done; 1 no setpoints in the
// log; 2 bad flags or no log.
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>

#include "cnc/lcmt_config.hpp"
#include "common/bus/bus.h"
#include "common/program/block_msg.h"
#include "common/service/service.h"
#include "common/service/spindle_status_msg.h"
#include "common/util/signals.h"
#include "tools/logexport/log_export.h"

namespace {

template <class Msg>
bool decode(const void* data, size_t size, Msg* out) {
  try {
    const size_t n = cnc::bus::payload_size(data, size);  // a signed cell's trailer follows the message
    return out->decode(data, 0, static_cast<int>(n)) == static_cast<int>(n);
  } catch (...) {
    return false;
  }
}

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

// LOG and the parts rotation made after it.
std::vector<std::string> log_parts(const std::string& log) {
  std::vector<std::string> parts = {log};
  if (!ends_with(log, ".lcmlog")) return parts;
  const std::string stem = log.substr(0, log.size() - 7);
  for (int i = 1; std::filesystem::exists(stem + "." + std::to_string(i) + ".lcmlog"); ++i)
    parts.push_back(stem + "." + std::to_string(i) + ".lcmlog");
  return parts;
}

int run_export(const cnc::config::MachineConfig&, const cnc::service::Args& args) {
  cnc::util::end_at_once_on_stop_signals();  // no loop here polls the stop flag
  const std::string log = args.option("log"), out = args.option("out");
  if (log.empty() || out.empty()) {
    std::fprintf(stderr, "cnc-logexport: --log LOG and --out DIR are required\n");
    return cnc::service::kExitBadInput;
  }
  if (!std::filesystem::is_regular_file(log)) {
    std::fprintf(stderr, "cnc-logexport: no log file at '%s'\n", log.c_str());
    return cnc::service::kExitBadInput;
  }
  std::string prefix = args.option("prefix");
  cnc::logexport::LogExport ex;
  std::map<std::string, cnc::logexport::ChannelSummary> channels;
  std::map<std::string, std::set<int32_t>> senders;
  // Messages of a known channel that do not decode in this build: a log recorded
  // by a version whose message had other fields. Left out of the tables, and said.
  std::map<std::string, int64_t> undecoded;
  const auto parts = log_parts(log);
  for (const auto& part : parts) {
    cnc::bus::Bus bus("file://" + part + "?speed=0");
    bus.subscribe_raw(".*", [&](const std::string& ch, const void* data, size_t size, int64_t) {
      if (const auto h = cnc::bus::peek_header(data, size)) senders[ch].insert(h->sender);
      if (prefix.empty() && ends_with(ch, "SETPOINTS")) prefix = ch.substr(0, ch.size() - 9);
      if (prefix.empty() || ch.rfind(prefix, 0) != 0) return;
      const std::string name = ch.substr(prefix.size());
      if (name == "SETPOINTS") {
        cnc::lcmt_setpoint m;
        if (decode(data, size, &m)) ex.on_setpoint(m);
        else ++undecoded[name];
      } else if (name == "MONITOR") {
        cnc::lcmt_monitor_report m;
        if (decode(data, size, &m)) ex.on_monitor(m);
        else ++undecoded[name];
      } else if (name == "AXIS_STATUS") {
        cnc::lcmt_axis_status m;
        if (decode(data, size, &m)) ex.on_axis_status(m);
        else ++undecoded[name];
      } else if (name == "ALARM") {
        cnc::lcmt_alarm m;
        if (decode(data, size, &m)) ex.on_alarm(m);
        else ++undecoded[name];
      } else if (name == "PROGRAM_STATE") {
        cnc::lcmt_program_state m;
        if (decode(data, size, &m)) ex.on_program_state(m);
        else ++undecoded[name];
      } else if (name == "INTERP_STATE") {
        cnc::lcmt_interp_state m;
        if (decode(data, size, &m)) ex.on_interp_state(m);
        else ++undecoded[name];
      } else if (name == "PROGRAM_BLOCKS") {
        cnc::lcmt_program_block m;
        cnc::lcmt_program_block_v2 v2;  // logs of formats 1 and 2
        if (decode(data, size, &m))
          ex.on_program_block(m);
        else if (decode(data, size, &v2))
          ex.on_program_block(cnc::program::from_v2(v2));
        else
          ++undecoded[name];
      } else if (name == "SPINDLE_STATUS") {
        cnc::lcmt_spindle_status m;  // of any format (lcmt_spindle_status_v1: formats 1 to 3)
        if (cnc::service::decode_spindle_status(data, size, &m)) ex.on_spindle_status(m);
        else ++undecoded[name];
      } else if (name == "LOGGER_STATS") {
        cnc::lcmt_logger_stats m;
        if (decode(data, size, &m)) ex.on_logger_stats(m);
        else ++undecoded[name];
      } else if (name == "INTERP_CONFIG") {
        cnc::lcmt_config m;
        if (!decode(data, size, &m)) {
          ++undecoded[name];
          return;
        }
        try {
          ex.on_config(cnc::config::parse_machine_config(m.yaml, m.source_file), m.source_file);
        } catch (const std::exception& e) {
          std::fprintf(stderr, "cnc-logexport: the recorded config does not load (%s): ignored\n", e.what());
        }
      }
    });
    while (bus.handle(1000) > 0) {
    }
    for (const auto& [ch, st] : bus.stats()) {
      auto& c = channels[ch];
      c.events += st.received;
      c.seq_gaps += st.seq_gaps;
      c.seq_restarts += st.seq_restarts;
    }
  }
  for (auto& [ch, c] : channels) c.senders = static_cast<int64_t>(senders[ch].size());
  for (const auto& [name, n] : undecoded)
    std::fprintf(stderr,
                 "cnc-logexport: %lld %s message(s) do not decode in this version (recorded by an older one with "
                 "other fields): left out of the tables\n",
                 static_cast<long long>(n), name.c_str());
  ex.write(out, parts, prefix, channels);
  std::printf("cnc-logexport: %zu setpoints from %zu file(s) into %s\n", ex.setpoints(), parts.size(), out.c_str());
  if (ex.setpoints() == 0) {
    std::fprintf(stderr, "cnc-logexport: no setpoints%s in %s\n", prefix.empty() ? "" : (" on " + prefix + "SETPOINTS").c_str(),
                 log.c_str());
    return cnc::service::kExitFailure;
  }
  return cnc::service::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-logexport", "CSV tables and a summary of a recorded run, for the report",
                          
                          {{"log", "LOG", "the cell's log (its rotated parts are read too)"},
                           {"out", "DIR", "where the CSV tables and summary.json go"},
                           {"prefix", "P", "the cell's channel prefix (default: the first SETPOINTS channel's)"}},
                          {},
                          false};
  return cnc::service::run(spec, argc, argv, run_export);
}
