// The part-program server: validation interprets the whole program once and keeps
// one hash per chunk of blocks; a second interpreter run serves the blocks, chunk by
// chunk, into a small cache, restarting from the program's start when an earlier
// block is asked for. It serves exactly the blocks a whole run gives, in any order;
// it refuses a bad program and keeps the one before; it never serves a file changed
// after validation; its memory is one hash per chunk. Its node answers block
// requests so that a lost block is re-sent on a re-request.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "cnc/lcmt_block_request.hpp"
#include "cnc/lcmt_program_block.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/program/block_msg.h"
#include "services/part_program_server/program_server.h"
#include "services/part_program_server/program_server_node.h"
#include "tests/unit/program_test_util.h"

namespace cnc::pps {
namespace {

namespace fs = std::filesystem;
using program::Block;
using program::BlockKind;
using test::TempDir;

void write(const fs::path& p, const std::string& text) { test::write_file(p, text); }

// Every kind of block, modal switches (G91, G20, planes, process), both NURBS
// dialects, a dwell: `repeats` times a pattern of 22 blocks, between a spindle start
// and M5 / M30 (events).
std::string mixed_program(int repeats) {
  std::ostringstream o;
  o << "(PROCESS, BALL_RADIUS=5, FLUTES=2, PICK_FEED=0.5, RMAX_UM=10.67)\nS10000 M3\nG0 X0 Y0 Z0\n";
  for (int r = 0; r < repeats; ++r) {
    o << "G1 X10 F1000\nY5\nG2 X20 Y5 I5 J0\nG3 X10 Y5 R5\nG91 G1 X1 Y1\nX-1 Y-1\nG90\n"
      << "G20\nG1 X0.5 F40\nG21 X0\nG18 G2 X10 Z0 I5\nG17 G0 X0 Y0 Z0\n"
      << "(PROCESS, RMAX_UM=" << (r % 2 ? "0" : "8") << ")\n"
      << "G06.2 P3 K0 X0 Y0 Z0 F500\nK0 X5 Z-1\nK0 X10 Z-1 R2\nK0.5 X15 Z0\nK1\nK1\nK1\n"
      << "G4 P0.01\nG0 X0 Y0 Z0\nF800\nG5.2 P1 L3\nX5 Y5 P1\nX10 Y0 P2\nX15 Y5 P1\nG5.3\nG0 X0 Y0\n"
      << "G3 X0 Y0 I3 P2\nG1 Z-1\nZ0\nX1\nX2\nX3\nX0\n";
  }
  o << "M5\nM30\n(nothing after M30 is read)\n";
  return o.str();
}
// The spindle start, the first G0, 22 per pattern, M5's spindle stop, the end (M30's
// pallet shuttle is no event: the cell has no pallet changer).
int64_t mixed_blocks(int repeats) { return 2 + 22 * int64_t{repeats} + 2; }

void expect_same_block(const Block& a, const Block& b) {
  EXPECT_EQ(a.index, b.index);
  EXPECT_EQ(a.kind, b.kind);
  EXPECT_EQ(a.source_line, b.source_line);
  EXPECT_EQ(a.source_column, b.source_column);
  EXPECT_EQ(a.source_file, b.source_file);
  EXPECT_EQ(a.start, b.start);
  EXPECT_EQ(a.end, b.end);
  EXPECT_EQ(a.feed_mm_per_min, b.feed_mm_per_min);
  EXPECT_EQ(a.spindle_rpm, b.spindle_rpm);
  EXPECT_EQ(a.dwell_s, b.dwell_s);
  EXPECT_EQ(a.process.target_rmax_um, b.process.target_rmax_um);
  EXPECT_EQ(a.arc.center, b.arc.center);
  EXPECT_EQ(a.arc.plane, b.arc.plane);
  EXPECT_EQ(a.arc.turns, b.arc.turns);
  EXPECT_EQ(a.nurbs.knots, b.nurbs.knots);
  EXPECT_EQ(a.nurbs.control_points, b.nurbs.control_points);
  EXPECT_EQ(a.nurbs.weights, b.nurbs.weights);
  EXPECT_EQ(a.event.kind, b.event.kind);
  EXPECT_EQ(a.event.number, b.event.number);
  EXPECT_EQ(a.event.value, b.event.value);
  EXPECT_EQ(a.event.text, b.event.text);
}

int64_t chunks(int64_t blocks, int64_t per) { return (blocks + per - 1) / per; }

TEST(ProgramServer, ServesWhatTheWholeRunGives) {
  TempDir dir;
  const fs::path file = dir / "mixed.ngc";
  write(file, mixed_program(100));
  const std::vector<Block> whole = test::run_program(file.string());
  ASSERT_EQ(static_cast<int64_t>(whole.size()), mixed_blocks(100));

  ProgramServer server(test::xyz_setup(), ServerLimits{16, 2});
  const LoadResult r = server.load(file.string(), 5);
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(server.token(), 5);
  EXPECT_EQ(server.path(), file.string());
  ASSERT_EQ(server.num_blocks(), static_cast<int64_t>(whole.size()));
  // Memory: one hash per chunk of 16 blocks, whatever the program.
  EXPECT_EQ(static_cast<int64_t>(server.num_checkpoints()), chunks(server.num_blocks(), 16));

  for (int64_t i = 0; i < server.num_blocks(); ++i) {
    const Block* b = server.block(i);
    ASSERT_NE(b, nullptr) << i << ": " << server.serving_error();
    expect_same_block(*b, whole[static_cast<size_t>(i)]);
  }
  EXPECT_EQ(server.block(server.num_blocks()), nullptr);
  EXPECT_EQ(server.block(-1), nullptr);
  // In order: each chunk made once by one serving run.
  EXPECT_EQ(server.chunk_reads(), static_cast<int64_t>(server.num_checkpoints()));
  EXPECT_EQ(server.restarts(), 0);

  // Out of order: a block before the serving run's position restarts it from the
  // program's start; the blocks are the same.
  std::mt19937 rng(20240607);
  std::uniform_int_distribution<int64_t> pick(0, server.num_blocks() - 1);
  for (int k = 0; k < 200; ++k) {
    const int64_t i = pick(rng);
    const Block* b = server.block(i);
    ASSERT_NE(b, nullptr) << i << ": " << server.serving_error();
    expect_same_block(*b, whole[static_cast<size_t>(i)]);
  }
  EXPECT_GT(server.restarts(), 0);
  EXPECT_LE(server.restarts(), 200);
}

TEST(ProgramServer, ARestartIsCountedAndServesTheSameBlocks) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  write(file, mixed_program(5));
  ProgramServer server(test::xyz_setup(), ServerLimits{8, 1});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  const int64_t last = server.num_blocks() - 1;
  ASSERT_NE(server.block(last), nullptr);
  const Block end = *server.block(last);
  EXPECT_EQ(end.kind, BlockKind::kEnd);
  EXPECT_EQ(server.restarts(), 0);
  const Block* first = server.block(0);  // behind the serving run, not in the one-chunk cache
  ASSERT_NE(first, nullptr) << server.serving_error();
  EXPECT_EQ(first->index, 0);
  EXPECT_EQ(server.restarts(), 1);
  ASSERT_NE(server.block(last), nullptr);  // forward again: no restart
  EXPECT_EQ(server.restarts(), 1);
  expect_same_block(*server.block(last), end);
  // Asking for the chunk in the cache again reads nothing.
  const int64_t reads = server.chunk_reads();
  ASSERT_NE(server.block(last - 1), nullptr);
  EXPECT_EQ(server.chunk_reads(), reads);
}

TEST(ProgramServer, AWindowMovingBackAndForthHitsTheCache) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  write(file, mixed_program(20));
  ProgramServer server(test::xyz_setup(), ServerLimits{64, 4});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  // The interpolator's pattern: a window of 32 ahead, with re-requests a little behind.
  for (int64_t first = 0; first < server.num_blocks(); first += 16)
    for (int64_t i = std::max<int64_t>(0, first - 8); i < std::min(first + 32, server.num_blocks()); ++i)
      ASSERT_NE(server.block(i), nullptr);
  EXPECT_EQ(server.chunk_reads(), static_cast<int64_t>(server.num_checkpoints()));
  EXPECT_EQ(server.restarts(), 0);
}

TEST(ProgramServer, MemoryIsOneHashPerChunkOfALongLoop) {
  TempDir dir;
  const fs::path file = dir / "loop.ngc";
  write(file, "F1000\n#1=0\no1 while [#1 LT 50000]\n  G1 X[#1 MOD 7]\n  #1=[#1+1]\no1 endwhile\nM2\n");
  ProgramServer server(test::xyz_setup(), ServerLimits{256, 2});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  EXPECT_EQ(server.num_blocks(), 50001);
  EXPECT_EQ(static_cast<int64_t>(server.num_checkpoints()), chunks(50001, 256));
  EXPECT_GT(server.lines_interpreted(), 100000);
  const Block* b = server.block(49999);
  ASSERT_NE(b, nullptr) << server.serving_error();
  EXPECT_EQ(b->end[0], 49999 % 7);
  EXPECT_EQ(server.block(50000)->kind, BlockKind::kEnd);
}

// A load of millions of lines validates for seconds: the server reports its progress
// (the node keeps its heartbeat going with it) as it begins and every 4,096 blocks.
TEST(ProgramServer, AValidationReportsItsProgressEvery4096Blocks) {
  TempDir dir;
  const fs::path file = dir / "loop.ngc";
  write(file, "F1000\n#1=0\no1 while [#1 LT 10000]\n  G1 X[#1 MOD 7]\n  #1=[#1+1]\no1 endwhile\nM2\n");
  ProgramServer server(test::xyz_setup(), ServerLimits{});
  std::vector<int64_t> calls;
  server.on_validation_progress([&calls](int64_t blocks) { calls.push_back(blocks); });
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  EXPECT_EQ(server.num_blocks(), 10001);
  EXPECT_EQ(calls, (std::vector<int64_t>{0, 4096, 8192}));
}

TEST(ProgramServer, AProgramThatNeverEndsIsRefused) {
  TempDir dir;
  const fs::path file = dir / "forever.ngc";
  write(file, "o1 while [1]\n  G0 X1\n  G0 X0\no1 endwhile\nM2\n");
  ProgramSetup s = test::xyz_setup();
  s.max_validation_lines = 10000;
  ProgramServer server(s, ServerLimits{});
  const LoadResult r = server.load(file.string(), 1);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.error.find("without ending"), std::string::npos) << r.error;
  EXPECT_FALSE(server.loaded());
}

TEST(ProgramServer, M19sAngleIsRPlusTheMachinesOrientOffset) {
  // spindle.orient_offset_deg is LinuxCNC's ORIENT_OFFSET: M19 R10 orients to 52 with 42.
  TempDir dir;
  const fs::path file = dir / "orient.ngc";
  write(file, "M3 S600\nM19 R10 Q2\nM19 P0\nM2\n");
  auto cfg = config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3_servo_spindle.yaml");
  std::vector<double> angles[2];
  for (int k = 0; k < 2; ++k) {
    cfg.spindle.orient_offset_deg = k == 0 ? 0.0 : 42.0;
    ProgramServer server(cfg);
    const LoadResult r = server.load(file.string(), 1);
    ASSERT_TRUE(r.ok) << r.error;
    for (int64_t i = 0; i < server.num_blocks(); ++i)
      if (server.block(i)->kind == program::BlockKind::kEvent &&
          server.block(i)->event.kind == program::EventKind::kSpindleOrient)
        angles[k].push_back(server.block(i)->event.value);
  }
  EXPECT_EQ(angles[0], (std::vector<double>{10.0, 0.0}));
  EXPECT_EQ(angles[1], (std::vector<double>{52.0, 42.0}));
}

TEST(ProgramServer, APathOutsideTheTravelIsRefusedWhereItIsWritten) {
  // Travel X [-5, 400], Y [-5, 300], Z [-150, 5]: a rapid to X1000, an arc that
  // bulges past X400 between two points inside, a G53 move under Z-150; and the
  // same arc inside the travel is accepted.
  TempDir dir;
  ProgramSetup s = test::xyz_setup();
  s.travel_mm = {{-5, 400}, {-5, 300}, {-150, 5}};
  ProgramServer server(s, ServerLimits{});
  struct Case {
    const char* text;
    int line;
    const char* what;
  };
  const Case cases[] = {
      {"G21 G90\nG0 X1000\nM2\n", 2, "X 1000.0000 mm"},
      {"G21 G90 G17\nG0 X395 Y100 Z0\nG3 X395 Y120 J10 F1000\nM2\n", 3, "on the way"},
      {"G21 G90\nG0 X10\n  G53 G0 Z-151\nM2\n", 3, "Z -151.0000 mm"},
  };
  int k = 0;
  for (const Case& c : cases) {
    const fs::path file = dir / ("out" + std::to_string(k++) + ".ngc");
    write(file, c.text);
    const LoadResult r = server.load(file.string(), 1);
    EXPECT_FALSE(r.ok) << c.text;
    EXPECT_EQ(r.line, c.line) << r.error;
    EXPECT_NE(r.error.find(c.what), std::string::npos) << r.error;
    EXPECT_NE(r.error.find("outside the axis's travel"), std::string::npos) << r.error;
  }
  write(dir / "in.ngc", "G21 G90 G17\nG0 X385 Y100 Z0\nG3 X385 Y120 J10 F1000\nM2\n");
  const LoadResult ok = server.load((dir / "in.ngc").string(), 1);
  EXPECT_TRUE(ok.ok) << ok.error;
}

TEST(ProgramServer, ALongDwellIsAcceptedWithAWarningNamingItsLine) {
  // G4 P100000: 27.8 hours (a P meant in ms?): loaded, with a warning at its line.
  TempDir dir;
  write(dir / "dwell.ngc", "G21 G90\nG4 P5\nG4 P100000\nM2\n");
  ProgramServer server(test::xyz_setup(), ServerLimits{});
  const LoadResult r = server.load((dir / "dwell.ngc").string(), 1);
  ASSERT_TRUE(r.ok) << r.error;
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("dwell.ngc:3:1: a dwell of 100000 s (27.8 hours)"), std::string::npos) << r.warnings[0];
}

TEST(ProgramServer, ARefusedProgramKeepsThePreviousOne) {
  TempDir dir;
  write(dir / "good.ngc", "G0 X1\nG1 X2 F100\nM30\n");
  write(dir / "bad.ngc", "G0 X1\nG06.2 P4 K0 X1 Y0 Z0 F100\nK0 X2\nK0 X3\nK0 X4\nK1\nK1\nK1\nG0 X0\nM2\n");
  ProgramServer server(test::xyz_setup(), ServerLimits{});
  ASSERT_TRUE(server.load((dir / "good.ngc").string(), 1).ok);
  const LoadResult r = server.load((dir / "bad.ngc").string(), 2);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.file, (dir / "bad.ngc").string());
  EXPECT_EQ(r.line, 9);
  EXPECT_EQ(r.column, 0);
  EXPECT_NE(r.error.find("bad.ngc:9: the G06.2 curve opened at line 2 has 7 knots; 4 control points of order 4 need 8"),
            std::string::npos)
      << r.error;
  EXPECT_EQ(server.token(), 1);
  EXPECT_EQ(server.num_blocks(), 3);  // G0, G1, the end
  ASSERT_NE(server.block(1), nullptr);
  EXPECT_EQ(server.block(1)->kind, BlockKind::kLine);
}

TEST(ProgramServer, AMissingFileIsRefused) {
  ProgramServer server(test::xyz_setup(), ServerLimits{});
  const LoadResult r = server.load("/nonexistent/p.ngc", 1);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.file, "/nonexistent/p.ngc");
  EXPECT_NE(r.error.find("cannot open"), std::string::npos) << r.error;
}

// Same length, one digit changed in the pattern at or after `from`: X10 becomes X19.
std::string edited(const std::string& text, size_t from) {
  std::string changed = text;
  const size_t at = changed.find("G1 X10 F1000", from);
  EXPECT_NE(at, std::string::npos);
  if (at != std::string::npos) changed[at + 5] = '9';
  return changed;
}

void overwrite_in_place(const fs::path& file, const std::string& text) {
  std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
  f.seekp(0);
  f << text;
}

// Serves blocks from 0 on until one is refused; every block served must be the
// validated program's. Returns the index of the first refused block (num_blocks if none).
int64_t serve_until_refused(ProgramServer& server, const std::vector<Block>& validated) {
  int64_t i = 0;
  for (; i < server.num_blocks(); ++i) {
    const Block* b = server.block(i);
    if (b == nullptr) break;
    expect_same_block(*b, validated[static_cast<size_t>(i)]);
  }
  return i;
}

TEST(ProgramServer, AFileEditedInPlaceAfterLoadIsNeverServed) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  const std::string text = mixed_program(10);
  write(file, text);
  const std::vector<Block> validated = test::run_program(file.string());
  ProgramServer server(test::xyz_setup(), ServerLimits{16, 1});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  const int64_t n = server.num_blocks();
  overwrite_in_place(file, edited(text, text.size() / 2));
  const int64_t refused = serve_until_refused(server, validated);
  EXPECT_LT(refused, n) << "the changed chunk was served";
  EXPECT_GE(refused, 16) << "the chunks before the change are served";
  EXPECT_EQ(refused % 16, 0) << "a chunk is served whole or not at all";
  EXPECT_NE(server.serving_error().find("no longer interprets as when it was loaded"), std::string::npos)
      << server.serving_error();
  EXPECT_FALSE(server.loaded());
  EXPECT_EQ(server.num_blocks(), 0);
  EXPECT_EQ(server.block(0), nullptr);
}

TEST(ProgramServer, AnEditWhileServingIsRefusedWhenTheRunReadsIt) {
  // The serving run reads the file as it goes (64 KiB at a time): an edit beyond what
  // it has read is refused when it gets there; what it had read is the validated text.
  TempDir dir;
  const fs::path file = dir / "big.ngc";
  const std::string text = mixed_program(400);
  ASSERT_GT(text.size(), 2u * 65536u);
  write(file, text);
  const std::vector<Block> validated = test::run_program(file.string());
  ProgramServer server(test::xyz_setup(), ServerLimits{64, 2});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  ASSERT_NE(server.block(0), nullptr);
  const int64_t n = server.num_blocks();
  overwrite_in_place(file, edited(text, text.size() - 2000));
  const int64_t refused = serve_until_refused(server, validated);
  EXPECT_LT(refused, n) << "the changed chunk was served";
  EXPECT_GT(refused, 64 * 100);
  EXPECT_FALSE(server.loaded());
}

TEST(ProgramServer, AnEditIsCaughtAtTheNextRestart) {
  // A small file is read whole when the serving run starts; an edit after that is
  // refused when an earlier block restarts the run from the program's start.
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  const std::string text = mixed_program(10);
  write(file, text);
  const std::vector<Block> validated = test::run_program(file.string());
  ProgramServer server(test::xyz_setup(), ServerLimits{16, 1});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  ASSERT_NE(server.block(40), nullptr);
  overwrite_in_place(file, edited(text, 0));  // the first pattern: block 3
  for (int64_t i = 40; i < server.num_blocks(); ++i) {
    const Block* b = server.block(i);
    ASSERT_NE(b, nullptr) << i;  // the run's copy is the validated text
    expect_same_block(*b, validated[static_cast<size_t>(i)]);
  }
  EXPECT_EQ(server.restarts(), 0);
  EXPECT_EQ(server.block(0), nullptr);  // restart: the run reads the edited file
  EXPECT_EQ(server.restarts(), 1);
  EXPECT_NE(server.serving_error().find("no longer interprets"), std::string::npos) << server.serving_error();
  EXPECT_FALSE(server.loaded());
}

TEST(ProgramServer, AFileReplacedAfterLoadIsNeverServed) {
  // The old server kept the validated file open, so a file replaced by rename still
  // served the validated program; the serving run opens the path again, so the new
  // file's blocks fail their chunk's hash and nothing of it is served.
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  write(file, "G0 X1\nG1 X2 F100\nM30\n");
  ProgramServer server(test::xyz_setup(), ServerLimits{1, 1});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  write(dir / "other.ngc", "G0 X7\nG0 X8\nG0 X9\nM30\n");
  fs::rename(dir / "other.ngc", file);
  EXPECT_EQ(server.block(0), nullptr);
  EXPECT_NE(server.serving_error().find("no longer interprets"), std::string::npos) << server.serving_error();
  EXPECT_FALSE(server.loaded());
}

TEST(ProgramServer, AnEditThatShortensTheProgramIsRefused) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  write(file, "G0 X1\nG0 X2\nG0 X3\nG0 X4\nM2\n");
  ProgramServer server(test::xyz_setup(), ServerLimits{2, 1});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  ASSERT_EQ(server.num_blocks(), 5);
  write(file, "G0 X1\nG0 X2\nM2\n");
  ASSERT_NE(server.block(0), nullptr);  // G0 X1, G0 X2: as validated
  EXPECT_EQ(server.block(2), nullptr);  // the end block where G0 X3 was
  EXPECT_FALSE(server.serving_error().empty());
  EXPECT_FALSE(server.loaded());
}

// ---- the node ----------------------------------------------------------------------

class NodeTest : public ::testing::Test {
 protected:
  NodeTest() : cfg_(config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml")), bus_("memq://", 77) {
    namespace ch = config::channels;
    bus_.subscribe<cnc::lcmt_program_state>(cfg_.channel(ch::kProgramState), [this](const auto& m) { states_.push_back(m); });
    bus_.subscribe_raw(bus::exact_channel(cfg_.channel(ch::kProgramBlocks)),
                       [this](const std::string&, const void* data, size_t size, int64_t) {
                         cnc::lcmt_program_block m;
                         ASSERT_EQ(m.decode(data, 0, static_cast<int>(size)), static_cast<int>(size));
                         blocks_.push_back(m);
                       });
  }
  void pump() {
    while (bus_.drain() > 0) {
    }
  }
  void command(int8_t c, const std::string& path = "") {
    cnc::lcmt_program_command m{};
    m.command = c;
    m.program_path = path;
    bus_.publish(cfg_.channel(config::channels::kProgramCmd), m);
    pump();
  }
  void request(int64_t token, int64_t first, int32_t count) {
    cnc::lcmt_block_request r{};
    r.program_token = token;
    r.first_block = first;
    r.count = count;
    bus_.publish(cfg_.channel(config::channels::kBlockRequest), r);
    pump();
  }

  config::MachineConfig cfg_;
  bus::Bus bus_;
  std::vector<cnc::lcmt_program_state> states_;
  std::vector<cnc::lcmt_program_block> blocks_;
};

TEST_F(NodeTest, ALostBlockIsResentOnReRequest) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  write(file, mixed_program(4));
  ProgramServerNode node(cfg_, bus_);
  command(cnc::lcmt_program_command::LOAD, file.string());
  ASSERT_FALSE(states_.empty());
  const cnc::lcmt_program_state loaded = states_.back();
  ASSERT_EQ(loaded.state, int8_t{cnc::lcmt_program_state::LOADED}) << loaded.error;
  ASSERT_EQ(loaded.num_blocks, mixed_blocks(4));

  request(loaded.program_token, 0, 32);
  ASSERT_EQ(blocks_.size(), 32u);
  for (size_t k = 0; k < blocks_.size(); ++k) {
    EXPECT_EQ(blocks_[k].block_index, static_cast<int64_t>(k));
    EXPECT_EQ(blocks_[k].seq, static_cast<int64_t>(k));  // consecutive: a receiver sees any gap
    EXPECT_EQ(blocks_[k].program_token, loaded.program_token);
  }
  // Block 5 "lost": the receiver keeps the others and asks again from 5 after its timeout.
  blocks_.clear();
  request(loaded.program_token, 5, 32);
  ASSERT_EQ(blocks_.size(), 32u);
  EXPECT_EQ(blocks_.front().block_index, 5);
  program::Block b;
  ASSERT_EQ(program::from_msg(blocks_.front(), 3, &b), "");
  // A request beyond the end is clipped; a stale token or a silly count is ignored.
  blocks_.clear();
  const int64_t tail = loaded.num_blocks - 80;
  request(loaded.program_token, 80, 32);
  EXPECT_EQ(static_cast<int64_t>(blocks_.size()), tail);
  EXPECT_EQ(blocks_.back().kind, int8_t{cnc::lcmt_program_block::END});
  blocks_.clear();
  request(loaded.program_token + 1, 0, 32);
  request(loaded.program_token, 0, 100000);
  request(loaded.program_token, -5, 3);
  EXPECT_TRUE(blocks_.empty());

  states_.clear();
  node.publish_state(true);
  pump();
  ASSERT_EQ(states_.size(), 1u);
  EXPECT_EQ(states_.back().blocks_sent, 37 + tail);  // 0..36 and 80..end, each counted once
  EXPECT_EQ(states_.back().blocks_resent, 27);     // 5..31 went out twice
}

TEST_F(NodeTest, ARefusalNamesThePlaceAndServesNothing) {
  TempDir dir;
  write(dir / "bad.ngc", "G0 X1\nG5.2 P1 F100\nX1 Y1 P1\nX2 Y0 P1\n");  // no G5.3, no end
  ProgramServerNode node(cfg_, bus_);
  command(cnc::lcmt_program_command::LOAD, (dir / "bad.ngc").string());
  ASSERT_FALSE(states_.empty());
  const cnc::lcmt_program_state s = states_.back();
  EXPECT_EQ(s.state, int8_t{cnc::lcmt_program_state::REFUSED});
  EXPECT_EQ(s.error_line, 4);
  EXPECT_EQ(s.error_column, 0);
  EXPECT_NE(s.error.find("the file ended inside a NURBS curve opened at line 2"), std::string::npos) << s.error;
  request(s.program_token, 0, 32);
  EXPECT_TRUE(blocks_.empty());
}

TEST_F(NodeTest, AFileChangedUnderTheServerIsWithdrawn) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  const std::string text = mixed_program(40);  // 884 blocks: several chunks of 256
  write(file, text);
  ProgramServerNode node(cfg_, bus_);
  command(cnc::lcmt_program_command::LOAD, file.string());
  const cnc::lcmt_program_state loaded = states_.back();
  ASSERT_EQ(loaded.state, int8_t{cnc::lcmt_program_state::LOADED}) << loaded.error;
  // Rewritten in place (same inode) before the serving run reads it: the run serves
  // the unchanged chunks and withdraws the program at the changed one.
  std::string changed = text;
  changed[changed.rfind("G1 X10 F1000") + 4] = '7';  // X10 becomes X70, in the last pattern
  write(file, changed);
  states_.clear();
  for (int64_t first = 0; first < loaded.num_blocks && states_.empty(); first += 32)
    request(loaded.program_token, first, 32);
  EXPECT_GE(blocks_.size(), 256u);
  ASSERT_FALSE(states_.empty());
  EXPECT_EQ(states_.back().state, int8_t{cnc::lcmt_program_state::REFUSED});
  EXPECT_NE(states_.back().error.find("no longer interprets as when it was loaded"), std::string::npos)
      << states_.back().error;
  for (const auto& b : blocks_) {
    program::Block mine;
    ASSERT_EQ(program::from_msg(b, 3, &mine), "");
    EXPECT_NE(mine.end[0], 70.0) << "a block of the changed text went out";
  }
  blocks_.clear();
  request(loaded.program_token, 0, 32);
  EXPECT_TRUE(blocks_.empty());
}

}  // namespace
}  // namespace cnc::pps

namespace cnc::pps {
namespace {

// A killed server restarted with the same state file: the same program under the
// same token from the same start, the same blocks byte for byte; idle until the
// interpolator says it runs it, and a LOAD replaces it.
TEST_F(NodeTest, ARestartedServerServesTheSameBlocksFromItsStateFile) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  write(file, mixed_program(4));
  const std::string state = (dir / "pps.state").string();
  std::vector<cnc::lcmt_program_block> first;
  int64_t token = 0;
  {
    // The first server on a bus of its own: its subscriptions end with it (the bus
    // keeps a handler as long as it lives, and this server is gone before the next).
    namespace ch = config::channels;
    bus::Bus bus1("memq://", 78);
    std::vector<cnc::lcmt_program_state> states1;
    bus1.subscribe<cnc::lcmt_program_state>(cfg_.channel(ch::kProgramState), [&](const auto& m) { states1.push_back(m); });
    bus1.subscribe<cnc::lcmt_program_block>(cfg_.channel(ch::kProgramBlocks), [&](const auto& m) { first.push_back(m); });
    auto pump1 = [&] {
      while (bus1.drain() > 0) {
      }
    };
    ProgramServerNode node(cfg_, bus1);
    node.use_state_file(state);
    cnc::lcmt_interp_state at{};  // the machine stands off home: the start of the program
    at.num_axes = 3;
    at.position_mm = {12.5, -1.25, -3.0};
    at.program_token = 0;
    bus1.publish(cfg_.channel(ch::kInterpState), at);
    pump1();
    cnc::lcmt_program_command load{};
    load.command = cnc::lcmt_program_command::LOAD;
    load.program_path = file.string();
    bus1.publish(cfg_.channel(ch::kProgramCmd), load);
    pump1();
    ASSERT_FALSE(states1.empty());
    ASSERT_EQ(states1.back().state, int8_t{cnc::lcmt_program_state::LOADED}) << states1.back().error;
    token = states1.back().program_token;
    cnc::lcmt_block_request r{};
    r.program_token = token;
    r.first_block = 0;
    r.count = 32;
    bus1.publish(cfg_.channel(ch::kBlockRequest), r);
    pump1();
    ASSERT_EQ(first.size(), 32u);
  }
  ASSERT_TRUE(fs::exists(state));
  blocks_.clear();
  states_.clear();
  ProgramServerNode again(cfg_, bus_);
  again.use_state_file(state);
  again.publish_state(true);
  pump();
  ASSERT_FALSE(states_.empty());
  EXPECT_EQ(states_.back().program_token, token);
  EXPECT_EQ(states_.back().state, int8_t{cnc::lcmt_program_state::IDLE}) << "idle until the interpolator runs it";
  request(token, 0, 32);
  ASSERT_EQ(blocks_.size(), first.size());
  for (size_t k = 0; k < first.size(); ++k) {
    auto a = first[k], b = blocks_[k];
    a.utime = b.utime = 0;
    a.seq = b.seq = 0;
    a.sender = b.sender = 0;
    std::vector<uint8_t> ea(static_cast<size_t>(a.getEncodedSize())), eb(static_cast<size_t>(b.getEncodedSize()));
    a.encode(ea.data(), 0, static_cast<int>(ea.size()));
    b.encode(eb.data(), 0, static_cast<int>(eb.size()));
    EXPECT_EQ(ea, eb) << "block " << k;
  }
  // The interpolator reports it running: so is the cell.
  cnc::lcmt_interp_state run{};
  run.num_axes = 3;
  run.position_mm = {12.5, -1.25, -3.0};
  run.program_token = token;
  run.state = cnc::lcmt_setpoint::STARVED;
  bus_.publish(cfg_.channel(config::channels::kInterpState), run);
  pump();
  EXPECT_EQ(states_.back().state, int8_t{cnc::lcmt_program_state::RUNNING});
  // A malformed state file is ignored.
  write(fs::path(state), "nonsense\n");
  ProgramServerNode third(cfg_, bus_);
  third.use_state_file(state);
}

}  // namespace
}  // namespace cnc::pps
