// G76, LinuxCNC's threading cycle: its canonical calls as LinuxCNC 2.9's rs274 prints
// them, its refusals (message and column), M19's orientation offset and checks, and
// the blocks the block builder makes of G76 (spindle-synchronised lines with their
// pitch in mm, the rapids between them, the feed override off while synchronised).
// The expected calls are the lines rs274 printed for each program's N900 block,
// without its call counter, run as
//   HOME=$(mktemp -d) rs274 -g PROGRAM OUT
// on Debian 12's linuxcnc-uspace 2.9.0~pre1+git20230208.f1270d6ed7.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "common/program/block.h"
#include "common/rs274/canon_printer.h"
#include "common/rs274/interpreter.h"
#include "tests/unit/program_test_util.h"

namespace cnc {
namespace {

using program::Block;
using program::BlockKind;
using program::EventKind;

rs274::MachineSetup encoder_setup() {
  rs274::MachineSetup s;
  s.spindle_sync = true;
  return s;
}

// The program's output as cnc-rs274 prints it (rs274's format).
std::string printed(const std::string& text, const rs274::MachineSetup& setup = encoder_setup()) {
  test::TempDir dir;
  const std::string path = dir.write("main.ngc", text);
  char* buf = nullptr;
  size_t len = 0;
  std::FILE* f = ::open_memstream(&buf, &len);
  {
    std::unique_ptr<rs274::Interpreter> in;
    rs274::CanonPrinter printer(f, [&in]() -> const std::string& { return in->current_text(); });
    in = std::make_unique<rs274::Interpreter>(setup, printer);
    in->open(path);
    while (in->execute_next()) {
    }
  }
  std::fclose(f);
  std::string out(buf, len);
  std::free(buf);
  return out;
}

// The calls of the N900 block, one per line, without the counter and the N field.
std::string block_900(const std::string& printed_text) {
  std::istringstream in(printed_text);
  std::string line, out;
  while (std::getline(in, line)) {
    const size_t n = line.find(" N900 ");
    if (n == std::string::npos) continue;
    out += line.substr(line.find_first_not_of(' ', n + 6));
    out += '\n';
  }
  return out;
}

// An external thread (I < 0) in mm with tapered entry and exit (E2 L3), the
// compound angle Q, one spring pass (H1), constant depth per pass (no R).
TEST(Rs274Threading, ExternalThreadWithTapersAndASpringPassAsRs274PrintsIt) {
  const std::string got =
      block_900(printed("G21 G18 S500 M3\nG0 X10 Z5\nN900 G76 P1.5 Z-10 I-1 J0.4 K1 Q29.5 H1 E2 L3\nM2\n"));
  std::string pass_at_full_depth =
      "STRAIGHT_TRAVERSE(10.0000, 0.0000, 4.4342, 0.0000, 0.0000, 0.0000)\n"
      "DISABLE_FEED_OVERRIDE()\n"
      "START_SPEED_FEED_SYNC(1.677051,0)\n"
      "STRAIGHT_FEED(9.0000, 0.0000, 4.4342, 0.0000, 0.0000, 0.0000)\n"
      "STRAIGHT_FEED(8.0000, 0.0000, 2.4342, 0.0000, 0.0000, 0.0000)\n"
      "START_SPEED_FEED_SYNC(1.500000,0)\n"
      "STRAIGHT_FEED(8.0000, 0.0000, -8.0000, 0.0000, 0.0000, 0.0000)\n"
      "START_SPEED_FEED_SYNC(1.677051,0)\n"
      "STRAIGHT_FEED(9.0000, 0.0000, -10.0000, 0.0000, 0.0000, 0.0000)\n"
      "STOP_SPEED_FEED_SYNCH()\n"
      "STRAIGHT_TRAVERSE(10.0000, 0.0000, -10.0000, 0.0000, 0.0000, 0.0000)\n"
      "ENABLE_FEED_OVERRIDE()\n";
  const std::string want =
      "STRAIGHT_TRAVERSE(10.6000, 0.0000, 4.7737, 0.0000, 0.0000, 0.0000)\n"
      "DISABLE_FEED_OVERRIDE()\n"
      "START_SPEED_FEED_SYNC(1.677051,0)\n"
      "STRAIGHT_FEED(9.6000, 0.0000, 4.7737, 0.0000, 0.0000, 0.0000)\n"
      "STRAIGHT_FEED(8.6000, 0.0000, 2.7737, 0.0000, 0.0000, 0.0000)\n"
      "START_SPEED_FEED_SYNC(1.500000,0)\n"
      "STRAIGHT_FEED(8.6000, 0.0000, -7.6605, 0.0000, 0.0000, 0.0000)\n"
      "START_SPEED_FEED_SYNC(1.677051,0)\n"
      "STRAIGHT_FEED(9.6000, 0.0000, -9.6605, 0.0000, 0.0000, 0.0000)\n"
      "STOP_SPEED_FEED_SYNCH()\n"
      "STRAIGHT_TRAVERSE(10.6000, 0.0000, -9.6605, 0.0000, 0.0000, 0.0000)\n"
      "ENABLE_FEED_OVERRIDE()\n"
      "STRAIGHT_TRAVERSE(10.2000, 0.0000, 4.5474, 0.0000, 0.0000, 0.0000)\n"
      "DISABLE_FEED_OVERRIDE()\n"
      "START_SPEED_FEED_SYNC(1.677051,0)\n"
      "STRAIGHT_FEED(9.2000, 0.0000, 4.5474, 0.0000, 0.0000, 0.0000)\n"
      "STRAIGHT_FEED(8.2000, 0.0000, 2.5474, 0.0000, 0.0000, 0.0000)\n"
      "START_SPEED_FEED_SYNC(1.500000,0)\n"
      "STRAIGHT_FEED(8.2000, 0.0000, -7.8868, 0.0000, 0.0000, 0.0000)\n"
      "START_SPEED_FEED_SYNC(1.677051,0)\n"
      "STRAIGHT_FEED(9.2000, 0.0000, -9.8868, 0.0000, 0.0000, 0.0000)\n"
      "STOP_SPEED_FEED_SYNCH()\n"
      "STRAIGHT_TRAVERSE(10.2000, 0.0000, -9.8868, 0.0000, 0.0000, 0.0000)\n"
      "ENABLE_FEED_OVERRIDE()\n" +
      pass_at_full_depth + pass_at_full_depth +  // the last cut and its spring pass
      "STRAIGHT_TRAVERSE(10.0000, 0.0000, -10.0000, 0.0000, 0.0000, 0.0000)\n";
  EXPECT_EQ(got, want);
}

// A boring thread (I > 0) in inches cut towards +Z (the compound angle and the taper
// turn round), degression R2, entry taper only (L1), and H-1: LinuxCNC's loop then
// makes no pass at the full depth at all.
TEST(Rs274Threading, BoringThreadTowardsPlusZWithDegressionAndNoFinalPass) {
  const std::string got =
      block_900(printed("G20 S800 M4\nG0 X.5 Z-1\nN900 G76 P.05 Z.2 I.02 J.01 K.02 R2 Q30 E.1 L1 H-1\nM2\n"));
  const std::string want =
      "STRAIGHT_TRAVERSE(0.4900, 0.0000, -0.9942, 0.0000, 0.0000, 0.0000)\n"
      "DISABLE_FEED_OVERRIDE()\n"
      "START_SPEED_FEED_SYNC(0.050990,0)\n"
      "STRAIGHT_FEED(0.5100, 0.0000, -0.9942, 0.0000, 0.0000, 0.0000)\n"
      "STRAIGHT_FEED(0.5300, 0.0000, -0.8942, 0.0000, 0.0000, 0.0000)\n"
      "START_SPEED_FEED_SYNC(0.050000,0)\n"
      "STRAIGHT_FEED(0.5300, 0.0000, 0.1942, 0.0000, 0.0000, 0.0000)\n"
      "STOP_SPEED_FEED_SYNCH()\n"
      "STRAIGHT_TRAVERSE(0.4900, 0.0000, 0.1942, 0.0000, 0.0000, 0.0000)\n"
      "ENABLE_FEED_OVERRIDE()\n"
      "STRAIGHT_TRAVERSE(0.4941, 0.0000, -0.9918, 0.0000, 0.0000, 0.0000)\n"
      "DISABLE_FEED_OVERRIDE()\n"
      "START_SPEED_FEED_SYNC(0.050990,0)\n"
      "STRAIGHT_FEED(0.5141, 0.0000, -0.9918, 0.0000, 0.0000, 0.0000)\n"
      "STRAIGHT_FEED(0.5341, 0.0000, -0.8918, 0.0000, 0.0000, 0.0000)\n"
      "START_SPEED_FEED_SYNC(0.050000,0)\n"
      "STRAIGHT_FEED(0.5341, 0.0000, 0.1966, 0.0000, 0.0000, 0.0000)\n"
      "STOP_SPEED_FEED_SYNCH()\n"
      "STRAIGHT_TRAVERSE(0.4941, 0.0000, 0.1966, 0.0000, 0.0000, 0.0000)\n"
      "ENABLE_FEED_OVERRIDE()\n"
      "STRAIGHT_TRAVERSE(0.4973, 0.0000, -0.9900, 0.0000, 0.0000, 0.0000)\n"
      "DISABLE_FEED_OVERRIDE()\n"
      "START_SPEED_FEED_SYNC(0.050990,0)\n"
      "STRAIGHT_FEED(0.5173, 0.0000, -0.9900, 0.0000, 0.0000, 0.0000)\n"
      "STRAIGHT_FEED(0.5373, 0.0000, -0.8900, 0.0000, 0.0000, 0.0000)\n"
      "START_SPEED_FEED_SYNC(0.050000,0)\n"
      "STRAIGHT_FEED(0.5373, 0.0000, 0.1985, 0.0000, 0.0000, 0.0000)\n"
      "STOP_SPEED_FEED_SYNCH()\n"
      "STRAIGHT_TRAVERSE(0.4973, 0.0000, 0.1985, 0.0000, 0.0000, 0.0000)\n"
      "ENABLE_FEED_OVERRIDE()\n"
      "STRAIGHT_TRAVERSE(0.5000, 0.0000, 0.2000, 0.0000, 0.0000, 0.0000)\n";
  EXPECT_EQ(got, want);
}

// G76 is modal: a later line with axis words threads again, and needs its words again.
TEST(Rs274Threading, TheMotionModeStaysG76) {
  const std::string two = printed("G21 S500 M3\nG0 X10 Z5\nG76 P1 Z-5 I-1 J.5 K1\nN900 Z-8 P1 I-1 J.5 K1\nM2\n");
  EXPECT_NE(block_900(two).find("STRAIGHT_FEED(8.0000, 0.0000, -8.0000"), std::string::npos) << two;
}

// G7 (lathe diameter mode): X words are diameters, and so are G76's I J K. A G7 on the
// G76's own line halves them once more (LinuxCNC scales the block's words to the new
// mode, then the cycle halves them again): both programs cut the same thread.
TEST(Rs274Threading, InDiameterModeIJKAreDiameters) {
  const std::string g7_before = block_900(printed("G21 S500 M3 G18\nG7 G0 X20 Z5\nN900 G76 P1.5 Z-20 I-2 J0.8 K2\nM2\n"));
  std::string g7_on_the_line = block_900(printed("G21 S500 M3 G18\nG0 X10 Z5\nN900 G7 G76 P1.5 Z-20 I-4 J1.6 K4\nM2\n"));
  const std::string comment = "COMMENT(\"interpreter: Lathe diameter mode changed to diameter\")\n";
  ASSERT_EQ(g7_on_the_line.rfind(comment, 0), 0u) << g7_on_the_line;
  g7_on_the_line.erase(0, comment.size());
  EXPECT_EQ(g7_before, g7_on_the_line);
  EXPECT_EQ(g7_before.substr(0, g7_before.find("DISABLE")),
            "STRAIGHT_TRAVERSE(10.6000, 0.0000, 5.0000, 0.0000, 0.0000, 0.0000)\n"
            "STRAIGHT_TRAVERSE(8.6000, 0.0000, 5.0000, 0.0000, 0.0000, 0.0000)\n");
}

TEST(Rs274Threading, DiameterModeHalvesXWordsAsRead) {
  const std::string got = block_900(printed(
      "G21\nN900 G7 G0 X10\nN900 G8 X10\nN900 G7\nN900 X4 Z1\n"
      "N900 (debug, #<_lathe_diameter_mode> #<_lathe_radius_mode> #<_x>)\nM2\n"));
  EXPECT_EQ(got,
            "COMMENT(\"interpreter: Lathe diameter mode changed to diameter\")\n"
            "STRAIGHT_TRAVERSE(5.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000)\n"
            "COMMENT(\"interpreter: Lathe diameter mode changed to radius\")\n"
            "STRAIGHT_TRAVERSE(10.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000)\n"
            "COMMENT(\"interpreter: Lathe diameter mode changed to diameter\")\n"
            "STRAIGHT_TRAVERSE(2.0000, 0.0000, 1.0000, 0.0000, 0.0000, 0.0000)\n"
            "MESSAGE(\" 1.000000 0.000000 2.000000\")\n");
}

// ---- refusals ---------------------------------------------------------------------------

// `line` follows the lines `before` and is refused at the word `at` (its column; the
// line's first column when `at` is empty) with `detail`.
void expect_refused(const std::string& before, const std::string& line, const std::string& at, const std::string& detail,
                    const rs274::MachineSetup& setup = encoder_setup()) {
  const std::string text = before + line + "\nM2\n";
  const int line_no = static_cast<int>(std::count(before.begin(), before.end(), '\n')) + 1;
  const int column = at.empty() ? 1 : static_cast<int>(line.find(at)) + 1;
  ASSERT_TRUE(at.empty() || line.find(at) != std::string::npos) << at;
  try {
    printed(text, setup);
    ADD_FAILURE() << "accepted:\n" << text;
  } catch (const rs274::Error& e) {
    EXPECT_EQ(e.where().line, line_no) << e.what();
    EXPECT_EQ(e.where().column, column) << e.what();
    EXPECT_EQ(e.detail(), detail) << text;
  }
}

const std::string kTurning = "G21 S500 M3\nG0 X10 Z5\n";

TEST(Rs274ThreadingError, LinuxCncsChecksWithTheirMessages) {
  const std::string& t = kTurning;
  // The block's words (LinuxCNC's enhance_block and check_other_codes).
  expect_refused(t, "G76 P1 I-1 J.2 K1", "", "All axes missing with motion code");
  expect_refused(t, "G76 Z-5 I-1 J.2 K1", "", "P word missing with G76");
  expect_refused(t, "G76 P-1 Z-5 I-1 J.2 K1", "", "P word missing with G76");  // LinuxCNC's mark of no P
  expect_refused(t, "G76 P1 Z-5 J.2 K1", "", "I J or K words missing with G76");
  expect_refused(t, "G76 P1 Z-5 I-1 K1", "", "I J or K words missing with G76");
  expect_refused(t, "G76 P1 Z-5 I-1 J.2", "", "I J or K words missing with G76");
  expect_refused(t + "G76 P1 Z-5 I-1 J.2 K1\n", "Z-8", "", "P word missing with G76");  // G76 stays the mode
  // H and L are integers (LinuxCNC reads them so for every code).
  expect_refused(t, "G76 P1 Z-5 I-1 J.2 K1 H1.5", "H1.5", "Non integer value for integer");
  expect_refused(t, "G76 P1 Z-5 I-1 J.2 K1 H-2", "H-2", "Negative h word used");
  expect_refused(t, "G76 P1 Z-5 I-1 J.2 K1 E1 L2.5", "L2.5", "Non integer value for integer");
  expect_refused(t, "G76 P1 Z-5 I-1 J.2 K1 L-1", "L-1", "Negative l word used");
  // The cycle's own (convert_straight, convert_threading_cycle), in LinuxCNC's order.
  expect_refused("G21 G0 X10 Z5\n", "G76 P1 Z-5 I-1 J.2 K1", "", "Chosen spindle (0) not turning in G76");
  expect_refused(t, "G76 P1 Z-5 I-1 J.2 K1 $1", "$1", "Invalid D-number in G76 cycle");
  expect_refused(t, "G76 P1 Z-5 I0 J.2 K1", "I0", "In G76, I must not be 0");
  expect_refused(t, "G76 P1 Z-5 I-1 J0 K1", "J0", "In G76, J must be greater than 0");
  expect_refused(t, "G76 P1 Z-5 I-1 J-.2 K1", "J-.2", "In G76, J must be greater than 0");
  expect_refused(t, "G76 P1 Z-5 I-1 J.2 K.2", "K.2", "In G76, K must be greater than J");
  expect_refused(t + "G18 G41.1 D0 G0 X12\n", "G76 P1 Z-5 I-1 J.2 K1", "",
                 "Cannot use G76 threading cycle with cutter radius compensation on");
  expect_refused(t, "G76 P1 Z-5 I-1 J.2 K1 G53", "G53", "G53 is only allowed with G0 or G1");
}

TEST(Rs274ThreadingError, RotaryAxesStay) {
  rs274::MachineSetup s = encoder_setup();
  s.axes = "XYZA";
  expect_refused(kTurning, "G76 P1 Z-5 I-1 J.2 K1 A10", "A10", "Cannot move rotary axes with G76", s);
  EXPECT_NO_THROW(printed(kTurning + "G76 P1 Z-5 I-1 J.2 K1 A0\nM2\n", s));  // A where it is
}

// Where this controller refuses what LinuxCNC runs: a pitch that never advances, and a
// cycle of passes without end (LinuxCNC would print 10^9 passes for this J, K and R).
TEST(Rs274ThreadingError, PitchAndPassCountAreBounded) {
  const std::string& t = kTurning;
  expect_refused(t, "G76 P0 Z-5 I-1 J.2 K1", "P0", "P (pitch) must be > 0 with G76");
  expect_refused(t, "G76 P1 Z-5 I-1 J.001 K1 R3", "J.001",
                 "G76 would make more than 10000 passes (J too small for K, or R too large)");
  expect_refused(t, "G76 P1 Z-5 I-1 J.2 K1 H10000", "H10000", "G76 would make more than 10000 passes (H spring passes)");
  EXPECT_NO_THROW(printed(t + "G76 P1 Z-5 I-1 J.2 K1 H9990\nM2\n"));
}

TEST(Rs274ThreadingError, AMachineWithoutASpindleEncoderRefusesItNamingTheKey) {
  expect_refused(kTurning, "G76 P1 Z-5 I-1 J.2 K1", "",
                 "G76 needs a spindle whose position the machine measures (spindle.encoder_counts_per_rev)",
                 rs274::MachineSetup{});
}

// G76's words: H is its spring passes (not a tool length offset's H), and I J K R Q
// E L $ are its own; without G76 (or G43) the same words are refused.
TEST(Rs274ThreadingError, ItsWordsBelongToIt) {
  const std::string& t = kTurning;
  EXPECT_NO_THROW(printed(t + "G76 P1 Z-5 I-1 J.2 K1 H2 R1.5 Q29.5 E1 L3 $0\nM2\n"));
  expect_refused(t, "G1 Z-5 F100 H2", "H2", "H word with no G43 or G76 that uses it");
  expect_refused(t, "G1 Z-5 F100 E2", "E2", "E word with no G76 or M code that uses it (M66, M67, M68)");
  expect_refused(t, "G0 Z-5 $0", "$0",
                 "$ (spindle selection) word with no M3, M4, M5, M19, M51, G33, G33.1, G76, G95, G96 or G97 to use it");
  // A line without axis words makes no G76 move (LinuxCNC's motion_to_be): P is unused.
  expect_refused(t + "G76 P1 Z-5 I-1 J.2 K1\n", "P1", "P1", "P word with no G code or M code that uses it");
}

// ---- M19, the orientation a spindle with an encoder also has -----------------------------

// LinuxCNC's tests/interp/m19 (its INI sets [RS274NGC]ORIENT_OFFSET = 42): R is from
// that offset; neither R nor P orients nothing; Q waits.
TEST(Rs274Orientation, LinuxCncsM19TestWithItsOrientOffset) {
  rs274::MachineSetup s = encoder_setup();
  s.orient_offset_deg = 42;
  const std::string out = printed("M19\nM19 R45 Q2\nM19 P1\nM19 R90 P0\nM19 R90 P1\nM19 Q1\n\nM2\n", s);
  std::string got;
  std::istringstream in(out);
  for (std::string line; std::getline(in, line);)
    if (line.find("ORIENT") != std::string::npos) got += line.substr(line.find_first_not_of(' ', line.find(" N") + 7)) + '\n';
  EXPECT_EQ(got,
            "ORIENT_SPINDLE(0, 87.0000, 0)\n"
            "SPINDLE.0.WAIT_ORIENT_COMPLETE(2.0000)\n"
            "ORIENT_SPINDLE(0, 42.0000, 1)\n"
            "ORIENT_SPINDLE(0, 132.0000, 0)\n"
            "ORIENT_SPINDLE(0, 132.0000, 1)\n"
            "SPINDLE.0.WAIT_ORIENT_COMPLETE(1.0000)\n");
}

TEST(Rs274Orientation, LinuxCncsChecksOfRAndP) {
  expect_refused("", "M19 R400", "R400", "R value must be within 0..360 with M19");
  expect_refused("", "M19 R-1", "R-1", "R value must be within 0..360 with M19");
  expect_refused("", "M19 P1.5", "P1.5", "P value not an integer with M19 G2 or G3");
  expect_refused("", "M19 P3", "P3", "P value must be 0,1,or 2 with M19");
  expect_refused("", "M19 R10 $1", "$1", "Spindle ($) number out of range in M19 Command");
}

// ---- blocks -------------------------------------------------------------------------------

pps::ProgramSetup encoder_program_setup() {
  pps::ProgramSetup s = test::xyz_setup();
  s.machine.spindle_sync = s.builder.spindle_sync = true;
  return s;
}

std::vector<Block> blocks_of(const std::string& text, const pps::ProgramSetup& s = encoder_program_setup()) {
  test::TempDir dir;
  return test::run_program(dir.write("t.ngc", text), s);
}

// The inch program of BoringThreadTowardsPlusZWithDegressionAndNoFinalPass: its
// passes become rapids and synchronised lines in mm, the pitch of each line in mm
// per revolution (the entry taper's longer pitch on its two lines), the feed override
// off from before the first synchronised line to after the last rapid out.
TEST(Rs274ThreadingBlocks, PassesBecomeSynchronisedLinesWithThePitchInMm) {
  const std::vector<Block> all = blocks_of("G20 S800 M4\nG0 X.5 Z-1\nG76 P.05 Z.2 I.02 J.01 K.02 R2 Q30 E.1 L1 H-1\nM2\n");
  constexpr double kIn = 25.4, kTol = 1e-4 * kIn;  // rs274's 4 decimals, in mm
  const double pitch_mm = 0.05 * kIn;
  const double taper_pitch_mm = 0.05 * std::hypot(0.1, 0.02) / 0.1 * kIn;  // rs274: 0.050990 in
  struct Want {
    BlockKind kind;
    double x_in, z_in;
    double pitch_mm;  // 0: not synchronised
  };
  // Per pass: back (rapid), the two taper lines, the thread, out (rapid).
  const double passes[3][4] = {{0.4900, 0.5100, 0.5300, -0.9942}, {0.4941, 0.5141, 0.5341, -0.9918},
                               {0.4973, 0.5173, 0.5373, -0.9900}};
  const double thread_end_z[3] = {0.1942, 0.1966, 0.1985};
  std::vector<Want> want;
  for (int i = 0; i < 3; ++i) {
    const double* p = passes[i];
    want.push_back({BlockKind::kRapid, p[0], p[3], 0});
    want.push_back({BlockKind::kLine, p[1], p[3], taper_pitch_mm});
    want.push_back({BlockKind::kLine, p[2], p[3] + 0.1, taper_pitch_mm});
    want.push_back({BlockKind::kLine, p[2], thread_end_z[i], pitch_mm});
    want.push_back({BlockKind::kRapid, p[0], thread_end_z[i], 0});
  }
  want.push_back({BlockKind::kRapid, 0.5, 0.2, 0});  // to the block's end point
  // The G76 line's blocks: after the G0 to the start.
  size_t at = 0;
  while (at < all.size() && all[at].source_line != 3) ++at;
  std::vector<Block> moves;
  int overrides_off = 0, overrides_on = 0;
  bool synced_with_override_on = false, override_on = true;
  for (size_t i = at; i < all.size() && all[i].source_line == 3; ++i) {
    const Block& b = all[i];
    if (b.kind == BlockKind::kEvent) {
      ASSERT_EQ(b.event.kind, EventKind::kOverrides);
      override_on = (b.event.number & 1) != 0;
      (override_on ? overrides_on : overrides_off)++;
      continue;
    }
    if (b.kind == BlockKind::kLine && override_on) synced_with_override_on = true;
    moves.push_back(b);
  }
  EXPECT_EQ(overrides_off, 3);
  EXPECT_EQ(overrides_on, 3);
  EXPECT_FALSE(synced_with_override_on);
  ASSERT_EQ(moves.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) {
    const Block& b = moves[i];
    SCOPED_TRACE("block " + std::to_string(i));
    EXPECT_EQ(b.kind, want[i].kind);
    EXPECT_NEAR(b.end[0], want[i].x_in * kIn, kTol);
    EXPECT_NEAR(b.end[1], 0.0, 1e-12);
    EXPECT_NEAR(b.end[2], want[i].z_in * kIn, kTol);
    if (want[i].pitch_mm > 0) {
      EXPECT_EQ(b.sync, program::kSyncG33);
      EXPECT_NEAR(b.sync_pitch_mm, want[i].pitch_mm, 1e-9);
      EXPECT_NEAR(b.feed_mm_per_min, want[i].pitch_mm * 800, 1e-6);  // pitch x S: the dry run's rate
      EXPECT_DOUBLE_EQ(b.spindle_rpm, 800);
    } else {
      EXPECT_EQ(b.sync, program::kSyncNone);
    }
    if (i > 0) {
      for (size_t a = 0; a < 3; ++a) EXPECT_DOUBLE_EQ(b.start[a], moves[i - 1].end[a]);  // one path, no gap
    }
  }
}

TEST(Rs274ThreadingBlocks, TheSpindleMustTurnAtASpeed) {
  // rs274 runs it; the block builder has no rate to follow with S0.
  try {
    blocks_of("G21 S0 M3\nG0 X10 Z5\nG76 P1 Z-5 I-1 J.5 K1\nM2\n");
    ADD_FAILURE() << "accepted";
  } catch (const rs274::Error& e) {
    EXPECT_EQ(e.where().line, 3);
    EXPECT_NE(e.detail().find("spindle stopped"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace cnc
