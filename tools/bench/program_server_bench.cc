// cnc-bench-program-server: throughput and peak memory of the RS274NGC interpreter
// (common/rs274) and of the part-program server built on it, against LinuxCNC 2.9's
// standalone interpreter rs274 on the same files, in the same run. A bench, not a
// test: it reports figures, and fails only when a run fails or two runs of the same
// program disagree on what they produced.
//
//   cnc-bench-program-server [--runs N] [--lines N] [--repeat N] [--iterations N]
//                            [--only NAME] [--no-rs274] [--rs274 PATH] [--keep]
//                            [--program FILE]... [--canon-dir DIR]
//                            [--profile count|builder|server|printer]
//
// Programs, written into a fresh temporary folder:
//   lines    --lines lines of CAM-like output (default 200,000): G21 G90 header,
//            `G1 X.. Y.. Z.. F..` with 4-decimal coordinates, M2;
//   repeat   `o100 repeat [--repeat]` (default 1,000,000) around one incremental G1;
//   while    `o101 while` with a counter parameter (#100) and expressions in the
//            G1 words, --iterations times (default 100,000);
//   sub      the same loop calling `o200 sub` (two G1 lines from its arguments),
//            --iterations / 2 calls (as many G1 blocks as `while`).
//   FILE     --program FILE (any number of times): a program of your own, e.g. the
//            10-million-line finishing program of tools/bench/finishing_program.py.
// Cases, each run --runs times (default 3, median shown), each run in a child process
// of its own so that its peak RSS (wait4's ru_maxrss) is its alone:
//   interp+count   Interpreter with a Canon that only counts the motion calls;
//   interp+builder Interpreter + BlockBuilder (the interpolator's blocks), popped;
//   server.load    ProgramServer::load (validation: a whole interpretation, a hash per
//   server.serve   chunk), then block(i) for every block in order (a second run);
//                  both in one child, so both rows show that child's peak RSS;
//   interp+printer CanonPrinter (rs274's text) to a file (--canon-dir, default the
//                  temporary folder; 1 MiB stdio buffer, as cnc-rs274), set up as
//                  cnc-rs274 is: the like-for-like comparison with rs274, which prints
//                  the same text to a file in the same folder (compared once: equal);
//   rs274          LinuxCNC's /usr/bin/rs274 -g -t TBL -v VAR FILE OUT, its own
//                  HOME and a fresh var file per run, timed from spawn to exit (so
//                  its start-up, shown on its own row, is included). A program whose
//                  first rs274 run takes over 6 s is run once, to keep the bench
//                  near two minutes on a 2-core machine; the runs column says so.
// --profile CASE runs that case once per program in this process and prints no
// table: for `valgrind --tool=callgrind`.
// "vs rs274" is rs274's median seconds over the case's: how many times faster; "cpu s"
// is the child's user + system time from wait4 (server.load: up to the load's end,
// getrusage; server.serve: the whole child), "cpu vs" the same ratio on it: on a machine busy with other
// work, wall seconds include waiting for a core, CPU seconds do not.
// blocks: motion canonical calls for the interpreter cases and rs274 (the program's
// G0/G1 moves), interpolator blocks (motion + event blocks) for builder and server.
#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
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

#include "common/rs274/block_builder.h"
#include "common/rs274/canon_printer.h"
#include "common/rs274/interpreter.h"
#include "services/part_program_server/program_server.h"
#include "common/util/cli.h"

extern char** environ;

namespace {

namespace rs = cnc::rs274;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// ---- programs ---------------------------------------------------------------------

struct Program {
  std::string name;
  std::string what;
  std::string path;
  int64_t motions = 0;  // G0/G1 moves the program makes when run
};

// A CAM-like 3-axis finishing pass: raster rows over a 120 x 80 mm field with a
// wavy Z, every line `G1 X Y Z F`, 4 decimals, the feed written on every line.
Program write_lines(const std::string& dir, int64_t lines) {
  Program p{"lines", "", dir + "/lines.ngc", 0};
  std::FILE* f = std::fopen(p.path.c_str(), "w");
  if (f == nullptr) std::abort();
  std::fprintf(f, "(cnc-bench-program-server: %" PRId64 "-line G1 program)\nG21 G90 G17 G94\nG0 X0.0000 Y0.0000 Z5.0000\n",
               lines);
  const int64_t moves = std::max<int64_t>(1, lines - 4);
  const int64_t per_row = 600;
  for (int64_t i = 0; i < moves; ++i) {
    const int64_t row = i / per_row, k = i % per_row;
    const double u = static_cast<double>(row % 2 == 0 ? k : per_row - 1 - k) / static_cast<double>(per_row - 1);
    const double x = 120.0 * u;
    const double y = 0.05 * static_cast<double>(row % 1600);
    const double z = -1.5 + 0.75 * std::sin(x * 0.21) * std::cos(y * 0.17) - 0.0001 * static_cast<double>(i % 13);
    std::fprintf(f, "G1 X%.4f Y%.4f Z%.4f F%d\n", x, y, z, 1200 + 100 * static_cast<int>(row % 3));
  }
  std::fprintf(f, "M2\n");
  std::fclose(f);
  p.motions = moves + 1;
  p.what = std::to_string(moves + 4) + " lines, " + std::to_string(moves) + " G1";
  return p;
}

Program write_repeat(const std::string& dir, int64_t times) {
  Program p{"repeat", "", dir + "/repeat.ngc", times + 1};
  std::ofstream(p.path) << "(cnc-bench-program-server: repeat loop)\nG21 G90 G17 G94\nG0 X0 Y0 Z1\nF1500\nG91\n"
                        << "o100 repeat [" << times << "]\n"
                        << "  G1 X0.0010 Y0.0005\n"
                        << "o100 endrepeat\nG90\nM2\n";
  p.what = "o100 repeat [" + std::to_string(times) + "] around one G1";
  return p;
}

Program write_while(const std::string& dir, int64_t times) {
  Program p{"while", "", dir + "/while.ngc", times + 1};
  std::ofstream(p.path) << "(cnc-bench-program-server: while loop, counter and expressions)\n"
                        << "G21 G90 G17 G94\nG0 X0 Y0 Z1\n#100 = 0\n"
                        << "o101 while [#100 LT " << times << "]\n"
                        << "  G1 X[#100 MOD 100 * 1.2] Y[FIX[#100 / 100] * 0.05] Z[-1 - [#100 MOD 7] * 0.01] F1200\n"
                        << "  #100 = [#100 + 1]\n"
                        << "o101 endwhile\nM2\n";
  p.what = "o101 while, " + std::to_string(times) + " passes, G1 from expressions";
  return p;
}

Program write_sub(const std::string& dir, int64_t moves) {
  const int64_t calls = std::max<int64_t>(1, moves / 2);
  Program p{"sub", "", dir + "/sub.ngc", 2 * calls + 1};
  std::ofstream(p.path) << "(cnc-bench-program-server: subroutine calls in a loop)\n"
                        << "o200 sub\n"
                        << "  G1 X[#1] Y[#2] F1200\n"
                        << "  G1 X[#1 + 1.5] Y[#2 + 0.25]\n"
                        << "o200 endsub\n"
                        << "G21 G90 G17 G94\nG0 X0 Y0 Z1\n#100 = 0\n"
                        << "o101 while [#100 LT " << calls << "]\n"
                        << "  o200 call [#100 MOD 50] [#100 * 0.001]\n"
                        << "  #100 = [#100 + 1]\n"
                        << "o101 endwhile\nM2\n";
  p.what = "o101 while, " + std::to_string(calls) + " calls of o200 sub (2 G1 each)";
  return p;
}

// A tool table and a var file both interpreters read (G54 at the origin).
void write_fixture(const std::string& dir) {
  std::ofstream tbl(dir + "/bench.tbl");
  for (int t = 1; t <= 10; ++t) tbl << "T" << t << " P" << t << " Z" << 0.25 + 0.05 * t << " D" << 0.02 * t << " ;tool\n";
  std::ofstream var(dir + "/bench.var0");
  for (int n : {5161, 5162, 5163, 5181, 5182, 5183, 5211, 5212, 5213, 5220, 5221, 5222, 5223})
    var << n << "\t" << (n == 5220 ? "1.000000" : "0.000000") << "\n";
}

// A fresh copy of the var file for one run (both interpreters write theirs at the end).
std::string fresh_var(const std::string& dir) {
  const std::string v = dir + "/run.var";
  fs::copy_file(dir + "/bench.var0", v, fs::copy_options::overwrite_existing);
  return v;
}

// ---- the cases --------------------------------------------------------------------

struct Result {
  int ok = 0;
  double seconds = 0;    // the whole case (server: load)
  double seconds2 = 0;   // server: serving every block
  double cpu_load = 0;   // server: the child's CPU seconds up to the end of the load
  int64_t blocks = 0;
  int64_t lines = 0;     // lines the interpreter executed
  uint64_t fingerprint = 14695981039346656037ull;
  char error[512] = {};
};

void mix(uint64_t* h, double v) {
  uint64_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  *h = (*h ^ bits) * 1099511628211ull;
}

// Cheap: the index, kind and end of a block (the server checks the full hash itself).
void fingerprint(uint64_t* h, const cnc::program::Block& b) {
  mix(h, static_cast<double>(b.index));
  mix(h, static_cast<double>(b.kind));
  for (double v : b.end) mix(h, v);
}

rs::MachineSetup machine(const std::string& dir, const std::string& var) {
  rs::MachineSetup m;
  m.axes = "XYZ";
  m.machine_units = rs::Units::kMm;
  m.tool_table = dir + "/bench.tbl";
  m.var_file = var;
  m.write_var_file = false;
  return m;
}

rs::BuilderSetup builder_setup() {
  rs::BuilderSetup b;
  b.axis_names = {"X", "Y", "Z"};
  b.start_position_mm = {0, 0, 0};
  return b;
}

class CountingCanon : public rs::Canon {
 public:
  int64_t motions = 0;
  void straight_traverse(const rs::SourceRef&, const rs::Pose&) override { ++motions; }
  void straight_feed(const rs::SourceRef&, const rs::Pose&) override { ++motions; }
  void arc_feed(const rs::SourceRef&, double, double, double, double, int, double, const rs::Pose&) override {
    ++motions;
  }
  void nurbs_feed(const rs::SourceRef&, int, const std::vector<rs::NurbsPoint>&, const std::vector<double>&,
                  const rs::Pose&) override {
    ++motions;
  }
  void dwell(const rs::SourceRef&, double) override {}
};

class CountingPrinter : public rs::CanonPrinter {
 public:
  using CanonPrinter::CanonPrinter;
  int64_t motions = 0;
  void straight_traverse(const rs::SourceRef& r, const rs::Pose& p) override {
    ++motions;
    CanonPrinter::straight_traverse(r, p);
  }
  void straight_feed(const rs::SourceRef& r, const rs::Pose& p) override {
    ++motions;
    CanonPrinter::straight_feed(r, p);
  }
  void arc_feed(const rs::SourceRef& r, double a, double b, double c, double d, int rot, double e,
                const rs::Pose& p) override {
    ++motions;
    CanonPrinter::arc_feed(r, a, b, c, d, rot, e, p);
  }
};

template <typename F>
Result guarded(F&& f) {
  Result r;
  try {
    f(r);
    r.ok = 1;
  } catch (const std::exception& e) {
    std::snprintf(r.error, sizeof r.error, "%s", e.what());
  }
  return r;
}

Result interp_count(const std::string& dir, const std::string& path, const std::string& var) {
  return guarded([&](Result& r) {
    const auto t0 = Clock::now();
    CountingCanon canon;
    rs::Interpreter interp(machine(dir, var), canon);
    interp.open(path);
    while (interp.execute_next()) {
    }
    r.seconds = seconds_since(t0);
    r.blocks = canon.motions;
    r.lines = interp.lines_executed();
  });
}

Result interp_builder(const std::string& dir, const std::string& path, const std::string& var) {
  return guarded([&](Result& r) {
    const auto t0 = Clock::now();
    const rs::Interpreter* ip = nullptr;
    rs::BlockBuilder builder(builder_setup(),
                             [&ip](int32_t f) -> const std::string& { return ip->file_names()[static_cast<size_t>(f)]; });
    rs::Interpreter interp(machine(dir, var), builder);
    ip = &interp;
    interp.open(path);
    auto& q = builder.blocks();
    for (;;) {
      const bool more = interp.execute_next();
      while (!q.empty()) {
        fingerprint(&r.fingerprint, q.front());
        q.pop_front();
        ++r.blocks;
      }
      if (!more) break;
    }
    r.seconds = seconds_since(t0);
    r.lines = interp.lines_executed();
  });
}

Result server(const std::string& dir, const std::string& path, const std::string& var) {
  return guarded([&](Result& r) {
    cnc::pps::ProgramSetup s;
    s.machine = machine(dir, var);
    s.builder = builder_setup();
    cnc::pps::ProgramServer srv(s, cnc::pps::ServerLimits{});
    auto t0 = Clock::now();
    const cnc::pps::LoadResult lr = srv.load(path, 1);
    r.seconds = seconds_since(t0);
    struct rusage ru {};
    getrusage(RUSAGE_SELF, &ru);
    r.cpu_load = static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
                 1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
    if (!lr.ok) throw std::runtime_error("load: " + lr.error);
    r.lines = srv.lines_interpreted();
    t0 = Clock::now();
    const int64_t n = srv.num_blocks();
    for (int64_t i = 0; i < n; ++i) {
      const cnc::program::Block* b = srv.block(i);
      if (b == nullptr) throw std::runtime_error("block " + std::to_string(i) + ": " + srv.serving_error());
      fingerprint(&r.fingerprint, *b);
    }
    r.seconds2 = seconds_since(t0);
    r.blocks = n;
  });
}

// As cnc-rs274 (tools/rs274/main.cc) sets up for the conformance harness.
Result interp_printer(const std::string& dir, const std::string& path, const std::string& var,
                      const std::string& canon) {
  return guarded([&](Result& r) {
    const auto t0 = Clock::now();
    std::FILE* out = std::fopen(canon.c_str(), "w");
    if (out == nullptr) throw std::runtime_error("cannot write " + canon);
    std::setvbuf(out, nullptr, _IOFBF, 1 << 20);
    rs::MachineSetup m = machine(dir, var);
    m.axes = "XYZABCUVW";
    m.machine_units = rs::Units::kInch;
    m.block_delete = false;
    m.write_var_file = true;
    const rs::Interpreter* ip = nullptr;
    static const std::string kEmpty;
    {
      CountingPrinter printer(out, [&ip]() -> const std::string& { return ip ? ip->current_text() : kEmpty; });
      rs::Interpreter interp(m, printer);
      ip = &interp;
      interp.open(path);
      while (interp.execute_next()) {
      }
      ip = nullptr;
      // rs274's closing resets, as cnc-rs274 prints them (run without an INI file: two).
      printer.on_reset(rs::SourceRef{});
      printer.on_reset(rs::SourceRef{});
      r.blocks = printer.motions;
      r.lines = interp.lines_executed();
    }
    std::fclose(out);
    r.seconds = seconds_since(t0);
  });
}

// ---- processes --------------------------------------------------------------------

struct Measured {
  Result r;
  double rss_mib = 0;
  double cpu_s = 0;  // the child's user + system time (wait4), whole process
};

double cpu_seconds(const struct rusage& ru) {
  return static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

// Runs `work` in a child; its result through a pipe, its peak RSS from wait4.
Measured in_child(const std::function<Result()>& work) {
  int fd[2];
  if (pipe(fd) != 0) std::abort();
  std::fflush(stdout);
  const pid_t pid = fork();
  if (pid < 0) std::abort();
  if (pid == 0) {
    close(fd[0]);
    const Result r = work();
    const ssize_t w = write(fd[1], &r, sizeof r);
    _exit(w == static_cast<ssize_t>(sizeof r) ? 0 : 1);
  }
  close(fd[1]);
  Measured m;
  size_t got = 0;
  while (got < sizeof m.r) {
    const ssize_t n = read(fd[0], reinterpret_cast<char*>(&m.r) + got, sizeof m.r - got);
    if (n <= 0) break;
    got += static_cast<size_t>(n);
  }
  close(fd[0]);
  int status = 0;
  struct rusage ru {};
  wait4(pid, &status, 0, &ru);
  if (got != sizeof m.r || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    m.r.ok = 0;
    if (m.r.error[0] == '\0') std::snprintf(m.r.error, sizeof m.r.error, "child died (status %d)", status);
  }
  m.rss_mib = static_cast<double>(ru.ru_maxrss) / 1024.0;  // KiB on Linux
  m.cpu_s = cpu_seconds(ru);
  return m;
}

// rs274 in its own process, HOME of its own, stdout and output to /dev/null, stderr
// kept for the report. Timed from spawn to exit.
Measured run_rs274(const std::string& exe, const std::string& dir, const std::string& path,
                   const std::string& canon = "/dev/null") {
  Measured m;
  const std::string var = fresh_var(dir);
  const std::string home = dir + "/home";
  fs::create_directories(home);
  const std::string err = dir + "/rs274.err";
  std::vector<std::string> env_s;
  for (char** e = environ; *e != nullptr; ++e)
    if (std::strncmp(*e, "HOME=", 5) != 0) env_s.emplace_back(*e);
  env_s.push_back("HOME=" + home);
  std::vector<char*> envp;
  for (auto& s : env_s) envp.push_back(s.data());
  envp.push_back(nullptr);
  std::vector<std::string> args = {exe, "-g", "-t", dir + "/bench.tbl", "-v", var, path, canon};
  std::vector<char*> argv;
  for (auto& s : args) argv.push_back(s.data());
  argv.push_back(nullptr);

  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = 0;
  const auto t0 = Clock::now();
  const int rc = posix_spawn(&pid, exe.c_str(), &fa, nullptr, argv.data(), envp.data());
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) {
    std::snprintf(m.r.error, sizeof m.r.error, "cannot start %s: %s", exe.c_str(), std::strerror(rc));
    return m;
  }
  int status = 0;
  struct rusage ru {};
  wait4(pid, &status, 0, &ru);
  m.r.seconds = seconds_since(t0);
  m.rss_mib = static_cast<double>(ru.ru_maxrss) / 1024.0;
  m.cpu_s = cpu_seconds(ru);
  m.r.ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  if (!m.r.ok) {
    std::ifstream in(err);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::snprintf(m.r.error, sizeof m.r.error, "rs274 exit status %d: %s", status, text.c_str());
  }
  return m;
}

// ---- the table --------------------------------------------------------------------

struct Row {
  std::string program, kase;
  int runs = 0;
  bool ok = true;
  std::string error;
  int64_t blocks = 0, lines = 0;
  double seconds = 0, rss_mib = 0, cpu_s = 0;
  uint64_t fingerprint = 0;
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n == 0 ? 0 : (n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]));
}

// Median seconds and median peak RSS of `runs` measurements; the figures of the
// first run (blocks, lines, fingerprint), which every other run must repeat.
Row summarise(const std::string& program, const std::string& kase, const std::vector<Measured>& ms, bool second) {
  Row row;
  row.program = program;
  row.kase = kase;
  row.runs = static_cast<int>(ms.size());
  std::vector<double> s, rss, cpu;
  for (const Measured& m : ms) {
    if (!m.r.ok) {
      row.ok = false;
      row.error = m.r.error;
      return row;
    }
    s.push_back(second ? m.r.seconds2 : m.r.seconds);
    rss.push_back(m.rss_mib);
    cpu.push_back(m.cpu_s);
    if (m.r.blocks != ms.front().r.blocks || m.r.fingerprint != ms.front().r.fingerprint) {
      row.ok = false;
      row.error = "runs disagree on the blocks made";
      return row;
    }
  }
  row.seconds = median(s);
  row.rss_mib = median(rss);
  row.cpu_s = median(cpu);
  row.blocks = ms.front().r.blocks;
  row.lines = ms.front().r.lines;
  row.fingerprint = ms.front().r.fingerprint;
  return row;
}

void print_row(const Row& r, double rs274_seconds, double rs274_cpu) {
  if (!r.ok) {
    std::printf("  %-15s FAILED: %s\n", r.kase.c_str(), r.error.c_str());
    return;
  }
  char lines_s[32] = "";
  if (r.lines > 0 && r.seconds > 0) std::snprintf(lines_s, sizeof lines_s, "%.0f", static_cast<double>(r.lines) / r.seconds);
  char vs[32] = "";
  if (rs274_seconds > 0 && r.seconds > 0) std::snprintf(vs, sizeof vs, "%.1fx", rs274_seconds / r.seconds);
  char vs_cpu[32] = "";
  if (rs274_cpu > 0 && r.cpu_s > 0) std::snprintf(vs_cpu, sizeof vs_cpu, "%.1fx", rs274_cpu / r.cpu_s);
  std::printf("  %-15s %4d %10" PRId64 " %9.3f %11.0f %11s %9.1f %9s %8.3f %9s\n", r.kase.c_str(), r.runs, r.blocks,
              r.seconds, r.seconds > 0 ? static_cast<double>(r.blocks) / r.seconds : 0.0, lines_s, r.rss_mib, vs,
              r.cpu_s, vs_cpu);
}

}  // namespace

int main(int argc, char** argv) {
  int runs = 3;
  int64_t lines = 200'000, repeat = 1'000'000, iterations = 100'000;
  std::string only, profile, rs274 = "/usr/bin/rs274", canon_dir;
  std::vector<std::string> extra;
  bool keep = false, no_rs274 = false;
  CLI::App app{"throughput and peak memory of the interpreter and the program server, against LinuxCNC's rs274", "cnc-bench-program-server"};
  cnc::util::cli::setup(app);
  app.add_option("--runs", runs, "runs per case; the best counts")->type_name("N")->check(CLI::Range(1, 1000));
  app.add_option("--lines", lines, "lines of the straight-line program")->type_name("N")->check(CLI::Range(int64_t{10}, int64_t{1} << 40));
  app.add_option("--repeat", repeat, "iterations of the O-repeat program")->type_name("N")->check(CLI::Range(int64_t{1}, int64_t{1} << 40));
  app.add_option("--iterations", iterations, "iterations of the while and sub programs")->type_name("N")->check(CLI::Range(int64_t{2}, int64_t{1} << 40));
  app.add_option("--only", only, "one case (none: with --program, only those)")
      ->check(CLI::IsMember({"lines", "repeat", "while", "sub", "none"}));
  app.add_option("--profile", profile, "one run of that stage per program, in this process, no table (for callgrind)")
      ->check(CLI::IsMember({"count", "builder", "server", "printer"}));
  app.add_option("--rs274", rs274, "LinuxCNC's rs274")->type_name("PATH");
  app.add_flag("--no-rs274", no_rs274, "without rs274's figures");
  app.add_flag("--keep", keep, "keep the generated programs");
  app.add_option("--program", extra, "a program of your own as one more case (any number of times)")
      ->type_name("FILE")->check(CLI::ExistingFile);
  app.add_option("--canon-dir", canon_dir, "where rs274 and interp+printer write their canon (default: the temporary folder)")
      ->type_name("DIR")->check(CLI::ExistingDirectory);
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  const auto t_start = Clock::now();
  char tmpl[] = "/tmp/cnc-bench-program-XXXXXX";
  if (mkdtemp(tmpl) == nullptr) {
    std::perror("mkdtemp");
    return 1;
  }
  const std::string dir = tmpl;
  write_fixture(dir);

  const bool have_rs274 = !no_rs274 && access(rs274.c_str(), X_OK) == 0;
  if (no_rs274) std::printf("rs274 baseline: skipped (--no-rs274)\n");
  else if (!have_rs274)
    std::printf("rs274 baseline: SKIPPED, %s is not installed (Debian: the linuxcnc-uspace package)\n", rs274.c_str());

  std::vector<Program> programs;
  if (only.empty() || only == "lines") programs.push_back(write_lines(dir, lines));
  if (only.empty() || only == "repeat") programs.push_back(write_repeat(dir, repeat));
  if (only.empty() || only == "while") programs.push_back(write_while(dir, iterations));
  if (only.empty() || only == "sub") programs.push_back(write_sub(dir, iterations));
  for (const std::string& f : extra) {
    Program p{fs::path(f).filename().string(), "", fs::absolute(f).string(), -1};
    p.what = "--program " + f;
    programs.push_back(p);
  }
  if (canon_dir.empty()) canon_dir = dir;
  if (programs.empty()) {
    std::fprintf(stderr, "--only: no program named %s\n", only.c_str());
    return 2;
  }

  if (!profile.empty()) {
    for (const Program& p : programs) {
      const std::string var = fresh_var(dir);
      const Result r = profile == "count"     ? interp_count(dir, p.path, var)
                       : profile == "builder" ? interp_builder(dir, p.path, var)
                       : profile == "server"  ? server(dir, p.path, var)
                                              : interp_printer(dir, p.path, var, canon_dir + "/ours.canon");
      std::printf("%s, %s: %s, %" PRId64 " blocks, %.3f s (+%.3f s)\n", p.name.c_str(), profile.c_str(),
                  r.ok ? "ok" : r.error, r.blocks, r.seconds, r.seconds2);
    }
    if (!keep) fs::remove_all(dir);
    return 0;
  }

  const Measured idle = in_child([] {
    Result r;
    r.ok = 1;
    return r;
  });
  std::printf("runs per case: %d (median shown); temp folder %s; idle child process peak RSS %.1f MiB\n", runs,
              dir.c_str(), idle.rss_mib);
  double rs274_startup = 0;
  if (have_rs274) {
    const std::string empty = dir + "/empty.ngc";
    std::ofstream(empty) << "M2\n";
    std::vector<double> t, rss;
    for (int k = 0; k < runs; ++k) {
      const Measured m = run_rs274(rs274, dir, empty);
      t.push_back(m.r.seconds);
      rss.push_back(m.rss_mib);
    }
    rs274_startup = median(t);
    std::printf("rs274 start-up and end (a program of just M2): %.3f s, peak RSS %.1f MiB\n", rs274_startup,
                median(rss));
  }

  int rc = 0;
  for (const Program& p : programs) {
    const double mib = static_cast<double>(fs::file_size(p.path)) / (1024.0 * 1024.0);
    if (p.motions >= 0)
      std::printf("\n%s: %s; %" PRId64 " moves; file %.2f MiB\n", p.name.c_str(), p.what.c_str(), p.motions, mib);
    else
      std::printf("\n%s: %s; file %.2f MiB\n", p.name.c_str(), p.what.c_str(), mib);
    const std::string ours_canon = canon_dir + "/ours.canon", rs274_canon = canon_dir + "/rs274.canon";
    std::printf("  %-15s %4s %10s %9s %11s %11s %9s %9s %8s %9s\n", "case", "runs", "blocks", "seconds", "blocks/s",
                "lines/s", "RSS MiB", "vs rs274", "cpu s", "cpu vs");
    std::vector<Measured> count, build, serve, print, base;
    for (int k = 0; k < runs; ++k) {
      count.push_back(in_child([&] { return interp_count(dir, p.path, fresh_var(dir)); }));
      build.push_back(in_child([&] { return interp_builder(dir, p.path, fresh_var(dir)); }));
      serve.push_back(in_child([&] { return server(dir, p.path, fresh_var(dir)); }));
      print.push_back(in_child([&] { return interp_printer(dir, p.path, fresh_var(dir), ours_canon); }));
    }
    if (have_rs274) {
      for (int k = 0; k < runs; ++k) {
        base.push_back(run_rs274(rs274, dir, p.path, rs274_canon));
        if (!base.back().r.ok || base.back().r.seconds > 6.0) break;
      }
      // rs274 prints; the moves are the program's (of a program of your own: as many as ours printed)
      for (Measured& m : base) m.r.blocks = p.motions >= 0 ? p.motions : (print.empty() ? 0 : print.front().r.blocks);
    }
    std::vector<Row> rows = {summarise(p.name, "interp+count", count, false),
                             summarise(p.name, "interp+builder", build, false),
                             summarise(p.name, "server.load", serve, false),
                             summarise(p.name, "server.serve", serve, true),
                             summarise(p.name, "interp+printer", print, false)};
    rows[2].lines = 0;  // the load interprets; serving interprets again (shown once)
    {  // the load's own CPU seconds (the child's up to the load's end)
      std::vector<double> c;
      for (const Measured& m : serve) c.push_back(m.r.cpu_load);
      if (rows[2].ok) rows[2].cpu_s = median(c);
    }
    Row base_row;
    double base_s = 0, base_cpu = 0;
    if (have_rs274) {
      base_row = summarise(p.name, "rs274", base, false);
      base_row.lines = 0;
      if (base_row.ok) {
        base_s = base_row.seconds;
        base_cpu = base_row.cpu_s;
      }
    }
    for (const Row& r : rows) print_row(r, base_s, base_cpu);
    if (have_rs274) print_row(base_row, 0, 0);
    // What the runs produced must agree: every move counted, the same blocks built and served.
    bool agree = true;
    for (const Row& r : rows) agree = agree && r.ok;
    if (have_rs274 && base_row.ok) {
      // Like for like: both wrote the same canon (the last runs of each).
      std::ifstream a(ours_canon, std::ios::binary), b(rs274_canon, std::ios::binary);
      const bool same = a && b && std::equal(std::istreambuf_iterator<char>(a), std::istreambuf_iterator<char>(),
                                             std::istreambuf_iterator<char>(b), std::istreambuf_iterator<char>());
      std::printf("  canon of interp+printer and rs274: %s (%.1f MB)\n", same ? "identical" : "DIFFERENT",
                  static_cast<double>(fs::file_size(rs274_canon)) / 1e6);
      if (!same) agree = false;
      if (rows[4].ok && rows[2].ok && rows[4].seconds > 0 && rows[2].seconds > 0)
        std::printf("  like for like: interp+printer %.2f x rs274 (wall), %.2f x (cpu); server.load %.2f x (wall), %.2f x (cpu)\n",
                    base_row.seconds / rows[4].seconds, base_row.cpu_s / rows[4].cpu_s, base_row.seconds / rows[2].seconds,
                    base_row.cpu_s / rows[2].cpu_s);
    }
    fs::remove(ours_canon);
    fs::remove(rs274_canon);
    if (agree) {
      if (p.motions >= 0 && (rows[0].blocks != p.motions || rows[4].blocks != p.motions)) {
        std::printf("  MISMATCH: %" PRId64 " moves expected, counted %" PRId64 " / printed %" PRId64 "\n", p.motions,
                    rows[0].blocks, rows[4].blocks);
        agree = false;
      }
      if (rows[1].blocks != rows[3].blocks || rows[1].fingerprint != rows[3].fingerprint) {
        std::printf("  MISMATCH: builder made %" PRId64 " blocks, the server served %" PRId64 " (or they differ)\n",
                    rows[1].blocks, rows[3].blocks);
        agree = false;
      }
    }
    if (!agree || (have_rs274 && !base_row.ok)) rc = 1;
  }
  if (have_rs274)
    std::printf("\nvs rs274: rs274's median seconds / the case's (rs274's include its start-up, %.3f s); cpu s: the\n"
                "child's user+system time (wait4), less disturbed than wall time on a busy machine; cpu vs: the same\n"
                "ratio on cpu s (server.load's up to the load's end, server.serve's of the whole child)\n",
                rs274_startup);
  std::printf("total bench time %.1f s\n", seconds_since(t_start));
  if (!keep) fs::remove_all(dir);
  else std::printf("kept %s\n", dir.c_str());
  return rc;
}
