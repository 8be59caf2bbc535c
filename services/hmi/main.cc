// cnc-hmi: the operator's page in a browser, a client of the cell like cnc-ctl.
//
// main only wires: the flags and the config, the bus, the HTTP/WebSocket server
// (web.h) and the HMI's API (api.h: the actions, answered by the same interlock as
// cnc-ctl's, and the cell's state pushed to every browser at hmi.status_rate_hz).
// docs/hmi-api.md has the WebSocket API.
//
//   cnc-hmi --machine M [--www DIR] [--runs DIR]
//   cnc-hmi --machine M --print-url            the page's address from the config
//   cnc-hmi --hash-password USER < password    a line for hmi.users_file
#include <sodium.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <deque>
#include <filesystem>
#include <iostream>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "common/service/heartbeat.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/install.h"
#include "common/util/signals.h"
#include "services/hmi/api.h"
#include "services/hmi/web.h"

namespace ch = cnc::config::channels;
using json = nlohmann::json;

namespace {

// A tool beside this executable (installed) or in the build tree's tools/.
std::string sibling_tool(const std::string& name) {
  const std::string installed = cnc::util::executable_dir() + "/" + name;
  return std::filesystem::exists(installed) ? installed : cnc::util::executable_dir() + "/../tools/" + name;
}

// --hash-password USER: a line for hmi.users_file from a password on standard input.
int hash_password(const std::string& user) {
  if (sodium_init() < 0) return 1;
  std::string password;
  std::getline(std::cin, password);
  char hash[crypto_pwhash_STRBYTES];
  if (password.empty() || crypto_pwhash_str(hash, password.c_str(), password.size(),
                                            crypto_pwhash_OPSLIMIT_INTERACTIVE,
                                            crypto_pwhash_MEMLIMIT_INTERACTIVE) != 0) {
    std::fprintf(stderr, "cnc-hmi: --hash-password: no password on standard input (or out of memory)\n");
    return cnc::service::kExitBadInput;
  }
  std::printf("%s:%s\n", user.c_str(), hash);
  return 0;
}

int run_hmi(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
  if (!args.option("hash-password").empty()) return hash_password(args.option("hash-password"));
  cnc::hmi::WebOptions wopt;
  wopt.listen = cfg.hmi.listen;
  wopt.port = args.option("port").empty() ? cfg.hmi.port : std::stoi(args.option("port"));
  wopt.read_only_without_login = cfg.hmi.read_only_without_login;
  wopt.www_dir = args.option("www", cnc::util::resource_path("services/hmi/www"));
  // three.js (npm ci from services/hmi/three/package-lock.json): beside the page when
  // installed (/usr/share/cnc/services/hmi/three), in the build tree beside this program otherwise.
  wopt.three_dir = cnc::util::resource_path("services/hmi/three/node_modules/three");
  if (std::error_code ec; !std::filesystem::is_directory(wopt.three_dir, ec))
    wopt.three_dir = cnc::util::executable_dir() + "/hmi/three/node_modules/three";
  // An upload (the API's `upload`) is one text frame: the program, JSON-escaped.
  wopt.max_message_bytes = static_cast<size_t>(2 * cfg.hmi.upload_max_bytes + 65536);
  wopt.runs_dir = args.option("runs", cfg.hmi.runs_dir.empty() ? cfg.log_directory : cfg.hmi.runs_dir);
  if (args.flags.count("print-url")) {
    std::printf("http://%s:%d/\n", wopt.listen.c_str(), wopt.port);
    return 0;
  }
  if (!cfg.hmi.users_file.empty()) {
    try {
      wopt.users = cnc::hmi::read_users_file(cfg.hmi.users_file);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "cnc-hmi: config error: %s\n", e.what());
      return cnc::service::kExitBadInput;
    }
  }
  cnc::bus::Bus bus(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-hmi"));

  // What the browsers say, handed over from the web thread.
  std::mutex in_mu;
  std::deque<cnc::hmi::WebEvent> inbound;
  cnc::hmi::WebServer web(wopt, [&](cnc::hmi::WebEvent e) {
    std::lock_guard<std::mutex> lk(in_mu);
    if (inbound.size() < 4096) inbound.push_back(std::move(e));
  });
  cnc::hmi::Outbox out;
  // A string that is not UTF-8 (a program's file name on disk, say) is sent with U+FFFD
  // in its place: dump() would otherwise throw out of the API.
  auto text = [](const json& j) {
    return std::make_shared<const std::string>(j.dump(-1, ' ', false, json::error_handler_t::replace));
  };
  out.broadcast = [&](const json& j, bool droppable) { web.broadcast(text(j), droppable); };
  out.send_to = [&](uint64_t client, const json& j) { web.send_to(client, text(j)); };
  cnc::hmi::ApiOptions aopt;
  aopt.machine_file = args.machine_file;
  aopt.plan_exe = sibling_tool("cnc-plan");
  aopt.logexport_exe = sibling_tool("cnc-logexport");
  aopt.make_report = cnc::util::resource_path("tools/report/make_report.py");
  aopt.runs_dir = wopt.runs_dir;
  aopt.login_required = !wopt.users.empty();
  cnc::hmi::Api api(cfg, bus, aopt, out);

  web.start();
  const std::string url = web.url();
  spdlog::info("cnc-hmi: the operator's page is at {} ({})", url,
               wopt.users.empty() ? "no login: localhost only"
                                  : std::to_string(wopt.users.size()) + " users, login required" +
                                        (wopt.read_only_without_login ? ", view only without" : ""));
  std::printf("cnc-hmi: open %s\n", url.c_str());
  std::fflush(stdout);

  cnc::service::Heartbeat hb(bus, cfg, "cnc-hmi");
  int64_t login_refusals = 0, logins = 0, refusals_alarmed = 0;
  double last_login_alarm_s = -1e9;
  const double status_period = 1.0 / cfg.hmi.status_rate_hz;
  double next_status = 0;
  while (!cnc::util::stop_requested()) {
    bus.handle(5);
    const double now = cnc::util::monotonic_s();
    std::deque<cnc::hmi::WebEvent> events;
    {
      std::lock_guard<std::mutex> lk(in_mu);
      events.swap(inbound);
    }
    for (const auto& e : events) {
      switch (e.kind) {
        case cnc::hmi::WebEvent::Kind::kOpen:
          spdlog::info("cnc-hmi: client {} connected ({}{})", e.client, e.user.empty() ? "not logged in" : e.user,
                       e.may_control ? "" : ", view only");
          api.open(e.client, e.may_control, e.user);
          break;
        case cnc::hmi::WebEvent::Kind::kClose:
          api.close(e.client);
          break;
        case cnc::hmi::WebEvent::Kind::kLogin:
          if (e.ok) {
            ++logins;
            spdlog::info("cnc-hmi: user '{}' logged in from {}", e.user, e.text);
          } else {
            ++login_refusals;
            spdlog::warn("cnc-hmi: login refused for user '{}' from {} ({} refused so far)", e.user, e.text,
                         login_refusals);
          }
          break;
        case cnc::hmi::WebEvent::Kind::kMessage:
          api.message(e.client, e.may_control, e.text, e.user);
          break;
      }
    }
    // Refused logins: an ALARM at most once a second, with the count since the last one.
    if (login_refusals > refusals_alarmed && now - last_login_alarm_s >= 1.0) {
      cnc::lcmt_alarm al{};
      al.source = "cnc-hmi";
      al.severity = cnc::lcmt_alarm::WARNING;
      al.code = "hmi_login_refused";
      al.text = std::to_string(login_refusals - refusals_alarmed) + " login(s) refused at " + url + " (" +
                std::to_string(login_refusals) + " since start)";
      bus.publish(cfg.channel(ch::kAlarm), al);
      refusals_alarmed = login_refusals;
      last_login_alarm_s = now;
    }
    api.update(now);
    if (now >= next_status) {
      // On a fixed schedule (a late frame does not delay the next ones), restarted after a stall.
      next_status = now - next_status > status_period ? now + status_period : next_status + status_period;
      if (web.clients() > 0) out.broadcast(api.status(now, login_refusals, web.clients()), true);
    }
    hb.tick(cnc::lcmt_heartbeat::RUNNING, 0,
            "url " + url + ", clients " + std::to_string(web.clients()) + ", logins " + std::to_string(logins) +
                ", login refusals " + std::to_string(login_refusals) + ", dropped " +
                std::to_string(web.dropped_messages()));
  }
  api.stop();
  web.stop();
  hb.tick(cnc::lcmt_heartbeat::STOPPING, 0, "", true);
  spdlog::info("cnc-hmi: stopped ({} logins, {} refused)", logins, login_refusals);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-hmi",
                          "the operator's page in a browser (HTTP and WebSocket), a client of the cell like cnc-ctl",
                          {{"www", "DIR", "the page's files (default: services/hmi/www, installed under /usr/share/cnc)"},
                           {"runs", "DIR", "where the run logs are listed from (default: the config's logger.directory)"},
                           {"port", "P", "the HTTP port (default: the config's hmi.port)", true},
                           {"hash-password", "USER", "print a line for hmi.users_file from a password on standard input"}},
                          {{"print-url", "", "print the page's address from the config and exit"}}};
  // --hash-password needs no machine: a users file is made before the cell is configured.
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--hash-password") spec.needs_machine = false;
  return cnc::service::run(spec, argc, argv, run_hmi);
}
