// Fanuc-style subprograms as LinuxCNC 2.9 runs them (its tests/interp/m98m99):
// a bare O-word heads a subprogram, M98 P<n> L<k> calls it k times, M99 returns
// (in the main program: the end, as M2, or a loop back to the start), #1..#30 are
// shared with the caller; the refusals of mixed styles, each at file:line:column.
// Also the block-comment rule (only a line's last ( ) comment runs) and the note
// rs274 makes when a program opened by '%' does not close with one.
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

// Records the calls a test looks at, as short text.
class Recorder : public Canon {
 public:
  std::vector<std::string> calls;
  void straight_traverse(const SourceRef& r, const Pose& p) override { add(r, "G0", p); }
  void straight_feed(const SourceRef& r, const Pose& p) override { add(r, "G1", p); }
  void arc_feed(const SourceRef&, double, double, double, double, int, double, const Pose&) override {
    calls.push_back("ARC");
  }
  void nurbs_feed(const SourceRef&, int, const std::vector<NurbsPoint>&, const std::vector<double>&,
                  const Pose&) override {
    calls.push_back("NURBS");
  }
  void dwell(const SourceRef&, double) override { calls.push_back("DWELL"); }
  void comment(const SourceRef&, const std::string& s) override { calls.push_back("COMMENT(" + s + ")"); }
  void message(const SourceRef&, const std::string& s) override { calls.push_back("MSG(" + s + ")"); }
  void program_end(const SourceRef& r) override { calls.push_back("END@" + std::to_string(r.line)); }
  void finish(const SourceRef& r) override { calls.push_back("FINISH@" + std::to_string(r.line)); }
  void set_tool_table_entry(const SourceRef&, int index, int tool, const Pose& o, double, double, double,
                            int) override {
    char buf[96];
    std::snprintf(buf, sizeof buf, "TOOL(%d,%d,%.4f,%.4f,%.4f)", index, tool, o[0], o[1], o[2]);
    calls.push_back(buf);
  }
  // The traverses and feeds only, as "G0 x y z".
  std::vector<std::string> moves() const {
    std::vector<std::string> out;
    for (const std::string& c : calls)
      if (c.rfind("G0 ", 0) == 0 || c.rfind("G1 ", 0) == 0) out.push_back(c);
    return out;
  }
  std::vector<std::string> messages() const {
    std::vector<std::string> out;
    for (const std::string& c : calls)
      if (c.rfind("MSG(", 0) == 0) out.push_back(c.substr(4, c.size() - 5));
    return out;
  }

 private:
  void add(const SourceRef&, const char* what, const Pose& p) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "%s %g %g %g", what, p[0], p[1], p[2]);
    calls.push_back(buf);
  }
};

using test::TempDir;

struct Outcome {
  Recorder canon;
  bool ended = false;
  int64_t lines = 0;
  double param(int i) const { return params[static_cast<size_t>(i)]; }
  std::vector<double> params = std::vector<double>(32, 0.0);
};

// Runs a program to its end (or `max_lines` lines); the Error propagates.
void run(Outcome& out, const std::string& text, MachineSetup setup = {}, int64_t max_lines = 100000,
         const TempDir* dir = nullptr) {
  TempDir own;
  const TempDir& d = dir ? *dir : own;
  const std::string path = d.write("main.ngc", text);
  Interpreter in(setup, out.canon);
  in.open(path);
  while (in.lines_executed() < max_lines && in.execute_next()) {
  }
  out.ended = in.ended();
  out.lines = in.lines_executed();
  for (int i = 1; i < 32; ++i) out.params[static_cast<size_t>(i)] = in.parameters().get(i);
}

// The refusal of a program: its Error.
Error refusal(const std::string& text, MachineSetup setup = {}) {
  Outcome r;
  try {
    run(r, text, std::move(setup));
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "the program was accepted";
  return Error(0, "accepted");
}

std::vector<std::string> g0x(std::initializer_list<double> xs, double y = 0, double z = 0) {
  std::vector<std::string> out;
  for (double x : xs) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "G0 %g %g %g", x, y, z);
    out.push_back(buf);
  }
  return out;
}

// ---- calls and returns -----------------------------------------------------------------

TEST(Rs274Subprogram, M98WithLRunsTheSubprogramLTimes) {
  Outcome r;
  run(r,
      "%\n"
      "G21 G90 G0 X0 Y0 Z0\n"
      "M98 P1 L3\n"
      "M30\n"
      "O1\n"
      "G91 G0 X1\n"
      "G90\n"
      "M99\n"
      "%\n");
  EXPECT_TRUE(r.ended);
  EXPECT_EQ(r.canon.moves(), g0x({0, 1, 2, 3}));
}

TEST(Rs274Subprogram, M98WithoutLRunsOnceAndL0NotAtAll) {
  Outcome r;
  run(r,
      "#1 = 0\n"
      "M98 P7\n"
      "M98 P7 L0\n"
      "M98 P999 L0 (no such subprogram: L0 does not look for it)\n"
      "M98 P7 L2\n"
      "M2\n"
      "O7\n"
      "#1 = [#1 + 1]\n"
      "M99\n");
  EXPECT_TRUE(r.ended);
  EXPECT_DOUBLE_EQ(r.param(1), 3.0);
}

TEST(Rs274Subprogram, M98SharesNumberedParametersOCallScopesThem) {
  // LinuxCNC's 02-variables: #1..#30 are global across M98, local to an O-call.
  Outcome r;
  run(r,
      "#1 = 42.01\n#30 = 42.3\n#31 = 42.31\n"
      "M98 P1\n"
      "#2 = #1\n#3 = #30\n#4 = #31\n"
      "#1 = 42.01\n#30 = 42.3\n#31 = 42.31\n"
      "O2 call\n"
      "M30\n"
      "O1\n#1 = 13.01\n#30 = 13.3\n#31 = 13.31\nM99\n"
      "O2 sub\n#1 = 13.01\n#30 = 13.3\n#31 = 13.31\nO2 endsub\n");
  EXPECT_DOUBLE_EQ(r.param(2), 13.01);  // changed by the M98 subprogram
  EXPECT_DOUBLE_EQ(r.param(3), 13.3);
  EXPECT_DOUBLE_EQ(r.param(4), 13.31);
  EXPECT_DOUBLE_EQ(r.param(1), 42.01);  // restored after the O-call
  EXPECT_DOUBLE_EQ(r.param(30), 42.3);
  EXPECT_DOUBLE_EQ(r.param(31), 13.31);  // #31 is global for both
}

TEST(Rs274Subprogram, NamedLocalsGetAFreshScopePerRun) {
  Outcome r;
  run(r,
      "#2 = 0\n"
      "M98 P5 L3\n"
      "M2\n"
      "O5\n"
      "O10 if [EXISTS[#<seen>]]\n#2 = [#2 + 100]\nO10 endif\n"
      "#<seen> = 1\n#2 = [#2 + 1]\n"
      "M99\n");
  EXPECT_DOUBLE_EQ(r.param(2), 3.0);
}

TEST(Rs274Subprogram, NestedSubprogramsRepeatIndependently) {
  // LinuxCNC's 07-nested-subs: O2 runs 5 times, each running O1 5 times.
  Outcome r;
  run(r,
      "#1 = 0\n#2 = 0\n"
      "M98 P2 L5\n"
      "M30\n"
      "O2\nM98 P1 L5\n#1 = [#1 + 1]\nM99\n"
      "O1\n#2 = [#2 + 1]\nM99\n");
  EXPECT_DOUBLE_EQ(r.param(1), 5.0);
  EXPECT_DOUBLE_EQ(r.param(2), 25.0);
}

TEST(Rs274Subprogram, NumbersCompareAsIntegersAndTheFirstHeadWins) {
  // LinuxCNC's 10-M98-P001: P0002 is subprogram 2, O0002 is its head, O2 after it is not reached.
  Outcome r;
  run(r,
      "M98 P0002\n"
      "M30\n"
      "O0002\n(DEBUG,first)\nM99\n"
      "O2\n(DEBUG,second)\nM99\n");
  EXPECT_EQ(r.canon.messages(), std::vector<std::string>{"first"});
}

TEST(Rs274Subprogram, ExpressionsNameTheSubprogram) {
  // LinuxCNC's 14-o-expression-call.
  Outcome r;
  run(r,
      "#2 = 10\n"
      "O[#2 * 10] call\n"
      "M98 P[5 * 5 * 2 * 2 + 100]\n"
      "M30\n"
      "O100 sub\n(DEBUG,in 100)\nO100 endsub\n"
      "O200\n(DEBUG,in 200)\nM99\n");
  EXPECT_EQ(r.canon.messages(), (std::vector<std::string>{"in 100", "in 200"}));
}

TEST(Rs274Subprogram, SubprogramFromAFileOnTheSubroutinePath) {
  TempDir dir;
  std::filesystem::create_directory((dir.path() / "subs").string());
  dir.write("subs/1234.ngc", "O1234 (a subprogram file)\n#5 = [#5 + 2]\nM99\n");
  MachineSetup s;
  s.subroutine_path = {(dir.path() / "subs").string()};
  Outcome r;
  run(r, "#5 = 1\nM98 P1234 L2\nM2\n", s, 100000, &dir);
  EXPECT_TRUE(r.ended);
  EXPECT_DOUBLE_EQ(r.param(5), 5.0);
}

TEST(Rs274Subprogram, BareOWordIsAProgramTitle) {
  // LinuxCNC's 11-main-program-oword and 13-named-program.
  Outcome r;
  run(r, "%\nO<MyProgram> (title)\nO42\nG0 X1\nM30\n%\n");
  EXPECT_TRUE(r.ended);
  EXPECT_EQ(r.canon.moves(), g0x({1}));
}

TEST(Rs274Subprogram, M99InTheMainProgramEndsItAsM2) {
  // rs274 (LinuxCNC's standalone interpreter): the program runs once (12-M99-endless-main-program).
  Outcome r;
  run(r, "G0 X1\nM99\nG0 X2\n");
  EXPECT_TRUE(r.ended);
  EXPECT_EQ(r.canon.moves(), g0x({1}));
  EXPECT_EQ(r.canon.calls.back(), "END@2");
}

TEST(Rs274Subprogram, M99InTheMainProgramLoopsWhenTheMachineSaysSo) {
  // LinuxCNC's task: back to the first line, here until a counter ends it with M30.
  MachineSetup s;
  s.loop_on_main_m99 = true;
  Outcome r;
  run(r,
      "%\n"
      "#100 = [#100 + 1]\n"
      "O1 if [#100 GT 3]\nM30\nO1 endif\n"
      "G0 X#100\n"
      "M99\n"
      "%\n",
      s);
  EXPECT_TRUE(r.ended);
  EXPECT_EQ(r.canon.moves(), g0x({1, 2, 3}));
  int finishes = 0;
  for (const std::string& c : r.canon.calls) finishes += c == "FINISH@7";
  EXPECT_EQ(finishes, 3);
}

TEST(Rs274Subprogram, EndlessMainProgramIsBoundedByTheCaller) {
  MachineSetup s;
  s.loop_on_main_m99 = true;
  Outcome r;
  run(r, "G0 X1\nM99\n", s, 1000);
  EXPECT_FALSE(r.ended);
  EXPECT_EQ(r.lines, 1000);
}

// ---- refusals, each where LinuxCNC refuses -----------------------------------------------

TEST(Rs274Subprogram, M98WithoutPIsRefused) {
  const Error e = refusal("%\n(c)\nM98\nM30\nO1\nM99\n%\n");
  EXPECT_EQ(e.where().line, 3);
  EXPECT_EQ(e.where().column, 1);
  EXPECT_NE(e.detail().find("without a P word"), std::string::npos) << e.what();
}

TEST(Rs274Subprogram, M98ToAMissingSubprogramIsRefused) {
  const Error e = refusal("%\nG0 X1\nN20 M98 P1\nM30\n%\nO1\nM99\n");  // O1 after the closing '%' does not count
  EXPECT_EQ(e.where().line, 3);
  EXPECT_EQ(e.where().column, 5);
  EXPECT_NE(e.detail().find("no subprogram O1"), std::string::npos) << e.what();
}

TEST(Rs274Subprogram, FanucSubprogramCalledWithOCallIsRefusedAtItsHead) {
  const Error e = refusal("%\nO1 call\nM30\nO1\n(DEBUG, fanuc)\nM99\n%\n");
  EXPECT_EQ(e.where().line, 4);
  EXPECT_EQ(e.where().column, 1);
  EXPECT_NE(e.detail().find("called with M98 P1"), std::string::npos) << e.what();
  ASSERT_EQ(e.call_chain().size(), 1u);
  EXPECT_NE(e.call_chain()[0].find(":2:1 (o<1> call)"), std::string::npos) << e.call_chain()[0];
}

TEST(Rs274Subprogram, OSubCalledWithM98IsRefusedAtItsHead) {
  const Error e = refusal("%\nM98 P1\nM30\n  O1 sub\n(DEBUG, sub)\nO1 endsub\n%\n");
  EXPECT_EQ(e.where().line, 4);
  EXPECT_EQ(e.where().column, 3);
  EXPECT_NE(e.detail().find("o<1> call, not M98"), std::string::npos) << e.what();
  ASSERT_EQ(e.call_chain().size(), 1u);
  EXPECT_NE(e.call_chain()[0].find(":2:1 (M98 P1)"), std::string::npos) << e.call_chain()[0];
}

TEST(Rs274Subprogram, FanucSubprogramEndedByEndsubIsRefused) {
  const Error e = refusal("%\nM98 P1\nM30\nO1\n(DEBUG, fanuc)\nO1 endsub\n%\n");
  EXPECT_EQ(e.where().line, 6);
  EXPECT_EQ(e.where().column, 1);
  EXPECT_NE(e.detail().find("it ends with M99"), std::string::npos) << e.what();
}

TEST(Rs274Subprogram, OSubEndedByM99IsRefused) {
  const Error e = refusal("%\nO1 call\nM30\nO1 sub\n(DEBUG, sub)\n M99\n%\n");
  EXPECT_EQ(e.where().line, 6);
  EXPECT_EQ(e.where().column, 2);
  EXPECT_NE(e.detail().find("endsub or return"), std::string::npos) << e.what();
}

TEST(Rs274Subprogram, M98AndM99OnlyAsTheFirstWord) {
  Error e = refusal("G0 X1 M98 P1\nM2\nO1\nM99\n");
  EXPECT_EQ(e.where().line, 1);
  EXPECT_EQ(e.where().column, 7);
  e = refusal("M98 P1\nM2\nO1\nG0 X1 M99\n");
  EXPECT_EQ(e.where().line, 4);
  EXPECT_EQ(e.where().column, 7);
  e = refusal("M98 P1\nM2\nO1\nM99 X1\n");
  EXPECT_EQ(e.where().line, 4);
  EXPECT_EQ(e.where().column, 5);
}

TEST(Rs274Subprogram, M98TakesOnlyPAndL) {
  Error e = refusal("M98 P1 X5\nM2\nO1\nM99\n");
  EXPECT_EQ(e.where().column, 8);
  e = refusal("M98 P1.5\nM2\n");
  EXPECT_EQ(e.where().column, 5);
  e = refusal("M98 P1 L-1\nM2\nO1\nM99\n");
  EXPECT_EQ(e.where().column, 8);
}

TEST(Rs274Subprogram, DisabledFanucSubprogramsAreRefused) {
  // LinuxCNC's [RS274NGC]DISABLE_FANUC_STYLE_SUB (09-disable-fanuc-subs).
  MachineSetup s;
  s.fanuc_subs = false;
  Error e = refusal("G0 X1\nM98 P1 L3\nM30\nO1\nM99\n", s);
  EXPECT_EQ(e.where().line, 2);
  EXPECT_NE(e.detail().find("DISABLE_FANUC_STYLE_SUB"), std::string::npos) << e.what();
  e = refusal("O1\nM30\n", s);
  EXPECT_EQ(e.where().line, 1);
  // O-word subroutines still run.
  Outcome r;
  run(r, "O1 sub\nG0 X1\nO1 endsub\nO1 call\nM30\n", s);
  EXPECT_EQ(r.canon.moves(), g0x({1}));
}

// ---- comments and the closing '%' ----------------------------------------------------------

TEST(Rs274Subprogram, OnlyTheLastCommentOfALineRunsAndAnEmptyOneMakesNoCall) {
  Outcome r;
  run(r, "%\n()\n(a) (b)\n(MSG,x) (c)\n(c) (MSG,y)\n(a) ; b\n(a)()\nM30\n%\n");
  std::vector<std::string> got;
  for (const std::string& c : r.canon.calls)
    if (c.rfind("COMMENT", 0) == 0 || c.rfind("MSG", 0) == 0) got.push_back(c);
  EXPECT_EQ(got, (std::vector<std::string>{"COMMENT(b)", "COMMENT(c)", "MSG(y)", "COMMENT(a)"}));
}

TEST(Rs274Subprogram, ProgramOpenedByPercentWithoutClosingOneIsNoted) {
  Outcome r;
  run(r, "%\nG0 X1\nM30\n");
  ASSERT_GE(r.canon.calls.size(), 2u);
  EXPECT_EQ(r.canon.calls[r.canon.calls.size() - 2], "END@3");
  EXPECT_EQ(r.canon.calls.back(), "COMMENT(interpreter: percent sign missing from end of file)");
  Outcome closed;
  run(closed, "%\nG0 X1\nM30\n  %  \n");
  EXPECT_EQ(closed.canon.calls.back(), "END@3");
}

// ---- G10 L1/L10 and the tool table entry -----------------------------------------------------

TEST(Rs274Subprogram, G10L10InARotatedSystemAndTheToolTableEntry) {
  // LinuxCNC's tests/interp/g10/g10-l1-l10: with G54 rotated 45 degrees, G10 L10 X1 at
  // the origin gives the tool offset (-0.707, -0.707); G43 then shows the point as X1 Y0.
  TempDir dir;
  MachineSetup s;
  s.tool_table = dir.write("t.tbl", "T1 P1 Z0 ;one\nT2 P2 Z0 ;two\n");
  Outcome r;
  run(r,
      "G21 G10 L2 P1 R45\nG0 X0 Y0 Z0\nT1 M6\nG10 L10 P1 X1\nG43\n#1 = #5420\n#2 = #5421\n"
      "G10 L10 P2 Y1\nM2\n",
      s, 100000, &dir);
  std::vector<std::string> tools;
  for (const std::string& c : r.canon.calls)
    if (c.rfind("TOOL", 0) == 0) tools.push_back(c);
  ASSERT_EQ(tools.size(), 3u);
  EXPECT_EQ(tools[0], "TOOL(1,1,-0.7071,-0.7071,0.0000)");
  EXPECT_EQ(tools[1], "TOOL(0,1,-0.7071,-0.7071,0.0000)");  // the tool in the spindle: entry 0 too
  EXPECT_EQ(tools[2].substr(0, 9), "TOOL(2,2,");              // not in the spindle: its entry only
  EXPECT_NEAR(r.param(1), 1.0, 1e-9);
  EXPECT_NEAR(r.param(2), 0.0, 1e-9);
}

// The cell's tool touch-off (README "Tool-length touch-off"): the tool in the spindle is
// #5400 of the var file, a program starts with it, and G10 L10 is written back to the
// tool table at the program's end, where the next program's G43 finds it.
TEST(Rs274Subprogram, ToolInTheSpindleFromTheVarFileAndTheTableWrittenBack) {
  TempDir dir;
  MachineSetup s;
  s.tool_table = dir.write("t.tbl", "T1 P1 Z0 D6 ;end mill\nT2 P2 Z4 ;two\n");
  s.var_file = dir.write("v.var", "5400\t1.000000\n");
  s.tool_in_var_file = true;
  s.write_tool_table = true;
  s.start_position[2] = -1.5;  // machine Z where the tool touches
  Outcome touch;
  run(touch, "#1 = #5400\nG10 L10 P#5400 Z0\nM2\n", s, 100000, &dir);
  EXPECT_NEAR(touch.param(1), 1.0, 0);  // the tool the var file had in the spindle
  std::ifstream in(s.tool_table);
  const std::string table((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(table, "T1 P1 Z-1.500000 D+6.000000 ;end mill\nT2 P2 Z+4.000000 D+0.000000 ;two\n");
  // The next program: G43 (no H: the tool in the spindle) makes Z read 0 at machine -1.5.
  s.start_position[2] = 0;
  Outcome next;
  run(next, "G43\n#1 = #5422\nG0 Z0\n#2 = #5400\nM61 Q0\nM2\n", s, 100000, &dir);
  EXPECT_NEAR(next.param(1), 1.5, 1e-9);
  EXPECT_NEAR(next.param(2), 1.0, 0);
  // M61 Q0 emptied the spindle: kept in the var file for the next program.
  Outcome empty;
  run(empty, "#1 = #5400\nM2\n", s, 100000, &dir);
  EXPECT_EQ(empty.param(1), 0.0);
}

// Found by fuzz_gcode (UBSan): M98 L333...3 (98 digits) converted the count to int64_t, beyond its range.
TEST(Rs274Subprogram, RepeatCountBeyondInt32IsRefused) {
  const Error e = refusal("G90\nM98 P1000 L3333333333333333333333\nM30\nO1000\nM99\n");
  EXPECT_EQ(e.where().line, 2);
  EXPECT_EQ(e.where().column, 11);
  EXPECT_NE(e.detail().find("repeat count is at most 2147483647"), std::string::npos) << e.what();
}

// ---- M6 remapped (program.m6_remap; LinuxCNC's REMAP=M6 ngc=NAME) ---------------------

// A remapped M6 calls its subroutine with change_prolog's locals; an M6 in it is the
// built-in change; the rest of the M6's block (G0 X9 here) runs after the return.
// LinuxCNC 2.9's rs274 with REMAP=M6 modalgroup=6 ngc=change makes the same calls
// (without a Python prolog its locals are unset).
TEST(Rs274Subprogram, ARemappedM6CallsItsSubroutineAndTheBlockGoesOnAfter) {
  TempDir dir;
  dir.dir("subs");
  dir.write("subs/change.ngc",
            "o<change> sub\n(debug, #<selected_tool> #<tool_in_spindle> #<selected_pocket> #<current_pocket>)\n"
            "G0 Z5\nM6\nG0 X1\no<change> endsub [1]\nM2\n");
  MachineSetup s;
  s.subroutine_path = {(dir.path() / "subs").string()};
  s.m6_remap = "change";
  Outcome r;
  run(r, "G21 G90 G0 X2 Y0 Z0\nT3 M6 G0 X9\nT3 M6\nM2\n", s, 100000, &dir);
  EXPECT_TRUE(r.ended);
  EXPECT_EQ(r.canon.moves(), (std::vector<std::string>{"G0 2 0 0", "G0 2 0 5", "G0 1 0 5", "G0 9 0 5", "G0 9 0 5",
                                                         "G0 1 0 5"}));
  EXPECT_EQ(r.canon.messages(), (std::vector<std::string>{" 3.000000 0.000000 3.000000 0.000000",
                                                            " 3.000000 3.000000 3.000000 3.000000"}));
}

TEST(Rs274Subprogram, ARemappedM6ThatReturnsANegativeValueAborts) {
  TempDir dir;
  dir.dir("subs");
  dir.write("subs/change.ngc", "o<change> sub\no<change> endsub [-2]\nM2\n");
  MachineSetup s;
  s.subroutine_path = {(dir.path() / "subs").string()};
  s.m6_remap = "change";
  Outcome r;
  try {
    run(r, "G21 G90\nT1 M6 G0 X9\nM2\n", s, 100000, &dir);
    FAIL() << "accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.where().line, 2) << e.what();
    EXPECT_NE(e.file_name().find("main.ngc"), std::string::npos) << e.what();
    EXPECT_NE(e.detail().find("M6 aborted (o<change> returned -2"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(r.canon.moves().empty());
}

}  // namespace
}  // namespace cnc::rs274
