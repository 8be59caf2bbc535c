// cnc-bench-interpolator: compute time of the interpolator's cyclic path per coarse
// cycle on a dense NURBS program at T = 1 ms (mean, p99, max) with the planning on
// the planner thread, as the node runs it (feed policy + plans taken + step), against
// the same with the planner inline in the cycle (the former design); setpoints per
// second of a dry run, and the feed fluctuation of the parameter updates — first
// order (seed 001 eq. 6), second order (seed 000 eq. 7) and eq. 7 with the
// chord-length correction — all measured in the same run on the same program.
//
//   cnc-bench-interpolator [--machine FILE] [--blocks N] [--paced]
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

#include "common/service/service.h"
#include "common/util/signals.h"
#include "services/interpolator/feed_policy.h"
#include "services/interpolator/interpolator.h"
#include "services/interpolator/planner_thread.h"

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

struct Result {
  std::vector<double> cycle_ns;
  double cpu_max_ns = 0;  // the longest cycle in this thread's CPU time (preemption left out)
  int64_t cpu_max_cycle = -1;  // ...and which cycle it was
  double wall_s = 0;
  double fluct_max = 0, fluct_rms = 0;
  int64_t cycles = 0;
  int64_t waits = 0;  // cycles the loop waited for the planner (outside the timing)
};

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
  r.cycle_ns.reserve(1 << 20);
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
    if (time_cycles) clock_gettime(CLOCK_THREAD_CPUTIME_ID, &c0);
    const auto t0 = std::chrono::steady_clock::now();
    // The cyclic path as in the node: the feed policy (plans taken, blocks handed
    // over) and the step; with Planning::kInline the planning happens in here too.
    feed.cycle(ip, next, [](int64_t) {}, [](int) {});
    const cnc::interp::Setpoint& sp = ip.step();
    const auto t1 = std::chrono::steady_clock::now();
    if (time_cycles) {
      clock_gettime(CLOCK_THREAD_CPUTIME_ID, &c1);
      r.cycle_ns.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count());
      const double cpu_ns =
          static_cast<double>(c1.tv_sec - c0.tv_sec) * 1e9 + static_cast<double>(c1.tv_nsec - c0.tv_nsec);
      if (cpu_ns > r.cpu_max_ns) {
        r.cpu_max_ns = cpu_ns;
        r.cpu_max_cycle = r.cycles;
      }
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
  }
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_all).count();
  r.fluct_rms = n_fl ? std::sqrt(sum2 / static_cast<double>(n_fl)) : 0;
  return r;
}

void report(const char* what, const Result& r, double period_s) {
  std::vector<double> ns = r.cycle_ns;
  std::sort(ns.begin(), ns.end());
  double mean = 0;
  for (double x : ns) mean += x;
  mean /= static_cast<double>(ns.size());
  const double p99 = ns[static_cast<size_t>(0.99 * static_cast<double>(ns.size() - 1))];
  std::printf("%s: mean %.2f us, p50 %.2f us, p99 %.2f us, p99.9 %.2f us, max %.2f us (max in thread CPU time %.2f us "
              "at cycle %lld; %lld cycles, %.1f s of machining, %lld waits for the planner)\n",
              what, mean * 1e-3, ns[ns.size() / 2] * 1e-3, p99 * 1e-3,
              ns[static_cast<size_t>(0.999 * static_cast<double>(ns.size() - 1))] * 1e-3, ns.back() * 1e-3,
              r.cpu_max_ns * 1e-3, static_cast<long long>(r.cpu_max_cycle), static_cast<long long>(r.cycles),
              static_cast<double>(r.cycles) * period_s,
              static_cast<long long>(r.waits));
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
  run(cfg, blocks, cnc::interp::ParamUpdate::kCorrected, false);  // warm-up
  std::printf("compute time of the cyclic path per coarse cycle (feed policy + plans taken + step):\n");
  report("  planning on the planner thread", run(cfg, blocks, cnc::interp::ParamUpdate::kCorrected, true,
                                                 Planning::kThread, paced),
         cfg.ipo_period_s);
  report("  planning inline in the cycle  ", run(cfg, blocks, cnc::interp::ParamUpdate::kCorrected, true,
                                                 Planning::kInline, paced),
         cfg.ipo_period_s);
  const Result dry = run(cfg, blocks, cnc::interp::ParamUpdate::kCorrected, false);
  std::printf("dry run: %.0f setpoints/s (%.0fx real time at 1 ms)\n",
              static_cast<double>(dry.cycles) / dry.wall_s, static_cast<double>(dry.cycles) / dry.wall_s * 1e-3);

  std::printf("feed fluctuation (realised step vs commanded, |.| max and rms, same program):\n");
  const std::pair<cnc::interp::ParamUpdate, const char*> modes[] = {
      {cnc::interp::ParamUpdate::kFirstOrder, "first order  u += ds/|P'|          "},
      {cnc::interp::ParamUpdate::kTaylor2, "second order (seed 000 eq. 7)      "},
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
  cnc::service::Spec spec{"cnc-bench-interpolator", "interpolator compute time and feed fluctuation", {"blocks"},
                          {"paced"}};
  if (argc == 1) {
    static char a0[] = "cnc-bench-interpolator", a1[] = "--machine", a2[] = CNC_SOURCE_DIR "/config/machines/sim3.yaml";
    static char* def[] = {a0, a1, a2, nullptr};
    return cnc::service::run(spec, 3, def, bench);
  }
  return cnc::service::run(spec, argc, argv, bench);
}
