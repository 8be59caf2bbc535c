// A randomized property test of the
// interpolator core. Random programs on sim3's travel (the generator and the checks:
// tests/unit/interpolator_property.h) run from G-code through the interpreter and the
// interpolator core, fed as the dry run feeds it; every program must give finite
// setpoints within the travel, per-axis velocity, acceleration and jerk (finite
// differences of the setpoints, T = the ipo period) within 1 % of the limits, a
// chord error on arcs and NURBS within the chord tolerance + 1 % measured against
// the exact curve, and a last setpoint on the program's end point within 1e-9 mm.
// The seed is fixed; tools/bench/path_property.cc (cnc-path-property --seed N
// --seconds S) runs the same generator for longer.
#include <gtest/gtest.h>

#include <cstdio>
#include <iomanip>

#include "tests/unit/interpolator_property.h"

namespace cnc::proptest {
namespace {

constexpr uint64_t kSeed = 20240613;
constexpr int kPrograms = 400;  // about 21 s of CPU on this VM
// Every class the generator has (NURBS G5.2/G6.2 with clustered and repeated knots,
// zero tangents, extreme weights; arcs in every plane, helices, ends off the radius;
// G1 micro-segments with and without G64 P; lines short and long). Long runs of
// cnc-path-property (--classes MASK shrinks each violation to a small program;
// --program FILE prints one program's figures): --seed 7 --seconds 60 --classes
// 0x1FFFF, 0 programs with a violation (was 2 of 557: jerk 2.08x on a G6.2 with
// clustered and repeated knots and a doubled start, 1.02x on a G5.2; before issue
// 13's fixes, --seed 1: 124 of 216, stalls, chord 446x, jerk 5711x); arcs (0xF600)
// --seed 5 --seconds 45: 1 of 2,554 programs, jerk 1.24x (a 3 um G19 arc between two
// arcs), not drawn by this seed.
constexpr uint32_t kClasses = kAllClasses;

TEST(InterpolatorProperty, RandomProgramsKeepEveryProperty) {
  const config::MachineConfig cfg = sim3();
  Generator gen(kSeed, kClasses);
  int64_t setpoints = 0, checks = 0, chord_steps = 0;
  uint32_t seen = 0;
  for (int i = 0; i < kPrograms; ++i) {
    const Program p = gen.program();
    seen |= p.classes;
    const Result r = run_and_check(cfg, p.text, p.end, p.max_cycles);
    setpoints += r.setpoints;
    checks += r.checks;
    chord_steps += r.chord_steps;
    const std::string v = violations(r);
    EXPECT_EQ(v, "") << "program " << i << " (" << class_names(p.classes) << "):\n" << p.text;
  }
  std::printf("  %d programs, %lld setpoints, %lld chord steps, %lld property checks; classes: %s\n", kPrograms,
              static_cast<long long>(setpoints), static_cast<long long>(chord_steps), static_cast<long long>(checks),
              class_names(seen).c_str());
  // The generator produced every class it was allowed.
  EXPECT_EQ(seen, kClasses) << class_names(kClasses & ~seen);
}

// The two programs cnc-path-property still found over the jerk limit before the
// planner's refinement closed in on point limits and took curvature jumps at knots
// (--seed 7 --seconds 60 --classes 0x1FFFF): a G6.2 with clustered and repeated
// knots and a doubled start (jerk 2.08x the limit: a corner-speed sample 2.6 mm from
// its neighbour, the line between them a slope the look-ahead did not see), and a
// degree-2 G5.2 (1.02x: its curvature jump at a knot smeared over a 0.29 mm interval).
TEST(InterpolatorProperty, NurbsFoundByLongRunsKeepTheJerkLimit) {
  const config::MachineConfig cfg = sim3();
  const std::string g6 =
      "G21 G90 G91.1 G17 G94\n"
      "G0 X174.659397 Y108.198002 Z-47.166536\n"
      "G6.2 P4 K0.000000 X174.659397 Y108.198002 Z-47.166536 R1.000000 F4507\n"
      "K0.000000 X174.659397 Y108.198002 Z-47.166536 R1.000000\n"
      "K0.000000 X185.203764 Y111.991296 Z-52.691048 R1.000000\n"
      "K0.000000 X172.980765 Y117.767062 Z-45.586669 R1.000000\n"
      "K0.394569 X173.479687 Y131.464317 Z-56.786618 R1.000000\n"
      "K0.395569 X166.782012 Y129.556585 Z-57.717520 R1.000000\n"
      "K0.395569 X179.052682 Y123.377619 Z-50.396959 R1.000000\n"
      "K0.395569 X167.735116 Y139.272324 Z-60.758051 R1.000000\n"
      "K1.000000\n"
      "K1.000000\n"
      "K1.000000\n"
      "K1.000000\n"
      "M2\n";
  const std::string g5 =
      "G21 G90 G91.1 G17 G94\n"
      "G0 X168.885264 Y259.364060 Z-66.611716\n"
      "G17 F3161\n"
      "G5.2 X168.965253 Y260.576049 P1.000000 L3\n"
      "X172.270337 Y267.680618 P1.000000\n"
      "X165.852938 Y275.393082 P1.000000\n"
      "X169.277478 Y280.781134 P1.000000\n"
      "X164.370993 Y280.689656 P1.000000\n"
      "X174.664441 Y288.289013 P1.000000\n"
      "X171.264437 Y289.084073 P1.000000\n"
      "X172.045335 Y295.000000 P1.000000\n"
      "G5.3\n"
      "M2\n";
  const Result r6 = run_and_check(cfg, g6, V3{167.735116, 139.272324, -60.758051}, 100000);
  EXPECT_EQ(violations(r6), "");
  EXPECT_LE(r6.jerk.value, 1.01);
  const Result r5 = run_and_check(cfg, g5, V3{172.045335, 295.0, -66.611716}, 100000);
  EXPECT_EQ(violations(r5), "");
  EXPECT_LE(r5.jerk.value, 1.01);
}

// Found by a 60 s run of seed 7 (program 1,0xx): a G5.2 with weights from 0.05 to 17.5
// has a near-cusp of radius ~1e-9 mm. The circle's chord formula gives a step of 2ρ
// there, so the path crawled at 3e-7 mm/s and the program never finished (a machine
// standing still with its program running). A step of arc length 2ε never leaves its
// chord by more than ε: the chord limit's floor.
TEST(InterpolatorProperty, AnExtremeWeightNearCuspDoesNotStallTheProgram) {
  const config::MachineConfig cfg = sim3();
  const std::string g5 =
      "G21 G90 G91.1 G17 G94\n"
      "G0 X238.487209 Y294.999549 Z-144.999458\n"
      "G17 F4316\n"
      "G5.2 X230.272426 Y295.000000 P7.537042 L4\n"
      "X238.408318 Y295.000000 P0.799587\n"
      "X214.955385 Y295.000000 P0.050000\n"
      "X224.635180 Y291.958053 P0.050000\n"
      "X204.708154 Y295.000000 P2.456023\n"
      "X216.056647 Y295.000000 P0.053852\n"
      "X227.374410 Y295.000000 P10.369841\n"
      "X214.772881 Y295.000000 P17.546620\n"
      "X189.115699 Y295.000000 P7.064191\n"
      "G5.3\n"
      "M2\n";
  // Before: not done after 15 million cycles (16.7 hours). Now: 1,722 setpoints.
  const Result r = run_and_check(cfg, g5, V3{189.115699, 295.0, -144.999458}, 20000);
  EXPECT_TRUE(r.done) << "stuck on line " << r.stuck_line;
  EXPECT_EQ(violations(r), "");
  EXPECT_LE(r.chord.value, 1.0);
  EXPECT_LE(r.jerk.value, 1.0 + 1e-9) << std::setprecision(12) << r.jerk.value;
}

// Found on the G61 raster of the micro-segment bench once lines between two stops ran
// with free limits: the brake check looked as far as the front block's brake needs.
// With a free block in front (0.97 of the axes' jerk; here on the second pass) the
// stop at the program's end came into the check too late for the brake of the lines
// before it (half the limits): acceleration 1.72x and jerk 19x the limits there. The
// horizon is now the brake distance with the least limits up to the next stop point.
TEST(InterpolatorProperty, AStopBehindBlocksOfLowerLimitsIsSeenInTime) {
  const config::MachineConfig cfg = sim3();
  std::string prog = "G21 G17 G90 G61\nG0 X14.200 Y17 Z-8.0\nF3000\n";
  const double z0[] = {-8.135, -8.163, -8.192, -8.222, -8.253, -8.284, -8.316,
                       -8.348, -8.382, -8.416, -8.450, -8.485, -8.521, -8.558};
  const double z1[] = {-8.570, -8.536, -8.502, -8.468, -8.435, -8.403, -8.372, -8.341, -8.311, -8.281, -8.252};
  char buf[96];
  for (int i = 0; i < 14; ++i) {  // 0.3 mm steps from X13.9 to X10, rounded to 3 decimals as a post writes them
    std::snprintf(buf, sizeof buf, "G1 X%.3f Y17.000 Z%.3f\n", 13.9 - 0.3 * i, z0[i]);
    prog += buf;
  }
  prog += "G1 X10.000 Y18.000 Z-8.605\n";  // the 1 mm step-over: a stop at either end
  for (int i = 0; i < 11; ++i) {
    std::snprintf(buf, sizeof buf, "G1 X%.3f Y18.000 Z%.3f\n", 10.3 + 0.3 * i, z1[i]);
    prog += buf;
  }
  prog += "M2\n";
  const Result r = run_and_check(cfg, prog, V3{13.3, 18.0, -8.252}, 20000);
  EXPECT_TRUE(r.done) << "stuck on line " << r.stuck_line;
  EXPECT_EQ(violations(r), "");
  EXPECT_LE(r.jerk.value, 1.0);
  EXPECT_LE(r.acc.value, 1.0);
}

}  // namespace
}  // namespace cnc::proptest
