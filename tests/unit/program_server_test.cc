// The part-program server: it serves exactly the blocks a whole-file parse gives,
// from checkpoints and a small cache, in any order; it refuses a bad program and
// keeps the one before; it never serves a file changed after validation; and its
// node answers block requests so that a lost block is re-sent on a re-request.
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
#include "cnc/lcmt_program_state.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/program/block_msg.h"
#include "services/part_program_server/program_server.h"
#include "services/part_program_server/program_server_node.h"

namespace cnc::pps {
namespace {

namespace fs = std::filesystem;
using program::Block;
using program::BlockKind;

program::ParserSettings xyz() {
  program::ParserSettings s;
  s.axis_names = {"X", "Y", "Z"};
  s.start_position_mm = {0, 0, 0};
  return s;
}

class TempDir {
 public:
  TempDir() {
    std::string tmpl = (fs::temp_directory_path() / "cnc-pps-test.XXXXXX").string();
    path_ = ::mkdtemp(tmpl.data());
  }
  ~TempDir() { fs::remove_all(path_); }
  fs::path operator/(const std::string& name) const { return path_ / name; }

 private:
  fs::path path_;
};

void write(const fs::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary);
  out << text;
}

// Every kind of block, modal switches (G91, G20, planes, process), both NURBS
// dialects: `repeats` times a pattern of 22 blocks.
std::string mixed_program(int repeats) {
  std::ostringstream o;
  o << "(PROCESS, BALL_RADIUS=5, FLUTES=2, PICK_FEED=0.5, RMAX_UM=10.67)\nS10000 M3\nG0 X0 Y0 Z0\n";
  for (int r = 0; r < repeats; ++r) {
    o << "G1 X10 F1000\nY5\nG2 X20 Y5 I5 J0\nG3 X10 Y5 R5\nG91 G1 X1 Y1\nX-1 Y-1\nG90\n"
      << "G20 G1 X0.5 F40\nG21 X0\nG18 G2 X10 Z0 I5\nG17 G0 X0 Y0 Z0\n"
      << "(PROCESS, RMAX_UM=" << (r % 2 ? "0" : "8") << ")\n"
      << "G06.2 P3 K0 X0 Y0 Z0 F500\nK0 X5 Z-1\nK0 X10 Z-1 R2\nK0.5 X15 Z0\nK1\nK1\nK1\n"
      << "G4 P0.01\nG0 X0 Y0 Z0\nF800\nG5.2 P1 L3\nX5 Y5 P1\nX10 Y0 P2\nX15 Y5 P1\nG5.3\nG0 X0 Y0\n"
      << "G3 X0 Y0 I3 P2\nG1 Z-1\nZ0\nX1\nX2\nX3\nX0\n";
  }
  o << "M5\nM30\n(nothing after M30 is read)\n";
  return o.str();
}

void expect_same_block(const Block& a, const Block& b) {
  EXPECT_EQ(a.index, b.index);
  EXPECT_EQ(a.kind, b.kind);
  EXPECT_EQ(a.source_line, b.source_line);
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
}

TEST(ProgramServer, ServesWhatTheWholeParseGives) {
  TempDir dir;
  const fs::path file = dir / "mixed.ngc";
  write(file, mixed_program(100));
  const program::Program whole = program::GcodeParser(xyz()).parse_file(file.string());
  ASSERT_EQ(whole.blocks.size(), 2202u);  // 22 per pattern, the first G0, the end

  ProgramServer server(xyz(), ServerLimits{16, 1 << 20, 2});
  const LoadResult r = server.load(file.string(), 5);
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(server.token(), 5);
  EXPECT_EQ(server.path(), file.string());
  ASSERT_EQ(server.num_blocks(), static_cast<int64_t>(whole.blocks.size()));
  // One checkpoint per 16 blocks or a little more (a NURBS curve delays one).
  EXPECT_GE(server.num_checkpoints(), whole.blocks.size() / 17);
  EXPECT_LE(server.num_checkpoints(), whole.blocks.size() / 16 + 1);

  for (int64_t i = 0; i < server.num_blocks(); ++i) {
    const Block* b = server.block(i);
    ASSERT_NE(b, nullptr) << i << ": " << server.serving_error();
    expect_same_block(*b, whole.blocks[static_cast<size_t>(i)]);
  }
  EXPECT_EQ(server.block(server.num_blocks()), nullptr);
  EXPECT_EQ(server.block(-1), nullptr);
  const int64_t sequential_reads = server.chunk_reads();
  EXPECT_EQ(sequential_reads, static_cast<int64_t>(server.num_checkpoints()));  // each chunk read once

  std::mt19937 rng(20240607);
  std::uniform_int_distribution<int64_t> pick(0, server.num_blocks() - 1);
  for (int k = 0; k < 2000; ++k) {
    const int64_t i = pick(rng);
    const Block* b = server.block(i);
    ASSERT_NE(b, nullptr) << i << ": " << server.serving_error();
    expect_same_block(*b, whole.blocks[static_cast<size_t>(i)]);
  }
}

TEST(ProgramServer, AWindowMovingBackAndForthHitsTheCache) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  write(file, mixed_program(20));
  ProgramServer server(xyz(), ServerLimits{64, 1 << 20, 4});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  // The interpolator's pattern: a window of 32 ahead, with re-requests a little behind.
  for (int64_t first = 0; first < server.num_blocks(); first += 16)
    for (int64_t i = std::max<int64_t>(0, first - 8); i < std::min(first + 32, server.num_blocks()); ++i)
      ASSERT_NE(server.block(i), nullptr);
  EXPECT_EQ(server.chunk_reads(), static_cast<int64_t>(server.num_checkpoints()));
}

TEST(ProgramServer, ARefusedProgramKeepsThePreviousOne) {
  TempDir dir;
  write(dir / "good.ngc", "G0 X1\nG1 X2 F100\nM30\n");
  write(dir / "bad.ngc", "G0 X1\nG06.2 P4 K0 X1 Y0 Z0 F100\nK0 X2\nK0 X3\nK0 X4\nK1\nK1\nK1\nG0 X0\n");
  ProgramServer server(xyz(), ServerLimits{});
  ASSERT_TRUE(server.load((dir / "good.ngc").string(), 1).ok);
  const LoadResult r = server.load((dir / "bad.ngc").string(), 2);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.line, 9);
  EXPECT_EQ(r.column, 1);
  EXPECT_NE(r.error.find("bad.ngc:9:1: the NURBS curve opened at line 2 ends with 7 knots for 4 control points"),
            std::string::npos)
      << r.error;
  EXPECT_EQ(server.token(), 1);
  EXPECT_EQ(server.num_blocks(), 3);
  ASSERT_NE(server.block(1), nullptr);
  EXPECT_EQ(server.block(1)->kind, BlockKind::kLine);
}

TEST(ProgramServer, AMissingFileIsRefused) {
  ProgramServer server(xyz(), ServerLimits{});
  const LoadResult r = server.load("/nonexistent/p.ngc", 1);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.error.find("cannot open"), std::string::npos);
}

TEST(ProgramServer, AFileChangedAfterValidationIsNeverServed) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  const std::string text = mixed_program(10);
  write(file, text);
  ProgramServer server(xyz(), ServerLimits{16, 1 << 20, 1});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  ASSERT_NE(server.block(0), nullptr);
  // Same length, one digit changed, far into the file: X10 becomes X19.
  std::string changed = text;
  const size_t at = changed.find("G1 X10 F1000", changed.size() / 2);
  ASSERT_NE(at, std::string::npos);
  changed[at + 5] = '9';
  {
    std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(0);
    f << changed;
  }
  const Block* b = nullptr;
  int64_t i = 0;
  for (; i < server.num_blocks(); ++i)
    if ((b = server.block(i)) == nullptr) break;
  EXPECT_EQ(b, nullptr) << "the changed block was served";
  EXPECT_GT(i, 0) << "the chunks before the change are served";
  EXPECT_NE(server.serving_error().find("changed since it was loaded"), std::string::npos) << server.serving_error();
  EXPECT_FALSE(server.loaded());
  EXPECT_EQ(server.block(0), nullptr);
}

TEST(ProgramServer, AFileReplacedByRenameStillServesTheValidatedProgram) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  write(file, "G0 X1\nG1 X2 F100\nM30\n");
  ProgramServer server(xyz(), ServerLimits{1, 1 << 20, 1});
  ASSERT_TRUE(server.load(file.string(), 1).ok);
  write(dir / "other.ngc", "G0 X7\nG0 X8\nG0 X9\nM30\n");
  fs::rename(dir / "other.ngc", file);
  ASSERT_NE(server.block(1), nullptr) << server.serving_error();
  EXPECT_EQ(server.block(1)->end[0], 2);
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
  EXPECT_EQ(loaded.num_blocks, 90);

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
  request(loaded.program_token, 80, 32);
  EXPECT_EQ(blocks_.size(), 10u);
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
  EXPECT_EQ(states_.back().blocks_sent, 37 + 10);  // 0..36 and 80..89, each counted once
  EXPECT_EQ(states_.back().blocks_resent, 27);     // 5..31 went out twice
}

TEST_F(NodeTest, ARefusalNamesThePlaceAndServesNothing) {
  TempDir dir;
  write(dir / "bad.ngc", "G0 X1\nG5.2 P1 F100\nX1 Y1 P1\nX2 Y0 P1\n");
  ProgramServerNode node(cfg_, bus_);
  command(cnc::lcmt_program_command::LOAD, (dir / "bad.ngc").string());
  ASSERT_FALSE(states_.empty());
  const cnc::lcmt_program_state s = states_.back();
  EXPECT_EQ(s.state, int8_t{cnc::lcmt_program_state::REFUSED});
  EXPECT_EQ(s.error_line, 2);
  EXPECT_EQ(s.error_column, 1);
  EXPECT_NE(s.error.find("never closed"), std::string::npos) << s.error;
  request(s.program_token, 0, 32);
  EXPECT_TRUE(blocks_.empty());
}

TEST_F(NodeTest, AFileChangedUnderTheServerIsWithdrawn) {
  TempDir dir;
  const fs::path file = dir / "p.ngc";
  const std::string text = mixed_program(40);  // 882 blocks: several chunks of 256
  write(file, text);
  ProgramServerNode node(cfg_, bus_);
  command(cnc::lcmt_program_command::LOAD, file.string());
  const cnc::lcmt_program_state loaded = states_.back();
  ASSERT_EQ(loaded.state, int8_t{cnc::lcmt_program_state::LOADED}) << loaded.error;
  request(loaded.program_token, 0, 32);
  ASSERT_EQ(blocks_.size(), 32u);
  std::string changed = text;
  changed[changed.rfind("G1 X10 F1000") + 4] = '7';  // X10 becomes X70, in the last pattern
  write(file, changed);  // rewritten in place: same inode
  blocks_.clear();
  states_.clear();
  for (int64_t first = 32; first < loaded.num_blocks && states_.empty(); first += 32)
    request(loaded.program_token, first, 32);
  ASSERT_FALSE(states_.empty());
  EXPECT_EQ(states_.back().state, int8_t{cnc::lcmt_program_state::REFUSED});
  EXPECT_NE(states_.back().error.find("changed since it was loaded"), std::string::npos) << states_.back().error;
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
