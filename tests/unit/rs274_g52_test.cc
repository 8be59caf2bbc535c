// G52 (local coordinate system offset) as LinuxCNC 2.9 runs it: G52 and G92 share one
// offset (convert_axis_offsets). G52 sets it for the axes named (the current point
// moves with it), G92 shifts it so the current point gets the values given; both set
// #5210 = 1 and #5211-#5219 to the whole offset and make a SET_G92_OFFSET call; G92.1
// and G92.2 clear it (#5210 = 0; G92.1 also #5211-#5219), G92.3 takes it back from
// #5211-#5219. Refused with cutter compensation on, with polar words, without axes.
// The expectations of the G52/G92 sequence are rs274's output for LinuxCNC's
// tests/interp/g52/g52-g92-interaction.
#include <gtest/gtest.h>

#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "common/rs274/canon.h"
#include "common/rs274/interpreter.h"
#include "tests/unit/temp_dir.h"

namespace cnc::rs274 {
namespace {

// Records the moves (machine-independent program values as the canon gets them) and
// the SET_G92_OFFSET calls.
class Recorder : public Canon {
 public:
  std::vector<std::string> calls;
  void set_g92_offset(const SourceRef&, const Pose& p) override { add("G92", p); }
  void straight_traverse(const SourceRef&, const Pose& p) override { add("G0", p); }
  void straight_feed(const SourceRef&, const Pose& p) override { add("G1", p); }
  void arc_feed(const SourceRef&, double, double, double, double, int, double, const Pose&) override {
    calls.push_back("ARC");
  }
  void nurbs_feed(const SourceRef&, int, const std::vector<NurbsPoint>&, const std::vector<double>&,
                  const Pose&) override {}
  void dwell(const SourceRef&, double) override {}

 private:
  void add(const char* what, const Pose& p) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "%s %g %g %g", what, p[0], p[1], p[2]);
    calls.push_back(buf);
  }
};

using test::TempDir;

// #5210..#5219 after each line that holds "(snap)": the offsets as the program sees them.
using Snap = std::array<double, 10>;

struct Outcome {
  Recorder canon;
  std::vector<Snap> snaps;
};

// `units`: of the parameters (rs274 keeps them in inches; the cell in its machine units).
void run(Outcome& out, const std::string& text, Units units = Units::kMm) {
  TempDir dir;
  const std::string path = dir.write("main.ngc", text);
  MachineSetup setup;
  setup.machine_units = units;
  Interpreter in(setup, out.canon);
  in.open(path);
  while (in.execute_next()) {
    if (in.current_text().find("(snap)") == std::string::npos) continue;
    Snap s{};
    for (int i = 0; i < 10; ++i) s[static_cast<size_t>(i)] = in.parameters().get(5210 + i);
    out.snaps.push_back(s);
  }
}

Error refusal(const std::string& text) {
  Outcome r;
  try {
    run(r, text);
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "the program was accepted";
  return Error(0, "accepted");
}

Snap snap(double flag, double x, double y, double z = 0) { return Snap{flag, x, y, z, 0, 0, 0, 0, 0, 0}; }

TEST(Rs274G52, SharesTheG92OffsetAndItsParametersAsLinuxCncG52G92Interaction) {
  // LinuxCNC's tests/interp/g52/g52-g92-interaction, in inches; the values rs274 prints.
  Outcome r;
  run(r,
      "G20\n"
      "G92 X1 Y2 (snap)\n"
      "G92.2 (snap)\n"
      "G92.3 (snap)\n"
      "G92.1 (snap)\n"
      "G52 X2 Y3 (snap)\n"
      "G92.2 (snap)\n"
      "G92.3 (snap)\n"
      "G52 X0 Y0 (snap)\n"
      "M30\n",
      Units::kInch);
  const std::vector<Snap> want = {
      snap(1, -1, -2),  // G92 X1 Y2 at the origin: offset -1 -2
      snap(0, -1, -2),  // G92.2: offset off, parameters kept
      snap(1, -1, -2),  // G92.3: back from the parameters
      snap(0, 0, 0),    // G92.1: all cleared
      snap(1, 2, 3),    // G52 X2 Y3: the offset is the values given
      snap(0, 2, 3),    // G92.2
      snap(1, 2, 3),    // G92.3
      snap(1, 0, 0),    // G52 X0 Y0: offset zero, #5210 stays 1
  };
  ASSERT_EQ(r.snaps.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) {
    for (size_t k = 0; k < 10; ++k) EXPECT_NEAR(r.snaps[i][k], want[i][k], 1e-12) << "snapshot " << i << " #" << 5210 + k;
  }
  // The canon gets the offset in program units (inches): at the start, then at each change.
  const std::vector<std::string> g92 = {"G92 0 0 0",   "G92 -1 -2 0", "G92 0 0 0", "G92 -1 -2 0", "G92 0 0 0",
                                        "G92 2 3 0",   "G92 0 0 0", "G92 2 3 0",   "G92 0 0 0"};
  std::vector<std::string> got;
  for (const std::string& c : r.canon.calls)
    if (c.rfind("G92 ", 0) == 0) got.push_back(c);
  EXPECT_EQ(got, g92);
}

TEST(Rs274G52, MovesTheOriginAndTheCurrentPointWithIt) {
  Outcome r;
  run(r,
      "G21 G90 G0 X1 Y1 Z1\n"
      "G52 X5 Y-2\n"   // the point stays where it is: in the new system X-4 Y3
      "G0 X0 Y0\n"     // machine X5 Y-2
      "G52 Z3\n"       // axes not named keep their offset
      "G0 Z0\n"        // machine Z3
      "G91 G52 X1\n"   // G91 does not make G52 relative (LinuxCNC)
      "G90 G0 X0\n"    // machine X1
      "M2\n");
  const std::vector<std::string> want = {"G92 0 0 0", "G0 1 1 1",  "G92 5 -2 0", "G0 0 0 1", "G92 5 -2 3",
                                         "G0 0 0 0", "G92 1 -2 3", "G0 0 0 0"};
  EXPECT_EQ(r.canon.calls, want);
}

TEST(Rs274G52, G92AfterG52ShiftsTheSameOffset) {
  Outcome r;
  run(r,
      "G21 G90 G0 X10 Y0 Z0\n"
      "G52 X4 (snap)\n"  // point X6 in the new system
      "G92 X0 (snap)\n"  // offset 4 + 6 = 10
      "M2\n");
  ASSERT_EQ(r.snaps.size(), 2u);
  EXPECT_DOUBLE_EQ(r.snaps[0][1], 4);
  EXPECT_DOUBLE_EQ(r.snaps[1][1], 10);
  EXPECT_DOUBLE_EQ(r.snaps[1][0], 1);
}

TEST(Rs274G52, G92WritesTheWholeOffsetToTheParameters) {
  // After G92.2 the offset is zero but #5211.. keep their values; a G92 naming X
  // writes the whole (zero) offset back, Y included (LinuxCNC's convert_axis_offsets).
  Outcome r;
  run(r,
      "G21 G90 G0 X0 Y0 Z0\n"
      "G92 X1 Y2\n"
      "G92.2 (snap)\n"
      "G92 X3 (snap)\n"
      "M2\n");
  ASSERT_EQ(r.snaps.size(), 2u);
  EXPECT_EQ(r.snaps[0], snap(0, -1, -2));
  EXPECT_EQ(r.snaps[1], snap(1, -3, 0));  // G92.2 put the point back at X0: offset 0 - 3, Y 0
}

TEST(Rs274G52, RefusedWithCutterCompensationOn) {
  const Error e = refusal("G21 G90 G0 X0 Y0 Z0\nG41.1 D2\nG1 X10 F100\nG52 X5\nG40\nM2\n");
  EXPECT_EQ(e.where().line, 4);
  EXPECT_EQ(e.column(), 1);
  EXPECT_NE(e.detail().find("cannot change axis offsets (G52) with cutter radius compensation on"), std::string::npos)
      << e.detail();
  const Error e2 = refusal("G21 G90 G0 X0 Y0 Z0\nG42.1 D2\nG1 X10 F100\nG92.1\nM2\n");
  EXPECT_EQ(e2.where().line, 4);
  EXPECT_NE(e2.detail().find("(G92.1) with cutter radius compensation on"), std::string::npos) << e2.detail();
}

TEST(Rs274G52, RefusedWithoutAxesWithPolarWordsAndWithMotion) {
  const Error none = refusal("G21\nG52\nM2\n");
  EXPECT_EQ(none.where().line, 2);
  EXPECT_NE(none.detail().find("G52 needs at least one axis word"), std::string::npos) << none.detail();
  const Error polar = refusal("G21\nG52 @5 ^10\nM2\n");
  EXPECT_EQ(polar.column(), 5);
  EXPECT_NE(polar.detail().find("polar coordinates"), std::string::npos) << polar.detail();
  const Error two = refusal("G21\nG52 X1 G1 Y3 F100\nM2\n");
  EXPECT_EQ(two.column(), 8);
  EXPECT_NE(two.detail().find("G52 and G1 both use axis words"), std::string::npos) << two.detail();
}

}  // namespace
}  // namespace cnc::rs274
