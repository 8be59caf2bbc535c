// The program server with input waits (M66), the same way as with probing moves:
// validation takes each as LinuxCNC's rs274 reads it; live, nothing after an M66 is
// served before its value, and the value revalidates the program from its start with
// every result so far (probes and inputs in program order): the branch the program
// takes on #5399, a timeout's -1 included. A result of the wrong kind is refused.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "services/part_program_server/program_server.h"
#include "tests/unit/program_test_util.h"

namespace cnc::pps {
namespace {

using program::Block;
using test::TempDir;

ProgramSetup io_setup() {
  ProgramSetup s = test::xyz_setup();
  s.machine.has_probe = true;
  s.machine.digital_inputs = 2;
  s.travel_mm = {{-100, 100}, {-100, 100}, {-30, 5}};
  return s;
}

// Waits for input 1 to rise (5 s at most); timed out, X goes to -5, else to 10 x #5399;
// then probes and waits again, immediately, on input 0.
const char* kProgram =
    "G21 G90 F100\n"
    "G0 X1\n"
    "M66 P1 L1 Q5\n"
    "o1 if [#5399 LT 0]\n"
    "  G0 X-5\n"
    "o1 else\n"
    "  G0 X[#5399 * 10]\n"
    "o1 endif\n"
    "G38.3 Z-10\n"
    "M66 P0\n"
    "G0 Y[#5399 + 1]\n"
    "M2\n";

std::vector<Block> served(ProgramServer& s) {
  std::vector<Block> out;
  for (int64_t i = 0; i < s.num_blocks(); ++i) {
    const Block* b = s.block(i);
    if (b == nullptr) break;
    out.push_back(*b);
  }
  return out;
}

TEST(ProgramServerInput, NothingAfterAnInputWaitBeforeItsValueThenTheBranchTaken) {
  for (const double value : {1.0, -1.0}) {
    TempDir dir;
    const std::string path = dir.write("p.ngc", kProgram);
    ProgramServer server(io_setup(), ServerLimits{4, 2});
    server.set_live_probing(true);
    const LoadResult r = server.load(path, 1);
    ASSERT_TRUE(r.ok) << r.error;
    EXPECT_EQ(server.awaited_result_block(), 1);
    EXPECT_FALSE(server.awaited_result_is_probe());
    const std::vector<Block> before = served(server);
    ASSERT_EQ(before.size(), 2u) << "the rapid and the wait only";
    EXPECT_EQ(before[1].event.kind, program::EventKind::kWaitInput);
    EXPECT_EQ(before[1].event.number, 1001);  // P1, L1
    EXPECT_EQ(before[1].event.value, 5.0);
    EXPECT_TRUE(server.awaiting_result(2));
    // A probe result where an input value is awaited is refused, nothing changes.
    EXPECT_FALSE(server.probe_result(1, ProbeResult{true, {1, 0, -3}, {1, 0, -3}}).ok);
    EXPECT_FALSE(server.input_result(0, 1).ok) << "not the block awaiting one";
    const LoadResult in = server.input_result(1, value);
    ASSERT_TRUE(in.ok) << in.error;
    EXPECT_EQ(server.inputs_known(), 1);
    // Served: up to the probing move, which is awaited next.
    EXPECT_EQ(server.awaited_result_block(), 3);
    EXPECT_TRUE(server.awaited_result_is_probe());
    const std::vector<Block> mid = served(server);
    ASSERT_EQ(mid.size(), 4u);
    EXPECT_EQ(mid[2].end[0], value < 0 ? -5.0 : 10.0) << "the branch on #5399";
    ASSERT_TRUE(server.probe_result(3, ProbeResult{true, {mid[2].end[0], 0, -3}, {mid[2].end[0], 0, -3}}).ok);
    EXPECT_EQ(server.awaited_result_block(), 4);
    ASSERT_TRUE(server.input_result(4, 0).ok);
    const std::vector<Block> all = served(server);
    ASSERT_EQ(all.size(), static_cast<size_t>(server.num_blocks()));
    ASSERT_GE(all.size(), 6u);
    EXPECT_EQ(all[5].end[1], 1.0) << "#5399 = 0 read by the second wait";
    EXPECT_EQ(server.awaited_result_block(), -1);
  }
}

TEST(ProgramServerInput, OfflineTheBlocksAreServedAsValidated) {
  TempDir dir;
  const std::string path = dir.write("p.ngc", kProgram);
  ProgramServer server(io_setup(), ServerLimits{4, 2});
  const LoadResult r = server.load(path, 1);
  ASSERT_TRUE(r.ok) << r.error;
  const std::vector<Block> all = served(server);
  ASSERT_EQ(all.size(), static_cast<size_t>(server.num_blocks()));
  // rs274's reading: #5399 stays 0 (a digital input 0), so X goes to 0.
  ASSERT_GE(all.size(), 3u);
  EXPECT_EQ(all[2].end[0], 0.0);
}

}  // namespace
}  // namespace cnc::pps
