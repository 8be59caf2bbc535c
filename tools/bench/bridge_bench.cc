// Drive bridge benchmark (figures, not a test), against the real cnc-servo-sim:
//  1. latency from a setpoint's publication (LCM UDP multicast, 250 Hz) to the
//     first Modbus write of a command heading for it, through the whole bridge
//     (LCM receive, fine interpolation with its jitter buffer, I/O thread), TCP;
//     with the LCM delivery alone as the baseline measured in the same run;
//  2. Modbus TCP exchange and transaction time per axis, for each shipped profile;
//  3. the update rate reachable over Modbus RTU at 115200 baud for three axes
//     (socat pseudo-terminals; the simulator holds each reply for the time the
//     bytes take on a real line), for each profile, against the line's bound.
//
//   cnc-bench-bridge [--seconds S]      (uses socat; run it where the tests run)
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "cnc/lcmt_setpoint.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/drive/drive_io.h"
#include "common/drive/link_factory.h"
#include "common/util/clock.h"
#include "services/drive_bridge/drive_bridge_node.h"
#include "common/util/cli.h"

extern char** environ;

namespace {

namespace fs = std::filesystem;
const std::string kSrc = CNC_SOURCE_DIR;

struct Child {
  pid_t pid = -1;
  Child() = default;
  explicit Child(const std::vector<std::string>& argv, const std::string& log) {
    std::vector<char*> a;
    for (const auto& s : argv) a.push_back(const_cast<char*>(s.c_str()));
    a.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    if (posix_spawnp(&pid, a[0], &fa, nullptr, a.data(), environ) != 0) pid = -1;
    posix_spawn_file_actions_destroy(&fa);
  }
  ~Child() {
    if (pid > 0) {
      kill(pid, SIGTERM);
      int st = 0;
      waitpid(pid, &st, 0);
    }
  }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
};

std::string read_file(const std::string& f) {
  std::ifstream in(f);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void replace_all(std::string& s, const std::string& from, const std::string& to) {
  for (size_t at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size())) s.replace(at, from.size(), to);
}

// A private copy of a shipped machine config: own ports, own serial device.
std::string machine_copy(const std::string& name, const std::string& dir, int port, const std::string& tty) {
  std::string y = read_file(kSrc + "/config/machines/" + name);
  replace_all(y, "port: 1502", "port: " + std::to_string(port));
  replace_all(y, "udpm://239.255.76.67:7667", "udpm://239.255.76.67:" + std::to_string(port + 1));
  replace_all(y, "/tmp/cnc-rtu-bridge", tty);
  const std::string out = dir + "/" + name;
  std::ofstream(out) << y;
  return out;
}

double pct(std::vector<double> v, double p) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p / 100.0 * static_cast<double>(v.size())))];
}

std::string sim_exe() { return (fs::canonical("/proc/self/exe").parent_path().parent_path() / "cnc-servo-sim").string(); }

bool wait_for(const std::string& path, double seconds) {
  for (int i = 0; i < seconds * 20; ++i) {
    if (fs::exists(path)) return true;
    usleep(50000);
  }
  return false;
}

// ---- 1. setpoint publication -> Modbus write ----------------------------------
void latency(const std::string& dir, double seconds) {
  const int port = 23000 + static_cast<int>(getpid() % 500) * 4;
  const std::string m = machine_copy("sim3.yaml", dir, port, "");
  Child sim({sim_exe(), "--machine", m}, dir + "/sim-latency.log");
  usleep(300000);
  const cnc::config::MachineConfig cfg = cnc::config::load_machine_config(m);
  cnc::bus::Bus bus(cfg.lcm_url);
  cnc::bus::Bus pub(cfg.lcm_url);
  cnc::bridge::DriveBridgeNode node(cfg, bus);
  std::mutex mu;
  std::map<int64_t, int64_t> published, first_write, received;
  node.set_write_probe([&](int axis, int64_t cycle, double) {
    if (axis != 0) return;
    const int64_t now = cnc::util::wall_utime();
    std::lock_guard<std::mutex> lock(mu);
    first_write.emplace(cycle, now);
  });
  // The baseline: the same datagrams received by a second subscriber in this process.
  cnc::bus::Bus probe(cfg.lcm_url);
  probe.subscribe<cnc::lcmt_setpoint>(cfg.channel("SETPOINTS"), [&](const cnc::lcmt_setpoint& sp) {
    received.emplace(sp.cycle, cnc::util::wall_utime());
  });
  node.start();
  std::atomic<bool> stop{false};
  std::atomic<bool> go{false};
  std::atomic<int64_t> engagement{0};  // the bridge's, echoed as the interpolator does
  std::thread publisher([&] {
    cnc::util::PeriodicTimer t(cfg.ipo_period_s);
    int64_t cycle = 0;
    int64_t go_cycle = -1;
    const double home = cfg.axes[0].home_mm;
    while (!stop) {
      t.wait();
      cnc::lcmt_setpoint sp{};
      sp.stream = 1;
      sp.engagement = engagement.load();
      sp.cycle = cycle;
      sp.period_s = cfg.ipo_period_s;
      sp.num_axes = static_cast<int32_t>(cfg.axes.size());
      // X: 20 mm amplitude at 1 Hz once the drives are up (v <= 126 mm/s, a <= 790 mm/s^2).
      if (go && go_cycle < 0) go_cycle = cycle;
      const double t_s = static_cast<double>(cycle - go_cycle) * cfg.ipo_period_s;
      sp.position_mm.assign(cfg.axes.size(), 0.0);
      for (size_t a = 0; a < cfg.axes.size(); ++a) sp.position_mm[a] = cfg.axes[a].home_mm;
      sp.position_mm[0] = go_cycle >= 0 ? home + 20.0 * (1 - std::cos(2 * M_PI * t_s)) : home;
      pub.publish(cfg.channel("SETPOINTS"), sp);
      {
        std::lock_guard<std::mutex> lock(mu);
        published[sp.cycle] = sp.utime;
      }
      ++cycle;
    }
  });
  cnc::util::PeriodicTimer timer(cfg.servo_period_s);
  const double start = cnc::util::monotonic_s();
  double go_at = -1;
  while (cnc::util::monotonic_s() - start < seconds + 3) {
    timer.wait();
    node.servo_tick(cnc::util::monotonic_s());
    engagement.store(node.core().engagement());
    probe.drain();
    if (go_at < 0 && node.state() == cnc::bridge::DriveBridgeNode::State::kEnabled) {
      go_at = cnc::util::monotonic_s();
      go = true;
    }
  }
  stop = true;
  publisher.join();
  node.shut_down();
  std::vector<double> to_write, to_receive;
  for (const auto& [cycle, w] : first_write) {
    if (!published.count(cycle) || published.begin()->first + 50 > cycle) continue;
    to_write.push_back(static_cast<double>(w - published[cycle]) * 1e-3);
    if (received.count(cycle)) to_receive.push_back(static_cast<double>(received[cycle] - published[cycle]) * 1e-3);
  }
  std::printf("1. setpoint publication -> first Modbus write heading for it (TCP, sim profile, %zu setpoints)\n",
              to_write.size());
  std::printf("   whole bridge:         p50 %6.2f ms   p99 %6.2f ms   max %6.2f ms\n", pct(to_write, 50),
              pct(to_write, 99), pct(to_write, 100));
  std::printf("   LCM delivery alone:   p50 %6.2f ms   p99 %6.2f ms   (baseline, same run)\n", pct(to_receive, 50),
              pct(to_receive, 99));
  std::printf("   (by design the command heads for a setpoint once the playback, %g periods behind on average,\n"
              "    has passed the one before: about 1 to 2 periods of %g ms)\n",
              2.0, cfg.ipo_period_s * 1e3);
}

// ---- 2. and 3.: exchanges with three drives on one link -------------------------
struct Rate {
  std::vector<double> exchange_ms;
  double rounds_per_s = 0;
  double tx_per_s = 0;
  int tx_per_exchange = 0;
};

Rate exchanges(const cnc::config::MachineConfig& cfg, double seconds) {
  cnc::config::DriveConfig d0 = cfg.axes[0].drive;
  d0.response_timeout_s = 0.2;
  std::unique_ptr<cnc::drive::Link> link = cnc::drive::make_link(d0);
  const cnc::drive::DriveProfile profile = cnc::drive::load_drive_profile(
      cnc::drive::find_drive_profile(d0.profile, cfg.source_file, ""));
  std::vector<std::unique_ptr<cnc::drive::DriveIo>> io;
  for (const auto& a : cfg.axes) io.push_back(std::make_unique<cnc::drive::DriveIo>(profile, a.drive.unit_id, *link));
  cnc::drive::LinkCounters c;
  Rate r;
  r.tx_per_exchange = io[0]->transactions_per_exchange();
  for (int i = 0; i < 20 && !link->ensure_open(cnc::util::monotonic_s()); ++i) usleep(100000);
  for (auto& d : io) d->exchange(nullptr, c);
  const double start = cnc::util::monotonic_s();
  int64_t rounds = 0;
  while (cnc::util::monotonic_s() - start < seconds) {
    for (auto& d : io) {
      const double t = d->actual_mm();
      const double t0 = cnc::util::monotonic_s();
      if (d->exchange(&t, c) == cnc::drive::TxResult::kOk) r.exchange_ms.push_back((cnc::util::monotonic_s() - t0) * 1e3);
    }
    ++rounds;
  }
  r.rounds_per_s = static_cast<double>(rounds) / (cnc::util::monotonic_s() - start);
  r.tx_per_s = static_cast<double>(c.transactions) / (cnc::util::monotonic_s() - start);
  if (c.timeouts + c.exceptions + c.crc_errors + c.other_errors > 0)
    std::printf("   (%lld failed transactions)\n", static_cast<long long>(c.timeouts + c.exceptions + c.crc_errors + c.other_errors));
  return r;
}

// Bytes on the wire for one exchange of a profile (RTU framing), for the line's bound.
int rtu_bytes(const cnc::drive::DriveProfile& p, int tx) {
  // Requests and replies: FC23 write 2 / read n: 13+4 / 5+2n; FC16 write 2: 13 / 8; FC3 read n: 8 / 5+2n.
  const int n_status = 1, n_pos = 2;
  if (p.name == "sim") return (17) + (5 + 2 * 7);
  if (p.write_and_read) return 17 + (5 + 2 * n_status) + 8 + (5 + 2 * n_pos) + (tx > 2 ? 13 : 0);
  return 13 + 8 + 8 + (5 + 2 * 4);
}

void transports(const std::string& dir, double seconds) {
  std::printf("\n2. Modbus TCP, three drives on one connection, cnc-servo-sim (exchange = write target + read status/position)\n");
  std::printf("   %-14s %5s %12s %12s %12s %16s %10s\n", "profile", "tx", "exch p50 ms", "exch p99 ms", "tx p50 ms",
              "rounds/s (3 ax)", "tx/s");
  int port = 24000 + static_cast<int>(getpid() % 500) * 4;
  for (const char* name : {"sim3.yaml", "sim3_cia402_tcp.yaml", "sim3_leadshine_tcp.yaml"}) {
    port += 4;
    const std::string m = machine_copy(name, dir, port, "");
    Child sim({sim_exe(), "--machine", m}, dir + "/sim-tcp.log");
    usleep(300000);
    const auto cfg = cnc::config::load_machine_config(m);
    const Rate r = exchanges(cfg, seconds);
    std::printf("   %-14s %5d %12.3f %12.3f %12.3f %16.0f %10.0f\n", cfg.axes[0].drive.profile.c_str(),
                r.tx_per_exchange, pct(r.exchange_ms, 50), pct(r.exchange_ms, 99),
                pct(r.exchange_ms, 50) / r.tx_per_exchange, r.rounds_per_s, r.tx_per_s);
  }
  std::printf("\n3. Modbus RTU at 115200 baud 8N1, three drives on one line (socat pty pair; the simulator holds\n"
              "   each reply for the time request and reply take on a real line)\n");
  std::printf("   %-14s %5s %12s %14s %22s\n", "profile", "tx", "exch p50 ms", "rounds/s (3 ax)",
              "line bound rounds/s");
  for (const char* name : {"sim3_cia402_rtu.yaml", "sim3_leadshine_rtu.yaml"}) {
    const std::string tb = dir + "/tty-bridge", ts = dir + "/tty-sim";
    fs::remove(tb);
    fs::remove(ts);
    Child socat({"socat", "pty,raw,echo=0,link=" + tb, "pty,raw,echo=0,link=" + ts}, dir + "/socat.log");
    if (!wait_for(ts, 5) || !wait_for(tb, 5)) {
      std::printf("   socat made no pseudo-terminals: RTU skipped\n");
      return;
    }
    const std::string m = machine_copy(name, dir, 0, tb);
    Child sim({sim_exe(), "--machine", m, "--device", ts}, dir + "/sim-rtu.log");
    usleep(300000);
    const auto cfg = cnc::config::load_machine_config(m);
    const Rate r = exchanges(cfg, seconds);
    const auto profile = cnc::drive::load_drive_profile(
        cnc::drive::find_drive_profile(cfg.axes[0].drive.profile, cfg.source_file, ""));
    // Each transaction also leaves 3.5 characters of silence after request and reply.
    const double chars = rtu_bytes(profile, r.tx_per_exchange) + 7.0 * r.tx_per_exchange;
    const double bound = 115200.0 / 10.0 / (3 * chars);
    std::printf("   %-14s %5d %12.3f %14.1f %22.1f\n", cfg.axes[0].drive.profile.c_str(), r.tx_per_exchange,
                pct(r.exchange_ms, 50), r.rounds_per_s, bound);
  }
  std::printf("   (rounds/s = commands per second each of the three drives receives)\n");
}

}  // namespace

int main(int argc, char** argv) {
  double seconds = 3.0;
  CLI::App app{"the drive bridge: setpoint-to-Modbus latency, TCP exchange times, RTU update rate", "cnc-bench-bridge"};
  cnc::util::cli::setup(app);
  app.add_option("--seconds", seconds, "how long each measurement runs")->type_name("S")->check(cnc::util::cli::positive());
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  spdlog::set_level(spdlog::level::warn);
  const std::string dir = fs::temp_directory_path() / ("cnc-bench-bridge." + std::to_string(getpid()));
  fs::create_directories(dir);
  latency(dir, seconds);
  transports(dir, seconds);
  fs::remove_all(dir);
  return 0;
}
