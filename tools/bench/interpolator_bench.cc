// cnc-bench-interpolator: compute time of the interpolator's cyclic path per coarse
// cycle on a dense NURBS program at T = 1 ms (mean, p99, max) with the planning on
// the planner thread, as the node runs it (feed policy + plans taken + step), against
// the same with the planner inline in the cycle (the former design); setpoints per
// second of a dry run, and the feed fluctuation of the parameter updates — first
// order (Kim, Song & Kwon eq. 6), second order (Choi et al. 2005 eq. 7) and eq. 7 with the
// chord-length correction — all measured in the same run on the same program.
//
//   cnc-bench-interpolator [--machine FILE] [--blocks N] [--paced] [--slowest] [--cyclic-only]
//
// Printed per run: min/mean/p99/p99.9/max of the cyclic compute (wall) and of the
// cyclic thread's CPU time per cycle; --slowest adds, for the slowest cycles, the
// block and the arc length in it, what the cycle did (plans taken, blocks started,
// Newton iterations, look-ahead samples, ...: Interpolator::work()) and the page
// faults and context switches of the thread (getrusage(RUSAGE_THREAD) around it).
// --cyclic-only stops after the planner-thread run and the platform's noise floor.
//
// Unpaced, cycles run back to back and, only where the path would otherwise run out
// of plans (fewer than two blocks queued while the planner works), the loop waits
// for the planner outside the timed part; --paced runs every cycle on a 1 ms
// absolute deadline instead (real time: use a small --blocks).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <memory>
#include <numbers>
#include <random>
#include <vector>

#include <sys/resource.h>
#include <unistd.h>

#include "common/motion/feed_policy.h"
#include "common/motion/interpolator.h"
#include "common/motion/planner_thread.h"
#include "common/service/service.h"
#include "common/util/realtime.h"
#include "common/util/signals.h"

namespace {

using cnc::interp::Interpolator;
using cnc::program::Block;
using cnc::program::BlockKind;

// A dense program: N cubic NURBS blocks of 7 control points each, ~3 mm long,
// a wavy surface-finishing pass in XYZ with G1-continuous joins.
std::vector<Block> dense_program(int n_blocks) {
  std::vector<Block> blocks;
  std::array<double, 3> p = {0, 0, 0};
  std::mt19937 rng(1);  // fixed seed
  std::uniform_real_distribution<double> jitter(-0.3, 0.3);
  double heading = 0;
  for (int i = 0; i < n_blocks; ++i) {
    Block b;
    b.index = i;
    b.source_line = i + 1;
    b.kind = BlockKind::kNurbs;
    b.feed_mm_per_min = 3000;
    b.start = {p[0], p[1], p[2]};
    b.nurbs.order = 4;
    const int n = 7;
    std::vector<std::array<double, 3>> cp = {p};
    for (int k = 1; k < n; ++k) {
      heading += 0.12 * std::sin(0.05 * (i * n + k));
      const double step = 0.5;
      std::array<double, 3> q = cp.back();
      q[0] += step * std::cos(heading);
      q[1] += step * std::sin(heading);
      q[2] = 2.0 * std::sin(0.02 * (i * n + k)) + (k == n - 1 ? 0 : 0.05 * jitter(rng));
      cp.push_back(q);
    }
    // G1 join: the second control point continues the previous block's last leg.
    if (!blocks.empty()) {
      const auto& prev = blocks.back().nurbs.control_points;
      const auto& a = prev[prev.size() - 2];
      for (int d = 0; d < 3; ++d) cp[1][d] = p[d] + (p[d] - a[d]);
    }
    b.nurbs.control_points = cp;
    b.nurbs.weights.assign(n, 1.0);
    b.nurbs.knots = {0, 0, 0, 0, 0.25, 0.5, 0.75, 1, 1, 1, 1};
    b.end = {cp.back()[0], cp.back()[1], cp.back()[2]};
    p = cp.back();
    blocks.push_back(b);
  }
  Block end;
  end.index = n_blocks;
  end.kind = BlockKind::kEnd;
  end.start = end.end = {p[0], p[1], p[2]};
  blocks.push_back(end);
  return blocks;
}

// What one cycle did: taken around it, outside its timed part.
struct CycleRecord {
  double wall_ns = 0, cpu_ns = 0;
  int64_t cycle = -1;
  int64_t block = -1;        // the block being executed at the cycle's start
  double s_mm = 0;           // ...and how far into it (arc length)
  int64_t queued = 0;        // blocks taken and not finished, at the start
  int64_t submitted = 0;     // blocks handed to the planner in the cycle
  int64_t minflt = 0, majflt = 0;  // page faults of this thread in the cycle
  int64_t nvcsw = 0, nivcsw = 0;   // context switches of this thread in the cycle
  cnc::interp::WorkCounters work;  // what the core did in the cycle (differences)
};

// The k largest records by a key, kept sorted (largest first), no allocation per insert.
class TopK {
 public:
  explicit TopK(size_t k, double CycleRecord::*key) : k_(k), key_(key) { v_.reserve(k + 1); }
  void offer(const CycleRecord& r) {
    if (v_.size() == k_ && r.*key_ <= v_.back().*key_) return;
    auto it = std::upper_bound(v_.begin(), v_.end(), r, [&](const CycleRecord& a, const CycleRecord& b) {
      return a.*key_ > b.*key_;
    });
    v_.insert(it, r);
    if (v_.size() > k_) v_.pop_back();
  }
  const std::vector<CycleRecord>& records() const { return v_; }

 private:
  size_t k_;
  double CycleRecord::*key_;
  std::vector<CycleRecord> v_;
};

cnc::interp::WorkCounters diff(const cnc::interp::WorkCounters& a, const cnc::interp::WorkCounters& b) {
  cnc::interp::WorkCounters d;
  d.plans_taken = b.plans_taken - a.plans_taken;
  d.blocks_taken = b.blocks_taken - a.blocks_taken;
  d.patch_values = b.patch_values - a.patch_values;
  d.blocks_started = b.blocks_started - a.blocks_started;
  d.table_lookups = b.table_lookups - a.table_lookups;
  d.newton_iters = b.newton_iters - a.newton_iters;
  d.bisect_evals = b.bisect_evals - a.bisect_evals;
  d.safe_calls = b.safe_calls - a.safe_calls;
  d.safe_samples = b.safe_samples - a.safe_samples;
  d.brake_evals = b.brake_evals - a.brake_evals;
  d.safe_skips = b.safe_skips - a.safe_skips;
  d.look_builds = b.look_builds - a.look_builds;
  d.look_fallbacks = b.look_fallbacks - a.look_fallbacks;
  d.curve_evals = b.curve_evals - a.curve_evals;
  d.curve_reuses = b.curve_reuses - a.curve_reuses;
  return d;
}

struct Result {
  std::vector<double> cycle_ns;
  std::vector<double> cpu_ns;  // the same cycles in this thread's CPU time
  double cpu_max_ns = 0;  // the longest cycle in this thread's CPU time (preemption left out)
  int64_t cpu_max_cycle = -1;  // ...and which cycle it was
  double wall_s = 0;
  double fluct_max = 0, fluct_rms = 0;
  int64_t cycles = 0;
  int64_t waits = 0;  // cycles the loop waited for the planner (outside the timing)
  TopK slow_wall{12, &CycleRecord::wall_ns};
  TopK slow_cpu{12, &CycleRecord::cpu_ns};
  int64_t minflt = 0;           // page faults of the cyclic thread in timed cycles, all of them
  int64_t faulting_cycles = 0;  // timed cycles with at least one
  cnc::interp::WorkCounters work;  // the core's counters over the run
  uint64_t digest = 1469598103934665603ull;  // FNV-1a over every setpoint's positions, feed and state
};

void fold(uint64_t* h, const void* p, size_t n) {
  const auto* b = static_cast<const unsigned char*>(p);
  for (size_t i = 0; i < n; ++i) *h = (*h ^ b[i]) * 1099511628211ull;
}

enum class Planning { kInline, kThread };

Result run(const cnc::config::MachineConfig& cfg, const std::vector<Block>& blocks, cnc::interp::ParamUpdate mode,
           bool time_cycles, Planning planning = Planning::kInline, bool paced = false) {
  std::unique_ptr<cnc::interp::PlanLink> link;
  cnc::interp::ThreadedPlanLink* thread = nullptr;
  if (planning == Planning::kThread) {
    auto t = std::make_unique<cnc::interp::ThreadedPlanLink>(cfg);
    thread = t.get();
    link = std::move(t);
  } else {
    link = std::make_unique<cnc::interp::SyncPlanLink>(cfg);
  }
  Interpolator ip(cfg, *link);
  const cnc::interp::FeedPolicy feed(cfg);
  ip.set_param_update(mode);
  ip.apply_command({cnc::interp::Command::Kind::kStart, 1.0});
  Result r;
  // Touched up front (not first touched by the loop as it grows).
  r.cycle_ns.assign(1 << 20, 0.0);
  r.cpu_ns.assign(1 << 20, 0.0);
  // The blocks as they would come out of the node's message decoding, made up front.
  std::vector<std::unique_ptr<Block>> source;
  source.reserve(blocks.size());
  for (const Block& b : blocks) source.push_back(std::make_unique<Block>(b));
  auto next = [&](int64_t index) -> std::unique_ptr<Block> {
    return static_cast<size_t>(index) < source.size() ? std::move(source[static_cast<size_t>(index)]) : nullptr;
  };
  std::array<double, cnc::program::kMaxAxes> prev = ip.last().position_mm;
  prev[0] = blocks[0].start[0];
  prev[1] = blocks[0].start[1];
  prev[2] = blocks[0].start[2];
  double sum2 = 0;
  int64_t n_fl = 0;
  timespec deadline{};
  clock_gettime(CLOCK_MONOTONIC, &deadline);
  const auto t_all = std::chrono::steady_clock::now();
  while (ip.state() != cnc::interp::RunState::kDone && r.cycles < 50'000'000) {
    if (paced) {
      deadline.tv_nsec += static_cast<long>(cfg.ipo_period_s * 1e9);
      while (deadline.tv_nsec >= 1'000'000'000) {
        deadline.tv_nsec -= 1'000'000'000;
        ++deadline.tv_sec;
      }
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &deadline, nullptr);
    } else if (thread != nullptr && ip.blocks_in_planning() > 0 && ip.queued_blocks() < 2) {
      thread->wait_idle();  // a free-running loop outruns real time: do not starve it
      ++r.waits;
    }
    timespec c0{}, c1{};
    rusage ru0{}, ru1{};
    CycleRecord rec;
    cnc::interp::WorkCounters w0;
    int64_t submitted = 0;
    if (time_cycles) {
      getrusage(RUSAGE_THREAD, &ru0);
      w0 = ip.work();
      rec.block = ip.queued_blocks() > 0 ? ip.last().block_index : -1;
      rec.s_mm = ip.s_in_block();
      rec.queued = static_cast<int64_t>(ip.queued_blocks());
      clock_gettime(CLOCK_THREAD_CPUTIME_ID, &c0);
    }
    const auto t0 = std::chrono::steady_clock::now();
    // The cyclic path as in the node: the feed policy (plans taken, blocks handed
    // over) and the step; with Planning::kInline the planning happens in here too.
    feed.cycle(ip, next, [&submitted](int64_t) { ++submitted; }, [](int) {});
    const cnc::interp::Setpoint& sp = ip.step();
    const auto t1 = std::chrono::steady_clock::now();
    if (time_cycles && static_cast<size_t>(r.cycles) < r.cycle_ns.size()) {
      clock_gettime(CLOCK_THREAD_CPUTIME_ID, &c1);
      getrusage(RUSAGE_THREAD, &ru1);
      const double wall_ns = std::chrono::duration<double, std::nano>(t1 - t0).count();
      const double cpu_ns =
          static_cast<double>(c1.tv_sec - c0.tv_sec) * 1e9 + static_cast<double>(c1.tv_nsec - c0.tv_nsec);
      r.cycle_ns[static_cast<size_t>(r.cycles)] = wall_ns;
      r.cpu_ns[static_cast<size_t>(r.cycles)] = cpu_ns;
      if (cpu_ns > r.cpu_max_ns) {
        r.cpu_max_ns = cpu_ns;
        r.cpu_max_cycle = r.cycles;
      }
      rec.wall_ns = wall_ns;
      rec.cpu_ns = cpu_ns;
      rec.cycle = r.cycles;
      rec.submitted = submitted;
      rec.minflt = ru1.ru_minflt - ru0.ru_minflt;
      rec.majflt = ru1.ru_majflt - ru0.ru_majflt;
      rec.nvcsw = ru1.ru_nvcsw - ru0.ru_nvcsw;
      rec.nivcsw = ru1.ru_nivcsw - ru0.ru_nivcsw;
      rec.work = diff(w0, ip.work());
      r.minflt += rec.minflt;
      if (rec.minflt > 0) ++r.faulting_cycles;
      r.slow_wall.offer(rec);
      r.slow_cpu.offer(rec);
    }
    ++r.cycles;
    // Feed fluctuation: the realised step (chord) against the commanded one, in cruise.
    double d2 = 0;
    for (int a = 0; a < 3; ++a) d2 += (sp.position_mm[a] - prev[a]) * (sp.position_mm[a] - prev[a]);
    const double actual = std::sqrt(d2) / cfg.ipo_period_s * 60.0;
    if (sp.feed_mm_per_min > 100) {
      const double f = (actual - sp.feed_mm_per_min) / sp.feed_mm_per_min;
      r.fluct_max = std::max(r.fluct_max, std::fabs(f));
      sum2 += f * f;
      ++n_fl;
    }
    prev = sp.position_mm;
    fold(&r.digest, sp.position_mm.data(), sizeof(double) * static_cast<size_t>(sp.num_axes));
    fold(&r.digest, &sp.feed_mm_per_min, sizeof sp.feed_mm_per_min);
    fold(&r.digest, &sp.state, sizeof sp.state);
  }
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_all).count();
  r.work = ip.work();
  if (time_cycles) {
    const size_t n = std::min(r.cycle_ns.size(), static_cast<size_t>(r.cycles));
    r.cycle_ns.resize(n);
    r.cpu_ns.resize(n);
  }
  r.fluct_rms = n_fl ? std::sqrt(sum2 / static_cast<double>(n_fl)) : 0;
  return r;
}

struct Stats {
  double min = 0, mean = 0, p99 = 0, p999 = 0, max = 0;
};

Stats stats(std::vector<double> ns) {
  Stats s;
  if (ns.empty()) return s;
  std::sort(ns.begin(), ns.end());
  for (double x : ns) s.mean += x;
  s.mean /= static_cast<double>(ns.size());
  s.min = ns.front();
  s.p99 = ns[static_cast<size_t>(0.99 * static_cast<double>(ns.size() - 1))];
  s.p999 = ns[static_cast<size_t>(0.999 * static_cast<double>(ns.size() - 1))];
  s.max = ns.back();
  return s;
}

void print_stats(const char* what, const Stats& s) {
  std::printf("    %-22s min %6.2f  mean %6.2f  p99 %7.2f  p99.9 %7.2f  max %8.2f us\n", what, s.min * 1e-3,
              s.mean * 1e-3, s.p99 * 1e-3, s.p999 * 1e-3, s.max * 1e-3);
}

void print_records(const char* title, const std::vector<CycleRecord>& recs) {
  std::printf("    %s\n", title);
  std::printf("      %8s %8s %8s %6s %7s %3s %3s %5s %5s %6s %4s %4s %6s %6s %5s %5s %6s %4s %4s\n", "wall_us", "cpu_us",
              "cycle", "block", "s_mm", "q", "sub", "taken", "blk", "patch", "strt", "tab", "newton", "bisect",
              "safe", "smpl", "brake", "mflt", "csw");
  for (const CycleRecord& r : recs) {
    const auto& w = r.work;
    std::printf("      %8.2f %8.2f %8lld %6lld %7.3f %3lld %3lld %5lld %5lld %6lld %4lld %4lld %6lld %6lld %5lld %5lld "
                "%6lld %4lld %2lld/%lld\n",
                r.wall_ns * 1e-3, r.cpu_ns * 1e-3, static_cast<long long>(r.cycle), static_cast<long long>(r.block),
                r.s_mm, static_cast<long long>(r.queued), static_cast<long long>(r.submitted),
                static_cast<long long>(w.plans_taken), static_cast<long long>(w.blocks_taken),
                static_cast<long long>(w.patch_values), static_cast<long long>(w.blocks_started),
                static_cast<long long>(w.table_lookups), static_cast<long long>(w.newton_iters),
                static_cast<long long>(w.bisect_evals), static_cast<long long>(w.safe_calls),
                static_cast<long long>(w.safe_samples), static_cast<long long>(w.brake_evals),
                static_cast<long long>(r.minflt + r.majflt), static_cast<long long>(r.nvcsw),
                static_cast<long long>(r.nivcsw));
  }
}

void report(const char* what, const Result& r, double period_s, bool detail) {
  std::printf("  %s: %lld cycles, %.1f s of machining, %lld waits for the planner; cyclic thread page faults %lld in "
              "%lld cycles\n",
              what, static_cast<long long>(r.cycles), static_cast<double>(r.cycles) * period_s,
              static_cast<long long>(r.waits), static_cast<long long>(r.minflt),
              static_cast<long long>(r.faulting_cycles));
  print_stats("cyclic compute (wall)", stats(r.cycle_ns));
  print_stats("thread CPU time", stats(r.cpu_ns));
  const double n = static_cast<double>(std::max<int64_t>(1, r.cycles));
  const auto& w = r.work;
  std::printf("    work per cycle: look-ahead checks %.3f, samples %.2f, brake distances %.3f, skips %.3f; Newton "
              "iterations %.3f, bisection points %.4f, table lookups %.3f\n",
              static_cast<double>(w.safe_calls) / n, static_cast<double>(w.safe_samples) / n,
              static_cast<double>(w.brake_evals) / n, static_cast<double>(w.safe_skips) / n,
              static_cast<double>(w.newton_iters) / n, static_cast<double>(w.bisect_evals) / n,
              static_cast<double>(w.table_lookups) / n);
  std::printf("    look-ahead searches with the samples gathered once: %lld, full checks in them: %lld; curve points "
              "per cycle %.3f computed, %.3f reused\n",
              static_cast<long long>(w.look_builds), static_cast<long long>(w.look_fallbacks),
              static_cast<double>(w.curve_evals) / n, static_cast<double>(w.curve_reuses) / n);
  if (!detail) return;
  print_records("slowest cycles by thread CPU time (taken: plans, blk: of which blocks, patch: look-ahead values "
                "copied, strt: blocks started, tab: table lookups, safe/smpl/brake: look-ahead checks, samples, brake "
                "distances, mflt: page faults, csw: context switches vol/invol):",
                r.slow_cpu.records());
  print_records("slowest cycles by wall time:", r.slow_wall.records());
}

// The platform's own noise on the same measurement: a fixed computation of about
// the mean cycle's length (the same work every time), timed as the cycles are. What
// its tail shows (interrupts, the hypervisor taking the virtual CPU: counted in the
// thread's CPU time too) is not the interpolator's.
Result noise_floor(int64_t cycles) {
  Result r;
  r.cycle_ns.assign(static_cast<size_t>(cycles), 0.0);
  r.cpu_ns.assign(static_cast<size_t>(cycles), 0.0);
  volatile double sink = 0;
  for (int64_t k = 0; k < cycles; ++k) {
    timespec c0{}, c1{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &c0);
    const auto t0 = std::chrono::steady_clock::now();
    double x = 1.0 + 1e-9 * static_cast<double>(k % 7);
    for (int i = 0; i < 400; ++i) x = std::sqrt(x * 1.0000001 + 0.5);
    sink = sink + x;
    const auto t1 = std::chrono::steady_clock::now();
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &c1);
    r.cycle_ns[static_cast<size_t>(k)] = std::chrono::duration<double, std::nano>(t1 - t0).count();
    r.cpu_ns[static_cast<size_t>(k)] =
        static_cast<double>(c1.tv_sec - c0.tv_sec) * 1e9 + static_cast<double>(c1.tv_nsec - c0.tv_nsec);
  }
  r.cycles = cycles;
  return r;
}

// Time the hypervisor ran others on this machine's virtual CPUs (/proc/stat "steal"), in s.
double steal_s() {
  std::FILE* f = std::fopen("/proc/stat", "r");
  if (f == nullptr) return 0;
  unsigned long long v[8] = {};
  const int n = std::fscanf(f, "cpu %llu %llu %llu %llu %llu %llu %llu %llu", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5],
                            &v[6], &v[7]);
  std::fclose(f);
  return n == 8 ? static_cast<double>(v[7]) / static_cast<double>(sysconf(_SC_CLK_TCK)) : 0.0;
}

int bench(const cnc::config::MachineConfig& machine, const cnc::service::Args& args) {
  cnc::util::end_at_once_on_stop_signals();  // no loop here polls the stop flag
  cnc::config::MachineConfig cfg = machine;
  cfg.ipo_period_s = 0.001;
  const int n_blocks = std::stoi(args.option("blocks", "2000"));
  const auto blocks = dense_program(n_blocks);
  std::printf("dense NURBS program: %d cubic blocks (7 control points each), F 3000 mm/min, T_ipo 1 ms, eps %.3g um\n",
              n_blocks, cfg.chord_tolerance_mm * 1e3);

  const bool paced = args.flags.count("paced") > 0;
  // As the service does (services/interpolator/main.cc): memory locked where permitted, stack touched.
  const std::string unlocked = cnc::util::prepare_cyclic_memory();
  std::printf("memory: %s\n", unlocked.empty() ? "locked (mlockall)" : ("not locked: " + unlocked).c_str());
  run(cfg, blocks, cnc::interp::ParamUpdate::kCorrected, false);  // warm-up
  std::printf("compute time of the cyclic path per coarse cycle (feed policy + plans taken + step):\n");
  const bool detail = args.flags.count("slowest") > 0;
  const double steal0 = steal_s();
  const Result threaded = run(cfg, blocks, cnc::interp::ParamUpdate::kCorrected, true, Planning::kThread, paced);
  const double steal1 = steal_s();
  report("planning on the planner thread", threaded, cfg.ipo_period_s, detail);
  {
    const Result floor = noise_floor(threaded.cycles);
    const double steal2 = steal_s();
    std::printf("  the same timing around a fixed computation (the platform's noise), %lld times:\n",
                static_cast<long long>(floor.cycles));
    print_stats("fixed work (wall)", stats(floor.cycle_ns));
    print_stats("thread CPU time", stats(floor.cpu_ns));
    std::printf("    CPU time stolen by the hypervisor (/proc/stat, all CPUs): %.2f s during the run above, %.2f s "
                "during this one\n",
                steal1 - steal0, steal2 - steal1);
  }
  if (args.flags.count("cyclic-only") > 0) return 0;
  report("planning inline in the cycle", run(cfg, blocks, cnc::interp::ParamUpdate::kCorrected, true,
                                             Planning::kInline, paced),
         cfg.ipo_period_s, false);
  const Result dry = run(cfg, blocks, cnc::interp::ParamUpdate::kCorrected, false);
  std::printf("dry run: %.0f setpoints/s (%.0fx real time at 1 ms), %lld setpoints, digest %016llx\n",
              static_cast<double>(dry.cycles) / dry.wall_s, static_cast<double>(dry.cycles) / dry.wall_s * 1e-3,
              static_cast<long long>(dry.cycles), static_cast<unsigned long long>(dry.digest));

  std::printf("feed fluctuation (realised step vs commanded, |.| max and rms, same program):\n");
  const std::pair<cnc::interp::ParamUpdate, const char*> modes[] = {
      {cnc::interp::ParamUpdate::kFirstOrder, "first order  u += ds/|P'|          "},
      {cnc::interp::ParamUpdate::kTaylor2, "second order (Choi et al. 2005 eq. 7)      "},
      {cnc::interp::ParamUpdate::kCorrected, "eq. 7 + chord-length correction    "}};
  double base_max = 0;
  for (const auto& [mode, name] : modes) {
    const Result m = run(cfg, blocks, mode, false);
    if (mode == cnc::interp::ParamUpdate::kFirstOrder) base_max = m.fluct_max;
    std::printf("  %s max %.3e  rms %.3e  (max %.2e of first order)  %.0f setpoints/s\n", name, m.fluct_max,
                m.fluct_rms, base_max > 0 ? m.fluct_max / base_max : 0.0,
                static_cast<double>(m.cycles) / m.wall_s);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-bench-interpolator", "interpolator compute time and feed fluctuation", 
                          {{"blocks", "N", "blocks of the dense NURBS program", true}},
                          {{"paced", "", "every cycle on a 1 ms absolute deadline (real time)"},
                           {"slowest", "", "what the slowest cycles did"},
                           {"cyclic-only", "", "stop after the planner-thread run and the noise floor"}}};
  if (argc == 1) {
    static char a0[] = "cnc-bench-interpolator", a1[] = "--machine", a2[] = CNC_SOURCE_DIR "/config/machines/sim3.yaml";
    static char* def[] = {a0, a1, a2, nullptr};
    return cnc::service::run(spec, 3, def, bench);
  }
  return cnc::service::run(spec, argc, argv, bench);
}
