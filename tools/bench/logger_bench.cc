// cnc-bench-logger: how many messages the logger loses, and what it costs in CPU.
//
// Starts cnc-logger as a child process on a private LCM port and channel prefix
// (a copy of config/machines/sim3.yaml), publishes lcmt_setpoint and
// lcmt_axis_status (3 axes, the sizes the cell sends) at --rate-hz each for
// --seconds, stops the logger with SIGTERM and reads its files back through the
// bus's file back end. Reports per channel: published, in the log, lost
// (published - logged), the gaps the log itself shows, and what the logger's own
// stats (lcmt_logger_stats, the closing report) say it received, saw missing and
// dropped; then the logger's CPU share (utime + stime from /proc/PID/stat over the
// publishing wall time) and CPU time per message.
//
// Multicast must reach the logger: run it inside a private network namespace
//   unshare -n sh -c 'ip link set lo up && ip route add 224.0.0.0/4 dev lo && cnc-bench-logger ...'
// or on a host whose default route carries multicast (the port is private anyway).
//
//   cnc-bench-logger [--seconds 600] [--rate-hz 1000] [--rotate-mb 64] [--logger EXE]
//                    [--work DIR] [--max-lost N] [--keep]
// Exit codes: 0 done (and lost <= --max-lost when given); 1 more lost, or the
// logger failed; 2 bad flags.
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>

#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_logger_stats.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/bus/bus.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/signals.h"

namespace fs = std::filesystem;

namespace {

// utime + stime of a process in seconds, from /proc/PID/stat; -1 when unreadable.
double cpu_seconds(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto close_paren = stat.rfind(')');
  if (close_paren == std::string::npos) return -1;
  std::istringstream f(stat.substr(close_paren + 2));
  std::string field;
  long long utime = 0, stime = 0;
  // Fields from 3 (state) on; utime is field 14, stime 15.
  for (int i = 3; i <= 15 && f >> field; ++i) {
    if (i == 14) utime = std::atoll(field.c_str());
    if (i == 15) stime = std::atoll(field.c_str());
  }
  return static_cast<double>(utime + stime) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

std::string replace_once(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  if (at == std::string::npos) throw std::runtime_error("sim3.yaml no longer contains '" + from + "'");
  return text.replace(at, from.size(), to);
}

// Where the stream of one channel has a hole: what the logger was doing then.
struct Gap {
  std::string channel;
  int64_t missing = 0;
  double at_s = 0;          // since the first event of the run
  double pause_s = 0;       // receive time between the messages around the hole
  int file = 0;
  double into_file_s = 0;   // since the first event of that file (a rotation's fsync?)
};

struct ChannelCount {
  int64_t published = 0;
  int64_t logged = 0;        // ours, in the log files
  int64_t gaps_in_log = 0;   // sequence gaps the log shows
  int64_t logger_received = 0, logger_gaps = 0, logger_dropped = 0;
};

int run_bench(const cnc::config::MachineConfig&, const cnc::service::Args& args) {
  const double seconds = std::atof(args.option("seconds", "600").c_str());
  const double rate_hz = std::atof(args.option("rate-hz", "1000").c_str());
  const double rotate_mb = std::atof(args.option("rotate-mb", "64").c_str());
  const long long max_lost = std::atoll(args.option("max-lost", "-1").c_str());
  const std::string logger_exe = args.option("logger", CNC_BINARY_DIR "/services/cnc-logger");
  if (!(seconds > 0) || !(rate_hz > 0 && rate_hz <= 20000) || !(rotate_mb >= 1)) {
    std::fprintf(stderr, "cnc-bench-logger: --seconds > 0, 0 < --rate-hz <= 20000, --rotate-mb >= 1\n");
    return cnc::service::kExitBadInput;
  }
  std::string work = args.option("work");
  const bool own_work = work.empty();
  if (own_work) {
    char tmpl[] = "/tmp/cnc-bench-logger.XXXXXX";
    if (mkdtemp(tmpl) == nullptr) throw std::runtime_error("mkdtemp failed");
    work = tmpl;
  }
  fs::create_directories(work);

  // A private port and prefix: a copy of the simulated cell's config.
  const int port = 20000 + static_cast<int>((static_cast<unsigned>(getpid()) * 7919u) % 20000u);
  const std::string prefix = "B" + std::to_string(port) + ".";
  std::ifstream src(CNC_SOURCE_DIR "/config/machines/sim3.yaml");
  std::string yaml((std::istreambuf_iterator<char>(src)), std::istreambuf_iterator<char>());
  yaml = replace_once(yaml, "udpm://239.255.76.67:7667", "udpm://239.255.76.67:" + std::to_string(port));
  yaml = replace_once(yaml, "channel_prefix: \"SIM3.\"", "channel_prefix: \"" + prefix + "\"");
  yaml = replace_once(yaml, "rotate_mb: 512", "rotate_mb: " + std::to_string(rotate_mb));
  const std::string machine = work + "/machine.yaml";
  std::ofstream(machine) << yaml;
  const cnc::config::MachineConfig cfg = cnc::config::load_machine_config(machine);
  if (cfg.security.signing && !fs::exists(cfg.security.key_file)) {
    cnc::bus::KeySet keys;  // signing as in the cell: the bench's own key beside its config
    keys.add(cnc::bus::generate_key());
    cnc::bus::write_key_file(cfg.security.key_file, keys);
  }
  const std::string base = work + "/bench";

  const pid_t logger = fork();
  if (logger < 0) throw std::runtime_error("fork failed");
  if (logger == 0) {
    const std::string out = work + "/logger.out";
    if (!freopen(out.c_str(), "w", stdout) || !freopen(out.c_str(), "a", stderr)) _exit(127);
    execl(logger_exe.c_str(), logger_exe.c_str(), "--machine", machine.c_str(), "--out", base.c_str(),
          static_cast<char*>(nullptr));
    _exit(127);
  }
  auto logger_failed = [&](const char* what) {
    kill(logger, SIGKILL);
    waitpid(logger, nullptr, 0);
    std::fprintf(stderr, "cnc-bench-logger: %s (logger output in %s/logger.out)\n", what, work.c_str());
    return cnc::service::kExitFailure;
  };

  // The logger is up when its first heartbeat arrives (it subscribes before it sends one).
  {
    cnc::bus::Bus probe(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-bench-logger"));
    bool up = false;
    probe.subscribe<cnc::lcmt_heartbeat>(cfg.channel("HEARTBEAT"), [&](const cnc::lcmt_heartbeat& hb) {
      if (hb.service == "cnc-logger" && hb.pid == logger) up = true;
    });
    const double deadline = cnc::util::monotonic_s() + 10;
    while (!up && cnc::util::monotonic_s() < deadline && !cnc::util::stop_requested()) probe.handle(100);
    if (!up) return logger_failed("no heartbeat from the logger within 10 s (is multicast routed? see --help)");
  }

  // Messages as the cell sends them: 3 axes.
  cnc::bus::Bus pub(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-bench-logger"));
  const std::string ch_sp = cfg.channel("SETPOINTS"), ch_as = cfg.channel("AXIS_STATUS");
  cnc::lcmt_setpoint sp{};
  sp.period_s = 1.0 / rate_hz;
  sp.num_axes = 3;
  sp.position_mm.assign(3, 0.0);
  sp.feed_mm_per_min = 3000;
  sp.program_token = 1;
  sp.limit = cnc::lcmt_setpoint::LIMIT_PROGRAM;
  sp.state = cnc::lcmt_setpoint::RUNNING;
  cnc::lcmt_axis_status as{};
  as.num_axes = 3;
  as.axis_name = {"X", "Y", "Z"};
  as.commanded_mm.assign(3, 0.0);
  as.actual_mm.assign(3, 0.0);
  as.following_error_mm.assign(3, 0.0);
  as.drive_state.assign(3, int8_t{cnc::lcmt_axis_status::ENABLED});  // by value: LCM never defines the constant
  as.fault.assign(3, "");
  for (auto* v : {&as.transactions, &as.timeouts, &as.exceptions, &as.crc_errors, &as.reconnects}) v->assign(3, 0);
  std::printf("cnc-bench-logger: %.0f s at %.0f Hz per channel, messages of %d B (setpoint) and %d B (axis status), "
              "logger pid %d, port %d\n",
              seconds, rate_hz, sp.getEncodedSize(), as.getEncodedSize(), static_cast<int>(logger), port);
  std::fflush(stdout);

  std::map<std::string, ChannelCount> counts;
  const auto cycles = static_cast<int64_t>(std::llround(seconds * rate_hz));
  cnc::util::PeriodicTimer timer(1.0 / rate_hz);
  const double cpu0 = cpu_seconds(logger), wall0 = cnc::util::monotonic_s();
  int64_t cycle = 0;
  for (; cycle < cycles && !cnc::util::stop_requested(); ++cycle) {
    timer.wait();
    const double t = static_cast<double>(cycle) / rate_hz;
    for (int a = 0; a < 3; ++a) {
      const double p = 50.0 * std::sin(0.5 * t + a);
      sp.position_mm[static_cast<size_t>(a)] = p;
      as.commanded_mm[static_cast<size_t>(a)] = p;
      as.actual_mm[static_cast<size_t>(a)] = p - 0.01;
      as.following_error_mm[static_cast<size_t>(a)] = 0.01;
      as.transactions[static_cast<size_t>(a)] = cycle;
    }
    sp.cycle = as.setpoint_cycle = cycle;
    sp.u = std::fmod(t, 1.0);
    pub.publish(ch_sp, sp);
    pub.publish(ch_as, as);
    if (cycle % 1000 == 0 && waitpid(logger, nullptr, WNOHANG) != 0) {
      return logger_failed("the logger ended during the run");
    }
  }
  const double wall = cnc::util::monotonic_s() - wall0;
  const double cpu = cpu_seconds(logger) - cpu0;
  counts[ch_sp].published = counts[ch_as].published = cycle;

  // Let the logger take what is queued, then stop it as the cell does.
  std::this_thread::sleep_for(std::chrono::seconds(1));
  kill(logger, SIGTERM);
  int status = 0;
  rusage usage{};
  if (wait4(logger, &status, 0, &usage) != logger || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::fprintf(stderr, "cnc-bench-logger: the logger did not exit 0 on SIGTERM (output in %s/logger.out)\n",
                 work.c_str());
    return cnc::service::kExitFailure;
  }
  const double cpu_total = static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
                           static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec) * 1e-6;

  // Read every file of the run back through the bus's file back end.
  int files = 0;
  uintmax_t log_bytes = 0;
  cnc::lcmt_logger_stats last_stats{};
  bool have_stats = false;
  const std::string ch_stats = cfg.channel("LOGGER_STATS");
  std::vector<Gap> gaps;
  std::map<std::string, std::pair<int64_t, int64_t>> last_seq;  // channel -> (seq, receive utime)
  int64_t run_start = -1;
  for (;; ++files) {
    const std::string path = files == 0 ? base + ".lcmlog" : base + "." + std::to_string(files) + ".lcmlog";
    if (!fs::exists(path)) break;
    log_bytes += fs::file_size(path);
    cnc::bus::Bus reader("file://" + path + "?speed=0");
    int64_t file_start = -1;
    reader.subscribe_raw(".*", [&](const std::string& ch, const void* data, size_t size, int64_t recv_utime) {
      if (file_start < 0) file_start = recv_utime;
      if (run_start < 0) run_start = recv_utime;
      const auto hdr = cnc::bus::peek_header(data, size);
      if ((ch == ch_sp || ch == ch_as) && hdr && hdr->sender == pub.sender()) {
        ++counts[ch].logged;
        auto it = last_seq.find(ch);
        if (it != last_seq.end() && hdr->seq > it->second.first + 1) {
          gaps.push_back({ch, hdr->seq - it->second.first - 1, 1e-6 * static_cast<double>(it->second.second - run_start),
                          1e-6 * static_cast<double>(recv_utime - it->second.second), files,
                          1e-6 * static_cast<double>(recv_utime - file_start)});
        }
        last_seq[ch] = {hdr->seq, recv_utime};
      }
      if (ch == ch_stats) {
        cnc::lcmt_logger_stats m;
        const size_t n = cnc::bus::payload_size(data, size);  // without a signature trailer
        if (m.decode(data, 0, static_cast<int>(n)) == static_cast<int>(n)) {
          last_stats = m;
          have_stats = true;
        }
      }
    });
    while (reader.handle(1000) > 0) {
    }
    for (const auto& ch : {ch_sp, ch_as}) counts[ch].gaps_in_log += reader.stats(ch).seq_gaps;
  }
  if (have_stats) {
    for (int i = 0; i < last_stats.num_channels; ++i) {
      auto it = counts.find(last_stats.channel[static_cast<size_t>(i)]);
      if (it == counts.end()) continue;
      it->second.logger_received = last_stats.received[static_cast<size_t>(i)];
      it->second.logger_gaps = last_stats.seq_gaps[static_cast<size_t>(i)];
      it->second.logger_dropped = last_stats.dropped[static_cast<size_t>(i)];
    }
  }

  int64_t published = 0, lost = 0;
  std::printf("%-22s %10s %10s %8s %8s | %-26s\n", "channel", "published", "in log", "lost", "lost %",
              "logger: received gaps dropped");
  for (const auto& [ch, c] : counts) {
    published += c.published;
    lost += c.published - c.logged;
    std::printf("%-22s %10lld %10lld %8lld %8.4f | %10lld %6lld %7lld\n", ch.c_str(),
                static_cast<long long>(c.published), static_cast<long long>(c.logged),
                static_cast<long long>(c.published - c.logged),
                100.0 * static_cast<double>(c.published - c.logged) / static_cast<double>(std::max<int64_t>(1, c.published)),
                static_cast<long long>(c.logger_received), static_cast<long long>(c.logger_gaps),
                static_cast<long long>(c.logger_dropped));
    if (c.gaps_in_log != c.published - c.logged)
      std::printf("  note: %s shows %lld sequence gaps in the log\n", ch.c_str(), static_cast<long long>(c.gaps_in_log));
  }
  std::printf("total: %lld published, %lld lost (%.4f %%)\n", static_cast<long long>(published),
              static_cast<long long>(lost), 100.0 * static_cast<double>(lost) / static_cast<double>(std::max<int64_t>(1, published)));
  std::printf("publisher: %.1f s wall for %lld cycles (%.1f Hz), %lld timer overruns\n", wall,
              static_cast<long long>(cycle), static_cast<double>(cycle) / wall, static_cast<long long>(timer.overruns()));
  std::printf("logger CPU: %.2f %% of one core while publishing (%.2f s utime+stime in %.1f s, /proc/%d/stat), "
              "%.2f us per message; whole run %.2f s (rusage)\n",
              100.0 * cpu / wall, cpu, wall, static_cast<int>(logger),
              1e6 * cpu / static_cast<double>(std::max<int64_t>(1, published)), cpu_total);
  if (have_stats) {
    std::printf("logger stats (closing report): %lld events, %lld bytes in %d file(s), %lld dropped, %lld write errors, "
                "%lld kernel socket drops; longest write/fsync %.3f s, longest loop pass %.3f s\n",
                static_cast<long long>(last_stats.events), static_cast<long long>(last_stats.bytes), last_stats.files,
                static_cast<long long>(last_stats.events_dropped), static_cast<long long>(last_stats.write_errors),
                static_cast<long long>(last_stats.socket_drops), last_stats.max_io_s, last_stats.max_loop_gap_s);
  } else {
    std::printf("logger stats: none in the log\n");
  }
  for (size_t i = 0; i < gaps.size() && i < 20; ++i) {
    const Gap& g = gaps[i];
    std::printf("hole: %s misses %lld at %.2f s (receive pause %.3f s), file %d, %.2f s after its first event\n",
                g.channel.c_str(), static_cast<long long>(g.missing), g.at_s, g.pause_s, g.file, g.into_file_s);
  }
  if (gaps.size() > 20) std::printf("(%zu holes, the first 20 shown)\n", gaps.size());
  std::printf("log: %d file(s), %.1f MB under %s\n", files, static_cast<double>(log_bytes) / 1e6, work.c_str());
  std::fflush(stdout);
  if (!args.flags.count("keep") && own_work) fs::remove_all(work);
  if (max_lost >= 0 && lost > max_lost) {
    std::fprintf(stderr, "cnc-bench-logger: %lld lost, more than --max-lost %lld\n", static_cast<long long>(lost), max_lost);
    return cnc::service::kExitFailure;
  }
  return have_stats ? cnc::service::kExitOk : cnc::service::kExitFailure;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-bench-logger",
                          "messages the logger loses at a given rate, and its CPU share",
                          {{"seconds", "S", "how long to publish (default 600)", true},
                           {"rate-hz", "HZ", "messages per second and channel (default 1000)", true},
                           {"rotate-mb", "MB", "the logger's file rotation size (default 64)", true},
                           {"logger", "EXE", "the logger to run (default: this build's)"},
                           {"work", "DIR", "where the logs go (default: a temporary directory)"},
                           {"max-lost", "N", "exit 1 when more are lost", true}},
                          {{"keep", "", "keep the logs"}},
                          false};
  return cnc::service::run(spec, argc, argv, run_bench);
}
