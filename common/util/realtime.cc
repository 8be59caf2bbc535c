#include "common/util/realtime.h"

#include <sched.h>
#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

namespace cnc::util {
namespace {

std::atomic<bool> g_memory_locked{false};

// A time in µs to the ns, as the file always gave it ("%.3f"); finite, or null.
nlohmann::ordered_json us(double v) {
  return std::isfinite(v) ? nlohmann::ordered_json(std::round(v * 1e3) / 1e3) : nlohmann::ordered_json();
}

nlohmann::ordered_json histogram_json(const LatencyHistogram& h) {
  nlohmann::ordered_json j;
  j["count"] = h.count();
  j["min_us"] = us(h.min_us());
  j["mean_us"] = us(h.mean_us());
  j["p50_us"] = us(h.percentile_us(0.5));
  j["p99_us"] = us(h.percentile_us(0.99));
  j["p999_us"] = us(h.percentile_us(0.999));
  j["max_us"] = us(h.max_us());
  j["overflow"] = h.overflow();
  j["negative"] = h.negative();
  auto& bins = j["bins"] = nlohmann::ordered_json::array();
  for (int i = 0; i < LatencyHistogram::kBins; ++i)
    if (h.bin_count(i) != 0) bins.push_back({LatencyHistogram::lower_us(i), LatencyHistogram::upper_us(i), h.bin_count(i)});
  if (h.overflow() > 0) bins.push_back({LatencyHistogram::kRangeUs, nullptr, h.overflow()});
  return j;
}

std::vector<int> current_cpus() {
  std::vector<int> out;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0) return out;
  for (int c = 0; c < CPU_SETSIZE; ++c)
    if (CPU_ISSET(c, &set)) out.push_back(c);
  return out;
}

}  // namespace

std::string LatencyHistogram::to_json() const { return histogram_json(*this).dump(); }

std::string make_realtime(int priority) {
  if (priority <= 0) return "";
  sched_param sp{};
  sp.sched_priority = priority;
  if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0) {
    const int err = errno;
    std::string why = "SCHED_FIFO priority " + std::to_string(priority) + ": " + std::strerror(err);
    if (err == EPERM) why += " (needs root, CAP_SYS_NICE or an RLIMIT_RTPRIO of at least " + std::to_string(priority) + ")";
    return why;
  }
#ifdef CNC_SANITIZED
  return "SCHED_FIFO set; memory not locked: a sanitizer build (its shadow memory cannot be locked)";
#else
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
    const int err = errno;
    return std::string("mlockall: ") + std::strerror(err) +
           " (SCHED_FIFO set; memory not locked: needs CAP_IPC_LOCK or a larger RLIMIT_MEMLOCK)";
  }
  g_memory_locked = true;
  return "";
#endif
}

namespace {

bool may_lock_memory(std::string* why) {
#ifdef CNC_SANITIZED
  *why = "a sanitizer build (its shadow memory cannot be locked)";
  return false;
#endif
  rlimit lim{};
  if (getrlimit(RLIMIT_MEMLOCK, &lim) == 0 && lim.rlim_cur == RLIM_INFINITY) return true;
  // CAP_IPC_LOCK (bit 14) in the effective set.
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("CapEff:", 0) != 0) continue;
    const unsigned long long caps = std::strtoull(line.c_str() + 7, nullptr, 16);
    if (caps & (1ull << 14)) return true;
    break;
  }
  *why = "no CAP_IPC_LOCK and RLIMIT_MEMLOCK is " + std::to_string(lim.rlim_cur / 1024) + " KiB";
  return false;
}

__attribute__((noinline)) void touch_stack(size_t bytes) {
  // A frame of `bytes`, written once per page: the pages are there before the cycles run.
  volatile char* frame = static_cast<volatile char*>(__builtin_alloca(bytes));
  for (size_t i = 0; i < bytes; i += 4096) frame[i] = 0;
  frame[bytes - 1] = 0;
}

}  // namespace

std::string prepare_cyclic_memory(size_t stack_bytes) {
  std::string why;
  if (!g_memory_locked && may_lock_memory(&why)) {
    if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
      g_memory_locked = true;
    } else {
      why = std::string("mlockall: ") + std::strerror(errno);
    }
  }
  if (stack_bytes > 0) touch_stack(stack_bytes);
  return g_memory_locked ? "" : why;
}

std::string cpu_list(const std::vector<int>& cpus) {
  std::string out;
  for (size_t i = 0; i < cpus.size();) {
    size_t j = i;
    while (j + 1 < cpus.size() && cpus[j + 1] == cpus[j] + 1) ++j;
    if (!out.empty()) out += ',';
    out += std::to_string(cpus[i]);
    if (j > i) out += '-' + std::to_string(cpus[j]);
    i = j + 1;
  }
  return out;
}

std::string pin_to_cpus(const std::vector<int>& cpus, std::vector<int>* applied) {
  if (applied) applied->clear();
  if (cpus.empty()) return "";
  const long configured = sysconf(_SC_NPROCESSORS_CONF);
  std::vector<int> missing, wanted;
  cpu_set_t set;
  CPU_ZERO(&set);
  for (const int c : cpus) {
    if (c < 0 || c >= CPU_SETSIZE || c >= configured) {
      missing.push_back(c);
    } else {
      CPU_SET(c, &set);
      wanted.push_back(c);
    }
  }
  std::string why;
  if (!missing.empty())
    why = "CPU " + cpu_list(missing) + " does not exist: this machine has CPUs 0-" + std::to_string(configured - 1);
  if (wanted.empty()) return why;
  const std::vector<int> before = current_cpus();
  if (sched_setaffinity(0, sizeof set, &set) != 0) {
    const int err = errno;
    if (!why.empty()) why += "; ";
    why += "sched_setaffinity(" + cpu_list(wanted) + "): " + std::strerror(err);
    if (err == EINVAL) why += " (none of them is online and allowed to this process; allowed: " + cpu_list(before) + ")";
    return why;
  }
  const std::vector<int> now = current_cpus();
  if (applied) *applied = now;
  if (now != wanted) {
    if (!why.empty()) why += "; ";
    why += "the kernel pinned to CPUs " + cpu_list(now) + " only (offline or outside this process's cpuset)";
  }
  return why;
}

void apply_realtime(const std::string& service, int priority, const std::vector<int>& cpus) {
  if (const std::string why = make_realtime(priority); !why.empty()) {
    spdlog::warn("{}: real-time scheduling not available ({}): running with {}", service, why,
                 why.find("SCHED_FIFO set") != std::string::npos ? "SCHED_FIFO, memory not locked"
                                                                  : "normal scheduling");
  }
  std::vector<int> applied;
  if (const std::string why = pin_to_cpus(cpus, &applied); !why.empty()) {
    spdlog::warn("{}: CPU affinity timing.realtime_cpus [{}] not applied as configured ({}): {}", service,
                 cpu_list(cpus), why, applied.empty() ? "running on every CPU" : "pinned to CPUs " + cpu_list(applied));
  }
  spdlog::info("{}: {}", service, describe_scheduling());
}

std::string describe_scheduling() {
  std::string out;
  const int policy = sched_getscheduler(0);
  sched_param sp{};
  sched_getparam(0, &sp);
  switch (policy) {
    case SCHED_FIFO: out = "SCHED_FIFO " + std::to_string(sp.sched_priority); break;
    case SCHED_RR: out = "SCHED_RR " + std::to_string(sp.sched_priority); break;
    case SCHED_OTHER: out = "SCHED_OTHER"; break;
    default: out = "policy " + std::to_string(policy); break;
  }
  out += g_memory_locked ? ", memory locked" : ", memory not locked";
  out += ", CPUs " + cpu_list(current_cpus());
  return out;
}

std::string latency_dir(const std::string& option) {
  if (!option.empty()) return option;
  const char* env = std::getenv("CNC_LATENCY_DIR");
  return env ? std::string(env) : std::string();
}

void report_latency(const LatencyReport& r, const std::string& dir) {
  static const LatencyHistogram kEmpty;
  const LatencyHistogram& w = r.wake ? *r.wake : kEmpty;
  const LatencyHistogram& c = r.compute ? *r.compute : kEmpty;
  const std::string sched = describe_scheduling();
  spdlog::info(
      "{} latency [us]: wake-up min {:.1f} mean {:.1f} p99 {:.1f} p99.9 {:.1f} max {:.1f} | compute min {:.1f} mean "
      "{:.1f} p99 {:.1f} p99.9 {:.1f} max {:.1f} | {} cycles, {} overruns | {}",
      r.service, w.min_us(), w.mean_us(), w.percentile_us(0.99), w.percentile_us(0.999), w.max_us(), c.min_us(),
      c.mean_us(), c.percentile_us(0.99), c.percentile_us(0.999), c.max_us(), r.cycles, r.overruns, sched);
  if (dir.empty()) return;
  try {
    std::filesystem::create_directories(dir);
    const std::string path = dir + "/" + r.service + ".json";
    const std::string tmp = path + ".tmp";
    {
      nlohmann::ordered_json j;
      j["service"] = r.service;
      j["loop"] = r.loop;
      j["period_us"] = us(r.period_s * 1e6);
      j["cycles"] = r.cycles;
      j["overruns"] = r.overruns;
      j["overruns_what"] = r.overruns_what;
      j["scheduling"] = sched;
      j["pid"] = getpid();
      j["wake_what"] = r.wake_what;
      j["compute_what"] = r.compute_what;
      j["wake"] = histogram_json(w);
      j["compute"] = histogram_json(c);
      std::ofstream f(tmp);
      f << j.dump(1) << "\n";
      if (!f) throw std::runtime_error("write failed");
    }
    std::filesystem::rename(tmp, path);
    spdlog::info("{}: cycle timing written to {}", r.service, path);
  } catch (const std::exception& e) {
    spdlog::warn("{}: cannot write the latency file into {}: {}", r.service, dir, e.what());
  }
}

void report_timer_latency(const std::string& service, const std::string& loop, const PeriodicTimer& timer,
                          const std::string& dir) {
  LatencyReport lat;
  lat.service = service;
  lat.loop = loop;
  lat.period_s = timer.period_s();
  lat.cycles = timer.cycles();
  lat.overruns = timer.overruns();
  lat.wake = &timer.wake_latency();
  lat.compute = &timer.compute_time();
  report_latency(lat, dir);
}

}  // namespace cnc::util
