// cnc-path-property: the randomized property check of the interpolator core
// (tests/unit/interpolator_property_test.cc's generator and checks) for as long as
// asked. Prints the counts, and for each kind of violation (property x the classes
// of the piece it happened in) the worst measured value and the smallest program
// found that still shows it (the piece alone after a G0 to its start, or with the
// piece before it).
//
//   cnc-path-property [--seed N] [--seconds S] [--classes MASK] [--verbose]
//   cnc-path-property --program FILE   (one program's figures: limits' use, chord error)
//
// MASK: the bits of cnc::proptest::Class the generator may use (default: all); the
// unit test runs kLine|kShort|kLong|kMicro = 0x1980. Exit status 1 when any program
// violated a property.
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>

#include "tests/unit/interpolator_property.h"
#include "common/util/cli.h"

namespace {

using namespace cnc::proptest;

// The properties a result violates, each with its measured value and line.
std::vector<std::pair<std::string, Worst>> failing(const Result& r) {
  std::vector<std::pair<std::string, Worst>> f;
  if (!r.error.empty()) f.push_back({"refused", Worst{}});
  if (!r.error.empty()) return f;
  if (!r.done) f.push_back({"unfinished", Worst{1, r.stuck_line, -1}});
  if (r.nonfinite > 0) f.push_back({"non-finite", Worst{static_cast<double>(r.nonfinite), 0, -1}});
  if (r.travel_mm.value > 0) f.push_back({"travel", r.travel_mm});
  if (r.vel.value > 1.01) f.push_back({"velocity", r.vel});
  if (r.acc.value > 1.01) f.push_back({"acceleration", r.acc});
  if (r.jerk.value > 1.01) f.push_back({"jerk", r.jerk});
  if (r.chord.value > 1.01) f.push_back({"chord", r.chord});
  if (r.off_curve_mm.value > 1e-6) f.push_back({"off-curve", r.off_curve_mm});
  if (!(r.end_mm <= 1e-9)) f.push_back({"end-point", Worst{r.end_mm, 0, -1}});
  return f;
}

std::string head(const V3& p) {
  return "G21 G90 G91.1 G17 G94\nG0 X" + fmt(p[0]) + " Y" + fmt(p[1]) + " Z" + fmt(p[2]) + "\n";
}

struct Found {
  int count = 0;
  double worst = 0;
  std::string repro;
  double repro_value = 0;
};

}  // namespace

int main(int argc, char** argv) {
  uint64_t seed = 1;
  double seconds = 10;
  uint32_t classes = kAllClasses;
  bool verbose = false;
  std::string program;  // --program FILE: check that program alone and print its figures
  std::string machine;  // --machine FILE: another machine than sim3 (its axes and path limits)
  CLI::App app{"the interpolator's randomized path property check, for as long as asked", "cnc-path-property"};
  cnc::util::cli::setup(app);
  app.add_option("--seed", seed, "the first program's seed")->type_name("N");
  app.add_option("--seconds", seconds, "how long to generate and check programs")->type_name("S");
  app.add_option("--classes", classes, "the program classes to generate, a bit mask (0x.. allowed)")->type_name("MASK");
  app.add_flag("--verbose", verbose, "every program's figures");
  app.add_option("--program", program, "check this program alone and print its figures")->type_name("FILE");
  app.add_option("--machine", machine, "the machine file (default: config/machines/sim3.yaml)")->type_name("FILE");
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  cnc::config::MachineConfig cfg;
  try {
    cfg = machine.empty() ? sim3() : cnc::config::load_machine_config(machine);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-path-property: %s\n", e.what());
    return 2;
  }
  if (!program.empty()) {
    std::FILE* f = std::fopen(program.c_str(), "r");
    if (f == nullptr) {
      std::fprintf(stderr, "cnc-path-property: cannot read %s\n", program.c_str());
      return 2;
    }
    std::string text;
    char buf[4096];
    for (size_t n; (n = std::fread(buf, 1, sizeof buf, f)) > 0;) text.append(buf, n);
    std::fclose(f);
    // The end point is not known here: the check's end figure is left out.
    const Result r = run_and_check(cfg, text, V3{0, 0, 0}, 15'000'000);
    std::printf("%s: %s, %" PRId64 " setpoints; peak use of the limits: velocity %.4g, acceleration %.4g, jerk %.4g; "
                "chord error %.4g of the tolerance (%" PRId64 " steps); off curve %.3g mm; %" PRId64
                " non-finite, %.3g mm outside the travel\n",
                program.c_str(), !r.error.empty() ? r.error.c_str() : r.done ? "finished" : "did not finish",
                r.setpoints, r.vel.value, r.acc.value, r.jerk.value, r.chord.value, r.chord_steps,
                r.off_curve_mm.value, r.nonfinite, r.travel_mm.value);
    return r.done && r.error.empty() ? 0 : 1;
  }
  Generator gen(seed, classes);
  const auto t0 = std::chrono::steady_clock::now();
  int64_t programs = 0, setpoints = 0, checks = 0, chord_steps = 0, bad = 0;
  std::map<std::string, Found> found;
  while (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < seconds) {
    const Program p = gen.program();
    const Result r = run_and_check(cfg, p.text, p.end, p.max_cycles);
    ++programs;
    setpoints += r.setpoints;
    checks += r.checks;
    chord_steps += r.chord_steps;
    const auto f = failing(r);
    if (f.empty()) continue;
    ++bad;
    if (verbose)
      std::printf("program %" PRId64 " (%s): %s\n", programs, class_names(p.classes).c_str(), violations(r).c_str());
    for (const auto& [prop, w] : f) {
      // The piece the worst value is in.
      const Piece* pc = nullptr;
      for (const Piece& x : p.pieces)
        if (w.line >= x.first_line && w.line <= x.last_line) pc = &x;
      const std::string key = prop + " in " + (pc ? class_names(pc->classes) : std::string("(no piece)"));
      Found& fd = found[key];
      ++fd.count;
      fd.worst = std::max(fd.worst, w.value);
      // Shrink: the piece alone, then with the piece before it; else the program.
      std::string repro = p.text;
      double value = w.value;
      if (pc != nullptr) {
        const size_t k = static_cast<size_t>(pc - p.pieces.data());
        std::vector<std::string> tries{head(pc->start) + pc->text + "M2\n"};
        if (k > 0) tries.push_back(head(p.pieces[k - 1].start) + p.pieces[k - 1].text + pc->text + "M2\n");
        for (const std::string& t : tries) {
          const auto g = failing(run_and_check(cfg, t, pc->end, p.max_cycles));
          bool same = false;
          for (const auto& [prop2, w2] : g)
            if (prop2 == prop) same = true, value = w2.value;
          if (same) {
            repro = t;
            break;
          }
        }
      }
      if (fd.repro.empty() || repro.size() < fd.repro.size()) {
        fd.repro = repro;
        fd.repro_value = value;
      }
    }
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("seed %" PRIu64 ", %.1f s: %" PRId64 " programs, %" PRId64 " setpoints, %" PRId64
              " chord steps measured, %" PRId64 " property checks; %" PRId64 " programs with a violation\n",
              seed, wall, programs, setpoints, chord_steps, checks, bad);
  int n_found = 0;
  for (const auto& [key, fd] : found) {
    // A long reproducer goes to a file in the working folder instead of the terminal.
    std::string shown = fd.repro;
    if (fd.repro.size() >= 4000) {
      const std::string file = "cnc-path-property-" + std::to_string(++n_found) + ".ngc";
      if (std::FILE* f = std::fopen(file.c_str(), "w")) {
        std::fwrite(fd.repro.data(), 1, fd.repro.size(), f);
        std::fclose(f);
        shown = "(long: written to " + file + ")\n";
      } else {
        shown = "(long)\n";
      }
    }
    std::printf("\n== %s: %d programs, worst %.4g; smallest reproducer (%.4g, %zu bytes):\n%s", key.c_str(), fd.count,
                fd.worst, fd.repro_value, fd.repro.size(), shown.c_str());
  }
  return bad == 0 ? 0 : 1;
}
