// cnc-bench-program-server: memory and speed of the part-program server on a long
// program, against the baseline of parsing the whole file into memory.
//
//   cnc-bench-program-server [--blocks N] [--keep]
//
// Writes an N-block program (default 1,000,000: lines and a few arcs) to a temporary
// file, then runs each measurement in its own child process so that each peak RSS
// (getrusage ru_maxrss via wait4) belongs to that measurement alone:
//   streaming  ProgramServer::load (validation, checkpoints), then every block served
//              in order in windows of 32 as the node does (block -> message -> bytes);
//   baseline   GcodeParser::parse of the whole file into a std::vector<Block>;
//   idle       a child that does nothing (the floor of any process here).
// Both measured runs fingerprint the blocks they saw; the fingerprints must agree.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "common/program/block_msg.h"
#include "common/program/gcode_parser.h"
#include "services/part_program_server/program_server.h"

namespace {

using Clock = std::chrono::steady_clock;

struct Result {
  int ok = 0;
  double load_s = 0;   // streaming: load; baseline: the whole parse
  double serve_s = 0;  // streaming only
  int64_t blocks = 0;
  int64_t checkpoints = 0;
  uint64_t fingerprint = 1469598103934665603ull;
  char error[256] = {};
};

struct Measured {
  Result r;
  double peak_rss_mb = 0;
};

void mix(uint64_t* h, double v) {
  uint64_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  *h = (*h ^ bits) * 1099511628211ull;
}

void fingerprint(uint64_t* h, const cnc::program::Block& b) {
  mix(h, static_cast<double>(b.index));
  mix(h, static_cast<double>(b.kind));
  for (double v : b.end) mix(h, v);
  for (double v : b.arc.center) mix(h, v);
}

cnc::program::ParserSettings settings() {
  cnc::program::ParserSettings s;
  s.axis_names = {"X", "Y", "Z"};
  s.start_position_mm = {0, 0, 0};
  return s;
}

// Lines zig-zagging over a 100 x 100 mm field, with a pair of arcs every 1000 blocks.
int64_t write_program(const std::string& path, int64_t blocks, int64_t* arcs) {
  std::ofstream out(path, std::ios::binary);
  out << "( cnc-bench-program-server: " << blocks << " blocks )\nG21 G90 G17\nS10000 M3\nG0 X0 Y0 Z0\n";
  int64_t n = 1;  // the G0
  *arcs = 0;
  char line[96];
  double x = 0, y = 0;
  while (n < blocks - 1) {  // the last block is the end
    if (n % 1000 == 500 && n + 2 < blocks - 1) {
      std::snprintf(line, sizeof line, "G2 X%.3f Y%.3f I5 J0 F1500\nG3 X%.3f Y%.3f R5\n", x + 10, y, x, y);
      out << line;
      n += 2;
      *arcs += 2;
      continue;
    }
    x = static_cast<double>(n % 100);
    y = std::fmod(static_cast<double>(n) * 0.037, 100.0);
    std::snprintf(line, sizeof line, "G1 X%.3f Y%.3f Z%.3f F%d\n", x, y, -0.001 * static_cast<double>(n % 7),
                  1000 + static_cast<int>(n % 5) * 100);
    out << line;
    ++n;
  }
  out << "M5\nM30\n";
  return n + 1;
}

// Runs `work` in a child; returns its result and its peak RSS.
Measured in_child(const std::function<Result()>& work) {
  int fd[2];
  if (pipe(fd) != 0) std::abort();
  const pid_t pid = fork();
  if (pid == 0) {
    close(fd[0]);
    Result r = work();
    const ssize_t w = write(fd[1], &r, sizeof r);
    _exit(w == static_cast<ssize_t>(sizeof r) ? 0 : 1);
  }
  close(fd[1]);
  Measured m;
  const ssize_t got = read(fd[0], &m.r, sizeof m.r);
  close(fd[0]);
  int status = 0;
  struct rusage ru {};
  wait4(pid, &status, 0, &ru);
  if (got != static_cast<ssize_t>(sizeof m.r) || !WIFEXITED(status)) m.r.ok = 0;
  m.peak_rss_mb = static_cast<double>(ru.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
  return m;
}

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

Result streaming(const std::string& path) {
  Result r;
  cnc::pps::ProgramServer server(settings(), cnc::pps::ServerLimits{});
  auto t0 = Clock::now();
  const cnc::pps::LoadResult lr = server.load(path, 1);
  r.load_s = seconds_since(t0);
  if (!lr.ok) {
    std::snprintf(r.error, sizeof r.error, "%s", lr.error.c_str());
    return r;
  }
  r.checkpoints = static_cast<int64_t>(server.num_checkpoints());
  std::vector<uint8_t> wire;
  constexpr int64_t kWindow = 32;
  t0 = Clock::now();
  for (int64_t first = 0; first < server.num_blocks(); first += kWindow) {
    for (int64_t i = first; i < std::min(first + kWindow, server.num_blocks()); ++i) {
      const cnc::program::Block* b = server.block(i);
      if (b == nullptr) {
        std::snprintf(r.error, sizeof r.error, "block %" PRId64 ": %s", i, server.serving_error().c_str());
        return r;
      }
      fingerprint(&r.fingerprint, *b);
      const cnc::lcmt_program_block m = cnc::program::to_msg(*b, 1);
      wire.resize(static_cast<size_t>(m.getEncodedSize()));
      m.encode(wire.data(), 0, static_cast<int>(wire.size()));
      ++r.blocks;
    }
  }
  r.serve_s = seconds_since(t0);
  r.ok = 1;
  return r;
}

Result whole_file(const std::string& path) {
  Result r;
  try {
    const auto t0 = Clock::now();
    const cnc::program::Program p = cnc::program::GcodeParser(settings()).parse_file(path);
    r.load_s = seconds_since(t0);
    for (const auto& b : p.blocks) fingerprint(&r.fingerprint, b);
    r.blocks = static_cast<int64_t>(p.blocks.size());
    r.ok = 1;
  } catch (const cnc::program::ProgramError& e) {
    std::snprintf(r.error, sizeof r.error, "%s", e.what());
  }
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  int64_t blocks = 1'000'000;
  bool keep = false;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--blocks") == 0 && i + 1 < argc) {
      blocks = std::max<int64_t>(10, std::atoll(argv[++i]));
    } else if (std::strcmp(argv[i], "--keep") == 0) {
      keep = true;
    } else {
      std::fprintf(stderr, "usage: cnc-bench-program-server [--blocks N] [--keep]\n");
      return 2;
    }
  }
  const std::string path =
      (std::filesystem::temp_directory_path() / ("cnc-bench-program-" + std::to_string(getpid()) + ".ngc")).string();
  int64_t arcs = 0;
  const int64_t expected = write_program(path, blocks, &arcs);
  const double file_mb = static_cast<double>(std::filesystem::file_size(path)) / (1024.0 * 1024.0);
  std::printf("program: %" PRId64 " blocks (%" PRId64 " arcs), %.1f MiB, %s\n", expected, arcs, file_mb, path.c_str());

  const Measured idle = in_child([] {
    Result r;
    r.ok = 1;
    return r;
  });
  const Measured s = in_child([&] { return streaming(path); });
  const Measured w = in_child([&] { return whole_file(path); });
  if (!keep) std::filesystem::remove(path);

  int rc = 0;
  if (!s.r.ok) {
    std::printf("streaming server FAILED: %s\n", s.r.error);
    rc = 1;
  } else {
    std::printf("streaming server: load (validate + %" PRId64 " checkpoints) %.2f s, %.0f blocks/s; "
                "served %" PRId64 " blocks in windows of 32 in %.2f s = %.0f blocks/s; peak RSS %.1f MiB\n",
                s.r.checkpoints, s.r.load_s, static_cast<double>(s.r.blocks) / s.r.load_s, s.r.blocks, s.r.serve_s,
                static_cast<double>(s.r.blocks) / s.r.serve_s, s.peak_rss_mb);
  }
  if (!w.r.ok) {
    std::printf("whole-file parse FAILED: %s\n", w.r.error);
    rc = 1;
  } else {
    std::printf("baseline, whole file in memory (GcodeParser::parse): %.2f s, peak RSS %.1f MiB\n", w.r.load_s,
                w.peak_rss_mb);
  }
  std::printf("idle child process: peak RSS %.1f MiB\n", idle.peak_rss_mb);
  if (s.r.ok && w.r.ok) {
    std::printf("peak RSS, whole file / streaming: %.1fx (above the idle process: %.1f MiB vs %.1f MiB)\n",
                w.peak_rss_mb / s.peak_rss_mb, w.peak_rss_mb - idle.peak_rss_mb, s.peak_rss_mb - idle.peak_rss_mb);
    const bool same = s.r.blocks == w.r.blocks && s.r.fingerprint == w.r.fingerprint && s.r.blocks == expected;
    std::printf("same blocks from both: %s\n", same ? "yes" : "NO");
    if (!same) rc = 1;
  }
  return rc;
}
