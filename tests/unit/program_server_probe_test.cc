// The program server with probing moves (G38.x). Validation takes each as tripped at
// its end. Live (set_live_probing), nothing after a probing move is served before its
// result; the result revalidates the program from its start with every result so far:
// the next block starts where the machine came to rest, the lines read #5061-#5070,
// the program's length may change, and a result that leads out of the travel (or to
// an error) withdraws the program with its file and line. Offline (the dry run) the
// blocks are served as validated.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "services/part_program_server/program_server.h"
#include "tests/unit/program_test_util.h"

namespace cnc::pps {
namespace {

using program::Block;
using test::TempDir;

ProgramSetup probe_setup() {
  ProgramSetup s = test::xyz_setup();
  s.machine.has_probe = true;
  s.travel_mm = {{-100, 100}, {-100, 100}, {-30, 5}};
  return s;
}

// Probes Z down; on a trip it retracts 1 mm above the trip and goes on, on a miss
// (#5070 = 0, G38.3) it moves X to 50 three times.
const char* kProgram =
    "G21 G90 F100\n"
    "G0 X10 Z-1\n"
    "G38.3 Z-10\n"
    "G0 Z[#5063 + 1]\n"
    "o1 if [#5070 EQ 0]\n"
    "  o2 repeat [3]\n"
    "    G0 X50\n"
    "    G0 X10\n"
    "  o2 endrepeat\n"
    "o1 endif\n"
    "G0 Z[#5063 - 5]\n"
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

TEST(ProgramServerProbe, NothingAfterAProbingMoveBeforeItsResult) {
  TempDir dir;
  const std::string path = dir.write("p.ngc", kProgram);
  ProgramServer server(probe_setup(), ServerLimits{4, 2});
  server.set_live_probing(true);
  const LoadResult r = server.load(path, 1);
  ASSERT_TRUE(r.ok) << r.error;
  // Validated as tripped at the end (Z -10); served: up to the probing move.
  EXPECT_EQ(server.awaited_result_block(), 1);
  const std::vector<Block> before = served(server);
  ASSERT_EQ(before.size(), 2u) << "the rapid and the probing move only";
  EXPECT_EQ(before[1].probe, 3);
  EXPECT_TRUE(server.awaiting_result(2));
  EXPECT_FALSE(server.awaiting_result(1));
  EXPECT_EQ(server.block(2), nullptr);
  EXPECT_TRUE(server.serving_error().empty());
}

TEST(ProgramServerProbe, TheResultIsReadAndTheNextBlockStartsAtRest) {
  TempDir dir;
  const std::string path = dir.write("p.ngc",
                                     "G21 G90 F100\nG0 X10 Z-1\nG38.2 Z-10\nG0 Z[#5063 + 1]\nG0 X[#5070 * 20]\nM2\n");
  ProgramServer server(probe_setup(), ServerLimits{4, 2});
  server.set_live_probing(true);
  ASSERT_TRUE(server.load(path, 1).ok);
  ASSERT_EQ(served(server).size(), 2u);
  ProbeResult pr{true, {10, 0, -4.25}, {10, 0, -4.2513}};
  const LoadResult r = server.probe_result(1, pr);
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(server.awaited_result_block(), -1);
  const std::vector<Block> all = served(server);
  ASSERT_EQ(all.size(), static_cast<size_t>(server.num_blocks()));
  ASSERT_GE(all.size(), 4u);
  EXPECT_EQ(all[2].start[2], -4.2513) << "the retract starts where the machine rests";
  EXPECT_EQ(all[2].end[2], -3.25) << "#5063 is the trip";
  EXPECT_EQ(all[3].end[0], 20) << "#5070 = 1";
  // A result for a block that is not the awaited probing move is refused.
  EXPECT_FALSE(server.probe_result(1, pr).ok);
}

TEST(ProgramServerProbe, AMissChangesTheProgramsLengthAndATravelErrorWithdrawsIt) {
  TempDir dir;
  const std::string path = dir.write("p.ngc", kProgram);
  {
    // As validated (tripped at Z -10) a last line to #5063 - 25 = -35 is out of the
    // travel (-30): refused at load, with its line.
    std::string far = kProgram;
    far.replace(far.find("- 5]"), 3, "- 25");
    ProgramServer server(probe_setup(), ServerLimits{4, 2});
    server.set_live_probing(true);
    const LoadResult r = server.load(dir.write("far.ngc", far), 1);
    ASSERT_FALSE(r.ok);
    EXPECT_EQ(r.line, 11) << r.error;
  }
  const std::string& ok_path = path;
  ProgramServer server(probe_setup(), ServerLimits{4, 2});
  server.set_live_probing(true);
  ASSERT_TRUE(server.load(ok_path, 1).ok);
  const int64_t validated = server.num_blocks();
  // No contact: the loop runs (6 more rapids); the last line goes to Z -15.
  ProbeResult miss{false, {10, 0, -10}, {10, 0, -10}};
  ASSERT_TRUE(server.probe_result(1, miss).ok);
  EXPECT_EQ(server.num_blocks(), validated + 6);
  const std::vector<Block> all = served(server);
  ASSERT_EQ(all.size(), static_cast<size_t>(server.num_blocks()));
  EXPECT_EQ(all[all.size() - 2].end[2], -15);
  // A trip deep down sends the last line out of the travel: withdrawn at that line.
  ProgramServer deep(probe_setup(), ServerLimits{4, 2});
  deep.set_live_probing(true);
  ASSERT_TRUE(deep.load(ok_path, 2).ok);
  ProbeResult low{true, {10, 0, -27}, {10, 0, -27.001}};
  const LoadResult r = deep.probe_result(1, low);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.line, 11) << r.error;
  EXPECT_NE(r.error.find("outside the axis's travel"), std::string::npos) << r.error;
  EXPECT_FALSE(deep.loaded());
}

TEST(ProgramServerProbe, OfflineTheBlocksAreServedAsValidated) {
  TempDir dir;
  const std::string path = dir.write("p.ngc", "G21 G90 F100\nG0 X10 Z-1\nG38.2 Z-10\nG0 Z[#5063 + 1]\nM2\n");
  ProgramServer server(probe_setup(), ServerLimits{4, 2});
  ASSERT_TRUE(server.load(path, 1).ok);
  const std::vector<Block> all = served(server);
  ASSERT_EQ(all.size(), static_cast<size_t>(server.num_blocks()));
  EXPECT_EQ(all[2].start[2], -10);
  EXPECT_EQ(all[2].end[2], -9);
}

}  // namespace
}  // namespace cnc::pps
