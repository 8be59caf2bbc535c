// G38.2-G38.5 straight probing as LinuxCNC 2.9 has it: the canonical calls (rs274's
// TURN_PROBE_ON, STRAIGHT_PROBE, TURN_PROBE_OFF), the refusals before the move, and the
// result read before the next line: #5061-#5069 where the probe input changed (current
// work coordinates, program units), #5070 1 or 0, the current point where the machine
// came to rest. With results supplied the interpreter reads no line until it has one.
#include <gtest/gtest.h>

#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/rs274/canon.h"
#include "common/rs274/interpreter.h"
#include "tests/unit/temp_dir.h"

namespace cnc::rs274 {
namespace {

class Recorder : public Canon {
 public:
  std::vector<std::string> calls;
  void straight_traverse(const SourceRef&, const Pose& p) override { add("G0", p); }
  void straight_feed(const SourceRef&, const Pose& p) override { add("G1", p); }
  void arc_feed(const SourceRef&, double, double, double, double, int, double, const Pose&) override {}
  void nurbs_feed(const SourceRef&, int, const std::vector<NurbsPoint>&, const std::vector<double>&,
                  const Pose&) override {}
  void dwell(const SourceRef&, double) override {}
  void turn_probe_on(const SourceRef&) override { calls.push_back("ON"); }
  void straight_probe(const SourceRef& r, const Pose& p, int kind) override {
    add(("P" + std::to_string(kind) + " line " + std::to_string(r.line)).c_str(), p);
  }
  void turn_probe_off(const SourceRef&) override { calls.push_back("OFF"); }
  void message(const SourceRef&, const std::string& t) override { calls.push_back("MSG " + t); }

 private:
  void add(const char* what, const Pose& p) {
    char buf[128];
    std::snprintf(buf, sizeof buf, "%s %g %g %g", what, p[0], p[1], p[2]);
    calls.push_back(buf);
  }
};

using test::TempDir;

MachineSetup probe_setup(bool supplied) {
  MachineSetup s;
  s.has_probe = true;
  s.machine_results_supplied = supplied;
  return s;
}

Error refusal(const std::string& text, MachineSetup setup = probe_setup(false)) {
  TempDir dir;
  const std::string path = dir.write("main.ngc", text);
  Recorder rec;
  Interpreter in(setup, rec);
  try {
    in.open(path);
    while (in.execute_next()) {
    }
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "accepted: " << text;
  return Error(0, "accepted");
}

TEST(Rs274Probe, CanonicalCallsAndRs274sSimulatedResultWithoutAMachine) {
  // rs274 (no machine): the probe at the move's end, not tripped (#5070 = 0), as
  // LinuxCNC's rs274 prints it for this program.
  TempDir dir;
  const std::string path = dir.write("main.ngc",
                                     "G21 G90 G0 X1 Y2 Z10\nF100\nG38.2 Z-5\n"
                                     "(debug, #5061 #5062 #5063 #5070)\nG0 Z[#5063+1]\nM2\n");
  Recorder rec;
  Interpreter in(probe_setup(false), rec);
  in.open(path);
  while (in.execute_next()) {
  }
  const std::vector<std::string> want = {"G0 1 2 10", "ON", "P2 line 3 1 2 -5", "OFF",
                                         "MSG  1.000000 2.000000 -5.000000 0.000000", "G0 1 2 -4"};
  EXPECT_EQ(rec.calls, want);
}

// The probing subroutines take machine Z from #5063 and the coordinate system's offset,
// #[5203 + 20 * #5220]: #5220 reads 1 in G54 from the start, without a var file, as
// LinuxCNC's (it read 0, and the tool setter wrote a length 3 mm off under a G54 Z -3).
TEST(Rs274Probe, TheCoordinateSystemNumberReadsOneInG54WithoutAVarFile) {
  TempDir dir;
  const std::string path = dir.write("main.ngc", "G21\n(debug, #5220)\nG55\n(debug, #5220)\nM2\n");
  Recorder rec;
  Interpreter in(probe_setup(false), rec);
  in.open(path);
  while (in.execute_next()) {
  }
  const std::vector<std::string> want = {"MSG  1.000000", "MSG  2.000000"};
  EXPECT_EQ(rec.calls, want);
}

TEST(Rs274Probe, Rs274sSimulatedMachineBacksOffFromTheEnd) {
  // saicanon's STRAIGHT_PROBE leaves the machine 0.254 mm (0.01 in) back from the
  // move's end towards its start: a relative move after it starts there (LinuxCNC's
  // rs274 prints -8.7460 and, in inches, -1.6700 for these programs).
  for (const auto& [text, want] :
       {std::pair{"G21 G90 F10\nG38.2 Z-10\nG91 G1 Z1\nM2\n", "G1 0 0 -8.746"},
        std::pair{"G20 G90 F10\nG38.2 Z-1.75\nG91 G1 Z0.07\nM2\n", "G1 0 0 -1.67"},
        std::pair{"G21 G90 F10\nG0 X3 Y4\nG38.3 X0 Y0\nG91 G1 X0\nM2\n", "G1 0.1524 0.2032 0"}}) {
    TempDir dir;
    const std::string path = dir.write("main.ngc", text);
    Recorder rec;
    Interpreter in(probe_setup(false), rec);
    in.open(path);
    while (in.execute_next()) {
    }
    ASSERT_FALSE(rec.calls.empty());
    EXPECT_EQ(rec.calls.back(), want) << text;
  }
}

TEST(Rs274Probe, WaitsForTheResultAndSetsTheParametersInWorkCoordinates) {
  // G55 with an offset and G20: #5061-#5063 in the work system and in inches; the next
  // move starts where the machine came to rest (past the trip point).
  TempDir dir;
  const std::string path = dir.write("main.ngc",
                                     "G10 L2 P2 X10 Y20 Z-30\nG55 G20 G90\nG0 X1 Y1 Z1\nF4\nG38.3 Z-1\n"
                                     "G1 Z[#5063 + 0.5]\nM2\n");
  Recorder rec;
  Interpreter in(probe_setup(true), rec);
  in.open(path);
  while (!in.waiting_for_probe()) ASSERT_TRUE(in.execute_next());
  // Nothing is read while the result is awaited.
  const size_t calls = rec.calls.size();
  const int64_t lines = in.lines_executed();
  EXPECT_TRUE(in.execute_next());
  EXPECT_EQ(rec.calls.size(), calls);
  EXPECT_EQ(in.lines_executed(), lines);
  // The target in machine mm: (1, 1, -1) in + G55's offset.
  const Pose t = in.probe_target_machine();
  EXPECT_NEAR(t[0], 10 + 25.4, 1e-9);
  EXPECT_NEAR(t[2], -30 - 25.4, 1e-9);
  Pose trip = t, rest = t;
  trip[2] = -30 + 0.25 * 25.4;  // tripped at Z 0.25 in (work)
  rest[2] = trip[2] - 0.001;    // came to rest 1 um further
  in.set_probe_result(true, trip, rest);
  EXPECT_FALSE(in.waiting_for_probe());
  EXPECT_NEAR(in.parameters().get(5061), 1.0, 1e-12);
  EXPECT_NEAR(in.parameters().get(5062), 1.0, 1e-12);
  EXPECT_NEAR(in.parameters().get(5063), 0.25, 1e-12);
  EXPECT_EQ(in.parameters().get(5070), 1.0);
  EXPECT_NEAR(in.parameters().get(5422), 0.25 - 0.001 / 25.4, 1e-12);  // the current point: the rest
  while (in.execute_next()) {
  }
  EXPECT_EQ(rec.calls.back(), "G1 1 1 0.75");
  EXPECT_THROW(in.set_probe_result(true, trip, rest), std::logic_error);
}

TEST(Rs274Probe, AMissLeavesTheEndAndZero) {
  TempDir dir;
  const std::string path = dir.write("main.ngc", "G0 Z0\nF50\nG38.5 Z-3\nG0 Z[#5063]\nM2\n");
  Recorder rec;
  Interpreter in(probe_setup(true), rec);
  in.open(path);
  while (!in.waiting_for_probe()) ASSERT_TRUE(in.execute_next());
  in.set_probe_result(false, in.probe_target_machine(), in.probe_target_machine());
  EXPECT_EQ(in.parameters().get(5070), 0.0);
  EXPECT_NEAR(in.parameters().get(5063), -3, 1e-12);
  while (in.execute_next()) {
  }
  EXPECT_EQ(in.probes_made(), 1);
}

TEST(Rs274Probe, RefusalsBeforeTheMoveAsLinuxCnc) {
  auto expect = [](const std::string& prog, const std::string& what, int line) {
    MachineSetup s = probe_setup(false);
    s.axes = "XYZA";
    const Error e = refusal(prog, s);
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    EXPECT_EQ(e.where().line, line) << e.what();
  };
  // LinuxCNC 2.9's rs274: only a G38.2/G38.4 of no length (0.1 mm, 1e-7 mm and a
  // G38.3/G38.5 of no length it accepts).
  expect("F100\nG38.2 Z0\nM2\n", "start point too close to probe point", 2);
  expect("G20 F10 G0 Z1\nG38.4 Z1\nM2\n", "start point too close to probe point", 2);
  expect("G38.2 Z-5\nM2\n", "cannot probe with zero feed rate", 1);
  expect("F0\nG38.3 Z-5\nM2\n", "cannot probe with zero feed rate", 2);
  expect("G93 G38.2 Z-5 F1\nM2\n", "cannot probe in inverse time feed mode", 1);
  expect("G95 F0.1\nG38.2 Z-5\nM2\n", "cannot probe with feed per rev mode", 2);
  expect("F100 G0 X0 Y0\nG41 D0 G1 X5\nG38.2 Z-5\nM2\n", "cutter radius compensation on", 3);
  expect("F100\nG38.4 A10 Z-5\nM2\n", "cannot move rotary axes during probing", 2);
  // Without a probe in the config, as before.
  MachineSetup none;
  const Error e = refusal("F100\nG38.2 Z-5\nM2\n", none);
  EXPECT_NE(std::string(e.what()).find("no probe input"), std::string::npos) << e.what();
}

TEST(Rs274Probe, ShortMovesAndAZeroLengthReadAreAccepted) {
  for (const char* prog : {"F100\nG38.2 Z-0.1\nM2\n", "F100\nG38.2 Z-0.0000001\nM2\n", "F100\nG38.3 Z0\nM2\n",
                           "F100\nG38.5 Z0\nM2\n"}) {
    TempDir dir;
    const std::string path = dir.write("main.ngc", prog);
    Recorder rec;
    Interpreter in(probe_setup(false), rec);
    in.open(path);
    EXPECT_NO_THROW({
      while (in.execute_next()) {
      }
    }) << prog;
    EXPECT_EQ(in.probes_made(), 1) << prog;
  }
}

TEST(Rs274Probe, EachKindNamesItself) {
  for (int k = 2; k <= 5; ++k) {
    TempDir dir;
    const std::string path = dir.write("main.ngc", "F100\nG38." + std::to_string(k) + " X4\nM2\n");
    Recorder rec;
    Interpreter in(probe_setup(false), rec);
    in.open(path);
    while (in.execute_next()) {
    }
    ASSERT_GE(rec.calls.size(), 3u);
    EXPECT_EQ(rec.calls[1], "P" + std::to_string(k) + " line 2 4 0 0");
  }
}

}  // namespace
}  // namespace cnc::rs274
