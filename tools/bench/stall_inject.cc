// cnc-stall-inject: stalls a process the way a busy VM does, to measure what the cell
// does with it. SIGSTOP, sleep STOP_MS, SIGCONT; then PERIOD_MS running; COUNT times.
// Prints the stalls' real durations (a loaded machine stretches them).
//
//   cnc-stall-inject PID STOP_MS PERIOD_MS COUNT
//
// tools/bench/stall_bench.sh runs a program on the cell while it stalls one service.
#include <signal.h>
#include <sys/types.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

#include "common/util/cli.h"

int main(int argc, char** argv) {
  pid_t pid = 0;
  double stop_ms = 0, period_ms = 0;
  int count = 0;
  CLI::App app{"stalls a process (SIGSTOP, STOP_MS, SIGCONT, PERIOD_MS running) COUNT times", "cnc-stall-inject"};
  cnc::util::cli::setup(app);
  app.add_option("pid", pid, "the process to stall")->type_name("PID")->required()->check(cnc::util::cli::positive());
  app.add_option("stop_ms", stop_ms, "how long each stall lasts, ms")->type_name("STOP_MS")->required()->check(cnc::util::cli::positive());
  app.add_option("period_ms", period_ms, "how long it runs between stalls, ms")->type_name("PERIOD_MS")->required()->check(cnc::util::cli::non_negative());
  app.add_option("count", count, "how many stalls")->type_name("COUNT")->required()->check(CLI::Range(1, 1 << 30));
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  using Clock = std::chrono::steady_clock;
  double longest = 0, sum = 0;
  int done = 0;
  for (; done < count; ++done) {
    const auto t0 = Clock::now();
    if (::kill(pid, SIGSTOP) != 0) break;  // the process is gone
    std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(stop_ms));
    ::kill(pid, SIGCONT);
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    sum += ms;
    longest = std::max(longest, ms);
    std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(period_ms));
  }
  std::printf("stalls=%d mean_ms=%.1f max_ms=%.1f\n", done, done > 0 ? sum / done : 0.0, longest);
  return done == count ? 0 : 1;
}
