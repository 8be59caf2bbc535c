// Run from line N: on a program with work offsets (G10 L2, G54/G55, G92), a
// tool change with its length (T2 M6 G43), spindle, coolant and an O-word subroutine,
// the interpreter's state before line N as the run from N rebuilds it (the validation
// run and the serving run) equals a full run's at line N, field by field; the blocks
// served after the approach are the full program's from line N (every field the
// interpolator uses, renumbered); and the interpolator's setpoints from line N on are
// the full run's, bit for bit (N after a program event, where the full run rests too:
// the approach ends at rest on the start point).
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/interpolator.h"
#include "services/part_program_server/program_server.h"
#include "tests/unit/temp_dir.h"

namespace cnc {
namespace {

using test::TempDir;

const config::MachineConfig& sim3() {
  static const config::MachineConfig cfg =
      config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  return cfg;
}

constexpr const char* kProgram =
    "G21 G90 G17 G94\n"          // 1
    "G10 L2 P2 X10 Y5 Z0\n"      // 2  G55's offset
    "G54 G0 X0 Y0 Z3\n"          // 3
    "T2 M6\n"                    // 4  tool change
    "G43 H2\n"                   // 5  its length
    "S8000 M3\n"                 // 6  spindle
    "M8\n"                       // 7  coolant
    "G1 Z-1 F600\n"              // 8
    "G1 X30 Y10\n"               // 9
    "G55\n"                      // 10
    "G92 X0 Y0\n"                // 11
    "o<corner> call [5]\n"       // 12 subroutine
    "G0 Z2\n"                    // 13
    "G54 G92.1\n"                // 14
    "G1 X40 Y20 F900\n"          // 15
    "M9\n"                       // 16
    "M5\n"                       // 17
    "G1 X50 Z-2\n"               // 18
    "G2 X60 Y20 I5 J0\n"         // 19
    "M2\n";                      // 20

constexpr const char* kSub =
    "o<corner> sub\n"
    "G1 X#1 Y0 F300\n"
    "G1 X#1 Y#1\n"
    "G1 X0 Y#1\n"
    "o<corner> endsub\n"
    "M2\n";

struct Files {
  TempDir dir;
  std::string program, tools;
  pps::ProgramSetup setup;
  Files() {
    program = dir.write("p.ngc", kProgram);
    dir.dir("subs");
    dir.write("subs/corner.ngc", kSub);
    tools = dir.write("tools.tbl", "T2 P2 Z1.5 D6\n");
    setup = pps::program_setup(sim3());
    setup.machine.tool_table = tools;
    setup.machine.subroutine_path = {(dir / "subs").string()};
  }
};

// The full run's state before the main file's line N, by an interpreter of its own.
rs274::ModalState full_run_state(const Files& f, int from_line) {
  std::unique_ptr<rs274::Interpreter> interp;
  rs274::BlockBuilder builder(
      f.setup.builder, [&interp](int32_t i) -> const std::string& { return interp->file_names()[static_cast<size_t>(i)]; });
  rs274::MachineSetup m = f.setup.machine;
  m.write_var_file = false;
  interp = std::make_unique<rs274::Interpreter>(m, builder);
  rs274::ModalState at;
  bool got = false;
  interp->set_line_hook([&](int32_t file, int32_t line) {
    if (!got && file == 0 && line >= from_line) {
      at = interp->modal_state();
      got = true;
    }
  });
  interp->open(f.program);
  while (interp->execute_next()) builder.blocks().clear();
  EXPECT_TRUE(got);
  return at;
}

// Field by field, each named; the number of fields that differ.
int compare(const rs274::ModalState& a, const rs274::ModalState& b, const std::string& what) {
  int diff = 0;
#define CMP(f)                                                          \
  if (!(a.f == b.f)) {                                                  \
    ++diff;                                                             \
    ADD_FAILURE() << what << ": field " #f " differs";                 \
  }
  CMP(motion) CMP(plane) CMP(incremental) CMP(arc_incremental) CMP(feed_mode) CMP(units) CMP(comp)
  CMP(comp_radius) CMP(tool_length) CMP(coord) CMP(retract_r) CMP(path) CMP(path_p) CMP(path_q) CMP(feed)
  CMP(speed) CMP(spindle) CMP(mist) CMP(flood) CMP(feed_override) CMP(speed_override) CMP(adaptive_feed)
  CMP(feed_hold) CMP(tool) CMP(selected_tool) CMP(tool_offset) CMP(g92) CMP(g92_active) CMP(rotation_deg)
  CMP(position)
#undef CMP
  for (size_t i = 0; i < a.offsets.size(); ++i) {
    if (std::memcmp(&a.offsets[i], &b.offsets[i], sizeof(double)) != 0) {
      ++diff;
      ADD_FAILURE() << what << ": parameter #" << 5161 + i << " differs: " << a.offsets[i] << " vs " << b.offsets[i];
    }
  }
  EXPECT_EQ(a, b);
  return diff;
}

std::vector<program::Block> served(pps::ProgramServer& s) {
  std::vector<program::Block> out;
  for (int64_t i = 0; i < s.num_blocks(); ++i) {
    const program::Block* b = s.block(i);
    EXPECT_NE(b, nullptr) << "block " << i << ": " << s.serving_error();
    if (b == nullptr) break;
    out.push_back(*b);
  }
  return out;
}

struct Sp {
  std::array<double, program::kMaxAxes> pos;
  double feed;
  int32_t line;
};

// The dry run of `blocks` in the interpolator core (pauses resumed at once); the
// setpoints from the first one that moves in block `from` or later.
std::vector<Sp> dry_run(const std::vector<program::Block>& blocks, int64_t from) {
  interp::Interpolator core(sim3());
  core.set_auto_resume_pauses(true);
  core.apply_command({interp::Command::Kind::kLoad, 1.0, {}});
  for (const auto& b : blocks) EXPECT_TRUE(core.apply_block(b)) << core.last_refusal();
  core.apply_command({interp::Command::Kind::kStart, 1.0, {}});
  std::vector<Sp> out;
  for (int i = 0; i < 1000000 && core.state() != interp::RunState::kDone; ++i) {
    const interp::Setpoint& s = core.step();
    if (out.empty() && !(s.block_index >= from && s.feed_mm_per_min > 0)) continue;
    out.push_back({s.position_mm, s.feed_mm_per_min, s.source_line});
  }
  EXPECT_EQ(core.state(), interp::RunState::kDone);
  return out;
}

TEST(RunFromLine, ModalStateAtLineNIsTheFullRunsFieldByField) {
  Files f;
  int compared = 0;
  for (const int n : {5, 8, 12, 13, 15, 18}) {
    pps::ProgramServer server(f.setup, {});
    const pps::LoadResult r = server.load_from(f.program, 1, {}, n);
    ASSERT_TRUE(r.ok) << r.error;
    const rs274::ModalState full = full_run_state(f, n);
    EXPECT_EQ(compare(server.state_at_from(), full, "validation run, line " + std::to_string(n)), 0);
    served(server);  // serves every block: the serving interpreter passes line N
    rs274::ModalState serving;
    ASSERT_TRUE(server.serving_state_at_from(&serving));
    EXPECT_EQ(compare(serving, full, "serving run, line " + std::to_string(n)), 0);
    ++compared;
    if (n == 12) {
      // Spot checks that the state holds what the program set: G55 active with G92, tool 2.
      EXPECT_EQ(full.coord, 2);
      EXPECT_TRUE(full.g92_active);
      EXPECT_EQ(full.tool, 2);
      EXPECT_EQ(full.spindle, 1);
      EXPECT_EQ(full.speed, 8000);
      EXPECT_TRUE(full.flood);
      EXPECT_EQ(full.tool_length, 430);
      EXPECT_EQ(full.offsets[5241 - 5161], 10.0) << "G55 X (#5241)";
    }
  }
  EXPECT_EQ(compared, 6);
}

TEST(RunFromLine, ThePathFromLineNIsTheFullRunsAfterTheApproach) {
  Files f;
  pps::ProgramServer full_server(f.setup, {});
  ASSERT_TRUE(full_server.load(f.program, 1).ok);
  const std::vector<program::Block> full = served(full_server);
  for (const int n : {8, 18}) {
    pps::ProgramServer server(f.setup, {});
    const pps::LoadResult r = server.load_from(f.program, 2, {}, n);
    ASSERT_TRUE(r.ok) << r.error;
    const std::vector<program::Block> from = served(server);
    const int64_t a = server.approach_blocks();
    ASSERT_GT(a, 0);
    // The approach: up to the safe height (Z's max, 5), across, the tool change (T2),
    // spindle (line 8: 8000 rpm cw; line 18: off after M5) and coolant (flood; off
    // after M9) as events, down, and at rest there.
    EXPECT_NE(server.approach_text().find("tool change T2"), std::string::npos) << server.approach_text();
    EXPECT_NE(server.approach_text().find(n == 8 ? "spindle cw 8000 rpm" : "spindle off"), std::string::npos)
        << server.approach_text();
    EXPECT_NE(server.approach_text().find(n == 8 ? "coolant flood" : "coolant off"), std::string::npos)
        << server.approach_text();
    EXPECT_EQ(from[0].end[2], 5.0) << "the first move lifts Z to the safe height";
    EXPECT_EQ(from[static_cast<size_t>(a - 1)].kind, program::BlockKind::kDwell);
    // The program's blocks from line N: the full program's, renumbered.
    const int64_t k = static_cast<int64_t>(full.size()) - (static_cast<int64_t>(from.size()) - a);
    ASSERT_GT(k, 0);
    EXPECT_EQ(full[static_cast<size_t>(k)].source_line, n);
    EXPECT_EQ(from[static_cast<size_t>(a - 1)].end, full[static_cast<size_t>(k)].start) << "the approach ends on line N's start";
    for (size_t j = 0; j + static_cast<size_t>(a) < from.size(); ++j) {
      program::Block x = from[j + static_cast<size_t>(a)], y = full[j + static_cast<size_t>(k)];
      EXPECT_EQ(x.index, a + static_cast<int64_t>(j));
      x.index = y.index = 0;
      EXPECT_EQ(pps::block_hash(x, 0), pps::block_hash(y, 0)) << "block " << j << " from line " << n;
    }
    // The setpoints from line N on: bit for bit the full run's.
    const std::vector<Sp> sp_full = dry_run(full, k), sp_from = dry_run(from, a);
    ASSERT_FALSE(sp_full.empty());
    ASSERT_EQ(sp_full.size(), sp_from.size()) << "line " << n;
    size_t differ = 0;
    for (size_t i = 0; i < sp_full.size(); ++i)
      if (std::memcmp(sp_full[i].pos.data(), sp_from[i].pos.data(), sizeof(double) * 3) != 0 ||
          std::memcmp(&sp_full[i].feed, &sp_from[i].feed, sizeof(double)) != 0 || sp_full[i].line != sp_from[i].line)
        ++differ;
    EXPECT_EQ(differ, 0u) << "of " << sp_full.size() << " setpoints from line " << n;
    std::printf("# run from line %d: %lld approach blocks (%s); %zu blocks and %zu setpoints from line %d, %zu differ\n", n,
                static_cast<long long>(a), server.approach_text().c_str(), from.size() - static_cast<size_t>(a),
                sp_from.size(), n, differ);
  }
}

TEST(RunFromLine, ALineNeverReachedIsRefusedWithItsPlace) {
  Files f;
  pps::ProgramServer server(f.setup, {});
  const pps::LoadResult r = server.load_from(f.program, 1, {}, 99);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.line, 99);
  EXPECT_NE(r.error.find("p.ngc:99:1: run from line 99: the program never gets there"), std::string::npos) << r.error;
}

// MDI (README "MDI"): consecutive lines share their modes: G91 in one line stays for
// the next, and a line of only X5 moves in the G0 of the line before.
TEST(RunFromLine, MdiLinesKeepTheirModes) {
  Files f;
  pps::ProgramServer server(f.setup, {});
  const auto line = [&](const std::string& name, const std::string& text, int64_t token) {
    const std::string path = f.dir.write(name, "%\n" + text + "\n%\n");  // as the program server writes it
    const std::optional<rs274::ModalState> modes = server.modes_after();
    server.next_load_is_line(modes ? &*modes : nullptr);
    return server.load(path, token, {0, 0, 0});
  };
  ASSERT_TRUE(line("a.ngc", "G0 X1", 1).ok);
  ASSERT_TRUE(server.modes_after().has_value());
  EXPECT_EQ(server.modes_after()->motion, 0);
  ASSERT_TRUE(line("b.ngc", "G91", 2).ok);
  EXPECT_TRUE(server.modes_after()->incremental);
  EXPECT_EQ(server.modes_after()->motion, 0);
  const pps::LoadResult r = line("c.ngc", "X5", 3);
  ASSERT_TRUE(r.ok) << r.error;
  const program::Block* b = server.block(0);
  ASSERT_NE(b, nullptr);
  EXPECT_EQ(b->kind, program::BlockKind::kRapid);
  EXPECT_NEAR(b->end[0], 5.0, 1e-9);  // from X 0 (the start given), incremental
  // The line's end is no program end: M8 and M3 stay on (M2's stops would turn them
  // off), and its end block says so to the interpolator. Blocks served, as
  // "kind[ event number]" each.
  const auto served = [&] {
    std::string out;
    for (int64_t i = 0; i < server.num_blocks(); ++i) {
      const program::Block* e = server.block(i);
      if (e == nullptr) return out + " (missing)";
      if (!out.empty()) out += ", ";
      out += program::to_string(e->kind);
      if (e->kind == program::BlockKind::kEvent) {
        out += ' ';
        out += program::to_string(e->event.kind);
      }
      if (e->kind == program::BlockKind::kEvent || e->kind == program::BlockKind::kEnd) {
        out += ' ';
        out += std::to_string(e->event.number);
      }
    }
    return out;
  };
  ASSERT_TRUE(line("m.ngc", "M8 M3 S1000", 5).ok);
  EXPECT_EQ(served(), "event spindle 1, event coolant 2, end " + std::to_string(program::kEndOfOperatorLine));
  // The next line starts with them on: M9 and M5 turn them off (before, the line's
  // interpreter thought them off already and made no event: the flood stayed on).
  ASSERT_TRUE(line("o.ngc", "M9 M5", 6).ok);
  EXPECT_EQ(served(), "event spindle 0, event coolant 0, end " + std::to_string(program::kEndOfOperatorLine));
  // A program load is not a line: the modes it starts in are a program's.
  const pps::LoadResult p = server.load(f.dir.write("d.ngc", "X5\nM2\n"), 4, {0, 0, 0});
  EXPECT_FALSE(p.ok);
  EXPECT_NE(p.error.find("motion mode is G80"), std::string::npos) << p.error;
}

}  // namespace
}  // namespace cnc
