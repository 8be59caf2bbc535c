// The RS274 parser: blocks with their modal state, and refusals that name the exact
// file:line:column.
#include <gtest/gtest.h>

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

}  // namespace
}  // namespace cnc::program
