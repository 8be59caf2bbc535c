// The RS274 parser: blocks with their modal state, and refusals that name the exact
// file:line:column.
#include <gtest/gtest.h>

#include <array>
#include <sstream>
#include <string>
#include <vector>

#include "common/program/gcode_parser.h"

namespace cnc::program {
namespace {

constexpr double kTol = 1e-12;
const std::string kFile = "t.nc";

ParserSettings xyz_settings(double default_feed = 0) {
  ParserSettings s;
  s.axis_names = {"X", "Y", "Z"};
  s.start_position_mm = {0, 0, 0};
  s.default_feed_mm_per_min = default_feed;
  return s;
}

Program parse(const std::string& text, ParserSettings settings = xyz_settings()) {
  std::istringstream in(text);
  return GcodeParser(std::move(settings)).parse(in, kFile);
}

void expect_point(const std::vector<double>& p, double x, double y, double z) {
  ASSERT_EQ(p.size(), 3u);
  EXPECT_NEAR(p[0], x, kTol);
  EXPECT_NEAR(p[1], y, kTol);
  EXPECT_NEAR(p[2], z, kTol);
}

// The last block ends the program where the last motion left the tool.
void expect_end_block(const Program& prog, double x, double y, double z) {
  ASSERT_FALSE(prog.blocks.empty());
  const Block& e = prog.blocks.back();
  EXPECT_EQ(e.kind, BlockKind::kEnd);
  EXPECT_EQ(e.index, static_cast<int64_t>(prog.blocks.size()) - 1);
  expect_point(e.start, x, y, z);
  expect_point(e.end, x, y, z);
}

ProgramError parse_error(const std::string& text, ParserSettings settings = xyz_settings()) {
  try {
    parse(text, std::move(settings));
  } catch (const ProgramError& e) {
    return e;
  }
  ADD_FAILURE() << "the parser accepted:\n" << text;
  return ProgramError(SourceLocation{}, "");
}

void expect_error_at(const std::string& text, int line, int column, const std::string& detail,
                     ParserSettings settings = xyz_settings(100)) {
  const ProgramError e = parse_error(text, std::move(settings));
  EXPECT_EQ(e.where().file, kFile);
  EXPECT_EQ(e.where().line, line) << e.what();
  EXPECT_EQ(e.where().column, column) << e.what();
  const std::string prefix = kFile + ":" + std::to_string(line) + ":" + std::to_string(column) + ": ";
  const std::string what = e.what();
  EXPECT_EQ(what.rfind(prefix, 0), 0u) << what;
  EXPECT_NE(e.detail().find(detail), std::string::npos) << "'" << detail << "' not in: " << what;
}

TEST(GcodeParser, RapidAndLinearMoves) {
  const Program p = parse("G0 X10 Y20\nG1 Z-5 F600\nX30\n");
  EXPECT_EQ(p.file, kFile);
  ASSERT_EQ(p.blocks.size(), 4u);
  const Block& b0 = p.blocks[0];
  EXPECT_EQ(b0.kind, BlockKind::kRapid);
  EXPECT_EQ(b0.index, 0);
  EXPECT_EQ(b0.source_line, 1);
  expect_point(b0.start, 0, 0, 0);
  expect_point(b0.end, 10, 20, 0);
  const Block& b1 = p.blocks[1];
  EXPECT_EQ(b1.kind, BlockKind::kLine);
  EXPECT_EQ(b1.index, 1);
  EXPECT_EQ(b1.source_line, 2);
  expect_point(b1.start, 10, 20, 0);
  expect_point(b1.end, 10, 20, -5);
  EXPECT_DOUBLE_EQ(b1.feed_mm_per_min, 600);
  const Block& b2 = p.blocks[2];  // G1 and F are modal
  EXPECT_EQ(b2.kind, BlockKind::kLine);
  expect_point(b2.start, 10, 20, -5);
  expect_point(b2.end, 30, 20, -5);
  EXPECT_DOUBLE_EQ(b2.feed_mm_per_min, 600);
  expect_end_block(p, 30, 20, -5);
  EXPECT_EQ(p.blocks[3].source_line, 3);
}

TEST(GcodeParser, StartPositionFromSettings) {
  ParserSettings s = xyz_settings();
  s.start_position_mm = {1, 2, 3};
  const Program p = parse("G0 Z10\n", s);
  ASSERT_EQ(p.blocks.size(), 2u);
  expect_point(p.blocks[0].start, 1, 2, 3);
  expect_point(p.blocks[0].end, 1, 2, 10);
}

TEST(GcodeParser, EmptyProgramIsJustTheEnd) {
  ParserSettings s = xyz_settings();
  s.start_position_mm = {4, 5, 6};
  const Program p = parse("\n(nothing)\n; at all\n", s);
  ASSERT_EQ(p.blocks.size(), 1u);
  expect_end_block(p, 4, 5, 6);
}

TEST(GcodeParser, IncrementalMoves) {
  const Program p = parse("G91\nG1 X10 F100\nX5 Y-2\nG90 X1\n");
  ASSERT_EQ(p.blocks.size(), 4u);
  expect_point(p.blocks[0].end, 10, 0, 0);
  expect_point(p.blocks[1].start, 10, 0, 0);
  expect_point(p.blocks[1].end, 15, -2, 0);
  expect_point(p.blocks[2].end, 1, -2, 0);
  expect_end_block(p, 1, -2, 0);
}

TEST(GcodeParser, InchesScaleAxesAndFeed) {
  const Program p = parse("G20 G1 X1 Y-0.5 F10\nG21 X1\n");
  ASSERT_EQ(p.blocks.size(), 3u);
  expect_point(p.blocks[0].end, 25.4, -12.7, 0);
  EXPECT_NEAR(p.blocks[0].feed_mm_per_min, 254.0, kTol);
  expect_point(p.blocks[1].end, 1, -12.7, 0);
  // The feed stays what it was set to in inches/min: 254 mm/min.
  EXPECT_NEAR(p.blocks[1].feed_mm_per_min, 254.0, kTol);
}

TEST(GcodeParser, UnitsApplyToTheWholeBlockWhateverTheWordOrder) {
  // RS274: the order of words in a block does not matter; G20 sets the units
  // before any coordinate or feed of its block is used.
  const Program p = parse("G1 X1 F10 G20\nX2 G21\n");
  ASSERT_EQ(p.blocks.size(), 3u);
  expect_point(p.blocks[0].end, 25.4, 0, 0);
  EXPECT_NEAR(p.blocks[0].feed_mm_per_min, 254.0, kTol);
  expect_point(p.blocks[1].end, 2, 0, 0);
}

TEST(GcodeParser, CommentsAndLineNumbers) {
  const Program p = parse(
      "%\n"
      "(a whole-line comment)\n"
      "N10 G1 X1 (inline) Y2 F100 ; trailing X99\n"
      "; a semicolon line G0 X50\n"
      "n20 x3(no space)\n");
  ASSERT_EQ(p.blocks.size(), 3u);
  EXPECT_EQ(p.blocks[0].source_line, 3);  // lines of the file, not N numbers
  expect_point(p.blocks[0].end, 1, 2, 0);
  EXPECT_EQ(p.blocks[1].source_line, 5);
  expect_point(p.blocks[1].end, 3, 2, 0);
  expect_end_block(p, 3, 2, 0);
}

TEST(GcodeParser, DefaultFeedFromSettings) {
  const Program p = parse("G1 X1\n", xyz_settings(750));
  ASSERT_EQ(p.blocks.size(), 2u);
  EXPECT_DOUBLE_EQ(p.blocks[0].feed_mm_per_min, 750);
}

TEST(GcodeParser, DwellHoldsPosition) {
  const Program p = parse("G0 X5\nG4 P0.25\nG1 X6 F60\n");
  ASSERT_EQ(p.blocks.size(), 4u);
  const Block& d = p.blocks[1];
  EXPECT_EQ(d.kind, BlockKind::kDwell);
  EXPECT_EQ(d.index, 1);
  EXPECT_EQ(d.source_line, 2);
  EXPECT_DOUBLE_EQ(d.dwell_s, 0.25);
  expect_point(d.start, 5, 0, 0);
  expect_point(d.end, 5, 0, 0);
  EXPECT_EQ(p.blocks[2].kind, BlockKind::kLine);  // G4 does not change the motion mode
  expect_point(p.blocks[2].start, 5, 0, 0);
}

TEST(GcodeParser, SpindleOnAndOff) {
  const Program p = parse("S8000\nG1 X1 F100\nM3\nX2\nM5 X3\nM3 S12000 X4\n");
  ASSERT_EQ(p.blocks.size(), 5u);
  EXPECT_DOUBLE_EQ(p.blocks[0].spindle_rpm, 0);  // S alone does not start the spindle
  EXPECT_DOUBLE_EQ(p.blocks[1].spindle_rpm, 8000);
  EXPECT_DOUBLE_EQ(p.blocks[2].spindle_rpm, 0);
  EXPECT_DOUBLE_EQ(p.blocks[3].spindle_rpm, 12000);
}

TEST(GcodeParser, M30EndsTheProgram) {
  const Program p = parse("G0 X1 Y1\nG1 Z-1 F50 M30\nG0 X99\nQ5 not even G-code (\n");
  ASSERT_EQ(p.blocks.size(), 3u);
  expect_point(p.blocks[1].end, 1, 1, -1);
  expect_end_block(p, 1, 1, -1);
  EXPECT_EQ(p.blocks.back().source_line, 2);
}

TEST(GcodeParser, M2EndsTheProgram) {
  const Program p = parse("G0 X1\nM2\nG0 X2\n");
  ASSERT_EQ(p.blocks.size(), 2u);
  expect_end_block(p, 1, 0, 0);
}

TEST(GcodeParser, MissingFileIsReported) {
  try {
    GcodeParser(xyz_settings()).parse_file("/nonexistent/prog.nc");
    FAIL() << "a missing file parsed";
  } catch (const ProgramError& e) {
    EXPECT_EQ(e.where().file, "/nonexistent/prog.nc");
    EXPECT_NE(std::string(e.what()).find("cannot open"), std::string::npos) << e.what();
  }
}

// ---- refusals ----------------------------------------------------------------------

TEST(GcodeParserError, UnknownWord) {
  expect_error_at("G0 X0\nG1 X1 F100 Q5\n", 2, 12, "unknown word 'Q'");
}

TEST(GcodeParserError, UnknownGCode) { expect_error_at("G0 X1\n  G7 X1\n", 2, 3, "unsupported G code 'G7'"); }

TEST(GcodeParserError, MalformedGCode) { expect_error_at("G0.25 X1\n", 1, 1, "malformed G code"); }

TEST(GcodeParserError, UnsupportedMCode) { expect_error_at("G0 X1 M6\n", 1, 7, "unsupported M code 'M6'"); }

TEST(GcodeParserError, NumberOutOfRange) {
  // The column is that of the number, right after its letter.
  expect_error_at("G0 X99999999\n", 1, 5, "out of range");
}

TEST(GcodeParserError, MissingNumber) { expect_error_at("G0 X\n", 1, 5, "expected a number after 'X'"); }

TEST(GcodeParserError, MissingNumberBeforeNextWord) {
  expect_error_at("G0 X Y1\n", 1, 6, "expected a number after 'X'");
}

TEST(GcodeParserError, UnterminatedComment) {
  expect_error_at("G0 X1\nG0 X2 (no end\n", 2, 7, "unterminated comment");
}

TEST(GcodeParserError, NestedComment) { expect_error_at("G0 (a (b) c) X1\n", 1, 7, "nested comment"); }

TEST(GcodeParserError, UnexpectedCharacter) { expect_error_at("G0 X1 #3\n", 1, 7, "unexpected character '#'"); }

TEST(GcodeParserError, LineWithoutAnyFeed) {
  expect_error_at("G0 X1\nG1 X2\n", 2, 1, "feed rate not set", xyz_settings(0));
}

TEST(GcodeParserError, ModalLineWithoutAnyFeedPointsAtTheBlock) {
  expect_error_at("G1\n  X2\n", 2, 3, "feed rate not set", xyz_settings(0));
}

TEST(GcodeParserError, AxisWordsBeforeAnyMotionMode) {
  expect_error_at("G21\n  X1 Y2\n", 2, 3, "axis words without a motion mode");
}

TEST(GcodeParserError, DuplicateWord) { expect_error_at("G0 X1 X2\n", 1, 7, "'X' appears twice"); }

TEST(GcodeParserError, TwoMotionCodes) { expect_error_at("G0 G1 X1\n", 1, 4, "two motion codes"); }

TEST(GcodeParserError, PWithoutG4) { expect_error_at("G0 X1 P2\n", 1, 7, "P word without G4"); }

TEST(GcodeParserError, G4WithoutP) { expect_error_at("G0 X1\nG4\n", 2, 1, "expected a P word"); }

TEST(GcodeParserError, G4WithAxisWords) { expect_error_at("G4 P1 X2\n", 1, 1, "cannot be combined with axis words"); }

TEST(GcodeParserError, NonPositiveFeed) { expect_error_at("G1 X1 F0\n", 1, 7, "positive feed rate"); }


// ---- arcs --------------------------------------------------------------------------

void expect_center(const Block& b, double x, double y, double z) {
  ASSERT_TRUE(b.kind == BlockKind::kArcCw || b.kind == BlockKind::kArcCcw) << to_string(b.kind);
  expect_point(b.arc.center, x, y, z);
}

TEST(GcodeParserArc, IjkQuarterCircle) {
  const Program p = parse("G0 X10 Y0\nG3 X0 Y10 I-10 J0 F100\n");
  ASSERT_EQ(p.blocks.size(), 3u);
  const Block& a = p.blocks[1];
  EXPECT_EQ(a.kind, BlockKind::kArcCcw);
  EXPECT_EQ(a.arc.plane, 17);
  EXPECT_EQ(a.arc.turns, 0);
  expect_center(a, 0, 0, 0);
  expect_point(a.start, 10, 0, 0);
  expect_point(a.end, 0, 10, 0);
  EXPECT_DOUBLE_EQ(a.feed_mm_per_min, 100);
}

TEST(GcodeParserArc, MissingOffsetIsZero) {
  const Program p = parse("G2 X10 Y0 I5 F100\n");  // J omitted: 0
  expect_center(p.blocks[0], 5, 0, 0);
  EXPECT_EQ(p.blocks[0].kind, BlockKind::kArcCw);
}

TEST(GcodeParserArc, RadiusFormPicksTheShortOrLongArc) {
  // From (0,0) to (10,10), radius 10: the two candidate centres are (10,0) and (0,10).
  const Program p = parse(
      "G2 X10 Y10 R10 F100\n"    // short clockwise: centre to the right of the chord
      "G0 X0 Y0\nG2 X10 Y10 R-10\n"  // long clockwise
      "G0 X0 Y0\nG3 X10 Y10 R10\n"   // short counter-clockwise
      "G0 X0 Y0\nG3 X10 Y10 R-10\n");  // long counter-clockwise
  ASSERT_EQ(p.blocks.size(), 8u);
  expect_center(p.blocks[0], 10, 0, 0);
  expect_center(p.blocks[2], 0, 10, 0);
  expect_center(p.blocks[4], 0, 10, 0);
  expect_center(p.blocks[6], 10, 0, 0);
}

TEST(GcodeParserArc, RadiusFormSemicircle) {
  const Program p = parse("G2 X10 Y0 R5 F100\n");
  expect_center(p.blocks[0], 5, 0, 0);
}

TEST(GcodeParserArc, RadiusSlightlyBelowHalfChordIsASemicircle) {
  // 0.001 mm short of half the chord: within the 0.002 mm tolerance.
  const Program p = parse("G2 X10 Y0 R4.999 F100\n");
  expect_center(p.blocks[0], 5, 0, 0);
}

TEST(GcodeParserArc, FullCircleWithIjk) {
  const Program p = parse("G0 X3 Y4\nG2 X3 Y4 I-3 J-4 F100\n");
  const Block& a = p.blocks[1];
  expect_center(a, 0, 0, 0);
  EXPECT_EQ(a.start, a.end);
  EXPECT_EQ(a.arc.turns, 0);
}

TEST(GcodeParserArc, HelixWithTurns) {
  const Program p = parse("G3 X0 Y0 Z-2 I5 P3 F100\n");
  const Block& a = p.blocks[0];
  EXPECT_EQ(a.kind, BlockKind::kArcCcw);
  EXPECT_EQ(a.arc.turns, 2);  // P3: the circle three times, i.e. two extra turns
  expect_center(a, 5, 0, 0);
  expect_point(a.end, 0, 0, -2);
}

TEST(GcodeParserArc, PlaneG18UsesZAndX) {
  const Program p = parse("G18 G2 X10 Z0 I5 K0 F100\n");
  const Block& a = p.blocks[0];
  EXPECT_EQ(a.arc.plane, 18);
  expect_center(a, 5, 0, 0);
  const Program q = parse("G18 G3 X0 Z10 K5 Y3 F100\n");  // helix along Y
  EXPECT_EQ(q.blocks[0].arc.plane, 18);
  expect_center(q.blocks[0], 0, 0, 5);
  expect_point(q.blocks[0].end, 0, 3, 10);
}

TEST(GcodeParserArc, PlaneG19UsesYAndZ) {
  const Program p = parse("G19 G3 Y10 Z0 J5 F100\n");
  const Block& a = p.blocks[0];
  EXPECT_EQ(a.arc.plane, 19);
  EXPECT_EQ(a.kind, BlockKind::kArcCcw);
  expect_center(a, 0, 5, 0);
}

TEST(GcodeParserArc, PlaneIsModal) {
  const Program p = parse("G18\nG2 X10 Z0 I5 F100\nG17 X20 Y0 I5\n");
  EXPECT_EQ(p.blocks[0].arc.plane, 18);
  EXPECT_EQ(p.blocks[1].arc.plane, 17);
  EXPECT_EQ(p.blocks[1].kind, BlockKind::kArcCw);  // G2 is modal
}

TEST(GcodeParserArc, OffsetsAreIncrementalUnderG90AndG91) {
  const Program p = parse("G0 X10\nG2 X20 Y0 I5 F100\nG91 G2 X10 Y0 I5\n");
  expect_center(p.blocks[1], 15, 0, 0);
  expect_point(p.blocks[2].end, 30, 0, 0);
  expect_center(p.blocks[2], 25, 0, 0);
}

TEST(GcodeParserArc, InchesScaleEndCentreAndRadius) {
  const Program p = parse("G20 G2 X1 Y0 I0.5 F10\nG3 X0 Y0 R0.5\n");
  expect_point(p.blocks[0].end, 25.4, 0, 0);
  expect_center(p.blocks[0], 12.7, 0, 0);
  expect_center(p.blocks[1], 12.7, 0, 0);
}

TEST(GcodeParserArcError, RadiusMismatchNamesTheOffset) {
  expect_error_at("G2 X10 Y0.5 I5 F100\n", 1, 13, "arc radius mismatch");
}

TEST(GcodeParserArcError, MismatchWithinToleranceIsAccepted) {
  EXPECT_NO_THROW(parse("G2 X10 Y0.2 I5 F100\n"));  // 0.004 mm of 5 mm: within 0.1 %
}

TEST(GcodeParserArcError, NoCentreNoRadius) { expect_error_at("G3 X1 Y1 F100\n", 1, 1, "G3 needs its centre or radius"); }

TEST(GcodeParserArcError, ModalArcWithoutCentrePointsAtTheBlock) {
  expect_error_at("G2 X10 I5 F100\n  X20\n", 2, 3, "G2 needs its centre or radius");
}

TEST(GcodeParserArcError, CentreAtTheStart) { expect_error_at("G2 X10 I0 J0 F100\n", 1, 8, "centre is its start point"); }

TEST(GcodeParserArcError, BadTurns) { expect_error_at("G2 X10 I5 P0.5 F100\n", 1, 11, "whole number of turns"); }

TEST(GcodeParserArcError, ArcsNeedThePlaneAxes) {
  ParserSettings s = xyz_settings(100);
  s.axis_names = {"X", "Y"};
  s.start_position_mm = {0, 0};
  expect_error_at("G18 G2 X10 I5\n", 1, 5, "arcs in the G18 plane need machine axes Z and X", s);
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

TEST(GcodeParserNurbs, FanucFig11) {
  const Program p = parse(kFig11Fanuc);
  ASSERT_EQ(p.blocks.size(), 4u);  // G0, the NURBS, G0, end
  const Block& n = p.blocks[1];
  EXPECT_EQ(n.kind, BlockKind::kNurbs);
  EXPECT_EQ(n.index, 1);
  EXPECT_EQ(n.source_line, 5);
  EXPECT_EQ(n.nurbs.order, 4);
  EXPECT_EQ(n.nurbs.knots, (std::vector<double>{0, 0, 0, 0, 0.2, 0.4, 0.6, 0.8, 1, 1, 1, 1}));
  const std::vector<std::array<double, 3>> cps = {{0, 0, 0},   {10, 0, 0},  {20, 0, -10}, {30, 0, -20},
                                                   {40, 0, -20}, {50, 0, -10}, {60, 0, 0},   {70, 0, 0}};
  EXPECT_EQ(n.nurbs.control_points, cps);
  EXPECT_EQ(n.nurbs.weights, std::vector<double>(8, 1.0));
  expect_point(n.start, 0, 0, 0);
  expect_point(n.end, 70, 0, 0);
  EXPECT_DOUBLE_EQ(n.feed_mm_per_min, 2000);
  EXPECT_DOUBLE_EQ(n.spindle_rpm, 10000);
  EXPECT_DOUBLE_EQ(n.process.ball_radius_mm, 5);
  EXPECT_EQ(n.process.flutes, 2);
  EXPECT_DOUBLE_EQ(n.process.pick_feed_mm, 0.5);
  EXPECT_DOUBLE_EQ(n.process.target_rmax_um, 10.67);
  expect_point(p.blocks[2].start, 70, 0, 0);  // the program goes on from the last control point
  expect_point(p.blocks[2].end, 70, 0, 5);
}

TEST(GcodeParserNurbs, FanucWeightsDefaultToOneAndOmittedAxesKeepTheirValue) {
  const Program p = parse("G0 X1 Y2 Z3\nG06.2 P2 K0 F100\nK0 X5 R0.5\nK0.5 Y7 R2\nK1\nK1\n");
  const Block& n = p.blocks[1];
  ASSERT_EQ(n.kind, BlockKind::kNurbs);
  const std::vector<std::array<double, 3>> cps = {{1, 2, 3}, {5, 2, 3}, {5, 7, 3}};
  EXPECT_EQ(n.nurbs.control_points, cps);
  EXPECT_EQ(n.nurbs.weights, (std::vector<double>{1, 0.5, 2}));
  EXPECT_EQ(n.nurbs.knots, (std::vector<double>{0, 0, 0.5, 1, 1}));
}

TEST(GcodeParserNurbs, FanucIncrementalControlPoints) {
  // Under G91 each control point is relative to the one before; the first is X0 Y0 Z0.
  const Program p = parse("G0 X10 Y10\nG91 G06.2 P2 K0 X0 Y0 Z0 F100\nK0 X5\nK0.5 X5 Y-2\nK1\nK1\n");
  const Block& n = p.blocks[1];
  const std::vector<std::array<double, 3>> cps = {{10, 10, 0}, {15, 10, 0}, {20, 8, 0}};
  EXPECT_EQ(n.nurbs.control_points, cps);
  expect_point(n.end, 20, 8, 0);
}

TEST(GcodeParserNurbs, InchesScaleControlPointsNotKnotsOrWeights) {
  const Program p = parse("G20 G06.2 P2 K0 X0 Y0 Z0 F10\nK0 X1 Y0.5 R2\nK2\nK2\n");
  const Block& n = p.blocks[0];
  ASSERT_EQ(n.nurbs.control_points.size(), 2u);
  EXPECT_DOUBLE_EQ(n.nurbs.control_points[1][0], 25.4);
  EXPECT_DOUBLE_EQ(n.nurbs.control_points[1][1], 12.7);
  EXPECT_EQ(n.nurbs.knots, (std::vector<double>{0, 0, 2, 2}));
  EXPECT_EQ(n.nurbs.weights, (std::vector<double>{1, 2}));
  EXPECT_DOUBLE_EQ(n.feed_mm_per_min, 254);
  expect_point(n.end, 25.4, 12.7, 0);
}

TEST(GcodeParserNurbs, CurveEndsAtTheEndOfTheFileAndBeforeTheNextCurve) {
  const Program p = parse("G06.2 P2 K0 X0 Y0 Z0 F100\nK0 X1\nK1\nK1\nG06.2 P2 K0 X1 F100\nK0 X2\nK1\nK1");
  ASSERT_EQ(p.blocks.size(), 3u);
  expect_point(p.blocks[0].end, 1, 0, 0);
  expect_point(p.blocks[1].start, 1, 0, 0);
  expect_point(p.blocks[1].end, 2, 0, 0);
  EXPECT_EQ(p.blocks[2].kind, BlockKind::kEnd);
}

TEST(GcodeParserNurbs, CommentsInsideACurve) {
  const Program p = parse("G06.2 P2 K0 X0 Y0 Z0 F100\n(a remark)\nK0 X1 ; more\n\nK1\nK1\nM30\n");
  EXPECT_EQ(p.blocks[0].kind, BlockKind::kNurbs);
}

TEST(GcodeParserNurbs, NoMotionModeAfterACurve) {
  expect_error_at("G06.2 P2 K0 X0 Y0 Z0 F100\nK0 X1\nK1\nK1\nX5\n", 5, 1, "axis words without a motion mode");
}

TEST(GcodeParserNurbsError, FirstControlPointUnderG91MustBeZero) {
  expect_error_at("G0 X10\nG91 G06.2 P2 K0 X1 F100\nK0 X1\nK1\nK1\n", 2, 17, "is not where the tool is");
}

TEST(GcodeParserNurbsError, FirstControlPointWithinAMicrometreIsContinuous) {
  EXPECT_NO_THROW(parse("G0 X10\nG06.2 P2 K0 X10.0000005 F100\nK0 X11\nK1\nK1\n"));
}

TEST(GcodeParserNurbsError, NurbsNeedsXyz) {
  ParserSettings s = xyz_settings(100);
  s.axis_names = {"X", "Y"};
  s.start_position_mm = {0, 0};
  expect_error_at("G06.2 P2 K0 X0\n", 1, 1, "machine axes X, Y and Z", s);
}

TEST(GcodeParserNurbsError, OtherAxesCannotTakePart) {
  ParserSettings s = xyz_settings(100);
  s.axis_names = {"X", "Y", "Z", "A"};
  s.start_position_mm = {0, 0, 0, 0};
  expect_error_at("G06.2 P2 K0 X0 A1\n", 1, 16, "a NURBS moves X, Y and Z only", s);
}

// ---- NURBS, LinuxCNC G5.2 / G5.3 ---------------------------------------------------

TEST(GcodeParserNurbs, LinuxCncDocumentationExample) {
  const Program p = parse("G0 X0 Y0 Z-1\nF10\nG5.2 P1 L3\nX0 Y1 P1\nX2 Y2 P1\nX2 Y0 P1\nX0 Y0 P2\nG5.3\nG0 X1\n");
  ASSERT_EQ(p.blocks.size(), 4u);
  const Block& n = p.blocks[1];
  EXPECT_EQ(n.kind, BlockKind::kNurbs);
  EXPECT_EQ(n.source_line, 3);
  EXPECT_EQ(n.nurbs.order, 3);
  // The start point is control point 0; LinuxCNC's uniform clamped knots for 5 points of order 3.
  const std::vector<std::array<double, 3>> cps = {{0, 0, -1}, {0, 1, -1}, {2, 2, -1}, {2, 0, -1}, {0, 0, -1}};
  EXPECT_EQ(n.nurbs.control_points, cps);
  EXPECT_EQ(n.nurbs.weights, (std::vector<double>{1, 1, 1, 1, 2}));
  EXPECT_EQ(n.nurbs.knots, (std::vector<double>{0, 0, 0, 1, 2, 3, 3, 3}));
  EXPECT_DOUBLE_EQ(n.feed_mm_per_min, 10);
  expect_point(n.end, 0, 0, -1);
  EXPECT_EQ(p.blocks[2].kind, BlockKind::kRapid);
}

TEST(GcodeParserNurbs, LinuxCncDefaultsAndFirstLinePoint) {
  // Without L the order is 3; X Y on the G5.2 line is the second control point and
  // the start point weighs 1.
  const Program p = parse("G0 X1 Y1\nG5.2 X2 Y3 P4 F100\nX5 Y5 P1\nG5.3\n");
  const Block& n = p.blocks[1];
  EXPECT_EQ(n.nurbs.order, 3);
  const std::vector<std::array<double, 3>> cps = {{1, 1, 0}, {2, 3, 0}, {5, 5, 0}};
  EXPECT_EQ(n.nurbs.control_points, cps);
  EXPECT_EQ(n.nurbs.weights, (std::vector<double>{1, 4, 1}));
  EXPECT_EQ(n.nurbs.knots, (std::vector<double>{0, 0, 0, 1, 1, 1}));
}

TEST(GcodeParserNurbs, LinuxCncFig11KnotsAreFig11sScaled) {
  std::string prog = "G0 X0 Y30\nG5.2 P1 L4 F2000\n";
  for (const char* xy : {"X10 Y30", "X20 Y20", "X30 Y10", "X40 Y10", "X50 Y20", "X60 Y30", "X70 Y30"})
    prog += std::string(xy) + " P1\n";
  prog += "G5.3\n";
  const Program p = parse(prog);
  const Block& n = p.blocks[1];
  EXPECT_EQ(n.nurbs.order, 4);
  EXPECT_EQ(n.nurbs.knots, (std::vector<double>{0, 0, 0, 0, 1, 2, 3, 4, 5, 5, 5, 5}));
  EXPECT_EQ(n.nurbs.control_points.size(), 8u);
  expect_point(n.end, 70, 30, 0);
}

TEST(GcodeParserNurbs, LinuxCncIncrementalIsFromTheCurveStart) {
  // LinuxCNC moves the current point only at G5.3, so G91 offsets all refer to the start.
  const Program p = parse("G0 X10 Y10\nG91 G5.2 F100\nX1 Y0 P1\nX2 Y1 P1\nG5.3\n");
  const std::vector<std::array<double, 3>> cps = {{10, 10, 0}, {11, 10, 0}, {12, 11, 0}};
  EXPECT_EQ(p.blocks[1].nurbs.control_points, cps);
}

TEST(GcodeParserNurbs, LinuxCncInches) {
  const Program p = parse("G20 F10\nG5.2 L3\nX1 Y0 P1\nX1 Y1 P1\nG5.3\n");
  EXPECT_DOUBLE_EQ(p.blocks[0].nurbs.control_points[2][1], 25.4);
}

TEST(GcodeParserNurbs, LinuxCncRepeatedG52ContinuesTheCurve) {
  const Program p = parse("F100\nG5.2 P1\nG5.2 X1 Y0 P1\nG5.2 X2 Y1 P1\nG5.3\nM2\n");
  ASSERT_EQ(p.blocks.size(), 2u);
  EXPECT_EQ(p.blocks[0].nurbs.control_points.size(), 3u);
}

TEST(GcodeParserNurbsError, LinuxCncPWithoutXyAfterTheFirstLine) {
  expect_error_at("F100\nG5.2 P1\nX1 Y0 P1\nP2\nG5.3\n", 4, 1, "P without X and Y");
}

TEST(GcodeParserNurbsError, LinuxCncCloseLineTakesNoPoint) {
  expect_error_at("F100\nG5.2 P1\nX1 Y0 P1\nG5.3 X2 Y1\n", 4, 6, "G5.3 takes no control point");
}

TEST(GcodeParserNurbsError, NoEndOnTheOpeningLine) {
  expect_error_at("G06.2 P2 K0 X0 Y0 Z0 F100 M30\nK0 X1\nK1\nK1\n", 1, 27, "cannot end on the line that opens");
  expect_error_at("F100\nG5.2 P1 M2\nX1 Y0 P1\nX2 Y0 P1\nG5.3\n", 2, 9, "cannot end on the line that opens");
}

TEST(GcodeParserNurbsError, LinuxCncOrderBelowThreeIsRefusedNotChanged) {
  expect_error_at("F100\nG5.2 P1 L2\n", 2, 9, "LinuxCNC uses 3 for any L below 4");
}

TEST(GcodeParserNurbsError, AtMostTenThousandControlPoints) {
  std::string prog = "G06.2 P2 K0 X0 Y0 Z0 F100\n";
  for (int i = 1; i <= 10000; ++i) prog += "K0 X" + std::to_string(i) + "\n";
  expect_error_at(prog, 10001, 1, "more than 10000 control points in one NURBS curve");
}

// ---- process directive -------------------------------------------------------------

TEST(GcodeParserProcess, DirectiveAppliesFromItsLineOn) {
  ParserSettings s = xyz_settings(100);
  s.process = ProcessParams{3, 4, 0.2, 5};  // from the machine config
  const Program p = parse("G1 X1\n(process, pick_feed=0.7, Flutes=2) G1 X2\nX3\n(PROCESS,RMAX_UM=0)\nX4\n", s);
  ASSERT_EQ(p.blocks.size(), 5u);
  EXPECT_DOUBLE_EQ(p.blocks[0].process.pick_feed_mm, 0.2);
  EXPECT_EQ(p.blocks[0].process.flutes, 4);
  for (int i : {1, 2}) {
    EXPECT_DOUBLE_EQ(p.blocks[i].process.ball_radius_mm, 3);  // not in the directive: kept
    EXPECT_EQ(p.blocks[i].process.flutes, 2);
    EXPECT_DOUBLE_EQ(p.blocks[i].process.pick_feed_mm, 0.7);
    EXPECT_DOUBLE_EQ(p.blocks[i].process.target_rmax_um, 5);
    EXPECT_TRUE(p.blocks[i].process.active());
  }
  EXPECT_DOUBLE_EQ(p.blocks[3].process.target_rmax_um, 0);
  EXPECT_FALSE(p.blocks[3].process.active());  // RMAX_UM=0: the roughness law is off
}

TEST(GcodeParserProcess, DirectiveIsInMillimetresUnderG20) {
  const Program p = parse("G20 (PROCESS, BALL_RADIUS=5, PICK_FEED=0.5) G1 X1\n", xyz_settings(100));
  EXPECT_DOUBLE_EQ(p.blocks[0].process.ball_radius_mm, 5);
  EXPECT_DOUBLE_EQ(p.blocks[0].process.pick_feed_mm, 0.5);
}

TEST(GcodeParserProcess, AnOrdinaryCommentIsNotADirective) {
  EXPECT_NO_THROW(parse("(process the part twice)\n(PROCESSED)\nG0 X1\n"));
}

TEST(GcodeParserProcessError, DuplicateKey) {
  expect_error_at("(PROCESS, FLUTES=2, flutes=3)\n", 1, 21, "FLUTES appears twice");
}

TEST(GcodeParserProcessError, NegativeRadius) {
  expect_error_at("(PROCESS, BALL_RADIUS=-1)\n", 1, 11, "expected a positive radius");
}

TEST(GcodeParserProcessError, NanValue) { expect_error_at("(PROCESS, RMAX_UM=nan)\n", 1, 11, "expected a number, found 'nan'"); }

TEST(GcodeParserProcessError, MissingSeparator) {
  expect_error_at("(PROCESS, FLUTES=2 PICK_FEED=1)\n", 1, 20, "expected ',' or ')'");
}

// ---- limits ------------------------------------------------------------------------

TEST(GcodeParserError, OverlongLine) {
  expect_error_at("G0 X1\n" + std::string(5000, ' ') + "\n", 2, 4097, "line longer than 4096 characters");
}

}  // namespace
}  // namespace cnc::program
