// M66, wait on an input, as LinuxCNC 2.9 has it: its checks and messages, the
// canonical call, and the value read into #5399 before the next line (rs274's
// simulated machine: #5399 as it was, a digital input 0 or 1; with results supplied,
// the machine's value, -1 on a timeout). M67/M68 set analog outputs.
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
  void wait_input(const SourceRef& r, int index, bool analog, int mode, double timeout_s) override {
    char buf[128];
    std::snprintf(buf, sizeof buf, "WAIT line %d %s%d L%d Q%g", r.line, analog ? "E" : "P", index, mode, timeout_s);
    calls.push_back(buf);
  }
  void analog_output(const SourceRef&, int index, double value, bool sync) override {
    char buf[128];
    std::snprintf(buf, sizeof buf, "%s E%d %g", sync ? "M67" : "M68", index, value);
    calls.push_back(buf);
  }
  void message(const SourceRef&, const std::string& t) override { calls.push_back("MSG " + t); }

 private:
  void add(const char* what, const Pose& p) {
    char buf[128];
    std::snprintf(buf, sizeof buf, "%s %g %g %g", what, p[0], p[1], p[2]);
    calls.push_back(buf);
  }
};

using test::TempDir;

MachineSetup io_setup(bool supplied) {
  MachineSetup s;
  s.digital_inputs = 2;
  s.analog_inputs = 1;
  s.analog_outputs = 2;
  s.machine_results_supplied = supplied;
  return s;
}

std::string refusal(const std::string& text, MachineSetup setup = io_setup(false)) {
  TempDir dir;
  const std::string path = dir.write("main.ngc", text);
  Recorder rec;
  Interpreter in(setup, rec);
  try {
    in.open(path);
    while (in.execute_next()) {
    }
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "accepted: " << text;
  return "accepted";
}

TEST(Rs274Input, Rs274sSimulatedMachineKeepsTheParameter) {
  // LinuxCNC's rs274: GET_EXTERNAL_DIGITAL_INPUT(index, #5399 != 0), the analog one #5399.
  TempDir dir;
  const std::string path = dir.write("main.ngc",
                                     "M66 P1 L3 Q2.5\n(debug, #5399)\n#5399 = 7\nM66 P0\n(debug, #5399)\n"
                                     "#5399 = 2.5\nM66 E0 L0\n(debug, #5399)\nM2\n");
  Recorder rec;
  Interpreter in(io_setup(false), rec);
  in.open(path);
  while (in.execute_next()) {
  }
  const std::vector<std::string> want = {"WAIT line 1 P1 L3 Q2.5", "MSG  0.000000", "WAIT line 4 P0 L0 Q0",
                                         "MSG  1.000000",          "WAIT line 7 E0 L0 Q0", "MSG  2.500000"};
  EXPECT_EQ(rec.calls, want);
}

TEST(Rs274Input, WaitsForTheMachinesValueAndBranchesOnIt) {
  // The next line is read only once the value is in; a timeout (-1) takes the other branch.
  for (const double value : {1.0, -1.0}) {
    TempDir dir;
    const std::string path = dir.write("main.ngc",
                                       "G21 G90 G0 X1\nM66 P1 L1 Q5\no10 if [#5399 LT 0]\nG0 X-1\no10 else\n"
                                       "G0 X[#5399 * 10]\no10 endif\nM2\n");
    Recorder rec;
    Interpreter in(io_setup(true), rec);
    in.open(path);
    while (!in.waiting_for_input()) ASSERT_TRUE(in.execute_next());
    EXPECT_EQ(in.input_waits_made(), 1);
    const size_t n = rec.calls.size();
    ASSERT_TRUE(in.execute_next());  // nothing is read meanwhile
    EXPECT_EQ(rec.calls.size(), n);
    EXPECT_THROW(in.set_probe_result(false, {}, {}), std::logic_error);
    in.set_input_result(value);
    EXPECT_FALSE(in.waiting_for_input());
    EXPECT_DOUBLE_EQ(in.parameters().get(5399), value);
    while (in.execute_next()) {
    }
    ASSERT_FALSE(rec.calls.empty());
    EXPECT_EQ(rec.calls.back(), value < 0 ? "G0 -1 0 0" : "G0 10 0 0");
    EXPECT_THROW(in.set_input_result(0), std::logic_error);
  }
}

TEST(Rs274Input, LinuxCncsRefusals) {
  EXPECT_NE(refusal("M66 P0 E0\nM2\n").find("invalid to select both a digital and an analog input with M66"),
            std::string::npos);
  // L 1..4 needs a timeout: no Q, or Q 0.
  EXPECT_NE(refusal("M66 P0 L1\nM2\n").find("zero timeout with wait type != immediate return"), std::string::npos);
  EXPECT_NE(refusal("M66 P0 L3 Q0\nM2\n").find("zero timeout"), std::string::npos);
  EXPECT_NE(refusal("M66 E0 L3 Q1\nM2\n").find("can't select analog input with wait type != immediate return"),
            std::string::npos);
  EXPECT_NE(refusal("M66 L0\nM2\n").find("need to have either a valid P or a valid E word with M66"), std::string::npos);
  EXPECT_NE(refusal("M66 P-1\nM2\n").find("need to have either a valid P or a valid E word"), std::string::npos);
  EXPECT_NE(refusal("M66 P0 L5 Q1\nM2\n").find("the wait mode is 0 (immediate)"), std::string::npos);
  // The index beyond the machine's inputs names the count and the key; at its column.
  const std::string p = refusal("M66 P2 L3 Q1\nM2\n");
  EXPECT_NE(p.find("main.ngc:1:5: digital input selected out of bounds: M66 P2, and this machine has 2 (0..1) "
                   "(io.digital_inputs)"),
            std::string::npos)
      << p;
  EXPECT_NE(refusal("M66 E1\nM2\n").find("analog input selected out of bounds: M66 E1, and this machine has 1"),
            std::string::npos);
  MachineSetup none = io_setup(false);
  none.digital_inputs = 0;
  EXPECT_NE(refusal("M66 P0\nM2\n", none).find("this machine has none"), std::string::npos);
  EXPECT_NE(refusal("G21 G0 X0 Y0\nG41 D0\nG1 X10 F100\nM66 P0\nM2\n").find("cannot wait for digital input with cutter radius compensation on"),
            std::string::npos);
  // L belongs to M66 here, not to a G code.
  EXPECT_NE(refusal("M3 L2\nM2\n").find("L word with no G code or M code that uses it"), std::string::npos);
}

TEST(Rs274Input, AnalogOutputs) {
  TempDir dir;
  const std::string path = dir.write("main.ngc", "M67 E1 Q2.5\nM68 E0 Q-1\nM2\n");
  Recorder rec;
  Interpreter in(io_setup(false), rec);
  in.open(path);
  while (in.execute_next()) {
  }
  const std::vector<std::string> want = {"M67 E1 2.5", "M68 E0 -1"};
  EXPECT_EQ(rec.calls, want);
  EXPECT_NE(refusal("M68 E2 Q1\nM2\n").find("output index 2 outside 0..1"), std::string::npos);
  EXPECT_NE(refusal("M67 Q1\nM2\n").find("M67 needs an E word"), std::string::npos);
}

}  // namespace
}  // namespace cnc::rs274
