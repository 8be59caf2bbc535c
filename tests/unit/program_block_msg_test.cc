// Block <-> lcmt_program_block: a round trip keeps every field, through the LCM wire
// format too; from_msg refuses what the network may bring that the interpolator
// must not see (bad counts, knots, weights, non-finite numbers, broken arcs).
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "common/program/block_msg.h"
#include "tests/unit/program_test_util.h"

namespace cnc::program {
namespace {

const std::string kProgram =
    "(PROCESS, BALL_RADIUS=5, FLUTES=2, PICK_FEED=0.5, RMAX_UM=10.67)\n"
    "S10000 M3\n"
    "G1 X1 F600\n"
    "G18 G2 X11 Z0 I5 K0 P2\n"
    "G17 G0 Z0\n"
    "G06.2 P4 K0 X11 Y0 Z0 R1 F2000\n"
    "K0 X21 R0.5\nK0 X31 Z-10 R2\nK0 X41 Z-20\nK0.5 X51 Z-20\nK1\nK1\nK1\nK1\n"
    "G4 P0.5\n"
    "(MSG, half way)\n"
    "M30\n";

// The blocks of kProgram, through the interpreter and the block builder.
const std::vector<Block>& program_blocks() {
  static const std::vector<Block> blocks = [] {
    test::TempDir dir;
    test::write_file(dir / "t.ngc", kProgram);
    return test::run_program((dir / "t.ngc").string());
  }();
  return blocks;
}

const Block& first_of(BlockKind kind) {
  for (const Block& b : program_blocks())
    if (b.kind == kind) return b;
  ADD_FAILURE() << "no " << to_string(kind) << " block";
  return program_blocks().front();
}

// Decodes what `m` encodes: the bytes a subscriber gets.
cnc::lcmt_program_block over_the_wire(const cnc::lcmt_program_block& m) {
  std::vector<uint8_t> buf(static_cast<size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  cnc::lcmt_program_block out;
  EXPECT_EQ(out.decode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  return out;
}

void expect_same(const Block& a, const Block& b) {
  EXPECT_EQ(a.index, b.index);
  EXPECT_EQ(a.source_line, b.source_line);
  EXPECT_EQ(a.source_column, b.source_column);
  EXPECT_EQ(a.source_file, b.source_file);
  EXPECT_EQ(a.kind, b.kind);
  EXPECT_EQ(a.start, b.start);
  EXPECT_EQ(a.end, b.end);
  EXPECT_EQ(a.feed_mm_per_min, b.feed_mm_per_min);
  EXPECT_EQ(a.dwell_s, b.dwell_s);
  EXPECT_EQ(a.spindle_rpm, b.spindle_rpm);
  EXPECT_EQ(a.process.ball_radius_mm, b.process.ball_radius_mm);
  EXPECT_EQ(a.process.flutes, b.process.flutes);
  EXPECT_EQ(a.process.pick_feed_mm, b.process.pick_feed_mm);
  EXPECT_EQ(a.process.target_rmax_um, b.process.target_rmax_um);
  if (a.kind == BlockKind::kArcCw || a.kind == BlockKind::kArcCcw) {
    EXPECT_EQ(a.arc.center, b.arc.center);
    EXPECT_EQ(a.arc.plane, b.arc.plane);
    EXPECT_EQ(a.arc.turns, b.arc.turns);
  }
  EXPECT_EQ(a.nurbs.order, b.nurbs.order);
  EXPECT_EQ(a.nurbs.knots, b.nurbs.knots);
  EXPECT_EQ(a.nurbs.control_points, b.nurbs.control_points);
  EXPECT_EQ(a.nurbs.weights, b.nurbs.weights);
  EXPECT_EQ(a.event.kind, b.event.kind);
  EXPECT_EQ(a.event.number, b.event.number);
  EXPECT_EQ(a.event.value, b.event.value);
  EXPECT_EQ(a.event.text, b.event.text);
}

TEST(BlockMsg, RoundTripOfEveryKind) {
  const std::vector<Block>& p = program_blocks();
  // The spindle start, the moves, the message, M30's spindle stop (the cell makes no
  // event of M30's pallet shuttle), the end.
  const std::vector<BlockKind> kinds = {BlockKind::kEvent, BlockKind::kLine,  BlockKind::kArcCw,
                                        BlockKind::kRapid, BlockKind::kNurbs, BlockKind::kDwell,
                                        BlockKind::kEvent, BlockKind::kEvent, BlockKind::kEnd};
  ASSERT_EQ(p.size(), kinds.size());
  EXPECT_EQ(p[6].event.kind, EventKind::kMessage);
  EXPECT_EQ(p[6].event.text, " half way");  // LinuxCNC keeps the space after the comma
  for (size_t i = 0; i < p.size(); ++i) {
    SCOPED_TRACE(i);
    const Block& b = p[i];
    EXPECT_EQ(b.kind, kinds[i]);
    const cnc::lcmt_program_block m = to_msg(b, 42);
    EXPECT_EQ(m.program_token, 42);
    Block back;
    ASSERT_EQ(from_msg(m, 3, &back), "");
    expect_same(b, back);
    Block wire;
    ASSERT_EQ(from_msg(over_the_wire(m), 3, &wire), "");
    expect_same(b, wire);
  }
}

TEST(BlockMsg, ArcAndNurbsFieldsOnTheWire) {
  const cnc::lcmt_program_block arc = to_msg(first_of(BlockKind::kArcCw), 1);
  EXPECT_EQ(arc.kind, int8_t{cnc::lcmt_program_block::ARC_CW});
  EXPECT_EQ(arc.plane, 18);
  EXPECT_EQ(arc.turns, 1);
  EXPECT_EQ(arc.center, (std::vector<double>{6, 0, 0}));
  EXPECT_EQ(arc.num_knots, 0);
  const cnc::lcmt_program_block n = to_msg(first_of(BlockKind::kNurbs), 1);
  EXPECT_EQ(n.kind, int8_t{cnc::lcmt_program_block::NURBS});
  EXPECT_EQ(n.order, 4);
  EXPECT_EQ(n.num_knots, 9);
  EXPECT_EQ(n.num_control_points, 5);
  EXPECT_EQ(n.control_points[2], (std::vector<double>{31, 0, -10}));
  EXPECT_EQ(n.weights, (std::vector<double>{1, 0.5, 2, 1, 1}));
  EXPECT_DOUBLE_EQ(n.ball_radius_mm, 5);
  EXPECT_EQ(n.flutes, 2);
  EXPECT_DOUBLE_EQ(n.target_rmax_um, 10.67);
  EXPECT_DOUBLE_EQ(n.spindle_rpm, 10000);
}

// ---- refusals ----------------------------------------------------------------------

const double kNaN = std::numeric_limits<double>::quiet_NaN();
const double kInf = std::numeric_limits<double>::infinity();

cnc::lcmt_program_block nurbs_msg() { return to_msg(first_of(BlockKind::kNurbs), 1); }
cnc::lcmt_program_block arc_msg() { return to_msg(first_of(BlockKind::kArcCw), 1); }

void expect_refused(cnc::lcmt_program_block m, const std::function<void(cnc::lcmt_program_block&)>& spoil,
                    const std::string& fragment) {
  spoil(m);
  Block out;
  out.index = -99;
  const std::string why = from_msg(m, 3, &out);
  EXPECT_NE(why.find(fragment), std::string::npos) << "'" << fragment << "' not in '" << why << "'";
  EXPECT_EQ(out.index, -99) << "a refused message must leave the output alone";
}

TEST(BlockMsgRefuses, NurbsKnotCount) {
  expect_refused(nurbs_msg(), [](auto& m) { m.knots.pop_back(); m.num_knots -= 1; }, "knots for 5 control points");
}

TEST(BlockMsgRefuses, NurbsCountsDisagreeWithArrays) {
  expect_refused(nurbs_msg(), [](auto& m) { m.num_knots += 1; }, "disagree with their counts");
  expect_refused(nurbs_msg(), [](auto& m) { m.weights.pop_back(); }, "disagree with their counts");
  expect_refused(nurbs_msg(), [](auto& m) { m.num_control_points = -1; }, "counts out of range");
  expect_refused(nurbs_msg(), [](auto& m) { m.control_points[1].pop_back(); }, "exactly 3 coordinates");
}

TEST(BlockMsgRefuses, NurbsKnots) {
  expect_refused(nurbs_msg(), [](auto& m) { m.knots[4] = -1; }, "non-decreasing");
  expect_refused(nurbs_msg(), [](auto& m) { m.knots[3] = 0.1; m.knots[4] = 0.6; }, "not clamped");
  expect_refused(nurbs_msg(), [](auto& m) { m.knots[5] = 0.9; }, "not clamped");
  expect_refused(nurbs_msg(), [](auto& m) { m.knots[2] = kNaN; }, "not a finite number");
  expect_refused(nurbs_msg(), [](auto& m) { for (auto& k : m.knots) k = 0; }, "all knots are equal");
}

TEST(BlockMsgRefuses, NurbsWeights) {
  expect_refused(nurbs_msg(), [](auto& m) { m.weights[1] = 0; }, "positive finite weight");
  expect_refused(nurbs_msg(), [](auto& m) { m.weights[1] = -2; }, "positive finite weight");
  expect_refused(nurbs_msg(), [](auto& m) { m.weights[1] = kInf; }, "positive finite weight");
  expect_refused(nurbs_msg(), [](auto& m) { m.weights[1] = kNaN; }, "positive finite weight");
}

TEST(BlockMsgRefuses, NurbsOrderAndPoints) {
  expect_refused(nurbs_msg(), [](auto& m) { m.order = 9; }, "out of range");
  expect_refused(nurbs_msg(), [](auto& m) { m.order = 1; }, "out of range");
  expect_refused(nurbs_msg(), [](auto& m) { m.control_points[2][1] = kNaN; }, "not finite");
  expect_refused(nurbs_msg(), [](auto& m) { m.control_points[0][0] += 0.5; }, "first control point");
  expect_refused(nurbs_msg(), [](auto& m) { m.end[2] += 0.5; }, "last control point");
}

TEST(BlockMsgRefuses, Arcs) {
  expect_refused(arc_msg(), [](auto& m) { m.plane = 20; }, "expected 17, 18 or 19");
  expect_refused(arc_msg(), [](auto& m) { m.center[0] = kNaN; }, "centre is not finite");
  expect_refused(arc_msg(), [](auto& m) { m.center[0] += 1; }, "radii differ");
  expect_refused(arc_msg(), [](auto& m) { m.center = m.start; }, "centre is at the start");
  expect_refused(arc_msg(), [](auto& m) { m.turns = -1; }, "turns out of range");
  expect_refused(arc_msg(), [](auto& m) { m.center.pop_back(); }, "axis arrays disagree");
}

TEST(BlockMsgRefuses, CommonFields) {
  expect_refused(arc_msg(), [](auto& m) { m.num_axes = 4; }, "block has 4 axes, machine has 3");
  expect_refused(arc_msg(), [](auto& m) { m.kind = 8; }, "unknown block kind");
  expect_refused(arc_msg(), [](auto& m) { m.end[1] = kInf; }, "non-finite coordinate");
  expect_refused(arc_msg(), [](auto& m) { m.feed_mm_per_min = 0; }, "without a feed");
  expect_refused(arc_msg(), [](auto& m) { m.feed_mm_per_min = kNaN; }, "bad feed");
  expect_refused(arc_msg(), [](auto& m) { m.spindle_rpm = -1; }, "bad spindle speed");
  expect_refused(arc_msg(), [](auto& m) { m.target_rmax_um = kNaN; }, "bad process parameters");
  expect_refused(arc_msg(), [](auto& m) { m.block_index = -1; }, "negative block index");
}

TEST(BlockMsg, AnEndSaysWhoseEndItIs) {
  // A program's (M2, M30: the spindle and coolant stop) or an operator line's (MDI,
  // jog: they stay): the interpolator reads it off the wire; anything else is refused.
  Block end = program_blocks().back();
  ASSERT_EQ(end.kind, BlockKind::kEnd);
  EXPECT_EQ(end.event.number, kEndOfProgram);
  for (const int32_t kind : {kEndOfProgram, kEndOfOperatorLine}) {
    end.event.number = kind;
    Block wire;
    ASSERT_EQ(from_msg(over_the_wire(to_msg(end, 7)), 3, &wire), "");
    EXPECT_EQ(wire.event.number, kind);
  }
  expect_refused(to_msg(end, 7), [](auto& m) { m.event_number = 2; }, "bad end (2: 0 a program's, 1 an operator line's)");
}

TEST(BlockMsgRefuses, Events) {
  const auto message = [] {
    for (const Block& b : program_blocks())
      if (b.kind == BlockKind::kEvent && b.event.kind == EventKind::kMessage) return to_msg(b, 1);
    ADD_FAILURE() << "no message block";
    return to_msg(program_blocks().front(), 1);
  };
  expect_refused(message(), [](auto& m) { m.event_kind = 0; }, "bad event");
  expect_refused(message(), [](auto& m) { m.event_kind = static_cast<int8_t>(EventKind::kLast) + 1; }, "bad event");
  expect_refused(message(), [](auto& m) { m.event_value = kNaN; }, "bad event");
  expect_refused(message(), [](auto& m) { m.event_text = std::string(5000, 'x'); }, "event text too long");
  expect_refused(arc_msg(), [](auto& m) { m.kind = static_cast<int8_t>(BlockKind::kEvent); }, "bad event");
}

}  // namespace
}  // namespace cnc::program
