// The command interlock (every cell of the README's table), the program server
// node refusing LOAD / START while a program runs and in FAULT, a failed publish
// (counted, no sequence number used, FAULT until RESET), and RESET as a recorded
// interpolator input.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "cnc/lcmt_interp_input.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/motion/interpolator.h"
#include "common/service/operator_commands.h"
#include "services/interpolator/inputs.h"
#include "services/part_program_server/interlock.h"
#include "services/part_program_server/program_server_node.h"

namespace cnc {
namespace {

namespace fs = std::filesystem;
using C = cnc::lcmt_program_command;
using pps::CellState;

lcmt_program_command cmd(int8_t c, double value = 1.0) {
  lcmt_program_command m{};
  m.command = c;
  m.feed_override = value;
  return m;
}

// ---- the table ---------------------------------------------------------------------

TEST(Interlock, EveryCellOfTheTable) {
  const CellState states[] = {CellState::kIdle, CellState::kLoaded, CellState::kRunning, CellState::kHeld,
                              CellState::kFault};
  // Expected: "" allowed, else a fragment of the reason. Columns: idle loaded running held fault.
  struct Row {
    int8_t command;
    const char* expect[5];
  };
  const Row rows[] = {
      {C::LOAD, {"", "", "p.ngc is running: STOP it first", "p.ngc is held: STOP it first", "FAULT (why): RESET first"}},
      {C::START, {"no program is loaded", "", "p.ngc is running already", "p.ngc is held: RESUME it", "FAULT (why)"}},
      {C::HOLD, {"no program is running", "no program is running", "", "", "nothing runs"}},
      {C::RESUME, {"no program is held", "no program is held", "", "", "RESET first"}},
      {C::STOP, {"", "", "", "", ""}},
      {C::OVERRIDE, {"", "", "", "", ""}},
      {C::RESET, {"", "", "p.ngc is running: STOP it first", "p.ngc is held: STOP it first", ""}},
  };
  for (const Row& r : rows) {
    for (int s = 0; s < 5; ++s) {
      pps::CellView v;
      v.state = states[s];
      v.program = "/x/p.ngc";
      v.fault = "why";
      const std::string got = pps::refusal(cmd(r.command), v);
      const std::string want = r.expect[s];
      if (want.empty()) {
        EXPECT_EQ(got, "") << "command " << int(r.command) << " in " << to_string(states[s]);
      } else {
        EXPECT_NE(got.find(want), std::string::npos)
            << "command " << int(r.command) << " in " << to_string(states[s]) << ": '" << got << "'";
      }
    }
  }
}

TEST(Interlock, StartNeedsEnabledDrivesAndOverrideItsRange) {
  pps::CellView v;
  v.state = CellState::kLoaded;
  v.program = "p.ngc";
  v.drives = "axis Y is in fault";
  EXPECT_EQ(pps::refusal(cmd(C::START), v), "axis Y is in fault: enable the drives first");
  EXPECT_NE(pps::refusal(cmd(C::OVERRIDE, 1.6), v).find("outside 0 .. 1.5"), std::string::npos);
  EXPECT_NE(pps::refusal(cmd(C::OVERRIDE, std::nan("")), v).find("outside"), std::string::npos);
  EXPECT_EQ(pps::refusal(cmd(C::OVERRIDE, 0.0), v), "");
}

// the operator commands in every state, and the program commands while an
// operator move runs or the axes are not homed (README, commands and states).
TEST(Interlock, OperatorCommandsInEveryState) {
  const CellState states[] = {CellState::kIdle,  CellState::kLoaded,  CellState::kRunning, CellState::kHeld,
                              CellState::kFault, CellState::kJogging, CellState::kHoming};
  struct Row {
    int8_t command;
    const char* expect[7];
  };
  const char* kMove = "jog X+ continuous runs: STOP it first";
  const Row rows[] = {
      {C::HOME, {"", "", "p.ngc is running: STOP it first", "p.ngc is held: STOP it first", "FAULT (why): RESET first", kMove, kMove}},
      {C::JOG, {"", "", "p.ngc is running: STOP it first", "p.ngc is held: STOP it first", "FAULT (why): RESET first", kMove, kMove}},
      {C::JOG_KEEPALIVE, {"", "", "", "", "", "", ""}},
      {C::TOUCH_OFF, {"", "", "p.ngc is running: STOP it first", "p.ngc is held: STOP it first", "FAULT (why): RESET first", kMove, kMove}},
      {C::MDI, {"", "", "p.ngc is running: STOP it first", "p.ngc is held: STOP it first", "FAULT (why): RESET first", kMove, kMove}},
      {C::HOMED, {"interpolator's own", "interpolator's own", "interpolator's own", "interpolator's own", "interpolator's own", "interpolator's own", "interpolator's own"}},
      {C::SPINDLE_AT_SPEED, {"interpolator's own", "interpolator's own", "interpolator's own", "interpolator's own", "interpolator's own", "interpolator's own", "interpolator's own"}},
      {C::LOAD, {"", "", "STOP it first", "STOP it first", "RESET first", kMove, kMove}},
      {C::START, {"no program is loaded", "", "already", "RESUME it", "RESET first", kMove, kMove}},
      {C::HOLD, {"no program is running", "no program is running", "", "", "nothing runs", "no program is running", "no program is running"}},
      {C::RESUME, {"no program is held", "no program is held", "", "", "RESET first", "no program is held", "no program is held"}},
      {C::STOP, {"", "", "", "", "", "", ""}},
      {C::RESET, {"", "", "STOP it first", "STOP it first", "", kMove, kMove}},
      {C::SINGLE_BLOCK, {"", "", "", "", "", "", ""}},
      {C::OPTIONAL_STOP, {"", "", "", "", "", "", ""}},
      {C::BLOCK_DELETE, {"", "", "p.ngc is running: block delete is read when a program is loaded",
                         "p.ngc is held: block delete is read when a program is loaded", "", "", ""}},
      {C::CONFIRM, {"no approach waits", "no approach waits", "no approach waits", "no approach waits", "RESET first",
                    "no approach waits", "no approach waits"}},
  };
  for (const Row& r : rows) {
    for (int s = 0; s < 7; ++s) {
      pps::CellView v;
      v.state = states[s];
      v.program = "/x/p.ngc";
      v.fault = "why";
      v.motion = "jog X+ continuous";
      lcmt_program_command c = cmd(r.command);
      c.value = 1.0;
      c.text = "G0 X1";
      const std::string got = pps::refusal(c, v);
      const std::string want = r.expect[s];
      if (want.empty()) {
        EXPECT_EQ(got, "") << "command " << int(r.command) << " in " << to_string(states[s]);
      } else {
        EXPECT_NE(got.find(want), std::string::npos)
            << "command " << int(r.command) << " in " << to_string(states[s]) << ": '" << got << "'";
      }
    }
  }
  // Not homed (operator.homing_required): START and MDI refused, jogging, homing and touch-off allowed.
  pps::CellView v;
  v.state = CellState::kLoaded;
  v.unhomed = "axis Z is not homed";
  EXPECT_EQ(pps::refusal(cmd(C::START), v), "axis Z is not homed: HOME first");
  lcmt_program_command mdi = cmd(C::MDI);
  mdi.text = "G0 X1";
  EXPECT_EQ(pps::refusal(mdi, v), "axis Z is not homed: HOME first");
  lcmt_program_command jog = cmd(C::JOG);
  jog.value = -2;
  EXPECT_EQ(pps::refusal(jog, v), "");
  EXPECT_EQ(pps::refusal(cmd(C::HOME), v), "");
  // Bad arguments.
  jog.value = 0;
  EXPECT_NE(pps::refusal(jog, v).find("non-zero"), std::string::npos);
  mdi.text = "G0 X1\nG0 X2";
  EXPECT_NE(pps::refusal(mdi, v).find("one line only"), std::string::npos);
  mdi.text = "";
  EXPECT_NE(pps::refusal(mdi, v).find("empty"), std::string::npos);
  lcmt_program_command tool = cmd(C::TOUCH_OFF);
  tool.value = 50;
  tool.jog_continuous = 2;
  // Allowed here; the program server refuses it without a tool in the spindle (integration.operator).
  EXPECT_EQ(pps::refusal(tool, v), "");
  {
    // On the max-end limit switch of axis 0: a jog towards it (X+) refused, naming the
    // switch, before the bridge would fault on it; away from it (X-) and other axes allowed.
    pps::CellView on = v;
    on.state = CellState::kIdle;
    on.limit_axis = 0;
    on.limit_side = 1;
    on.limit_switch = "x_max";
    lcmt_program_command j = cmd(C::JOG);
    j.axis = 0;
    j.value = 1;
    EXPECT_EQ(pps::refusal(j, on), "jog towards the limit switch x_max, which is open: jog the axis away from it");
    j.jog_continuous = 1;
    EXPECT_NE(pps::refusal(j, on), "");
    j.value = -1;
    EXPECT_EQ(pps::refusal(j, on), "");
    j.axis = 1;
    j.value = 1;
    EXPECT_EQ(pps::refusal(j, on), "");
    on.limit_axis = 1;
    on.limit_side = -1;
    j.value = -0.1;
    EXPECT_NE(pps::refusal(j, on).find("limit switch x_max"), std::string::npos);
  }
  {
    lcmt_program_command r = cmd(C::RAPID_OVERRIDE);
    r.feed_override = 0.25;
    EXPECT_EQ(pps::refusal(r, v), "");
    r.feed_override = 1.5;
    EXPECT_EQ(pps::refusal(r, v), "rapid override 1.500000 is outside 0 .. 1");
  }
  {
    // The spindle override's range is the machine's (spindle.min_override .. max_override).
    lcmt_program_command r = cmd(C::SPINDLE_OVERRIDE);
    r.feed_override = 0.8;
    EXPECT_EQ(pps::refusal(r, v), "");
    r.feed_override = 1.2;
    EXPECT_EQ(pps::refusal(r, v), "spindle override 1.200000 is outside 0.5 .. 1 (spindle.min_override .. max_override)");
    pps::CellView wide = v;
    wide.spindle_max_override = 1.5;
    EXPECT_EQ(pps::refusal(r, wide), "");
    r.feed_override = std::nan("");
    EXPECT_NE(pps::refusal(r, wide), "");
  }
  tool.jog_continuous = 3;
  EXPECT_NE(pps::refusal(tool, v).find("neither 0 (the work offset) nor 2"), std::string::npos);
  // Run from line N: START waits for CONFIRM of the approach, which is then allowed.
  {
    pps::CellView from;
    from.state = CellState::kLoaded;
    from.program = "p.ngc";
    from.approach = "from line 8: rapid up";
    EXPECT_EQ(pps::refusal(cmd(C::START), from), "program p.ngc runs from line 8: rapid up: CONFIRM the approach first");
    EXPECT_EQ(pps::refusal(cmd(C::CONFIRM), from), "");
  }
  // The switches take 1 (on) or 0 (off) only.
  for (const int8_t sw : {C::SINGLE_BLOCK, C::OPTIONAL_STOP, C::BLOCK_DELETE}) {
    lcmt_program_command c = cmd(sw);
    c.value = 0;
    EXPECT_EQ(pps::refusal(c, v), "");
    c.value = 2;
    EXPECT_NE(pps::refusal(c, v).find("the value is 1 (on) or 0 (off)"), std::string::npos);
    c.value = std::nan("");
    EXPECT_NE(pps::refusal(c, v).find("the value is 1 (on) or 0 (off)"), std::string::npos);
  }
}

// ---- the bus -------------------------------------------------------------------------

TEST(BusPublishFailure, IsCountedNamedAndUsesNoSequenceNumber) {
  bus::Bus bus("memq://", 5);
  std::vector<int64_t> seqs;
  bus.subscribe<lcmt_program_command>("CMD", [&](const lcmt_program_command& m) { seqs.push_back(m.seq); });
  lcmt_program_command m{};
  ASSERT_TRUE(bus.publish("CMD", m));
  bus.inject_publish_failures(2);
  EXPECT_FALSE(bus.publish("CMD", m));  // no throw
  EXPECT_FALSE(bus.publish("CMD", m));
  ASSERT_TRUE(bus.publish("CMD", m));
  while (bus.drain() > 0) {
  }
  EXPECT_EQ(seqs, (std::vector<int64_t>{0, 1}));  // contiguous: the failures took no number
  EXPECT_EQ(bus.publish_failures(), 2);
  EXPECT_EQ(bus.stats("CMD").publish_failures, 2);
  EXPECT_EQ(bus.stats("CMD").published, 2);
  EXPECT_STREQ(bus.last_publish_error(), "publish on CMD failed: Operation not permitted");
}

// ---- the program server node -------------------------------------------------------------

class ServerInterlock : public ::testing::Test {
 protected:
  ServerInterlock()
      : cfg_(config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml")),
        bus_("memq://", 77), dir_(fs::temp_directory_path() / ("cnc-interlock-" + std::to_string(::getpid()))) {
    fs::create_directories(dir_);
    for (const char* name : {"a.ngc", "b.ngc"}) std::ofstream(dir_ / name) << "G1 X10 F1000\nM30\n";
    bus_.subscribe<lcmt_program_state>(cfg_.channel(config::channels::kProgramState),
                                       [this](const lcmt_program_state& m) { states_.push_back(m); });
  }
  ~ServerInterlock() override { fs::remove_all(dir_); }
  void pump() {
    while (bus_.drain() > 0) {
    }
  }
  int64_t send(int8_t c, const std::string& path = "") {
    lcmt_program_command m = cmd(c);
    m.program_path = path;
    bus_.publish(cfg_.channel(config::channels::kProgramCmd), m);
    pump();
    return m.seq;
  }
  void interp(int8_t state, int64_t token) {
    lcmt_interp_state s{};
    s.state = state;
    s.program_token = token;
    s.num_axes = 3;
    s.position_mm = {0, 0, 0};
    bus_.publish(cfg_.channel(config::channels::kInterpState), s);
    pump();
  }
  std::string path(const char* name) const { return (dir_ / name).string(); }

  config::MachineConfig cfg_;
  bus::Bus bus_;
  fs::path dir_;
  std::vector<lcmt_program_state> states_;
};

TEST_F(ServerInterlock, LoadAndStartWhileRunningAreRefusedNamingTheProgram) {
  pps::ProgramServerNode node(cfg_, bus_);
  send(C::LOAD, path("a.ngc"));
  ASSERT_EQ(states_.back().state, int8_t{lcmt_program_state::LOADED});
  const int64_t token = states_.back().program_token;
  send(C::START);
  interp(lcmt_setpoint::RUNNING, token);
  ASSERT_EQ(states_.back().state, int8_t{lcmt_program_state::RUNNING});

  const int64_t seq = send(C::LOAD, path("b.ngc"));
  const lcmt_program_state& s = states_.back();
  EXPECT_EQ(s.state, int8_t{lcmt_program_state::RUNNING});  // the running program goes on
  EXPECT_EQ(s.program_token, token);
  EXPECT_EQ(s.refused_sender, bus_.sender());
  EXPECT_EQ(s.refused_seq, seq);
  EXPECT_EQ(s.refusal, "LOAD " + path("b.ngc") + " refused: program " + path("a.ngc") + " is running: STOP it first");

  send(C::START);
  EXPECT_NE(states_.back().refusal.find("START refused: program " + path("a.ngc") + " is running already"),
            std::string::npos);
  EXPECT_EQ(states_.back().refusals, 2);

  // The program ends: a new one loads.
  interp(lcmt_setpoint::DONE, token);
  EXPECT_EQ(states_.back().state, int8_t{lcmt_program_state::DONE});
  send(C::LOAD, path("b.ngc"));
  EXPECT_EQ(states_.back().state, int8_t{lcmt_program_state::LOADED});
  EXPECT_NE(states_.back().program_token, token);
}

TEST_F(ServerInterlock, EveryDecisionStaysInTheAnswersWhenTheStateNamesTheNextOne) {
  // fault_reset's interlock section under two busy loops: three cnc-ctl at once; the
  // state named a LOAD's refusal for 36 ms before the next command's answer replaced it,
  // that one datagram did not reach its cnc-ctl, and it waited 2 s for its resend.
  lcmt_command_answers answers{};
  int n_answers = 0;
  bus_.subscribe<lcmt_command_answers>(cfg_.channel(config::channels::kProgramAnswers),
                                       [&](const lcmt_command_answers& m) { answers = m, ++n_answers; });
  pps::ProgramServerNode node(cfg_, bus_);
  send(C::LOAD, path("a.ngc"));
  const int64_t token = states_.back().program_token;
  send(C::START);
  interp(lcmt_setpoint::RUNNING, token);
  const int64_t load = send(C::LOAD, path("b.ngc"));
  const int64_t start = send(C::START);
  const int64_t hold = send(C::HOLD);
  // The state names one decision, a later one than the LOAD's: that answer is gone from it.
  EXPECT_GT(states_.back().answered_seq, load);
  EXPECT_EQ(service::refusal_of(states_.back(), bus_.sender(), load), "");
  // The answers hold each, newest first, with its refusal ("" when taken).
  ASSERT_GT(n_answers, 0);
  std::string why;
  ASSERT_TRUE(service::answer_of(answers, bus_.sender(), load, &why));
  EXPECT_EQ(why, "LOAD " + path("b.ngc") + " refused: program " + path("a.ngc") + " is running: STOP it first");
  ASSERT_TRUE(service::answer_of(answers, bus_.sender(), start, &why));
  EXPECT_NE(why.find("START refused"), std::string::npos) << why;
  ASSERT_TRUE(service::answer_of(answers, bus_.sender(), hold, &why));
  EXPECT_EQ(why, "");
  EXPECT_FALSE(service::answer_of(answers, bus_.sender() + 1, hold, &why));  // another client's seq
  EXPECT_FALSE(service::answer_of(answers, bus_.sender(), hold + 1, &why));
  EXPECT_EQ(answers.answer_seq[0], hold);
  // At most the last 16: the oldest go first.
  for (int i = 0; i < 20; ++i) send(C::OVERRIDE);
  EXPECT_EQ(answers.num_answers, 16);
  EXPECT_FALSE(service::answer_of(answers, bus_.sender(), load, &why));
}

TEST_F(ServerInterlock, InterpolatorFaultRefusesLoadUntilReset) {
  pps::ProgramServerNode node(cfg_, bus_);
  interp(lcmt_setpoint::FAULT, 0);
  EXPECT_EQ(states_.back().state, int8_t{lcmt_program_state::FAULT});
  send(C::LOAD, path("a.ngc"));
  EXPECT_NE(states_.back().refusal.find("refused: the cell is in FAULT"), std::string::npos) << states_.back().refusal;
  interp(lcmt_setpoint::IDLE, 0);  // the interpolator took RESET
  send(C::RESET);
  send(C::LOAD, path("a.ngc"));
  EXPECT_EQ(states_.back().state, int8_t{lcmt_program_state::LOADED}) << states_.back().refusal;
}

TEST_F(ServerInterlock, AFailedPublishIsAFaultUntilReset) {
  pps::ProgramServerNode node(cfg_, bus_);
  bus_.inject_publish_failures(1);
  node.publish_state(true);  // fails
  node.poll(1.0);            // FAULT; the alarm goes out now that the bus works
  pump();
  send(C::LOAD, path("a.ngc"));
  EXPECT_EQ(states_.back().state, int8_t{lcmt_program_state::FAULT});
  EXPECT_NE(states_.back().refusal.find("could not publish: publish on"), std::string::npos) << states_.back().refusal;
  send(C::RESET);
  send(C::LOAD, path("a.ngc"));
  EXPECT_EQ(states_.back().state, int8_t{lcmt_program_state::LOADED});
}

// ---- RESET as an interpolator input ------------------------------------------------------

TEST(InterpolatorReset, TheRecordedPositionIsWhereThePathRestsAndReplaysTheSame) {
  const auto cfg = config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  lcmt_interp_input in{};
  in.kind = lcmt_interp_input::COMMAND;
  in.command.command = C::RESET;
  in.command.num_axes = 3;
  in.command.position_mm = {147.3404, 12.5, -0.25};
  interp::Interpolator live(cfg), replayed(cfg);
  ASSERT_EQ(interp::apply_recorded_input(live, in, 3), "");
  ASSERT_EQ(interp::apply_recorded_input(replayed, in, 3), "");
  const interp::Setpoint a = live.step(), b = replayed.step();
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(a.position_mm[static_cast<size_t>(i)], in.command.position_mm[static_cast<size_t>(i)]);
    EXPECT_EQ(a.position_mm[static_cast<size_t>(i)], b.position_mm[static_cast<size_t>(i)]);
  }
  EXPECT_TRUE(a.state == interp::RunState::kIdle);
  // Malformed: no position, a NaN, the wrong axis count.
  in.command.num_axes = 0;
  in.command.position_mm.clear();
  EXPECT_NE(interp::apply_recorded_input(live, in, 3), "");
  in.command.num_axes = 3;
  in.command.position_mm = {1, std::nan(""), 2};
  EXPECT_NE(interp::apply_recorded_input(live, in, 3), "");
  in.command.num_axes = 2;
  in.command.position_mm = {1, 2};
  EXPECT_NE(interp::apply_recorded_input(live, in, 3), "");
}

}  // namespace
}  // namespace cnc
