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

int main(int argc, char** argv) {
  if (argc != 5) {
    std::fprintf(stderr, "usage: cnc-stall-inject PID STOP_MS PERIOD_MS COUNT\n");
    return 2;
  }
  const pid_t pid = static_cast<pid_t>(std::atol(argv[1]));
  const double stop_ms = std::atof(argv[2]);
  const double period_ms = std::atof(argv[3]);
  const int count = std::atoi(argv[4]);
  if (pid <= 0 || stop_ms <= 0 || period_ms < 0 || count <= 0) {
    std::fprintf(stderr, "cnc-stall-inject: PID, STOP_MS and COUNT must be positive, PERIOD_MS not negative\n");
    return 2;
  }
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
