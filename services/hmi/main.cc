// cnc-hmi: the operator's page in a browser, a client of the cell like cnc-ctl.
//
// It reads the cell's state from the bus (AXIS_STATUS, SETPOINTS, INTERP_STATE,
// PROGRAM_STATE, PROGRAM_BLOCKS, ALARM, HEARTBEAT), pushes a snapshot to every
// browser over WebSocket at hmi.status_rate_hz (25 Hz), and turns a browser's
// actions into the same signed PROGRAM_CMD and DRIVE_CMD messages cnc-ctl sends
// (common/service/operator_commands.h), answered by the same interlock. README,
// "The browser HMI", has the WebSocket API.
//
//   cnc-hmi --machine M [--www DIR] [--runs DIR]
//   cnc-hmi --machine M --print-url            the page's address from the config
//   cnc-hmi --hash-password USER < password    a line for hmi.users_file
#include <fcntl.h>
#include <signal.h>
#include <sodium.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_program_block.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/program/block.h"
#include "common/service/heartbeat.h"
#include "common/service/operator_commands.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/install.h"
#include "common/util/signals.h"
#include "services/hmi/programs.h"
#include "services/hmi/runs.h"
#include "services/hmi/web.h"

namespace ch = cnc::config::channels;
using cnc::lcmt_program_command;
using json = nlohmann::json;

namespace {

constexpr size_t kAlarmsKept = 200;

const char* program_state_name(int8_t s) {
  static const char* const k[] = {"idle", "loaded", "running", "held", "done", "refused", "stopped", "fault"};
  return s >= 0 && s <= 7 ? k[s] : "?";
}
const char* interp_state_name(int8_t s) {
  static const char* const k[] = {"idle", "running", "held", "done", "starved", "fault"};
  return s >= 0 && s <= 5 ? k[s] : "?";
}
const char* drive_state_name(int8_t s) {
  static const char* const k[] = {"disabled", "enabling", "enabled", "stopping", "fault"};
  return s >= 0 && s <= 4 ? k[s] : "?";
}

// A finite number for JSON (NaN and infinities are not JSON).
double fin(double v) { return std::isfinite(v) ? v : 0.0; }

std::string read_text(const std::string& path, size_t limit) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return "";
  std::string s(limit, '\0');
  f.read(s.data(), static_cast<std::streamsize>(limit));
  s.resize(static_cast<size_t>(f.gcount()));
  return s;
}

// The dry run of a loaded program for the preview: cnc-plan (the same code as
// `./cnc plan`) in a child process, its setpoints thinned to what a canvas shows.
class DryRun {
 public:
  DryRun(std::string machine_file, std::string plan_exe) : machine_(std::move(machine_file)), exe_(std::move(plan_exe)) {}
  ~DryRun() { cancel(); }

  void start(int64_t token, const std::string& program) {
    cancel();
    cancelled_ = false;
    thread_ = std::thread([this, token, program] { run(token, program); });
  }
  void cancel() {
    cancelled_ = true;
    if (const pid_t p = pid_.load(); p > 0) kill(p, SIGTERM);
    if (thread_.joinable()) thread_.join();
  }
  // The finished preview, once (a JSON text), or "".
  std::string take() {
    std::lock_guard<std::mutex> lk(mu_);
    std::string r;
    r.swap(result_);
    return r;
  }

 private:
  void run(int64_t token, const std::string& program) {
    char tmpl[] = "/tmp/cnc-hmi-plan-XXXXXX";
    const int fd = mkstemp(tmpl);
    if (fd < 0) return;
    close(fd);
    const std::string csv = tmpl;
    const pid_t child = fork();
    if (child == 0) {
      const int devnull = open("/dev/null", O_WRONLY);
      if (devnull >= 0) {
        dup2(devnull, 1);
        dup2(devnull, 2);
      }
      execl(exe_.c_str(), exe_.c_str(), "--machine", machine_.c_str(), "--program", program.c_str(), "--csv",
            csv.c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
    json out;
    out["t"] = "preview";
    out["token"] = token;
    out["path"] = program;
    if (child < 0) {
      out["error"] = "cannot start the dry run";
    } else {
      pid_ = child;
      int status = 0;
      waitpid(child, &status, 0);
      pid_ = 0;
      if (cancelled_) {
        std::filesystem::remove(csv);
        return;
      }
      if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
        out["error"] = "the dry run (" + exe_ + ") ended with status " + std::to_string(WEXITSTATUS(status));
      } else {
        // Thinned: a point where the path moved 0.05 mm or its line changed, at most 40,000.
        std::ifstream f(csv);
        std::string row;
        std::getline(f, row);  // header
        std::vector<double> pts;
        std::vector<int> lines;
        double lx = 1e300, ly = 1e300, lz = 1e300;
        int lline = -1;
        double tol = 0.05;
        while (std::getline(f, row)) {
          double v[6];
          size_t b = 0;
          int k = 0;
          for (; k < 6; ++k) {
            size_t e = row.find(',', b);
            if (e == std::string::npos) break;
            v[k] = std::strtod(row.c_str() + b, nullptr);
            b = e + 1;
          }
          if (k < 6) continue;
          const int line = static_cast<int>(v[5]);
          if (std::fabs(v[2] - lx) + std::fabs(v[3] - ly) + std::fabs(v[4] - lz) < tol && line == lline) continue;
          lx = v[2], ly = v[3], lz = v[4], lline = line;
          pts.insert(pts.end(), {std::round(v[2] * 1000) / 1000, std::round(v[3] * 1000) / 1000,
                                 std::round(v[4] * 1000) / 1000});
          lines.push_back(line);
          if (lines.size() > 40000) {  // coarser, from the start again would cost a second pass: halve
            std::vector<double> p2;
            std::vector<int> l2;
            for (size_t i = 0; i < lines.size(); i += 2) {
              p2.insert(p2.end(), {pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]});
              l2.push_back(lines[i]);
            }
            pts.swap(p2);
            lines.swap(l2);
            tol *= 2;
          }
        }
        out["points"] = pts;
        out["lines"] = lines;
      }
    }
    std::filesystem::remove(csv);
    std::lock_guard<std::mutex> lk(mu_);
    result_ = out.dump();
  }

  std::string machine_, exe_;
  std::thread thread_;
  std::atomic<pid_t> pid_{0};
  std::atomic<bool> cancelled_{false};
  std::mutex mu_;
  std::string result_;
};

// Runs a program to its end (a child process; its output to `log_file`): its exit
// status, or -1 when it could not start or was cancelled.
int run_child(const std::vector<std::string>& argv, const std::string& log_file, std::atomic<pid_t>* pid_slot) {
  std::vector<char*> a;
  for (const auto& s : argv) a.push_back(const_cast<char*>(s.c_str()));
  a.push_back(nullptr);
  const pid_t child = fork();
  if (child == 0) {
    const int out = open(log_file.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (out >= 0) {
      dup2(out, 1);
      dup2(out, 2);
    }
    execv(a[0], a.data());
    _exit(127);
  }
  if (child < 0) return -1;
  *pid_slot = child;
  int status = 0;
  waitpid(child, &status, 0);
  *pid_slot = 0;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// The runs directory for the page (issue 17 item 3), on a thread of its own: a log is
// read whole for its summary (cached by path, size and time), and a report is made by
// the same two steps as ./cnc report (cnc-logexport, make_report.py). Nothing here
// touches the machine.
class RunsWorker {
 public:
  struct Job {
    uint64_t client = 0;
    json id;
    std::string kind;  // "list" or "report"
    std::string log;   // report: the log, relative to the runs directory (as listed)
  };
  RunsWorker(std::string dir, std::string logexport, std::string make_report)
      : dir_(std::move(dir)), logexport_(std::move(logexport)), make_report_(std::move(make_report)) {
    thread_ = std::thread([this] { loop(); });
  }
  ~RunsWorker() {
    {
      std::lock_guard<std::mutex> lk(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    if (const pid_t p = child_.load(); p > 0) kill(p, SIGTERM);
    thread_.join();
  }
  bool post(Job j) {
    std::lock_guard<std::mutex> lk(mu_);
    if (jobs_.size() >= 8) return false;
    jobs_.push_back(std::move(j));
    cv_.notify_one();
    return true;
  }
  std::vector<std::pair<uint64_t, json>> take() {
    std::lock_guard<std::mutex> lk(mu_);
    std::vector<std::pair<uint64_t, json>> out;
    out.swap(out_);
    return out;
  }

 private:
  static std::string report_dir(const cnc::hmi::RunEntry& r) {
    if (r.log.find('/') != std::string::npos) return r.name + "/report";
    return std::filesystem::path(r.name).stem().string() + "-report";
  }
  json list() {
    json runs = json::array();
    for (const auto& r : cnc::hmi::list_runs(dir_)) {
      const std::string path = dir_ + "/" + r.log;
      const std::string key = path + "|" + std::to_string(r.bytes) + "|" + std::to_string(r.mtime_s);
      auto it = cache_.find(path);
      if (it == cache_.end() || it->second.first != key) {
        it = cache_.insert_or_assign(path, std::make_pair(key, cnc::hmi::summarize_log(path))).first;
      }
      const cnc::hmi::RunSummary& sum = it->second.second;
      json row = {{"name", r.name},         {"log", r.log},         {"mtime", r.mtime_s},
                  {"bytes", r.bytes},       {"report", r.report},   {"programs", sum.programs},
                  {"mdi_lines", sum.mdi_lines}, {"duration_s", std::round(sum.duration_s * 10) / 10},
                  {"start", sum.start_utime_s}, {"alarms", sum.alarms}, {"faults", sum.faults}};
      if (!sum.ok) row["error"] = sum.error;
      if (r.report) row["report_url"] = "/runs/" + report_dir(r) + "/index.html";
      runs.push_back(row);
    }
    return {{"t", "runs"}, {"runs", runs}, {"dir", dir_}};
  }
  json report(const Job& j) {
    const auto all = cnc::hmi::list_runs(dir_);
    const auto it = std::find_if(all.begin(), all.end(), [&](const auto& r) { return r.log == j.log; });
    if (it == all.end())
      return {{"t", "result"}, {"id", j.id}, {"ok", false}, {"text", "report: no run '" + j.log + "' in " + dir_}};
    const std::string out = dir_ + "/" + report_dir(*it);
    std::filesystem::create_directories(out);
    const std::string log = dir_ + "/" + it->log;
    const std::string messages = out + "/make.log";
    std::filesystem::remove(messages);
    int rc = run_child({logexport_, "--log", log, "--out", out}, messages, &child_);
    if (rc == 0) {
      std::vector<std::string> mk = {"/usr/bin/python3", make_report_, out, "--title", it->name};
      const std::string lat = std::filesystem::path(log).parent_path().string() + "/latency";
      if (std::filesystem::is_directory(lat)) mk.insert(mk.end(), {"--latency-dir", lat});
      rc = run_child(mk, messages, &child_);
    }
    if (rc != 0)
      return {{"t", "result"}, {"id", j.id}, {"ok", false},
              {"text", "report of " + it->log + " failed (status " + std::to_string(rc) + "): see " + messages}};
    return {{"t", "result"}, {"id", j.id}, {"ok", true}, {"text", "report of " + it->log + " ready"},
            {"report_url", "/runs/" + report_dir(*it) + "/index.html"}};
  }
  // The run's path for the page to play back in its preview (the page animates it: the
  // machine is not involved).
  json playback(const Job& j) {
    const auto all = cnc::hmi::list_runs(dir_);
    const auto it = std::find_if(all.begin(), all.end(), [&](const auto& r) { return r.log == j.log; });
    if (it == all.end())
      return {{"t", "result"}, {"id", j.id}, {"ok", false}, {"text", "playback: no run '" + j.log + "' in " + dir_}};
    const cnc::hmi::RunPath p = cnc::hmi::log_path(dir_ + "/" + it->log);
    if (!p.ok || p.t_s.empty())
      return {{"t", "result"}, {"id", j.id}, {"ok", false},
              {"text", "playback: " + (p.ok ? "no setpoints in " + it->log : p.error)}};
    std::vector<double> xyz(p.xyz.size()), ts(p.t_s.size());
    for (size_t i = 0; i < xyz.size(); ++i) xyz[i] = std::round(p.xyz[i] * 1000) / 1000;
    for (size_t i = 0; i < ts.size(); ++i) ts[i] = std::round(p.t_s[i] * 1000) / 1000;
    return {{"t", "playback"}, {"id", j.id}, {"log", it->log}, {"points", xyz}, {"times", ts}, {"lines", p.lines},
            {"duration_s", p.duration_s}, {"setpoints", p.setpoints}};
  }
  void loop() {
    for (;;) {
      Job j;
      {
        std::unique_lock<std::mutex> lk(mu_);
        cv_.wait(lk, [&] { return stop_ || !jobs_.empty(); });
        if (stop_) return;
        j = std::move(jobs_.front());
        jobs_.pop_front();
      }
      json r = j.kind == "report" ? report(j) : j.kind == "playback" ? playback(j) : list();
      std::lock_guard<std::mutex> lk(mu_);
      out_.emplace_back(j.client, std::move(r));
      if (j.kind == "report") out_.emplace_back(j.client, list());
    }
  }

  std::string dir_, logexport_, make_report_;
  std::map<std::string, std::pair<std::string, cnc::hmi::RunSummary>> cache_;
  std::thread thread_;
  std::atomic<pid_t> child_{0};
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Job> jobs_;
  std::vector<std::pair<uint64_t, json>> out_;
  bool stop_ = false;
};

// An action sent to the cell, waiting for its answer (a refusal, a load, a start).
struct Pending {
  uint64_t client = 0;
  json id;
  std::string action;
  int8_t command = 0;
  int64_t seq = -1;
  double sent_s = 0;
  size_t alarms_at = 0;    // index into the alarm history at send time
  std::string path;        // LOAD: the absolute path
  int64_t old_token = 0;
  std::string suffix;      // MDI, touch-off: the line's program file
  int stage = 0;           // MDI: 0 loading, 1 waiting for the interpolator to take it, 2 started
  int64_t token = 0;
  int attempts = 0;
  double next_s = 0;
  double deadline_s = 0;
};

int run_hmi(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
  if (!args.option("hash-password").empty()) {
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
    std::printf("%s:%s\n", args.option("hash-password").c_str(), hash);
    return 0;
  }
  cnc::hmi::WebOptions wopt;
  wopt.listen = cfg.hmi.listen;
  wopt.port = args.option("port").empty() ? cfg.hmi.port : std::stoi(args.option("port"));
  wopt.read_only_without_login = cfg.hmi.read_only_without_login;
  wopt.www_dir = args.option("www", cnc::util::resource_path("services/hmi/www"));
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
  const std::string program_dir = cfg.hmi.program_dir;
  std::string plan_exe = cnc::util::executable_dir() + "/cnc-plan";
  if (!std::filesystem::exists(plan_exe)) plan_exe = cnc::util::executable_dir() + "/../tools/cnc-plan";

  cnc::bus::Bus bus(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-hmi"));
  const int naxes = static_cast<int>(cfg.axes.size());

  // ---- the cell's state, as the bus tells it ----
  cnc::lcmt_axis_status axes{};
  bool have_axes = false;
  cnc::lcmt_interp_state interp{};
  bool have_interp = false;
  cnc::lcmt_program_state program{};
  bool have_program = false;
  cnc::lcmt_setpoint setpoint{};
  bool have_setpoint = false;
  struct Seen {
    cnc::lcmt_heartbeat hb;
    double at_s;
  };
  std::map<std::string, Seen> services;
  std::vector<json> alarm_history;  // every alarm (its index matters), the newest kAlarmsKept shown
  size_t alarms_total = 0;
  std::deque<json> alarms_shown;
  struct BlockInfo {
    int line;
    bool in_program;  // the block's line is in the loaded program (not a subroutine file)
    double end[cnc::program::kMaxAxes];
  };
  std::map<int64_t, BlockInfo> blocks;  // of the loaded program's token
  int64_t blocks_token = -1;

  cnc::hmi::WebServer* web_ptr = nullptr;
  auto broadcast = [&](const json& j, bool droppable) {
    if (web_ptr) web_ptr->broadcast(std::make_shared<const std::string>(j.dump()), droppable);
  };
  auto send_to = [&](uint64_t client, const json& j) {
    if (web_ptr) web_ptr->send_to(client, std::make_shared<const std::string>(j.dump()));
  };

  bus.subscribe<cnc::lcmt_axis_status>(cfg.channel(ch::kAxisStatus), [&](const auto& m) {
    axes = m;
    have_axes = true;
  });
  bus.subscribe<cnc::lcmt_interp_state>(cfg.channel(ch::kInterpState), [&](const auto& m) {
    interp = m;
    have_interp = true;
  });
  bus.subscribe<cnc::lcmt_program_state>(cfg.channel(ch::kProgramState), [&](const auto& m) {
    program = m;
    have_program = true;
  });
  bus.subscribe<cnc::lcmt_setpoint>(cfg.channel(ch::kSetpoints), [&](const auto& m) {
    setpoint = m;
    have_setpoint = true;
  });
  bus.subscribe<cnc::lcmt_heartbeat>(cfg.channel(ch::kHeartbeat),
                                     [&](const auto& m) { services[m.service] = Seen{m, cnc::util::monotonic_s()}; });
  bus.subscribe<cnc::lcmt_program_block>(cfg.channel(ch::kProgramBlocks), [&](const auto& m) {
    if (!have_program || m.program_token != program.program_token) return;
    if (blocks_token != m.program_token) {
      blocks.clear();
      blocks_token = m.program_token;
    }
    BlockInfo b{};
    b.line = m.source_line;
    b.in_program = m.source_file == program.program_path || m.source_file.empty();
    for (int a = 0; a < naxes && a < m.num_axes; ++a) b.end[a] = m.end[static_cast<size_t>(a)];
    blocks[m.block_index] = b;
    // Bounded: the blocks well behind the path are dropped.
    while (blocks.size() > 4096) blocks.erase(blocks.begin());
  });
  bus.subscribe<cnc::lcmt_alarm>(cfg.channel(ch::kAlarm), [&](const auto& m) {
    static const char* const kSeverity[] = {"info", "warning", "fault"};
    json a = {{"utime", m.utime},
              {"source", m.source},
              {"severity", m.severity >= 0 && m.severity <= 2 ? kSeverity[m.severity] : "?"},
              {"code", m.code},
              {"text", m.text},
              {"n", alarms_total}};
    ++alarms_total;
    alarm_history.push_back(a);
    if (alarm_history.size() > 4 * kAlarmsKept) alarm_history.erase(alarm_history.begin(), alarm_history.begin() + kAlarmsKept);
    alarms_shown.push_back(a);
    if (alarms_shown.size() > kAlarmsKept) alarms_shown.pop_front();
    json msg = a;
    msg["t"] = "alarm";
    broadcast(msg, false);
  });
  // The alarms since a pending action was sent, by code (its index in the total count).
  auto alarm_since = [&](size_t from, std::initializer_list<const char*> codes) -> std::string {
    for (const json& a : alarm_history) {
      if (a["n"].get<size_t>() < from) continue;
      for (const char* c : codes)
        if (a["code"] == c) return a["text"].get<std::string>();
    }
    return "";
  };

  // ---- what the browsers say, handed over from the web thread ----
  std::mutex in_mu;
  std::deque<cnc::hmi::WebEvent> inbound;
  cnc::hmi::WebServer web(wopt, [&](cnc::hmi::WebEvent e) {
    std::lock_guard<std::mutex> lk(in_mu);
    if (inbound.size() < 4096) inbound.push_back(std::move(e));
  });
  web_ptr = &web;
  web.start();
  const std::string url = web.url();
  spdlog::info("cnc-hmi: the operator's page is at {} ({})", url,
               wopt.users.empty() ? "no login: localhost only"
                                  : std::to_string(wopt.users.size()) + " users, login required" +
                                        (wopt.read_only_without_login ? ", view only without" : ""));
  std::printf("cnc-hmi: open %s\n", url.c_str());
  std::fflush(stdout);

  cnc::service::Heartbeat hb(bus, cfg, "cnc-hmi");
  DryRun dry(args.machine_file, plan_exe);
  std::string logexport_exe = cnc::util::executable_dir() + "/cnc-logexport";
  if (!std::filesystem::exists(logexport_exe)) logexport_exe = cnc::util::executable_dir() + "/../tools/cnc-logexport";
  RunsWorker runs(wopt.runs_dir, logexport_exe, cnc::util::resource_path("tools/report/make_report.py"));
  std::vector<Pending> pending;
  std::map<uint64_t, int> jogging;  // client -> axis of its continuous jog
  int64_t login_refusals = 0, logins = 0, refusals_alarmed = 0;
  double last_login_alarm_s = -1e9;
  std::string program_text_path;
  json program_msg = {{"t", "program"}, {"path", ""}, {"text", ""}};
  json preview_msg;
  int64_t preview_token = 0;
  std::string dry_error;

  auto hello = [&](uint64_t client, bool may_control, const std::string& user) {
    json ax = json::array();
    for (const auto& a : cfg.axes) ax.push_back({{"name", a.name}, {"min", a.min_mm}, {"max", a.max_mm}});
    send_to(client, {{"t", "hello"},
                     {"machine", cfg.name},
                     {"version", cnc::util::version()},
                     {"axes", ax},
                     {"may_control", may_control},
                     {"user", user},
                     {"login", !wopt.users.empty()},
                     {"program_dir", program_dir},
                     {"programs", cnc::hmi::list_programs(program_dir)},
                     // Commands the cell does not have yet: their controls stay disabled.
                     {"unavailable", json::array()},
                     {"status_rate_hz", cfg.hmi.status_rate_hz}});
    send_to(client, program_msg);
    if (!preview_msg.is_null()) send_to(client, preview_msg);
    json list = json::array();
    for (const auto& a : alarms_shown) list.push_back(a);
    send_to(client, {{"t", "alarms"}, {"alarms", list}});
  };
  auto result = [&](uint64_t client, const json& id, bool ok, const std::string& text) {
    send_to(client, {{"t", "result"}, {"id", id}, {"ok", ok}, {"text", text}});
    if (!ok) spdlog::info("cnc-hmi: client {}: {}", client, text);
  };
  auto axis_index = [&](const json& j) -> int {
    if (!j.contains("axis") || j["axis"].is_null()) return -1;
    if (j["axis"].is_string()) return cfg.axis_index(j["axis"].get<std::string>());
    return j["axis"].get<int>();
  };
  auto number = [](const json& j, const char* key, double fallback) {
    if (!j.contains(key)) return fallback;
    if (j[key].is_number()) return j[key].get<double>();
    if (j[key].is_string()) {
      const std::string s = j[key].get<std::string>();
      char* end = nullptr;
      const double v = std::strtod(s.c_str(), &end);
      if (end != s.c_str() && *end == '\0' && std::isfinite(v)) return v;
    }
    throw std::invalid_argument(std::string("'") + key + "' must be a number");
  };
  auto send_cmd = [&](uint64_t client, const json& id, const std::string& action,
                      const cnc::service::OperatorCommand& c) -> Pending* {
    const int64_t seq = cnc::service::send_program_command(bus, cfg, c);
    if (seq < 0) {
      result(client, id, false, std::string("not sent: ") + bus.last_publish_error());
      return nullptr;
    }
    Pending p;
    p.client = client;
    p.id = id;
    p.action = action;
    p.command = c.command;
    p.seq = seq;
    p.sent_s = cnc::util::monotonic_s();
    p.alarms_at = alarms_total;
    p.deadline_s = p.sent_s + 2.0;
    pending.push_back(p);
    return &pending.back();
  };
  auto all_enabled = [&] {
    if (!have_axes || axes.num_axes == 0) return false;
    for (int8_t s : axes.drive_state)
      if (s != cnc::lcmt_axis_status::ENABLED) return false;
    return true;
  };

  auto act = [&](const cnc::hmi::WebEvent& e) {
    json j;
    try {
      j = json::parse(e.text);
    } catch (const json::exception& ex) {
      send_to(e.client, {{"t", "result"}, {"id", nullptr}, {"ok", false}, {"text", std::string("not JSON: ") + ex.what()}});
      return;
    }
    const json id = j.contains("id") ? j["id"] : json(nullptr);
    const std::string action = j.value("action", "");
    try {
      if (action == "programs") {
        send_to(e.client, {{"t", "programs"}, {"programs", cnc::hmi::list_programs(program_dir)}});
        return;
      }
      if (action == "runs") {
        if (!runs.post({e.client, id, "list", ""})) result(e.client, id, false, "runs: busy, try again");
        return;
      }
      if (action == "ping") {
        send_to(e.client, {{"t", "pong"}, {"id", id}});
        return;
      }
      if (!e.may_control) {
        result(e.client, id, false, "view only: log in to operate the machine");
        return;
      }
      if (action == "playback") {
        if (!runs.post({e.client, id, "playback", j.value("log", "")})) result(e.client, id, false, "playback: busy, try again");
        return;
      }
      if (action == "report") {
        if (!runs.post({e.client, id, "report", j.value("log", "")})) result(e.client, id, false, "report: busy, try again");
        return;
      }
      cnc::service::OperatorCommand c;
      if (action == "load") {
        std::string why;
        const std::string path = cnc::hmi::resolve_program(program_dir, j.value("path", ""), &why);
        if (path.empty()) {
          result(e.client, id, false, "load refused: " + why);
          return;
        }
        c.command = lcmt_program_command::LOAD;
        c.program_path = path;
        // Run from line N (0: from the start): the cell shows the approach and waits for a confirm.
        const double from = number(j, "from_line", 0.0);
        if (!(from >= 0 && from <= 1e7 && from == std::floor(from))) {
          result(e.client, id, false, "load refused: from_line must be a line number >= 1");
          return;
        }
        c.from_line = static_cast<int32_t>(from);
        if (Pending* p = send_cmd(e.client, id, action, c)) {
          p->path = path;
          p->old_token = have_program ? program.program_token : 0;
          p->deadline_s = p->sent_s + 10.0;
        }
        return;
      }
      if (action == "start" || action == "hold" || action == "resume" || action == "stop" || action == "confirm") {
        c.command = *cnc::service::program_command_by_name(action);
        if (action == "stop") jogging.erase(e.client);
        if (send_cmd(e.client, id, action, c)) result(e.client, id, true, action + " sent");
        return;
      }
      if (action == "single_block" || action == "optional_stop" || action == "block_delete") {
        // The switches (1 on, 0 off): the interlock answers as for cnc-ctl --do single-block ...
        std::string name = action;
        std::replace(name.begin(), name.end(), '_', '-');
        c.command = *cnc::service::program_command_by_name(name);
        const bool on = j.value("value", false);
        c.value = on ? 1 : 0;
        c.axis = -1;
        c.feed_override = 0;
        if (send_cmd(e.client, id, action, c)) result(e.client, id, true, name + (on ? " on" : " off") + " sent");
        return;
      }
      if (action == "override" || action == "rapid_override") {
        const bool rapid = action == "rapid_override";
        c.command = rapid ? lcmt_program_command::RAPID_OVERRIDE : lcmt_program_command::OVERRIDE;
        c.feed_override = number(j, "value", 1.0);
        if (send_cmd(e.client, id, action, c)) result(e.client, id, true, action + " sent");
        return;
      }
      if (action == "enable" || action == "disable") {
        const int8_t d = action == "enable" ? cnc::lcmt_drive_command::ENABLE : cnc::lcmt_drive_command::DISABLE;
        if (!cnc::service::send_drive_command(bus, cfg, d))
          result(e.client, id, false, std::string("not sent: ") + bus.last_publish_error());
        else
          result(e.client, id, true, action + " sent");
        return;
      }
      if (action == "reset") {
        // As cnc-ctl --do reset: the drives enabled first (ENABLE every second until they
        // are), then RESET every 0.5 s until the interpolator's `reset` alarm.
        Pending p;
        p.client = e.client;
        p.id = id;
        p.action = "reset";
        p.command = lcmt_program_command::RESET;
        p.sent_s = cnc::util::monotonic_s();
        p.alarms_at = alarms_total;
        p.deadline_s = p.sent_s + 30;
        pending.push_back(p);
        return;
      }
      if (action == "home") {
        c.command = lcmt_program_command::HOME;
        c.axis = axis_index(j);
        c.feed_override = 0;
        if (j.contains("axis") && !j["axis"].is_null() && c.axis < 0) {
          result(e.client, id, false, "home: the machine has no axis " + j["axis"].dump());
          return;
        }
        if (send_cmd(e.client, id, action, c)) result(e.client, id, true, "home sent");
        return;
      }
      if (action == "jog" || action == "jog_keepalive" || action == "jog_stop") {
        const int a = axis_index(j);
        if (a < 0 || a >= naxes) {
          result(e.client, id, false, action + ": the machine has no axis " + j.value("axis", json()).dump());
          return;
        }
        c.axis = a;
        c.feed_override = 0;
        if (action == "jog_keepalive") {
          // Only for the jog this client holds: a late keepalive never restarts anything.
          const auto it = jogging.find(e.client);
          if (it == jogging.end() || it->second != a) return;
          c.command = lcmt_program_command::JOG_KEEPALIVE;
          cnc::service::send_program_command(bus, cfg, c);
          return;
        }
        if (action == "jog_stop") {
          jogging.erase(e.client);
          c.command = lcmt_program_command::STOP;
          c.axis = -1;
          c.feed_override = 1.0;
          if (send_cmd(e.client, id, action, c)) result(e.client, id, true, "jog stopped");
          return;
        }
        c.command = lcmt_program_command::JOG;
        c.value = number(j, "value", 0);
        c.feed_mm_per_min = number(j, "feed", 0);
        c.jog_continuous = j.value("continuous", false) ? 1 : 0;
        if (c.jog_continuous) jogging[e.client] = a;
        if (send_cmd(e.client, id, action, c)) result(e.client, id, true, "jog sent");
        return;
      }
      if (action == "touch_off" || action == "mdi") {
        if (action == "touch_off") {
          c.command = lcmt_program_command::TOUCH_OFF;
          c.axis = axis_index(j);
          if (c.axis < 0 || c.axis >= naxes) {
            result(e.client, id, false, "touch_off: the machine has no axis " + j.value("axis", json()).dump());
            return;
          }
          c.value = number(j, "value", 0);
        } else {
          c.command = lcmt_program_command::MDI;
          c.text = j.value("line", "");
          if (c.text.empty()) {
            result(e.client, id, false, "mdi: no line");
            return;
          }
        }
        c.feed_override = 0;
        if (Pending* p = send_cmd(e.client, id, action, c)) {
          p->suffix = cnc::service::mdi_program_suffix(bus.sender(), p->seq);
          p->old_token = have_program ? program.program_token : 0;
          p->deadline_s = p->sent_s + 10.0;
        }
        return;
      }
      result(e.client, id, false, "unknown action '" + action + "'");
    } catch (const std::exception& ex) {
      result(e.client, id, false, action + ": " + ex.what());
    }
  };

  // Pending actions: answered by a refusal, a load, a start, or their time running out.
  auto follow = [&](double now) {
    for (size_t i = 0; i < pending.size();) {
      Pending& p = pending[i];
      bool done = false;
      auto finish = [&](bool ok, const std::string& text) {
        result(p.client, p.id, ok, text);
        done = true;
      };
      const std::string why = have_program ? cnc::service::refusal_of(program, bus.sender(), p.seq) : "";
      if (!why.empty()) {
        finish(false, p.action + " refused: " + why);
      } else if (p.command == lcmt_program_command::JOG || p.command == lcmt_program_command::HOME) {
        if (const std::string a = alarm_since(p.alarms_at, {"jog_refused", "home_refused"}); !a.empty()) {
          finish(false, p.action + " refused: " + a);
          jogging.erase(p.client);
        } else if (now > p.deadline_s) {
          done = true;
        }
      } else if (p.command == lcmt_program_command::LOAD) {
        if (have_program && program.program_path == p.path && program.state == cnc::lcmt_program_state::REFUSED) {
          finish(false, "program refused: " + program.error);
        } else if (have_program && program.program_path == p.path && program.program_token != p.old_token &&
                   program.state == cnc::lcmt_program_state::LOADED) {
          finish(true, "loaded " + p.path + ": " + std::to_string(program.num_blocks) + " blocks");
        } else if (now > p.deadline_s) {
          finish(false, "the program server did not answer the load of " + p.path);
        }
      } else if (p.command == lcmt_program_command::MDI || p.command == lcmt_program_command::TOUCH_OFF) {
        if (p.stage == 0 && have_program && program.program_path.ends_with(p.suffix)) {
          if (program.state == cnc::lcmt_program_state::REFUSED) {
            finish(false, p.action + " refused: " + program.error);
          } else if (program.state == cnc::lcmt_program_state::LOADED && program.program_token != p.old_token) {
            p.stage = 1;
            p.token = program.program_token;
            spdlog::info("cnc-hmi: client {}: {} loaded as {} (token {})", p.client, p.action, program.program_path,
                         p.token);
          }
        }
        if (!done && p.stage == 1 && have_interp && interp.program_token == p.token) {
          // As cnc-ctl: the line's program, once the interpolator took it, is started.
          cnc::service::OperatorCommand c;
          c.command = lcmt_program_command::START;
          p.seq = cnc::service::send_program_command(bus, cfg, c);
          spdlog::info("cnc-hmi: client {}: {}: START sent (seq {})", p.client, p.action, p.seq);
          p.stage = 2;
          p.attempts = 1;
          p.next_s = now + 1.0;
        }
        if (!done && p.stage == 2) {
          if (have_interp && interp.program_token == p.token && interp.state != cnc::lcmt_setpoint::IDLE) {
            finish(true, p.action + " started");
          } else if (now >= p.next_s && p.attempts < 5) {
            cnc::service::OperatorCommand c;
            c.command = lcmt_program_command::START;
            p.seq = cnc::service::send_program_command(bus, cfg, c);
            ++p.attempts;
            p.next_s = now + 1.0;
          }
        }
        if (!done && now > p.deadline_s) finish(false, p.action + ": the cell did not run the line");
      } else if (p.command == lcmt_program_command::RESET) {
        if (p.stage == 0) {
          if (all_enabled()) {
            p.stage = 1;
            p.next_s = 0;
          } else if (now >= p.next_s) {
            cnc::service::send_drive_command(bus, cfg, cnc::lcmt_drive_command::ENABLE);
            p.next_s = now + 1.0;
          }
        }
        if (p.stage == 1) {
          if (!alarm_since(p.alarms_at, {"reset"}).empty()) {
            finish(true, "reset: the drives are enabled and the interpolator stands where they are");
          } else if (now >= p.next_s) {
            cnc::service::OperatorCommand c;
            c.command = lcmt_program_command::RESET;
            p.seq = cnc::service::send_program_command(bus, cfg, c);
            p.next_s = now + 0.5;
          }
        }
        if (!done && now > p.deadline_s)
          finish(false, p.stage == 0 ? "reset: the drives did not enable" : "reset: the interpolator did not reset");
      } else if (now > p.deadline_s) {
        done = true;  // answered "sent" already; no refusal came
      }
      if (done) {
        pending.erase(pending.begin() + static_cast<std::ptrdiff_t>(i));
      } else {
        ++i;
      }
    }
  };

  auto status_json = [&](double now) {
    json ax = json::array();
    const bool sp_is_program = have_setpoint && have_program && setpoint.program_token == program.program_token;
    const BlockInfo* blk = nullptr;
    if (sp_is_program) {
      const auto it = blocks.find(setpoint.block_index);
      if (it != blocks.end()) blk = &it->second;
    }
    for (int a = 0; a < naxes; ++a) {
      const size_t i = static_cast<size_t>(a);
      json x = {{"name", cfg.axes[i].name}};
      if (have_axes && a < axes.num_axes) {
        x["cmd"] = fin(axes.commanded_mm[i]);
        x["act"] = fin(axes.actual_mm[i]);
        x["fe"] = fin(axes.following_error_mm[i]);
        x["drive"] = drive_state_name(axes.drive_state[i]);
        if (!axes.fault[i].empty()) x["fault"] = axes.fault[i];
      }
      if (have_interp && a < interp.num_axes) x["pos"] = fin(interp.position_mm[i]);
      if (have_interp && a < interp.num_homed) x["homed"] = interp.homed[i] != 0;
      if (blk != nullptr && have_axes && a < axes.num_axes) x["dtg"] = fin(blk->end[a] - axes.commanded_mm[i]);
      ax.push_back(x);
    }
    json s = {{"t", "status"}, {"axes", ax}, {"time", cnc::util::wall_utime()}};
    if (have_interp) {
      static const char* const kModes[] = {"program", "jog", "home"};
      s["interp"] = {{"state", interp_state_name(interp.state)},
                     {"mode", interp.mode >= 0 && interp.mode <= 2 ? kModes[interp.mode] : "?"},
                     {"mode_text", interp.mode_text},
                     {"feed_override", fin(interp.feed_override)},
                     {"rapid_override", fin(interp.rapid_override)},
                     {"token", interp.program_token},
                     {"blocks_done", interp.blocks_done},
                     {"program_time_s", fin(interp.program_time_s)},
                     {"single_block", interp.single_block != 0},
                     {"optional_stop", interp.optional_stop != 0},
                     {"source_line", interp.source_line}};
    }
    if (have_program) {
      s["program"] = {{"state", program_state_name(program.state)},
                      {"path", program.program_path},
                      {"token", program.program_token},
                      {"blocks", program.num_blocks},
                      {"error", program.error},
                      {"refusal", program.refusal},
                      {"block_delete", program.block_delete != 0},
                      {"from_line", program.from_line},
                      {"approach", program.approach},
                      {"approach_pending", program.approach_pending != 0}};
    }
    if (have_setpoint) {
      s["feed"] = fin(setpoint.feed_mm_per_min);
      if (sp_is_program) {
        // Held (single block, M1, a hold): the line the path stands before, from the interpolator.
        const bool held = have_interp && interp.state == cnc::lcmt_setpoint::HELD && interp.source_line > 0 &&
                          interp.program_token == setpoint.program_token;
        s["line"] = held ? interp.source_line : setpoint.source_line;
        s["line_in_program"] = blk == nullptr || blk->in_program;
        s["block"] = setpoint.block_index;
      }
    }
    json sv = json::object();
    static const char* const kHb[] = {"starting", "running", "stopping", "fault"};
    for (const auto& [name, seen] : services)
      sv[name] = {{"state", seen.hb.state >= 0 && seen.hb.state <= 3 ? kHb[seen.hb.state] : "?"},
                  {"age", std::round((now - seen.at_s) * 100) / 100},
                  {"lost", now - seen.at_s > cfg.heartbeat_timeout_s}};
    s["services"] = sv;
    s["login_refusals"] = login_refusals;
    s["clients"] = web.clients();
    return s;
  };

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
          hello(e.client, e.may_control, e.user);
          break;
        case cnc::hmi::WebEvent::Kind::kClose:
          // A client that held a continuous jog and went away: stopped now, not only
          // by the interpolator's keepalive timeout.
          if (jogging.count(e.client)) {
            cnc::service::OperatorCommand c;
            c.command = lcmt_program_command::STOP;
            cnc::service::send_program_command(bus, cfg, c);
            jogging.erase(e.client);
            spdlog::warn("cnc-hmi: client {} left during a continuous jog: STOP sent", e.client);
          }
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
          act(e);
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
    follow(now);

    // The loaded program: its text and its dry run for the preview, once per load.
    if (have_program && !program.program_path.empty() && program.program_path != program_text_path) {
      program_text_path = program.program_path;
      std::string text = read_text(program_text_path, 4 << 20);
      program_msg = {{"t", "program"},
                     {"path", program_text_path},
                     {"name", std::filesystem::path(program_text_path).filename().string()},
                     {"text", text}};
      broadcast(program_msg, false);
    }
    if (have_program && program.state == cnc::lcmt_program_state::LOADED && program.program_token != preview_token &&
        !program.program_path.empty()) {
      preview_token = program.program_token;
      // An MDI or touch-off line keeps the program's preview.
      if (std::filesystem::path(program.program_path).filename().string().rfind("mdi-", 0) != 0)
        dry.start(preview_token, program.program_path);
    }
    if (std::string p = dry.take(); !p.empty()) {
      preview_msg = json::parse(p);
      broadcast(preview_msg, false);
    }

    for (auto& [client, msg] : runs.take()) send_to(client, msg);
    if (now >= next_status) {
      // On a fixed schedule (a late frame does not delay the next ones), restarted after a stall.
      next_status = now - next_status > status_period ? now + status_period : next_status + status_period;
      if (web.clients() > 0) broadcast(status_json(now), true);
    }
    hb.tick(cnc::lcmt_heartbeat::RUNNING, 0,
            "url " + url + ", clients " + std::to_string(web.clients()) + ", logins " + std::to_string(logins) +
                ", login refusals " + std::to_string(login_refusals) + ", dropped " +
                std::to_string(web.dropped_messages()));
  }
  // Leaving with a jog held by a browser: stopped.
  if (!jogging.empty()) {
    cnc::service::OperatorCommand c;
    c.command = lcmt_program_command::STOP;
    cnc::service::send_program_command(bus, cfg, c);
  }
  dry.cancel();
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
