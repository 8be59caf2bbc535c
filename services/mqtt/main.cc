// cnc-mqtt: the cell's state, alarms and job records on an MQTT broker for a fleet
// (docs/mqtt.md). It reads the cell's bus like the monitor and the logger and sends
// nothing that moves the machine: it subscribes to no broker topic at all, and on the
// bus it publishes only its heartbeat.
//
//   cnc-mqtt --machine M
//   cnc-mqtt --machine M --print-url     the broker's address (exit 3: no mqtt: section)
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_logger_stats.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_spindle_status.hpp"
#include "common/service/heartbeat.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/signals.h"
#include "common/util/install.h"
#include "services/mqtt/fleet_reporter.h"
#include "services/mqtt/mqtt_client.h"

namespace ch = cnc::config::channels;

namespace {

constexpr int kExitNotConfigured = 3;
constexpr int64_t kMaxKept = 10000;  // records waiting for the broker (some 5 MB)

// "" when `path` is a regular file of this user that group and others cannot read.
std::string secret_file_problem(const std::string& key, const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return key + " " + path + ": " + std::strerror(errno);
  if (!S_ISREG(st.st_mode)) return key + " " + path + " is not a regular file";
  if (st.st_uid != ::geteuid() && ::geteuid() != 0)
    return key + " " + path + " belongs to uid " + std::to_string(st.st_uid) + ", not to this user";
  if ((st.st_mode & 077) != 0) {
    char mode[8];
    std::snprintf(mode, sizeof mode, "%04o", static_cast<unsigned>(st.st_mode & 07777));
    return key + " " + path + " has mode " + mode + ": group or others may read it (chmod 600 " + path + ")";
  }
  return "";
}

std::string first_line(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  if (!line.empty() && line.back() == '\r') line.pop_back();
  return line;
}

int run_mqtt(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
  const cnc::config::MqttConfig& q = cfg.mqtt;
  if (!q.enabled) {
    std::fprintf(stderr, "cnc-mqtt: %s has no mqtt: section: nothing to publish (docs/mqtt.md)\n",
                 args.machine_file.c_str());
    return kExitNotConfigured;
  }
  const std::string host = q.host.find(':') != std::string::npos ? "[" + q.host + "]" : q.host;
  if (args.flags.count("print-url")) {
    std::printf("%s://%s:%d/%s/%s\n", q.ca_file.empty() ? "mqtt" : "mqtts", host.c_str(), q.port,
                q.topic_prefix.c_str(), cfg.name.c_str());
    return 0;
  }
  cnc::mqtt::ClientOptions o;
  for (const auto& [key, path] : {std::pair{"mqtt.password_file", q.password_file}, {"mqtt.key_file", q.key_file}}) {
    if (path.empty()) continue;
    if (const std::string why = secret_file_problem(key, path); !why.empty()) {
      std::fprintf(stderr, "cnc-mqtt: config error: %s\n", why.c_str());
      return cnc::service::kExitBadInput;
    }
  }
  if (!q.password_file.empty()) {
    o.password = first_line(q.password_file);
    if (o.password.empty()) {
      std::fprintf(stderr, "cnc-mqtt: config error: mqtt.password_file %s: the first line is empty\n",
                   q.password_file.c_str());
      return cnc::service::kExitBadInput;
    }
  }
  std::vector<std::string> axes;
  for (const auto& a : cfg.axes) axes.push_back(a.name);
  cnc::mqtt::FleetReporter core(q.topic_prefix + "/" + cfg.name, cfg.name, axes, q.state_period_s,
                                cnc::util::version(), cfg.spindle.enabled);
  o.host = q.host;
  o.port = q.port;
  o.client_id = q.client_id;
  o.keepalive_s = q.keepalive_s;
  o.username = q.username;
  o.ca_file = q.ca_file;
  o.cert_file = q.cert_file;
  o.key_file = q.key_file;
  o.will = core.will();
  cnc::mqtt::MqttClient client(o);

  cnc::bus::Bus bus(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-mqtt"));
  std::vector<cnc::mqtt::Record> out;
  bus.subscribe<cnc::lcmt_program_state>(cfg.channel(ch::kProgramState), [&](const cnc::lcmt_program_state& m) {
    cnc::mqtt::ProgramStateIn p;
    p.utime = m.utime;
    p.state = m.state;
    p.token = m.program_token;
    p.path = m.program_path;
    p.error = m.error;
    core.on_program_state(p, &out);
  });
  cnc::mqtt::InterpStateIn is;
  bus.subscribe<cnc::lcmt_interp_state>(cfg.channel(ch::kInterpState), [&](const cnc::lcmt_interp_state& m) {
    is.utime = m.utime;
    is.state = m.state;
    is.mode = m.mode;
    is.mode_text = m.mode_text;
    is.program_token = m.program_token;
    is.blocks_done = m.blocks_done;
    is.program_time_s = m.program_time_s;
    is.feed_override = m.feed_override;
    is.rapid_override = m.rapid_override;
    is.spindle_override = m.spindle_override;
    is.position_mm.assign(m.position_mm.begin(), m.position_mm.end());
    core.on_interp_state(is);
  });
  bus.subscribe<cnc::lcmt_axis_status>(cfg.channel(ch::kAxisStatus), [&](const cnc::lcmt_axis_status& m) {
    const int n = std::min({m.num_axes, static_cast<int>(m.actual_mm.size()), static_cast<int>(m.following_error_mm.size())});
    core.on_axis_status(m.actual_mm.data(), m.following_error_mm.data(), n);
  });
  if (cfg.spindle.enabled)
    bus.subscribe<cnc::lcmt_spindle_status>(cfg.channel(ch::kSpindleStatus), [&](const cnc::lcmt_spindle_status& m) {
      core.on_spindle({m.state, m.commanded_rpm, m.actual_rpm});
    });
  bus.subscribe<cnc::lcmt_alarm>(cfg.channel(ch::kAlarm), [&](const cnc::lcmt_alarm& m) {
    core.on_alarm({m.utime, m.source, m.severity, m.code, m.text}, &out);
  });
  bus.subscribe<cnc::lcmt_logger_stats>(cfg.channel("LOGGER_STATS") /* the logger's (LoggerNode::kStatsChannel) */,
                                        [&](const cnc::lcmt_logger_stats& m) { core.on_log_path(m.path); });
  cnc::service::Heartbeat hb(bus, cfg, "cnc-mqtt");

  client.start();
  spdlog::info("cnc-mqtt: publishing {}/{}/... to {}:{} as {}{}", q.topic_prefix, cfg.name, q.host, q.port, q.client_id,
               q.ca_file.empty() ? "" : " (TLS)");
  int64_t connections = 0, dropped = 0;
  while (!cnc::util::stop_requested()) {
    bus.handle(50);
    // A (re)connection: online, and the state at once (the retained one may be old).
    const int64_t c = client.connections();
    const bool fresh = c != connections && client.connected();
    if (fresh) {
      connections = c;
      client.publish(core.birth(cnc::util::wall_utime()));
    }
    core.tick(cnc::util::monotonic_s(), cnc::util::wall_utime(), fresh, &out);
    for (const auto& r : out) {
      if (!r.durable && !client.connected()) continue;
      // The records kept for a broker that stays away are bounded: past kMaxKept the
      // alarms are dropped (counted), the job records still kept.
      if (!client.connected() && client.published() - client.acknowledged() >= kMaxKept &&
          r.topic.size() >= 6 && r.topic.compare(r.topic.size() - 6, 6, "/alarm") == 0) {
        if (dropped++ % 1000 == 0)
          spdlog::warn("cnc-mqtt: the broker is away and {} records wait: alarm records dropped ({} so far)", kMaxKept,
                       dropped);
        continue;
      }
      client.publish(r);
    }
    out.clear();
    hb.tick(cnc::lcmt_heartbeat::RUNNING, 0, client.connected() ? "broker connected" : "broker not connected");
  }
  client.stop(core.stopped(cnc::util::wall_utime()), 2.0);
  spdlog::info("cnc-mqtt: stopped: {} jobs started, {} ended, {} alarms, {} states; {} records published, {} acknowledged, {} "
               "alarm records dropped while the broker was away",
               core.jobs_started(), core.jobs_ended(), core.alarms(), core.states(), client.published(),
               client.acknowledged(), dropped);
  hb.tick(cnc::lcmt_heartbeat::STOPPING, 0, "", true);
  return cnc::service::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{
      "cnc-mqtt",
      "the cell's state, alarms and job records on an MQTT broker (read-only: nothing that moves the machine)",
      {},
      {{"print-url", "", "print the broker's address and the cell's topic and exit (3: the config has no mqtt: section)"}}};
  return cnc::service::run(spec, argc, argv, run_mqtt);
}
