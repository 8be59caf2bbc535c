// Where a call goes, as LinuxCNC 2.9's control_back_to / execute_call decide it:
// * M98 P<n> L<k>: a run counter of the caller's level takes L once; while runs remain
//   M99 returns to the M98 line, which is read again, so P#n is evaluated per run;
// * o<name> call: a subroutine the program ran through before, else <name>.ngc on the
//   subroutine path (the first 10 directories that exist) or in the program's folder,
//   else o<name> sub further down the current file from the call (not before it);
// * a sub head inside a sub definition is refused (nested subroutine definition).
// Expectations checked against rs274 (tools/conformance) where it can run them.
#include <gtest/gtest.h>

#include <unistd.h>

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

class Recorder : public Canon {
 public:
  std::vector<std::string> moves;
  void straight_traverse(const SourceRef&, const Pose& p) override { add("G0", p); }
  void straight_feed(const SourceRef&, const Pose& p) override { add("G1", p); }
  void arc_feed(const SourceRef&, double, double, double, double, int, double, const Pose&) override {}
  void nurbs_feed(const SourceRef&, int, const std::vector<NurbsPoint>&, const std::vector<double>&,
                  const Pose&) override {}
  void dwell(const SourceRef&, double) override {}

 private:
  void add(const char* what, const Pose& p) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "%s %g %g", what, p[0], p[1]);
    moves.push_back(buf);
  }
};

using test::TempDir;

// Runs main.ngc of `dir` to its end; the Error propagates.
std::vector<std::string> run(const TempDir& dir, const std::string& text, MachineSetup setup = {}) {
  const std::string path = dir.write("main.ngc", text);
  Recorder canon;
  Interpreter in(setup, canon);
  in.open(path);
  while (in.execute_next()) {
  }
  EXPECT_TRUE(in.ended());
  return canon.moves;
}

Error refusal(const TempDir& dir, const std::string& text, MachineSetup setup = {}) {
  try {
    run(dir, text, std::move(setup));
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "the program was accepted";
  return Error(0, "accepted");
}

bool has(const Error& e, const std::string& what) { return e.detail().find(what) != std::string::npos; }

// ---- M98 P L ---------------------------------------------------------------------------

TEST(Rs274M98Repeat, PIsReadAgainForEveryRun) {
  // Each subprogram sets #1 (shared with the caller) to the next one's number.
  TempDir d;
  const auto moves = run(d,
                         "G21 G90 F100\n#1 = 100\n"
                         "M98 P#1 L3\n"
                         "M30\n"
                         "O100\nG1 X1 Y#1\n#1 = 200\nM99\n"
                         "O200\nG1 X2 Y#1\n#1 = 300\nM99\n"
                         "O300\nG1 X3 Y#1\n#1 = 100\nM99\n");
  EXPECT_EQ(moves, (std::vector<std::string>{"G1 1 100", "G1 2 200", "G1 3 300"}));
}

TEST(Rs274M98Repeat, LIsReadOnceAtTheFirstRun) {
  // The subprogram changes #2, which L reads: the count stays the first one (LinuxCNC
  // keeps the counter while it runs).
  TempDir d;
  const auto moves = run(d,
                         "G21 G90 F100\n#2 = 2\n#3 = 0\n"
                         "M98 P5 L#2\n"
                         "M30\n"
                         "O5\n#3 = [#3 + 1]\n#2 = 7\nG1 X#3\nM99\n");
  EXPECT_EQ(moves, (std::vector<std::string>{"G1 1 0", "G1 2 0"}));
}

TEST(Rs274M98Repeat, NestedRepeatsKeepTheirOwnCounters) {
  TempDir d;
  const auto moves = run(d,
                         "G21 G90 F100\n#1 = 0\n"
                         "M98 P10 L2\n"
                         "M30\n"
                         "O10\nM98 P20 L3\nG1 X#1 Y1\nM99\n"
                         "O20\n#1 = [#1 + 1]\nM99\n");
  EXPECT_EQ(moves, (std::vector<std::string>{"G1 3 1", "G1 6 1"}));
}

TEST(Rs274M98Repeat, AMissingSubprogramOnALaterRunIsRefusedAtTheM98Line) {
  TempDir d;
  const Error e = refusal(d,
                          "#1 = 1\n"
                          "M98 P#1 L2\n"
                          "M30\n"
                          "O1\n#1 = 2\nM99\n");
  EXPECT_EQ(e.where().line, 2);
  EXPECT_EQ(e.column(), 1);
  EXPECT_TRUE(has(e, "M98 P2: no subprogram O2")) << e.detail();
}

// ---- o<name> call ----------------------------------------------------------------------

TEST(Rs274CallLookup, FurtherDownTheMainProgram) {
  TempDir d;
  const auto moves = run(d, "G21 G90 F100\no<later> call [4]\nM2\no<later> sub\nG1 X#1\no<later> endsub\n");
  EXPECT_EQ(moves, (std::vector<std::string>{"G1 4 0"}));
}

TEST(Rs274CallLookup, AFileOnThePathComesBeforeADefinitionFurtherDown) {
  TempDir d;
  const std::string lib = d.dir("lib");
  d.write("lib/twin.ngc", "o<twin> sub\nG1 X1\no<twin> endsub\nM2\n");
  MachineSetup setup;
  setup.subroutine_path = {lib};
  const auto moves = run(d, "G21 G90 F100\no<twin> call\nM2\no<twin> sub\nG1 X2\no<twin> endsub\n", setup);
  EXPECT_EQ(moves, (std::vector<std::string>{"G1 1 0"}));
}

TEST(Rs274CallLookup, ADefinitionBeforeTheCallThatTheFlowSkippedIsNotFound) {
  // o<helper> sits in the file before o<outer>, which the call jumped to: the program
  // never ran through it, and LinuxCNC only looks further down from the call.
  TempDir d;
  const std::string lib = d.dir("lib");
  d.write("lib/outer.ngc",
          "o<helper> sub\nG1 X9\no<helper> endsub\n"
          "o<outer> sub\no<helper> call\no<outer> endsub\nM2\n");
  MachineSetup setup;
  setup.subroutine_path = {lib};
  const Error e = refusal(d, "G21 G90 F100\no<outer> call\nM2\n", setup);
  EXPECT_EQ(e.where().line, 5);
  EXPECT_EQ(e.column(), 1);
  EXPECT_NE(e.file_name().find("outer.ngc"), std::string::npos) << e.file_name();
  EXPECT_TRUE(has(e, "o<helper> call: no file helper.ngc on the subroutine path nor o<helper> sub further down"))
      << e.detail();
}

TEST(Rs274CallLookup, AHelperAfterTheSubInItsFileIsFound) {
  // LinuxCNC's tests/interp/nested-sub-in-file-error as LinuxCNC 2.9.0 runs it (later
  // versions refuse it): the helper comes after the caller's endsub in the same file.
  TempDir d;
  const std::string subs = d.dir("subs");
  d.write("subs/sequential.ngc",
          "o<sequential> sub\no200 call [4]\no<sequential> endsub\n\no200 sub\nG1 X#1\no200 endsub\nM2\n");
  MachineSetup setup;
  setup.subroutine_path = {subs};
  const auto moves = run(d, "G21 G90 F100\no<sequential> call [7]\nM2\n", setup);
  EXPECT_EQ(moves, (std::vector<std::string>{"G1 4 0"}));
}

TEST(Rs274CallLookup, OnlyTheFirstTenDirectoriesOfThePathCount) {
  TempDir d;
  MachineSetup setup;
  setup.subroutine_path.push_back((d.path() / "missing").string());  // not there: does not count
  for (const char* name : {"p1", "p2", "p3", "p4", "p5", "p6", "p7", "p8", "p9", "p10", "p11"})
    setup.subroutine_path.push_back(d.dir(name));
  d.write("p10/tenth.ngc", "o<tenth> sub\nG1 X10\no<tenth> endsub\nM2\n");
  d.write("p11/eleventh.ngc", "o<eleventh> sub\nG1 X11\no<eleventh> endsub\nM2\n");
  EXPECT_EQ(run(d, "G21 G90 F100\no<tenth> call\nM2\n", setup), (std::vector<std::string>{"G1 10 0"}));
  const Error e = refusal(d, "G21 G90 F100\no<eleventh> call\nM2\n", setup);
  EXPECT_EQ(e.where().line, 2);
  EXPECT_TRUE(has(e, "eleventh.ngc is in directory 11 of the subroutine path, which LinuxCNC does not search"))
      << e.detail();
}

TEST(Rs274CallLookup, ASubHeadInsideASubDefinitionIsRefused) {
  // LinuxCNC's tests/interp/nested-sub-error/subs/nested.ngc: rs274 says "Nested
  // subroutine definition" at the inner head.
  TempDir d;
  const Error e = refusal(d,
                          "o<nested> sub\n"
                          "o100 sub\n"
                          "o100 endsub\n"
                          "o100 call [4] [5] [6]\n"
                          "o<nested> endsub\n"
                          "M2\n");
  EXPECT_EQ(e.where().line, 2);
  EXPECT_EQ(e.column(), 1);
  EXPECT_TRUE(has(e, "nested subroutine definition: a sub inside the definition of o<nested> sub (line 1)"))
      << e.detail();
}

}  // namespace
}  // namespace cnc::rs274
