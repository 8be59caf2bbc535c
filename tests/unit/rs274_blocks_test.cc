// Part programs through the RS274NGC interpreter and the block builder: the blocks
// the interpolator gets (machine coordinates in mm, kinds, arc centres, NURBS,
// feeds in mm/min, spindle, process parameters, event blocks) and the refusals,
// each at its file:line:column. The tests of the old parser (GcodeParser) live on
// here; where LinuxCNC (rs274, the oracle) behaves differently from the old parser
// the test follows LinuxCNC and says so.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "common/program/block.h"
#include "common/program/block_msg.h"
#include "common/motion/path_segment.h"
#include "services/part_program_server/program_server.h"
#include "tests/unit/program_test_util.h"

namespace cnc::program {
namespace {

constexpr double kTol = 1e-9;  // mm; inch programs and R-form arcs go through a multiply or a sqrt

using Points = std::vector<std::array<double, 3>>;

// A test's program file: written to a temporary folder, run whole.
class Prog {
 public:
  explicit Prog(const std::string& text, const std::string& name = "t.ngc") : path_((dir_ / name).string()) {
    test::write_file(path_, text);
  }
  const std::string& path() const { return path_; }
  const test::TempDir& dir() const { return dir_; }

 private:
  test::TempDir dir_;
  std::string path_;
};

std::vector<Block> run(const std::string& text, const pps::ProgramSetup& s = test::xyz_setup()) {
  Prog p(text);
  return test::run_program(p.path(), s);
}

// The motion and dwell blocks only (what the old parser made), in order.
std::vector<Block> moves(const std::vector<Block>& all) {
  std::vector<Block> out;
  for (const Block& b : all)
    if (b.kind != BlockKind::kEvent && b.kind != BlockKind::kEnd) out.push_back(b);
  return out;
}

void expect_point(const std::vector<double>& p, double x, double y, double z, double tol = kTol) {
  ASSERT_EQ(p.size(), 3u);
  EXPECT_NEAR(p[0], x, tol);
  EXPECT_NEAR(p[1], y, tol);
  EXPECT_NEAR(p[2], z, tol);
}

void expect_points(const Points& got, const Points& want, double tol = kTol) {
  ASSERT_EQ(got.size(), want.size());
  for (size_t i = 0; i < got.size(); ++i)
    for (size_t a = 0; a < 3; ++a) EXPECT_NEAR(got[i][a], want[i][a], tol) << "control point " << i << " axis " << a;
}

void expect_values(const std::vector<double>& got, const std::vector<double>& want, double tol = kTol) {
  ASSERT_EQ(got.size(), want.size());
  for (size_t i = 0; i < got.size(); ++i) EXPECT_NEAR(got[i], want[i], tol) << "entry " << i;
}

// The last block ends the program where the last motion left the tool; indices run 0..n-1.
void expect_end_block(const std::vector<Block>& blocks, double x, double y, double z) {
  ASSERT_FALSE(blocks.empty());
  for (size_t i = 0; i < blocks.size(); ++i) EXPECT_EQ(blocks[i].index, static_cast<int64_t>(i));
  const Block& e = blocks.back();
  EXPECT_EQ(e.kind, BlockKind::kEnd);
  expect_point(e.start, x, y, z);
  expect_point(e.end, x, y, z);
}

void expect_error_at(const std::string& text, int line, int column, const std::string& detail,
                     const pps::ProgramSetup& s = test::xyz_setup()) {
  Prog p(text);
  try {
    test::run_program(p.path(), s);
    ADD_FAILURE() << "accepted:\n" << text;
  } catch (const rs274::Error& e) {
    EXPECT_EQ(e.file_name(), p.path());
    EXPECT_EQ(e.where().line, line) << e.what();
    EXPECT_EQ(e.where().column, column) << e.what();
    // "file:line:column: " ("file:line: " when the line as a whole is at fault).
    const std::string prefix =
        p.path() + ":" + std::to_string(line) + (column > 0 ? ":" + std::to_string(column) : std::string()) + ": ";
    const std::string what = e.what();
    EXPECT_EQ(what.rfind(prefix, 0), 0u) << what;
    EXPECT_NE(e.detail().find(detail), std::string::npos) << "'" << detail << "' not in: " << what;
  }
}

TEST(Rs274Blocks, RapidAndLinearMoves) {
  Prog prog("G0 X10 Y20\nG1 Z-5 F600\nX30\nM2\n");
  const std::vector<Block> p = test::run_program(prog.path());
  ASSERT_EQ(p.size(), 4u);
  const Block& b0 = p[0];
  EXPECT_EQ(b0.kind, BlockKind::kRapid);
  EXPECT_EQ(b0.source_line, 1);
  EXPECT_EQ(b0.source_column, 1);
  EXPECT_EQ(b0.source_file, prog.path());
  expect_point(b0.start, 0, 0, 0);
  expect_point(b0.end, 10, 20, 0);
  const Block& b1 = p[1];
  EXPECT_EQ(b1.kind, BlockKind::kLine);
  EXPECT_EQ(b1.source_line, 2);
  expect_point(b1.start, 10, 20, 0);
  expect_point(b1.end, 10, 20, -5);
  EXPECT_DOUBLE_EQ(b1.feed_mm_per_min, 600);
  const Block& b2 = p[2];  // G1 and F are modal
  EXPECT_EQ(b2.kind, BlockKind::kLine);
  expect_point(b2.start, 10, 20, -5);
  expect_point(b2.end, 30, 20, -5);
  EXPECT_DOUBLE_EQ(b2.feed_mm_per_min, 600);
  expect_end_block(p, 30, 20, -5);
  EXPECT_EQ(p[3].source_line, 4);  // the end block is M2's
}

TEST(Rs274Blocks, StartPositionFromTheSetup) {
  pps::ProgramSetup s = test::xyz_setup();
  s.builder.start_position_mm = {1, 2, 3};
  const std::vector<Block> p = run("G0 Z10\nM2\n", s);
  ASSERT_EQ(p.size(), 2u);
  expect_point(p[0].start, 1, 2, 3);
  expect_point(p[0].end, 1, 2, 10);
}

TEST(Rs274Blocks, AProgramMustEnd) {
  // The old parser made a lone end block of an empty file. LinuxCNC (rs274: "File
  // ended with no percent sign or program end") needs M2, M30 or a closing '%'.
  expect_error_at("\n(nothing)\n; at all\n", 3, 0, "the file ended with no percent sign or program end");
  pps::ProgramSetup s = test::xyz_setup();
  s.builder.start_position_mm = {4, 5, 6};
  const std::vector<Block> p = run("\n(nothing)\n; at all\nM2\n", s);
  ASSERT_EQ(p.size(), 1u);
  expect_end_block(p, 4, 5, 6);
  const std::vector<Block> q = run("%\nG0 X1\n%\n", s);
  ASSERT_EQ(q.size(), 2u);
  expect_end_block(q, 1, 5, 6);
}

TEST(Rs274Blocks, IncrementalMoves) {
  const std::vector<Block> p = run("G91\nG1 X10 F100\nX5 Y-2\nG90 X1\nM2\n");
  ASSERT_EQ(p.size(), 4u);
  expect_point(p[0].end, 10, 0, 0);
  expect_point(p[1].start, 10, 0, 0);
  expect_point(p[1].end, 15, -2, 0);
  expect_point(p[2].end, 1, -2, 0);
  expect_end_block(p, 1, -2, 0);
}

TEST(Rs274Blocks, InchesScaleAxesAndFeed) {
  const std::vector<Block> p = run("G20\nG1 X1 Y-0.5 F10\nG21 X1\nM2\n");
  ASSERT_EQ(p.size(), 3u);
  expect_point(p[0].end, 25.4, -12.7, 0);
  EXPECT_NEAR(p[0].feed_mm_per_min, 254.0, kTol);
  expect_point(p[1].end, 1, -12.7, 0);
  // The feed keeps its speed across G21 (LinuxCNC's canon converts F when it is set): 254 mm/min.
  EXPECT_NEAR(p[1].feed_mm_per_min, 254.0, kTol);
}

TEST(Rs274Blocks, UnitsApplyToTheWholeBlockWhateverTheWordOrder) {
  // The order of words in a block does not matter; G20 sets the units before the
  // coordinates of its block are used. Not its feed: LinuxCNC sets F (step 3 of its
  // order of execution) before the units (rs274: SET_FEED_RATE(10) then
  // USE_LENGTH_UNITS(CANON_UNITS_INCHES)), and its canon converts F when it is set,
  // so F10 on a G20 line is 10 mm/min. The old parser made it 254 mm/min.
  const std::vector<Block> p = run("G1 X1 F10 G20\nX2 G21\nM2\n");
  ASSERT_EQ(p.size(), 3u);
  expect_point(p[0].end, 25.4, 0, 0);
  EXPECT_NEAR(p[0].feed_mm_per_min, 10.0, kTol);
  expect_point(p[1].end, 2, 0, 0);
  EXPECT_NEAR(p[1].feed_mm_per_min, 10.0, kTol);
}

TEST(Rs274Blocks, InchProgram) {
  // A whole program in inches: axes, arc centres, feeds and dwell in the machine's mm.
  const std::vector<Block> p = run("G20 G90\nG0 X1 Y1 Z0.5\nG1 Z-0.1 F20\nG2 X2 Y1 I0.5 J0\nG4 P0.5\nM2\n");
  ASSERT_EQ(p.size(), 5u);
  expect_point(p[0].end, 25.4, 25.4, 12.7);
  expect_point(p[1].end, 25.4, 25.4, -2.54);
  EXPECT_NEAR(p[1].feed_mm_per_min, 508, kTol);
  EXPECT_EQ(p[2].kind, BlockKind::kArcCw);
  expect_point(p[2].end, 50.8, 25.4, -2.54);
  expect_point(p[2].arc.center, 38.1, 25.4, -2.54);
  EXPECT_NEAR(p[2].feed_mm_per_min, 508, kTol);
  EXPECT_EQ(p[3].kind, BlockKind::kDwell);
  EXPECT_DOUBLE_EQ(p[3].dwell_s, 0.5);
}

TEST(Rs274Blocks, CommentsAndLineNumbers) {
  const std::vector<Block> p = run(
      "%\n"
      "(a whole-line comment)\n"
      "N10 G1 X1 (inline) Y2 F100 ; trailing X99\n"
      "; a semicolon line G0 X50\n"
      "n20 x3(no space)\n"
      "%\n");
  ASSERT_EQ(p.size(), 3u);
  EXPECT_EQ(p[0].source_line, 3);  // lines of the file, not N numbers
  expect_point(p[0].end, 1, 2, 0);
  EXPECT_EQ(p[1].source_line, 5);
  expect_point(p[1].end, 3, 2, 0);
  expect_end_block(p, 3, 2, 0);
}

TEST(Rs274Blocks, ThereIsNoDefaultFeed) {
  // The old parser took a default feed from its settings. LinuxCNC starts at F0 and
  // refuses a feed move without F (rs274: "Cannot do g1 with zero feed rate").
  expect_error_at("G0 X1\nG1 X2\nM2\n", 2, 1, "cannot do G1 with zero feed rate");
  expect_error_at("G1\n  X2\nM2\n", 1, 1, "cannot do G1 with zero feed rate");
}

TEST(Rs274Blocks, F0IsAFeedOfZero) {
  // The old parser refused F0 at its word. LinuxCNC takes F0 as a rate of 0, which
  // only a feed move refuses (rs274 accepts "F0 / G0 X1").
  EXPECT_EQ(moves(run("F0\nG0 X1\nM2\n")).size(), 1u);
  expect_error_at("G1 X1 F0\nM2\n", 1, 1, "cannot do G1 with zero feed rate");
}

TEST(Rs274Blocks, G0WithoutAxisWordsMovesNothing) {
  // The old parser refused axis words without a motion mode and a G0 alone meant
  // nothing; LinuxCNC's G0 alone sets the motion mode (rs274 accepts "G0 / X1").
  // rs274 makes a zero-length STRAIGHT_TRAVERSE of the lone G0.
  const std::vector<Block> p = run("G0\nX1\nM2\n");
  ASSERT_EQ(p.size(), 3u);
  EXPECT_EQ(p[0].kind, BlockKind::kRapid);
  EXPECT_EQ(p[0].source_line, 1);
  expect_point(p[0].end, 0, 0, 0);
  EXPECT_EQ(p[1].kind, BlockKind::kRapid);
  EXPECT_EQ(p[1].source_line, 2);
  expect_point(p[1].end, 1, 0, 0);
}

TEST(Rs274Blocks, HashIsAParameter) {
  // The old parser refused '#'. In RS274NGC it is a parameter.
  const std::vector<Block> p = run("#1=5\n#<depth>=-2\nG1 X#1 Z#<depth> F[#1*100]\nM2\n");
  ASSERT_EQ(p.size(), 2u);
  expect_point(p[0].end, 5, 0, -2);
  EXPECT_DOUBLE_EQ(p[0].feed_mm_per_min, 500);
  // rs274: "Equal sign missing in parameter setting".
  expect_error_at("G0 X1 #3\nM2\n", 1, 9, "expected '=' in the parameter setting");
}

TEST(Rs274Blocks, DwellHoldsPosition) {
  const std::vector<Block> p = run("G0 X5\nG4 P0.25\nG1 X6 F60\nM2\n");
  ASSERT_EQ(p.size(), 4u);
  const Block& d = p[1];
  EXPECT_EQ(d.kind, BlockKind::kDwell);
  EXPECT_EQ(d.index, 1);
  EXPECT_EQ(d.source_line, 2);
  EXPECT_DOUBLE_EQ(d.dwell_s, 0.25);
  expect_point(d.start, 5, 0, 0);
  expect_point(d.end, 5, 0, 0);
  EXPECT_EQ(p[2].kind, BlockKind::kLine);  // G4 does not change the motion mode
  expect_point(p[2].start, 5, 0, 0);
}

TEST(Rs274Blocks, SpindleOnAndOff) {
  const std::vector<Block> p = run("S8000\nG1 X1 F100\nM3\nX2\nM5 X3\nM3 S12000 X4\nM2\n");
  const std::vector<Block> m = moves(p);
  ASSERT_EQ(m.size(), 4u);
  EXPECT_DOUBLE_EQ(m[0].spindle_rpm, 0);  // S alone does not start the spindle
  EXPECT_DOUBLE_EQ(m[1].spindle_rpm, 8000);
  EXPECT_DOUBLE_EQ(m[2].spindle_rpm, 0);  // M5 acts before the motion of its line
  EXPECT_DOUBLE_EQ(m[3].spindle_rpm, 12000);
  // The spindle changes are event blocks in program order, before their line's motion.
  std::vector<std::pair<int, double>> events;
  for (const Block& b : p)
    if (b.kind == BlockKind::kEvent) {
      EXPECT_EQ(b.event.kind, EventKind::kSpindle);
      events.emplace_back(b.event.number, b.event.value);
    }
  EXPECT_EQ(events, (std::vector<std::pair<int, double>>{{1, 8000}, {0, 0}, {1, 12000}, {0, 0}}));
  EXPECT_EQ(p[1].kind, BlockKind::kEvent);
  EXPECT_EQ(p[1].source_line, 3);
  EXPECT_EQ(p[3].kind, BlockKind::kEvent);  // M5 of line 5 ...
  EXPECT_EQ(p[4].kind, BlockKind::kLine);   // ... then its X3
  EXPECT_EQ(p[4].source_line, 5);
}

TEST(Rs274Blocks, M30EndsTheProgram) {
  const std::vector<Block> p = run("G0 X1 Y1\nG1 Z-1 F50 M30\nG0 X99\nQ5 not even G-code (\n");
  const std::vector<Block> m = moves(p);
  ASSERT_EQ(m.size(), 2u);
  expect_point(m[1].end, 1, 1, -1);
  expect_end_block(p, 1, 1, -1);
  EXPECT_EQ(p.back().source_line, 2);
  // rs274 makes M30 a PALLET_SHUTTLE and PROGRAM_END; the cell has no pallet changer,
  // so the shuttle is no event block: the program's blocks are its moves and the end.
  EXPECT_EQ(p.size(), 3u);
}

TEST(Rs274Blocks, M2EndsTheProgram) {
  const std::vector<Block> p = run("G0 X1\nM2\nG0 X2\n");
  ASSERT_EQ(p.size(), 2u);
  expect_end_block(p, 1, 0, 0);
}

TEST(Rs274Blocks, AMissingFileIsReported) {
  try {
    test::run_program("/nonexistent/prog.ngc");
    FAIL() << "a missing file ran";
  } catch (const rs274::Error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/prog.ngc"), std::string::npos) << e.what();
  }
}

// ---- refusals ----------------------------------------------------------------------

TEST(Rs274BlocksError, UnknownWord) {
  // rs274: "Q word with no G5, G10, G64, G73, G76, G83, M19, M66, M67, M68 or user M code that uses it".
  expect_error_at("G0 X0\nG1 X1 F100 Q5\nM2\n", 2, 12, "Q word with no G code or M code that uses it");
}

TEST(Rs274BlocksError, UnknownGCode) {
  // G7 (the old test's code) is LinuxCNC's lathe diameter mode; G12 is no LinuxCNC code.
  expect_error_at("G0 X1\n  G12 X1\nM2\n", 2, 3, "unknown or unsupported G code G12");
}

TEST(Rs274BlocksError, MalformedGCode) { expect_error_at("G0.25 X1\nM2\n", 1, 1, "unknown G code G0.25"); }

TEST(Rs274BlocksError, UnknownMCode) { expect_error_at("G0 X1 M45\nM2\n", 1, 7, "unknown M code M45"); }

TEST(Rs274BlocksError, LargeNumbersAreNumbers) {
  // The old parser refused numbers beyond 1e6; rs274 accepts G0 X99999999.
  const std::vector<Block> p = run("G0 X99999999\nM2\n");
  expect_point(p[0].end, 99999999, 0, 0);
}

TEST(Rs274BlocksError, MissingNumber) { expect_error_at("G0 X\nM2\n", 1, 4, "word 'X' has no value"); }

TEST(Rs274BlocksError, MissingNumberBeforeNextWord) {
  // LinuxCNC reads "X Y1" as X followed by a function Y (rs274: "Unknown word where
  // unary operation could be").
  expect_error_at("G0 X Y1\nM2\n", 1, 6, "unknown function 'Y'");
}

TEST(Rs274BlocksError, UnterminatedComment) { expect_error_at("G0 X1\nG0 X2 (no end\nM2\n", 2, 7, "unclosed comment"); }

TEST(Rs274BlocksError, NestedComment) { expect_error_at("G0 (a (b) c) X1\nM2\n", 1, 7, "nested comment"); }

TEST(Rs274BlocksError, AxisWordsBeforeAnyMotionMode) {
  expect_error_at("G21\n  X1 Y2\nM2\n", 2, 3, "axis words without a G code that uses them");
}

TEST(Rs274BlocksError, DuplicateWord) { expect_error_at("G0 X1 X2\nM2\n", 1, 7, "word 'X' given twice on one line"); }

TEST(Rs274BlocksError, TwoMotionCodes) { expect_error_at("G0 G1 X1\nM2\n", 1, 4, "two G codes from the same modal group"); }

TEST(Rs274BlocksError, PWithoutG4) { expect_error_at("G0 X1 P2\nM2\n", 1, 7, "P word with no G code or M code that uses it"); }

TEST(Rs274BlocksError, G4WithoutP) { expect_error_at("G0 X1\nG4\nM2\n", 2, 1, "G4 needs a P word"); }

TEST(Rs274BlocksError, G4WithAxisWords) {
  // rs274: "Cannot use axis values without a g code that uses them".
  expect_error_at("G4 P1 X2\nM2\n", 1, 7, "axis words without a G code that uses them");
}

// LinuxCNC's check_g_codes: G53 goes with the distance mode the block leaves.
TEST(Rs274BlocksError, G53WithG91) {
  expect_error_at("G91\nG53 G0 X1\nM2\n", 2, 1, "G53 with G91 (incremental) is not allowed");
  expect_error_at("G53 G91 G0 X1\nM2\n", 1, 1, "G53 with G91 (incremental) is not allowed");
  const std::vector<Block> m = moves(run("G91\nG90 G53 G0 X1\nM2\n"));
  ASSERT_EQ(m.size(), 1u);
  expect_point(m[0].end, 1, 0, 0);
}

// ---- arcs --------------------------------------------------------------------------

void expect_center(const Block& b, double x, double y, double z) {
  ASSERT_TRUE(b.kind == BlockKind::kArcCw || b.kind == BlockKind::kArcCcw) << to_string(b.kind);
  expect_point(b.arc.center, x, y, z);
}

TEST(Rs274BlocksArc, IjkQuarterCircle) {
  const std::vector<Block> p = run("G0 X10 Y0\nG3 X0 Y10 I-10 J0 F100\nM2\n");
  ASSERT_EQ(p.size(), 3u);
  const Block& a = p[1];
  EXPECT_EQ(a.kind, BlockKind::kArcCcw);
  EXPECT_EQ(a.arc.plane, 17);
  EXPECT_EQ(a.arc.turns, 0);
  expect_center(a, 0, 0, 0);
  expect_point(a.start, 10, 0, 0);
  expect_point(a.end, 0, 10, 0);
  EXPECT_DOUBLE_EQ(a.feed_mm_per_min, 100);
}

TEST(Rs274BlocksArc, MissingOffsetIsZero) {
  const std::vector<Block> p = run("G2 X10 Y0 I5 F100\nM2\n");  // J omitted: 0
  expect_center(p[0], 5, 0, 0);
  EXPECT_EQ(p[0].kind, BlockKind::kArcCw);
}

TEST(Rs274BlocksArc, RadiusFormPicksTheShortOrLongArc) {
  // From (0,0) to (10,10), radius 10: the two candidate centres are (10,0) and (0,10).
  const std::vector<Block> p = run(
      "G2 X10 Y10 R10 F100\n"          // short clockwise: centre to the right of the chord
      "G0 X0 Y0\nG2 X10 Y10 R-10\n"    // long clockwise
      "G0 X0 Y0\nG3 X10 Y10 R10\n"     // short counter-clockwise
      "G0 X0 Y0\nG3 X10 Y10 R-10\nM2\n");  // long counter-clockwise
  ASSERT_EQ(p.size(), 8u);
  expect_center(p[0], 10, 0, 0);
  expect_center(p[2], 0, 10, 0);
  expect_center(p[4], 0, 10, 0);
  expect_center(p[6], 10, 0, 0);
}

TEST(Rs274BlocksArc, RadiusFormSemicircle) {
  const std::vector<Block> p = run("G2 X10 Y0 R5 F100\nM2\n");
  expect_center(p[0], 5, 0, 0);
}

TEST(Rs274BlocksArc, RadiusSlightlyBelowHalfChordIsASemicircle) {
  // 0.001 mm short of half the chord: LinuxCNC (rs274 accepts) takes the semicircle;
  // 0.01 short it refuses ("Arc radius too small to reach end point").
  const std::vector<Block> p = run("G2 X10 Y0 R4.999 F100\nM2\n");
  expect_center(p[0], 5, 0, 0);
  expect_error_at("G2 X10 Y0 R4.99 F100\nM2\n", 1, 11, "too small to reach the end point");
}

TEST(Rs274BlocksArc, FullCircleWithIjk) {
  const std::vector<Block> p = run("G0 X3 Y4\nG2 X3 Y4 I-3 J-4 F100\nM2\n");
  const Block& a = p[1];
  expect_center(a, 0, 0, 0);
  EXPECT_EQ(a.start, a.end);
  EXPECT_EQ(a.arc.turns, 0);
}

TEST(Rs274BlocksArc, HelixWithTurns) {
  const std::vector<Block> p = run("G3 X0 Y0 Z-2 I5 P3 F100\nM2\n");
  const Block& a = p[0];
  EXPECT_EQ(a.kind, BlockKind::kArcCcw);
  EXPECT_EQ(a.arc.turns, 2);  // P3: the circle three times, i.e. two extra turns
  expect_center(a, 5, 0, -2);  // the centre's normal coordinate is the end's (LinuxCNC's ARC_FEED)
  expect_point(a.end, 0, 0, -2);
}

TEST(Rs274BlocksArc, PlaneG18UsesZAndX) {
  const std::vector<Block> p = run("G18 G2 X10 Z0 I5 K0 F100\nM2\n");
  EXPECT_EQ(p[0].arc.plane, 18);
  expect_center(p[0], 5, 0, 0);
  const std::vector<Block> q = run("G18 G3 X0 Z10 K5 Y3 F100\nM2\n");  // helix along Y
  EXPECT_EQ(q[0].arc.plane, 18);
  expect_center(q[0], 0, 3, 5);  // the centre's normal coordinate is the end's (LinuxCNC's ARC_FEED)
  expect_point(q[0].end, 0, 3, 10);
}

TEST(Rs274BlocksArc, PlaneG19UsesYAndZ) {
  const std::vector<Block> p = run("G19 G3 Y10 Z0 J5 F100\nM2\n");
  EXPECT_EQ(p[0].arc.plane, 19);
  EXPECT_EQ(p[0].kind, BlockKind::kArcCcw);
  expect_center(p[0], 0, 5, 0);
}

TEST(Rs274BlocksArc, PlaneIsModal) {
  const std::vector<Block> p = run("G18\nG2 X10 Z0 I5 F100\nG17 X20 Y0 I5\nM2\n");
  EXPECT_EQ(p[0].arc.plane, 18);
  EXPECT_EQ(p[1].arc.plane, 17);
  EXPECT_EQ(p[1].kind, BlockKind::kArcCw);  // G2 is modal
}

TEST(Rs274BlocksArc, OffsetsAreIncrementalUnderG90AndG91) {
  const std::vector<Block> p = run("G0 X10\nG2 X20 Y0 I5 F100\nG91 G2 X10 Y0 I5\nM2\n");
  expect_center(p[1], 15, 0, 0);
  expect_point(p[2].end, 30, 0, 0);
  expect_center(p[2], 25, 0, 0);
}

TEST(Rs274BlocksArc, G901MakesCentresAbsolute) {
  const std::vector<Block> p = run("G0 X10\nG90.1 G2 X20 Y0 I15 J0 F100\nM2\n");
  expect_center(p[1], 15, 0, 0);
}

TEST(Rs274BlocksArc, InchesScaleEndCentreAndRadius) {
  const std::vector<Block> p = run("G20 G2 X1 Y0 I0.5 F10\nG3 X0 Y0 R0.5\nM2\n");
  expect_point(p[0].end, 25.4, 0, 0);
  expect_center(p[0], 12.7, 0, 0);
  expect_center(p[1], 12.7, 0, 0);
}

TEST(Rs274BlocksArcError, RadiusMismatch) {
  // LinuxCNC's own check (0.028 mm... and 0.1 %): rs274 refuses this one too.
  expect_error_at("G2 X10 Y0.6 I5 F100\nM2\n", 1, 1, "radius to end of arc differs from radius to start");
}

TEST(Rs274BlocksArcError, WhatLinuxCncAcceptsRunsOnTheCell) {
  // rs274 accepts a 0.025 mm difference of radii (its tolerance is 0.028 mm unless
  // the error is under 0.1 %): so does the cell, which runs it as a spiral.
  EXPECT_NO_THROW(run("G2 X10 Y0.5 I5 F100\nM2\n"));
  EXPECT_NO_THROW(run("G2 X10 Y0.2 I5 F100\nM2\n"));  // 0.004 mm of 5 mm: within 0.1 %
}

TEST(Rs274BlocksArcError, NoCentreNoRadius) {
  expect_error_at("G3 X1 Y1 F100\nM2\n", 1, 1, "an arc needs R or a centre offset (I or J) in this plane");
}

TEST(Rs274BlocksArcError, ModalArcWithoutCentre) {
  // rs274 refuses the second line: "R i j k words all missing for arc".
  expect_error_at("G2 X10 I5 F100\n  X20\nM2\n", 2, 0, "an arc needs R or a centre offset");
}

TEST(Rs274BlocksArcError, CentreAtTheStart) { expect_error_at("G2 X10 I0 J0 F100\nM2\n", 1, 1, "zero-radius arc"); }

TEST(Rs274BlocksArcError, BadTurns) {
  // rs274: "P value not an integer with M19 G2 or G3".
  expect_error_at("G2 X10 I5 P0.5 F100\nM2\n", 1, 11, "P (turns) of an arc must be a whole number");
}

TEST(Rs274BlocksArcError, ArcsNeedThePlaneAxes) {
  pps::ProgramSetup s = test::xyz_setup();
  s.machine.axes = "XY";
  s.builder.axis_names = {"X", "Y"};
  s.builder.start_position_mm = {0, 0};
  expect_error_at("F100\nG18 G2 X10 I5\nM2\n", 2, 5, "arcs need the machine's first three axes to be X, Y and Z", s);
}

// ---- NURBS, Fanuc G06.2 ------------------------------------------------------------

const std::string kFig11Fanuc =
    "G21 G90 G17\n"
    "(PROCESS, BALL_RADIUS=5, FLUTES=2, PICK_FEED=0.5, RMAX_UM=10.67)\n"
    "S10000 M3\n"
    "G0 X0 Y0 Z0\n"
    "G06.2 P4 K0 X0 Y0 Z0 R1 F2000\n"
    "K0 X10 Z0 R1\nK0 X20 Z-10 R1\nK0 X30 Z-20 R1\nK0.2 X40 Z-20 R1\n"
    "K0.4 X50 Z-10 R1\nK0.6 X60 Z0 R1\nK0.8 X70 Z0 R1\n"
    "K1\nK1\nK1\nK1\n"
    "G0 Z5\nM30\n";

TEST(Rs274BlocksNurbs, FanucFig11) {
  const std::vector<Block> m = moves(run(kFig11Fanuc));
  ASSERT_EQ(m.size(), 3u);  // G0, the NURBS, G0
  const Block& n = m[1];
  EXPECT_EQ(n.kind, BlockKind::kNurbs);
  // The curve's block is made when it closes: at the line of its last knot.
  EXPECT_EQ(n.source_line, 16);
  EXPECT_EQ(n.nurbs.order, 4);
  expect_values(n.nurbs.knots, {0, 0, 0, 0, 0.2, 0.4, 0.6, 0.8, 1, 1, 1, 1});
  expect_points(n.nurbs.control_points,
                {{0, 0, 0}, {10, 0, 0}, {20, 0, -10}, {30, 0, -20}, {40, 0, -20}, {50, 0, -10}, {60, 0, 0}, {70, 0, 0}});
  expect_values(n.nurbs.weights, std::vector<double>(8, 1.0));
  expect_point(n.start, 0, 0, 0);
  expect_point(n.end, 70, 0, 0);
  EXPECT_DOUBLE_EQ(n.feed_mm_per_min, 2000);
  EXPECT_DOUBLE_EQ(n.spindle_rpm, 10000);
  EXPECT_DOUBLE_EQ(n.process.ball_radius_mm, 5);
  EXPECT_EQ(n.process.flutes, 2);
  EXPECT_DOUBLE_EQ(n.process.pick_feed_mm, 0.5);
  EXPECT_DOUBLE_EQ(n.process.target_rmax_um, 10.67);
  expect_point(m[2].start, 70, 0, 0);  // the program goes on from the last control point
  expect_point(m[2].end, 70, 0, 5);
}

TEST(Rs274BlocksNurbs, FanucWeightsDefaultToOneAndOmittedAxesKeepTheirValue) {
  const std::vector<Block> m = moves(run("G0 X1 Y2 Z3\nG06.2 P2 K0 X1 Y2 Z3 F100\nK0 X5 R0.5\nK0.5 Y7 R2\nK1\nK1\nM2\n"));
  // Degree 1: a polyline, whose inner vertex is a corner: two blocks meeting there.
  ASSERT_EQ(m.size(), 3u);
  const Block& n = m[1];
  ASSERT_EQ(n.kind, BlockKind::kNurbs);
  expect_points(n.nurbs.control_points, {{1, 2, 3}, {5, 2, 3}});
  expect_values(n.nurbs.weights, {1, 0.5});
  expect_values(n.nurbs.knots, {0, 0, 0.5, 0.5});
  expect_points(m[2].nurbs.control_points, {{5, 2, 3}, {5, 7, 3}});
  expect_values(m[2].nurbs.weights, {0.5, 2});
  expect_values(m[2].nurbs.knots, {0.5, 0.5, 1, 1});
}

TEST(Rs274BlocksNurbs, FanucIncrementalControlPoints) {
  // Under G91 each control point is relative to the one before; the first is X0 Y0 Z0.
  const std::vector<Block> m =
      moves(run("G0 X10 Y10\nG91 G06.2 P2 K0 X0 Y0 Z0 F100\nK0 X5\nK0.5 X5 Y-2\nK1\nK1\nM2\n"));
  // Degree 1 with a corner at (15, 10): two blocks.
  ASSERT_EQ(m.size(), 3u);
  expect_points(m[1].nurbs.control_points, {{10, 10, 0}, {15, 10, 0}});
  expect_points(m[2].nurbs.control_points, {{15, 10, 0}, {20, 8, 0}});
  expect_point(m[1].end, 15, 10, 0);
  expect_point(m[2].end, 20, 8, 0);
}

TEST(Rs274BlocksNurbs, InchesScaleControlPointsNotKnotsOrWeights) {
  const std::vector<Block> m = moves(run("G20\nG06.2 P2 K0 X0 Y0 Z0 F10\nK0 X1 Y0.5 R2\nK2\nK2\nM2\n"));
  const Block& n = m[0];
  ASSERT_EQ(n.nurbs.control_points.size(), 2u);
  EXPECT_NEAR(n.nurbs.control_points[1][0], 25.4, kTol);
  EXPECT_NEAR(n.nurbs.control_points[1][1], 12.7, kTol);
  expect_values(n.nurbs.knots, {0, 0, 2, 2});
  expect_values(n.nurbs.weights, {1, 2});
  EXPECT_NEAR(n.feed_mm_per_min, 254, kTol);
  expect_point(n.end, 25.4, 12.7, 0);
}

TEST(Rs274BlocksNurbs, CurveEndsBeforeTheNextCurveAndAtTheProgramEnd) {
  const std::vector<Block> p = run("G06.2 P2 K0 X0 Y0 Z0 F100\nK0 X1\nK1\nK1\nG06.2 P2 K0 X1 F100\nK0 X2\nK1\nK1\nM2\n");
  ASSERT_EQ(p.size(), 3u);
  expect_point(p[0].end, 1, 0, 0);
  expect_point(p[1].start, 1, 0, 0);
  expect_point(p[1].end, 2, 0, 0);
  EXPECT_EQ(p[2].kind, BlockKind::kEnd);
}

// A comment or blank line inside a curve leaves it open (rs274 accepts them).
TEST(Rs274BlocksNurbs, CommentsInsideACurve) {
  const std::vector<Block> p = run("G06.2 P2 K0 X0 Y0 Z0 F100\n(a remark)\nK0 X1 ; more\n\nK1\nK1\nM30\n");
  EXPECT_EQ(p[0].kind, BlockKind::kNurbs);
}

TEST(Rs274BlocksNurbs, NoMotionModeAfterACurve) {
  expect_error_at("G06.2 P2 K0 X0 Y0 Z0 F100\nK0 X1\nK1\nK1\nX5\nM2\n", 5, 1, "axis words without a G code that uses them");
}

TEST(Rs274BlocksNurbsError, FirstControlPointUnderG91MustBeZero) {
  expect_error_at("G0 X10\nG91 G06.2 P2 K0 X1 F100\nK0 X1\nK1\nK1\nM2\n", 2, 5, "must be where the tool is");
}

TEST(Rs274BlocksNurbsError, FirstControlPointWithinAMicrometreIsContinuous) {
  EXPECT_NO_THROW(run("G0 X10\nG06.2 P2 K0 X10.0000005 F100\nK0 X11\nK1\nK1\nM2\n"));
}

TEST(Rs274BlocksNurbsError, NurbsNeedsXyz) {
  pps::ProgramSetup s = test::xyz_setup();
  s.machine.axes = "XY";
  s.builder.axis_names = {"X", "Y"};
  s.builder.start_position_mm = {0, 0};
  expect_error_at("G06.2 P2 K0 X0 F100\nK0 X1\nK1\nK1\nM2\n", 4, 1, "NURBS need the machine's first three axes", s);
}

TEST(Rs274BlocksNurbsError, OtherAxesCannotTakePart) {
  pps::ProgramSetup s = test::xyz_setup();
  s.machine.axes = "XYZA";
  s.builder.axis_names = {"X", "Y", "Z", "A"};
  s.builder.start_position_mm = {0, 0, 0, 0};
  expect_error_at("G06.2 P2 K0 X0 A1 F100\nK0 X1\nK1\nK1\nM2\n", 1, 0, "a G06.2 control point takes only X, Y and Z", s);
}

// ---- NURBS, LinuxCNC G5.2 / G5.3 ---------------------------------------------------

TEST(Rs274BlocksNurbs, LinuxCncDocumentationExample) {
  const std::vector<Block> p =
      run("G0 X0 Y0 Z-1\nF10\nG5.2 P1 L3\nX0 Y1 P1\nX2 Y2 P1\nX2 Y0 P1\nX0 Y0 P2\nG5.3\nG0 X1\nM2\n");
  ASSERT_EQ(p.size(), 4u);
  const Block& n = p[1];
  EXPECT_EQ(n.kind, BlockKind::kNurbs);
  EXPECT_EQ(n.source_line, 8);  // LinuxCNC makes NURBS_FEED at G5.3
  EXPECT_EQ(n.nurbs.order, 3);
  // The start point is control point 0; LinuxCNC's uniform clamped knots for 5 points of order 3.
  expect_points(n.nurbs.control_points, {{0, 0, -1}, {0, 1, -1}, {2, 2, -1}, {2, 0, -1}, {0, 0, -1}});
  expect_values(n.nurbs.weights, {1, 1, 1, 1, 2});
  expect_values(n.nurbs.knots, {0, 0, 0, 1, 2, 3, 3, 3});
  EXPECT_DOUBLE_EQ(n.feed_mm_per_min, 10);
  expect_point(n.end, 0, 0, -1);
  EXPECT_EQ(p[2].kind, BlockKind::kRapid);
}

TEST(Rs274BlocksNurbs, LinuxCncDefaultsAndFirstLinePoint) {
  // Without L the order is 3; X Y on the G5.2 line is the second control point and
  // the line's P its weight; the start point weighs 1 (LinuxCNC's convert_nurbs: the
  // opening P weighs the start point only on a line without X Y).
  const std::vector<Block> p = run("G0 X1 Y1\nG5.2 X2 Y3 P4 F100\nX5 Y5 P1\nG5.3\nM2\n");
  const Block& n = p[1];
  EXPECT_EQ(n.nurbs.order, 3);
  expect_points(n.nurbs.control_points, {{1, 1, 0}, {2, 3, 0}, {5, 5, 0}});
  expect_values(n.nurbs.weights, {1, 4, 1});
  expect_values(n.nurbs.knots, {0, 0, 0, 1, 1, 1});
}

TEST(Rs274BlocksNurbs, LinuxCncFig11Knots) {
  std::string prog = "G0 X0 Y30\nG5.2 P1 L4 F2000\n";
  for (const char* xy : {"X10 Y30", "X20 Y20", "X30 Y10", "X40 Y10", "X50 Y20", "X60 Y30", "X70 Y30"})
    prog += std::string(xy) + " P1\n";
  prog += "G5.3\nM2\n";
  const std::vector<Block> p = run(prog);
  const Block& n = p[1];
  EXPECT_EQ(n.nurbs.order, 4);
  expect_values(n.nurbs.knots, {0, 0, 0, 0, 1, 2, 3, 4, 5, 5, 5, 5});
  EXPECT_EQ(n.nurbs.control_points.size(), 8u);
  expect_point(n.end, 70, 30, 0);
}

TEST(Rs274BlocksNurbs, LinuxCncIncrementalIsFromTheCurveStart) {
  // LinuxCNC moves the current point only at G5.3, so G91 offsets all refer to the start.
  const std::vector<Block> p = run("G0 X10 Y10\nG91 G5.2 F100\nX1 Y0 P1\nX2 Y1 P1\nG5.3\nM2\n");
  expect_points(p[1].nurbs.control_points, {{10, 10, 0}, {11, 10, 0}, {12, 11, 0}});
}

TEST(Rs274BlocksNurbs, LinuxCncInches) {
  const std::vector<Block> p = run("G20 F10\nG5.2 L3\nX1 Y0 P1\nX1 Y1 P1\nG5.3\nM2\n");
  EXPECT_NEAR(p[0].nurbs.control_points[2][1], 25.4, kTol);
}

// rs274 accepts G5.2 repeated on the control point lines (one NURBS_FEED).
TEST(Rs274BlocksNurbs, LinuxCncRepeatedG52ContinuesTheCurve) {
  const std::vector<Block> p = run("F100\nG5.2 P1\nG5.2 X1 Y0 P1\nG5.2 X2 Y1 P1\nG5.3\nM2\n");
  ASSERT_EQ(p.size(), 2u);
  EXPECT_EQ(p[0].nurbs.control_points.size(), 3u);
}

TEST(Rs274BlocksNurbsError, LinuxCncXWithoutY) {
  expect_error_at("F100\nG5.2 P1\nX1 P1\nG5.3\nM2\n", 3, 1, "a G5.2 control point needs both X and Y");
}

TEST(Rs274BlocksNurbsError, LinuxCncG53WithoutG52) { expect_error_at("F100\nG5.3\nM2\n", 2, 1, "G5.3 without G5.2"); }

TEST(Rs274BlocksNurbsError, LinuxCncTooFewPoints) {
  expect_error_at("F100\nG5.2 P1 L4\nX1 Y0 P1\nX2 Y1 P1\nG5.3\nM2\n", 5, 1,
                  "a curve of order L = 4 needs at least that many control points");
}

TEST(Rs274BlocksNurbsError, FanucOrderOutOfRange) {
  expect_error_at("G06.2 P9 K0 X0 Y0 Z0 F100\nM2\n", 1, 7, "G06.2 P (order) must be 2 to 8");
}

TEST(Rs274BlocksNurbsError, AtMostTenThousandControlPoints) {
  std::string prog = "G06.2 P2 K0 X0 Y0 Z0 F100\n";
  for (int i = 1; i <= 10000; ++i) prog += "K0 X" + std::to_string(i) + "\n";
  prog += "K1\nK1\nM2\n";
  expect_error_at(prog, 10003, 1, "10001 control points: at most 10000 in one curve");
}

// ---- process directive -------------------------------------------------------------

TEST(Rs274BlocksProcess, DirectiveAppliesFromItsLineOnAndTheMachineSectionFillsInWhatItLeavesOut) {
  pps::ProgramSetup s = test::xyz_setup();
  s.builder.process = ProcessParams{3, 4, 0.2, 5};  // from the machine config
  const std::vector<Block> p =
      run("F100\nG1 X1\n(process, pick_feed=0.7, Flutes=2) G1 X2\nX3\n(PROCESS,RMAX_UM=0)\nX4\nM2\n", s);
  ASSERT_EQ(p.size(), 5u);
  // Before the program describes its cut, no law: not the machine file's tool.
  EXPECT_FALSE(p[0].process.active());
  EXPECT_DOUBLE_EQ(p[0].process.ball_radius_mm, 0);
  EXPECT_DOUBLE_EQ(p[0].process.target_rmax_um, 0);
  for (int i : {1, 2}) {
    EXPECT_DOUBLE_EQ(p[i].process.ball_radius_mm, 3);  // not in the directive: kept
    EXPECT_EQ(p[i].process.flutes, 2);
    EXPECT_DOUBLE_EQ(p[i].process.pick_feed_mm, 0.7);
    EXPECT_DOUBLE_EQ(p[i].process.target_rmax_um, 5);
    EXPECT_TRUE(p[i].process.active());
  }
  EXPECT_DOUBLE_EQ(p[3].process.target_rmax_um, 0);
  EXPECT_FALSE(p[3].process.active());  // RMAX_UM=0: the roughness law is off
  // A program that never says PROCESS runs without the law, spindle on or not.
  const std::vector<Block> q = run("S12000 M3\nF100\nG1 X1\nM2\n", s);
  ASSERT_GE(q.size(), 1u);
  for (const Block& b : q) EXPECT_FALSE(b.process.active()) << b.source_line;
}

TEST(Rs274BlocksProcess, DirectiveIsInMillimetresUnderG20) {
  const std::vector<Block> p = run("G20 (PROCESS, BALL_RADIUS=5, PICK_FEED=0.5) G1 X1 F10\nM2\n");
  EXPECT_DOUBLE_EQ(p[0].process.ball_radius_mm, 5);
  EXPECT_DOUBLE_EQ(p[0].process.pick_feed_mm, 0.5);
}

TEST(Rs274BlocksProcess, AnOrdinaryCommentIsNotADirective) {
  EXPECT_NO_THROW(run("(process the part twice)\n(PROCESSED)\nG0 X1\nM2\n"));
}

TEST(Rs274BlocksProcessError, DuplicateKey) {
  expect_error_at("(PROCESS, FLUTES=2, flutes=3)\nM2\n", 1, 21, "FLUTES appears twice");
}

TEST(Rs274BlocksProcessError, NegativeRadius) {
  expect_error_at("(PROCESS, BALL_RADIUS=-1)\nM2\n", 1, 11, "expected a positive radius");
}

TEST(Rs274BlocksProcessError, NanValue) {
  expect_error_at("(PROCESS, RMAX_UM=nan)\nM2\n", 1, 11, "expected a number, found 'nan'");
}

TEST(Rs274BlocksProcessError, MissingSeparator) {
  expect_error_at("(PROCESS, FLUTES=2 PICK_FEED=1)\nM2\n", 1, 20, "expected ',' or ')'");
}

// ---- limits ------------------------------------------------------------------------

// rs274 refuses a line longer
// than LinuxCNC's limit ("Command too long"); the interpreter accepts 5000 spaces.
TEST(Rs274BlocksError, OverlongLine) {
  // LinuxCNC's LINELEN: "Command too long" past 255 characters.
  expect_error_at("G0 X1\n" + std::string(5000, ' ') + "X2\nM2\n", 2, 256, "line longer than 255 characters");
}

// ---- what the block builder adds: offsets, units, tools, rotation --------------------

TEST(Rs274BlocksOffsets, G54AndG55) {
  const std::vector<Block> p =
      run("G10 L2 P1 X10 Y20 Z0\nG10 L2 P2 X100 Y0 Z-5\nG0 X1 Y1\nG55 G0 X1 Y1 Z0\nG54 X0 Y0\nM2\n");
  ASSERT_EQ(p.size(), 4u);
  expect_point(p[0].end, 11, 21, 0);
  expect_point(p[1].end, 101, 1, -5);
  expect_point(p[2].end, 10, 20, -5);  // Z not named: it stays where it is on the machine
}

TEST(Rs274BlocksOffsets, G92ShiftsTheProgramOrigin) {
  const std::vector<Block> p = run("G0 X5 Y5\nG92 X0 Y0\nG0 X1 Y2\nG92.1\nG0 X1 Y2\nM2\n");
  ASSERT_EQ(p.size(), 4u);
  expect_point(p[1].end, 6, 7, 0);
  expect_point(p[2].end, 1, 2, 0);  // G92.1: the offset is gone
}

TEST(Rs274BlocksOffsets, ToolLengthOffsetFromTheToolTable) {
  Prog tools("T1 P1 Z10 D6 ;ten mm long\nT2 P2 Z-2.5\n", "tools.tbl");
  pps::ProgramSetup s = test::xyz_setup();
  s.machine.tool_table = tools.path();
  const std::vector<Block> p = run("T1 M6\nG43 H1\nG0 X1 Z0\nT2 M6\nG43\nG0 Z0\nG49\nG0 Z0\nM2\n", s);
  std::vector<Block> m = moves(p);
  ASSERT_EQ(m.size(), 3u);
  expect_point(m[0].end, 1, 0, 10);
  expect_point(m[1].end, 1, 0, -2.5);  // G43 without H: the tool in the spindle
  expect_point(m[2].end, 1, 0, 0);     // G49: no offset
  ASSERT_EQ(p[0].kind, BlockKind::kEvent);
  EXPECT_EQ(p[0].event.kind, EventKind::kToolChange);
  EXPECT_EQ(p[0].event.number, 1);
  EXPECT_TRUE(p[0].event.pauses());
  // A tool the table does not have: refused at its line (rs274: "Requested tool 3 not
  // found in the tool table").
  expect_error_at("T3 M6\nM2\n", 1, 1, "tool T3 is not in the tool table", s);
}

TEST(Rs274BlocksOffsets, XyRotation) {
  // G10 L2 R: the coordinate system turns about its origin (LinuxCNC's SET_XY_ROTATION).
  const std::vector<Block> p = run("G10 L2 P1 X10 Y0 R90\nG0 X1 Y0 Z2\nG1 X1 Y1 F100\nM2\n");
  ASSERT_EQ(p.size(), 3u);
  expect_point(p[0].end, 10, 1, 2);
  expect_point(p[1].end, 9, 1, 2);
  const std::vector<Block> q = run("G10 L2 P1 R30\nG0 X10 Y0\nM2\n");
  expect_point(q[0].end, 10 * std::cos(M_PI / 6), 10 * std::sin(M_PI / 6), 0);
  expect_error_at("G10 L2 P1 R30\nG18 G2 X10 Z0 I5 F100\nM2\n", 2, 5, "rotated coordinate system");
}

// ---- event blocks --------------------------------------------------------------------

std::vector<Block> events(const std::vector<Block>& all) {
  std::vector<Block> out;
  for (const Block& b : all)
    if (b.kind == BlockKind::kEvent) out.push_back(b);
  return out;
}

TEST(Rs274BlocksEvents, ProgramStopsPause) {
  const std::vector<Block> p = run("G0 X1\nM0\nG0 X2\nM1\nM60\nM2\n");
  const std::vector<Block> e = events(p);
  ASSERT_EQ(e.size(), 3u);
  EXPECT_EQ(e[0].event.kind, EventKind::kProgramStop);
  EXPECT_EQ(e[0].source_line, 2);
  EXPECT_TRUE(e[0].event.pauses());
  expect_point(e[0].start, 1, 0, 0);
  expect_point(e[0].end, 1, 0, 0);
  EXPECT_EQ(e[1].event.kind, EventKind::kOptionalStop);
  EXPECT_TRUE(e[1].event.pauses());
  // M60: LinuxCNC's PALLET_SHUTTLE and PROGRAM_STOP; no pallet changer here, the stop holds.
  EXPECT_EQ(e[2].event.kind, EventKind::kProgramStop);
  EXPECT_EQ(e[2].source_line, 5);
  EXPECT_EQ(p[1].index, 1);  // in program order between the moves
  EXPECT_EQ(p[2].kind, BlockKind::kRapid);
}

TEST(Rs274BlocksEvents, OptionalStopSwitchedOff) {
  pps::ProgramSetup s = test::xyz_setup();
  s.machine.optional_stop = false;
  EXPECT_TRUE(events(run("G0 X1\nM1\nM2\n", s)).empty());
}

TEST(Rs274BlocksEvents, SpindleAndCoolant) {
  const std::vector<Block> e = events(run("S5000 M3\nM8\nM7\nM9\nM4\nS6000\nM5\nM2\n"));
  std::vector<std::tuple<EventKind, int, double>> got;
  for (const Block& b : e) got.emplace_back(b.event.kind, b.event.number, b.event.value);
  const std::vector<std::tuple<EventKind, int, double>> want = {
      {EventKind::kSpindle, 1, 5000}, {EventKind::kCoolant, 2, 0},     {EventKind::kCoolant, 3, 0},
      {EventKind::kCoolant, 2, 0},    {EventKind::kCoolant, 0, 0},  // M9: mist off, then flood off
      {EventKind::kSpindle, -1, 5000},
      {EventKind::kSpindle, -1, 6000}, {EventKind::kSpindle, 0, 0}};
  EXPECT_EQ(got, want);
  for (const Block& b : e) EXPECT_FALSE(b.event.pauses());
}

TEST(Rs274BlocksEvents, Messages) {
  const std::vector<Block> e = events(run("(MSG, tool 3 please)\n(DEBUG,depth=#<_z>)\n(a comment)\nM2\n"));
  ASSERT_GE(e.size(), 1u);
  EXPECT_EQ(e[0].event.kind, EventKind::kMessage);
  EXPECT_EQ(e[0].event.text, " tool 3 please");  // rs274: MESSAGE(" tool 3 please")
  EXPECT_EQ(e[0].source_line, 1);
}

TEST(Rs274BlocksEvents, Outputs) {
  const std::vector<Block> e = events(run("M62 P3\nM65 P3\nM64 P0\nM67 E2 Q5.5\nM68 E1 Q-2\nM2\n"));
  std::vector<std::tuple<EventKind, int, double>> got;
  for (const Block& b : e) got.emplace_back(b.event.kind, b.event.number, b.event.value);
  // M62 on with the next motion (1 + 2), M65 off at once (0), M64 on at once (1).
  const std::vector<std::tuple<EventKind, int, double>> want = {{EventKind::kDigitalOutput, 3, 3},
                                                                {EventKind::kDigitalOutput, 3, 0},
                                                                {EventKind::kDigitalOutput, 0, 1},
                                                                {EventKind::kAnalogOutput, 1002, 5.5},
                                                                {EventKind::kAnalogOutput, 1, -2}};
  EXPECT_EQ(got, want);
}

TEST(Rs274BlocksEvents, M6IsAToolChangeThatPauses) {
  // The old parser refused M6. LinuxCNC changes tools: an event block that holds the
  // motion until the operator resumes.
  Prog tools("T7 P1 Z0\n", "tools.tbl");
  pps::ProgramSetup s = test::xyz_setup();
  s.machine.tool_table = tools.path();
  const std::vector<Block> p = run("G0 X1\nT7 M6\nG0 X2\nM2\n", s);
  ASSERT_EQ(p.size(), 4u);
  EXPECT_EQ(p[1].kind, BlockKind::kEvent);
  EXPECT_EQ(p[1].event.kind, EventKind::kToolChange);
  EXPECT_EQ(p[1].event.number, 7);
  EXPECT_TRUE(p[1].event.pauses());
}

TEST(Rs274BlocksEvents, EveryEventPassesTheNetworkCheck) {
  const std::vector<Block> p = run("S100 M3\nM8\n(MSG,hi)\nM62 P1\nM67 E0 Q1\nM0\nM5\nM9\nM30\n");
  for (const Block& b : p) {
    Block back;
    EXPECT_EQ(from_msg(to_msg(b, 3), 3, &back), "") << b.index;
    EXPECT_EQ(back.event.kind, b.event.kind);
    EXPECT_EQ(back.event.number, b.event.number);
    EXPECT_EQ(back.event.value, b.event.value);
    EXPECT_EQ(back.event.text, b.event.text);
  }
}

// ---- subroutines and loops -----------------------------------------------------------

TEST(Rs274BlocksFlow, SubroutineFromTheSubroutinePath) {
  test::TempDir subs;
  const std::string sub = (subs / "square.ngc").string();
  test::write_file(sub,
                   "o<square> sub\n"
                   "G1 X#1 F600\n"
                   "Y#1\n"
                   "X0\n"
                   "Y0\n"
                   "o<square> endsub\n"
                   "M2\n");
  pps::ProgramSetup s = test::xyz_setup();
  s.machine.subroutine_path = {subs.path().string()};
  Prog main("G0 X0 Y0\no<square> call [10]\no<square> call [5]\nG0 Z5\nM2\n");
  const std::vector<Block> p = test::run_program(main.path(), s);
  ASSERT_EQ(p.size(), 11u);
  EXPECT_EQ(p[0].source_file, main.path());
  for (int i = 1; i <= 8; ++i) {
    EXPECT_EQ(p[i].source_file, sub) << i;
    EXPECT_EQ(p[i].kind, BlockKind::kLine);
  }
  EXPECT_EQ(p[1].source_line, 2);
  expect_point(p[1].end, 10, 0, 0);
  expect_point(p[2].end, 10, 10, 0);
  expect_point(p[6].end, 5, 5, 0);
  EXPECT_EQ(p[9].source_file, main.path());
  EXPECT_EQ(p[9].source_line, 4);
  // The server serves them the same, file names included.
  pps::ProgramServer server(s, pps::ServerLimits{3, 1});
  ASSERT_TRUE(server.load(main.path(), 1).ok);
  ASSERT_EQ(server.num_blocks(), 11);
  ASSERT_NE(server.block(2), nullptr);
  EXPECT_EQ(server.block(2)->source_file, sub);
  // An error in the subroutine names the subroutine's file and line.
  test::write_file(sub, "o<square> sub\nG1 X#1 Q1\no<square> endsub\nM2\n");
  try {
    test::run_program(main.path(), s);
    ADD_FAILURE() << "accepted";
  } catch (const rs274::Error& e) {
    EXPECT_EQ(e.file_name(), sub) << e.what();
    EXPECT_EQ(e.where().line, 2) << e.what();
  }
}

TEST(Rs274BlocksFlow, ALoopRunsTenThousandTimes) {
  const std::vector<Block> p = run(
      "F1000\n#1=0\n"
      "o100 while [#1 LT 10000]\n"
      "  G1 X[#1 MOD 2] Y[#1 / 1000]\n"
      "  #1=[#1+1]\n"
      "o100 endwhile\n"
      "M2\n");
  ASSERT_EQ(p.size(), 10001u);
  for (size_t i = 0; i < 10000; ++i) ASSERT_EQ(p[i].source_line, 4);
  expect_point(p[9999].end, 1, 9.999, 0, 1e-12);
  expect_end_block(p, 1, 9.999, 0);
  // The server counts them without keeping them: one hash per chunk.
  Prog prog("F1000\n#1=0\no100 while [#1 LT 10000]\n  G1 X[#1 MOD 2]\n  #1=[#1+1]\no100 endwhile\nM2\n");
  pps::ProgramServer server(test::xyz_setup(), pps::ServerLimits{256, 2});
  ASSERT_TRUE(server.load(prog.path(), 1).ok);
  EXPECT_EQ(server.num_blocks(), 10001);
  EXPECT_EQ(server.num_checkpoints(), (10001u + 255u) / 256u);
}

// ---- differences from rs274 found by the port, fixed ----------------------------------

// rs274 accepts M6 without a T word (START_CHANGE, CHANGE_TOOL(0)).
TEST(Rs274BlocksRs274Differences, M6WithoutATWord) {
  const std::vector<Block> e = events(run("G0 X1\nM6\nM2\n"));
  ASSERT_EQ(e.size(), 1u);
  EXPECT_EQ(e[0].event.kind, EventKind::kToolChange);
  EXPECT_EQ(e[0].event.number, 0);
}

// rs274 makes SET_SPINDLE_SPEED(0, 100) before NURBS_FEED for an S on a G5.2 control
// point line.
TEST(Rs274BlocksRs274Differences, SWordInsideAG52Curve) {
  const std::vector<Block> p = run("F500\nS1000 M3\nG5.2 P1 L3\nX10 Y0 P1 S100\nX20 Y5 P1\nG5.3\nM2\n");
  const std::vector<Block> m = moves(p);
  ASSERT_EQ(m.size(), 1u);
  EXPECT_DOUBLE_EQ(m[0].spindle_rpm, 100);
}

// rs274 refuses a fractional order ("Non integer value for integer": it reads every L
// as an integer, as here).
TEST(Rs274BlocksRs274Differences, FractionalOrder) {
  expect_error_at("F500\nG5.2 P1 L3.5\nX10 Y0 P1\nX20 Y5 P1\nX30 Y0 P1\nG5.3\nM2\n", 2, 9, "Non integer value for integer");
  expect_error_at("G06.2 P3.5 K0 X0 Y0 Z0 F500\nM2\n", 1, 7, "P");
}

// A deliberate difference: LinuxCNC 2.9's rs274 takes G5.2's X and Y whatever the
// plane (in G18 it refuses Z X points); newer LinuxCNC (its nc_files/nurbs/G5
// *-zx and *-yz examples) and this interpreter take the active plane's two axes.
TEST(Rs274BlocksRs274Differences, G52TakesThePlanesAxes) {
  const std::vector<Block> m = moves(run("F500\nG18\nG5.2 P1\nZ10 X0 P1\nZ20 X5 P1\nG5.3\nM2\n"));
  ASSERT_EQ(m.size(), 1u);
  expect_points(m[0].nurbs.control_points, {{0, 0, 0}, {0, 0, 10}, {5, 0, 20}});
  expect_error_at("F500\nG18\nG5.2 P1\nX10 Y0 P1\nX20 Y5 P1\nG5.3\nM2\n", 4, 1, "needs both Z and X");
}

// rs274 accepts comment and blank lines inside a G5.2 curve.
TEST(Rs274BlocksRs274Differences, CommentsInsideAG52Curve) {
  EXPECT_NO_THROW(run("F100\nG5.2 P1\n(remark)\nX1 Y0 P1\n\nX2 Y1 P1\nG5.3\nM2\n"));
}

TEST(Rs274BlocksNurbs, ACornerInsideANurbsSplitsItIntoBlocksOfTheSameCurve) {
  // The paths issue's program: degree 2, the knot 0.5 twice (= the degree), the
  // control polygon turning at (15, 5): the curve has a sharp corner there. It
  // becomes two blocks (a junction the planner slows or stops for) that trace the
  // same curve: every point of the pieces lies on the unsplit curve.
  const std::string text =
      "G0 X5 Y5 Z0\nG06.2 P3 K0 X5 Y5 Z0 R1 F3000\nK0 X10 Y6 Z0 R1\nK0 X15 Y5 Z0 R1\nK0.5 X16 Y10 Z0 R1\n"
      "K0.5 X15 Y15 Z0 R1\nK1\nK1\nK1\nM30\n";
  const std::vector<Block> m = moves(run(text));
  ASSERT_EQ(m.size(), 3u);  // the rapid and two pieces
  ASSERT_EQ(m[1].kind, BlockKind::kNurbs);
  ASSERT_EQ(m[2].kind, BlockKind::kNurbs);
  EXPECT_EQ(m[1].end, m[2].start);
  EXPECT_NEAR(m[1].end[0], 15.0, 1e-12);
  EXPECT_NEAR(m[1].end[1], 5.0, 1e-12);
  EXPECT_NEAR(m[2].end[0], 15.0, 1e-12);
  EXPECT_NEAR(m[2].end[1], 15.0, 1e-12);
  // The unsplit curve, as the program wrote it.
  Block whole = m[1];
  whole.end = m[2].end;
  whole.nurbs.knots = {0, 0, 0, 0.5, 0.5, 1, 1, 1};
  whole.nurbs.control_points = {{5, 5, 0}, {10, 6, 0}, {15, 5, 0}, {16, 10, 0}, {15, 15, 0}};
  whole.nurbs.weights = {1, 1, 1, 1, 1};
  const motion::PathSegment w(whole, 3), a(m[1], 3), c(m[2], 3);
  EXPECT_DOUBLE_EQ(a.u_end(), 0.5);
  EXPECT_DOUBLE_EQ(c.u_begin(), 0.5);
  for (int i = 0; i <= 40; ++i) {
    const double u = i / 40.0;
    const motion::AxisVec q = w.point(u);
    const motion::AxisVec r = u <= 0.5 ? a.point(u) : c.point(u);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(r[k], q[k], 1e-12) << "u " << u;
  }
  // A smooth knot of the same multiplicity (the polygon in line there) stays one block.
  const std::vector<Block> smooth = moves(run(
      "G0 X5 Y5 Z0\nG06.2 P3 K0 X5 Y5 Z0 R1 F3000\nK0 X10 Y5 Z0 R1\nK0 X15 Y5 Z0 R1\nK0.5 X20 Y5 Z0 R1\n"
      "K0.5 X25 Y10 Z0 R1\nK1\nK1\nK1\nM30\n"));
  EXPECT_EQ(smooth.size(), 2u);
}

}  // namespace
}  // namespace cnc::program

namespace cnc::program {
namespace {

// X Y Z and a rotary A (degrees), wrapped or not, as program_setup makes it from sim4_rotary.
pps::ProgramSetup xyza_setup(bool wrapped) {
  pps::ProgramSetup s = test::xyz_setup();
  s.machine.axes = "XYZA";
  s.builder.axis_names.push_back("A");
  s.builder.start_position_mm.push_back(0);
  s.builder.rotary = {false, false, false, true};
  if (wrapped) s.machine.wrapped = "A";
  return s;
}

std::vector<double> a_ends(const std::vector<Block>& blocks) {
  std::vector<double> out;
  for (const Block& b : moves(blocks)) out.push_back(b.end[3]);
  return out;
}

// LinuxCNC 2.9's rs274 with [AXIS_A] WRAPPED_ROTARY = 1 prints these A ends for the
// program (STRAIGHT_TRAVERSE/STRAIGHT_FEED's fourth number).
TEST(Rs274BlocksRotary, WrappedAxisTakesTheWaySignSaysAsRs274) {
  const std::string text =
      "G21 G90\nG0 A10\nG0 A350\nG0 A-10\nG0 A-350\nG1 X1 A90 F100\nG0 A-0\nG0 A0\nG91 G0 A400\nG90 G0 A5\n"
      "G53 G0 A20\nM2\n";
  expect_values(a_ends(run(text, xyza_setup(true))), {10, 350, 10, -10, 90, 0, 0, 400, 725, 740});
  // Not wrapped: the words as they are.
  expect_values(a_ends(run(text, xyza_setup(false))), {10, 350, -10, -350, 90, 0, 0, 400, 5, 20});
  expect_error_at("G90 G0 A360\nM2\n", 1, 8, "Invalid absolute position 360.00 for wrapped rotary axis A",
                  xyza_setup(true));
}

// LinuxCNC's tests/interp/bad/a-in-canned-cycle and a-in-canned-cycle2: rs274 refuses
// an A word with a canned cycle, on the cycle's line or under its modal motion.
TEST(Rs274BlocksRotary, NoRotaryWordInACannedCycleAsRs274) {
  expect_error_at("G81 X0 Y0 Z-1 R0 A90 F12\nM2\n", 1, 18, "Cannot put an a in canned cycle", xyza_setup(false));
  expect_error_at("G81 X0 Y0 Z-1 R0 F12\nA90\nM2\n", 2, 1, "Cannot put an a in canned cycle", xyza_setup(false));
}

// LinuxCNC's feed rules in the block's feed (mm/min along the path over X Y Z and A,
// the planner's length): a mixed move F·L/L_xyz, A alone F in deg/min (also G20),
// G93 the rate that takes 1/F minutes.
TEST(Rs274BlocksRotary, FeedAlongThePathOfAllAxes) {
  const auto b = moves(run("G21 G90 G1 X30 A40 F600\nG1 A130 F900\nG20\nG1 A220 F900\nG21 G93 G1 X60 A0 F2\nM2\n",
                           xyza_setup(false)));
  ASSERT_EQ(b.size(), 4u);
  EXPECT_NEAR(b[0].feed_mm_per_min, 600.0 * 50.0 / 30.0, 1e-9);
  EXPECT_NEAR(b[1].feed_mm_per_min, 900.0, 1e-9);
  EXPECT_NEAR(b[2].feed_mm_per_min, 900.0, 1e-9);
  // 30 mm and 220° in 0.5 min.
  EXPECT_NEAR(b[3].feed_mm_per_min, std::hypot(30.0, 220.0) * 2.0, 1e-9);
  // Without rotary motion nothing changes: the old feed bit for bit.
  const auto plain = moves(run("G21 G90 G1 X30 F600\nM2\n", xyza_setup(false)));
  EXPECT_EQ(plain[0].feed_mm_per_min, 600.0);
}

}  // namespace
}  // namespace cnc::program
