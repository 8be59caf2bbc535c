// The interpolator's cyclic path never allocates or frees memory: every cycle of a
// whole program — the feed policy (plans taken from the planner thread, blocks
// handed to it), commands (hold, resume, override changes, stop, load) and step() —
// runs inside a malloc-counting guard (alloc_guard.h, per thread: the planner thread
// allocates freely). The run is then replayed with the planner inline, taking the
// plans at the recorded cycles: the setpoints are identical bit for bit.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/feed_policy.h"
#include "common/motion/interpolator.h"
#include "common/motion/planner_thread.h"
#include "services/part_program_server/program_server.h"
#include "tests/unit/alloc_guard.h"

namespace cnc::interp {
namespace {

config::MachineConfig sim3() { return config::load_machine_config(CNC_SOURCE_DIR "/config/machines/sim3.yaml"); }

std::vector<program::Block> load_program(const config::MachineConfig& cfg, const std::string& file,
                                         const std::vector<double>& here = {}) {
  pps::ProgramServer server(cfg);
  const auto r = here.empty() ? server.load(CNC_SOURCE_DIR "/config/programs/" + file, 1)
                              : server.load(CNC_SOURCE_DIR "/config/programs/" + file, 1, here);
  EXPECT_TRUE(r.ok) << r.error;
  std::vector<program::Block> blocks;
  for (int64_t i = 0; i < server.num_blocks(); ++i) blocks.push_back(*server.block(i));
  return blocks;
}

// One recorded input, as the node records them: a command, a block handed to the
// planner, or n plans taken, at a cycle.
struct Input {
  enum Kind { kCommand, kBlock, kPlans } kind;
  int64_t cycle;
  int64_t n;  // kBlock: index; kPlans: count
  Command cmd;
};

TEST(InterpolatorAlloc, GuardSeesAnAllocation) {
  test::AllocGuard g;
  void* p = ::operator new(24);
  ::operator delete(p);
  EXPECT_EQ(g.allocations(), 1);
  EXPECT_EQ(g.frees(), 1);
}

TEST(InterpolatorAlloc, CyclicPathAllocatesNothingAndReplaysBitForBit) {
  const config::MachineConfig cfg = sim3();
  const auto program = load_program(cfg, "butterfly.ngc");
  ASSERT_GT(program.size(), 3u);
  // The same program twice: the first run with hold, resume and override changes to
  // its end, the second stopped in the middle (then a fresh load).
  std::map<int64_t, Command> script = {
      {0, {Command::Kind::kLoad, 1.0, {}}},      {1, {Command::Kind::kStart, 1.0, {}}},
      {250, {Command::Kind::kOverride, 0.5, {}}}, {600, {Command::Kind::kHold, 1.0, {}}},
      {900, {Command::Kind::kResume, 1.0, {}}},   {1100, {Command::Kind::kOverride, 1.3, {}}},
      {1500, {Command::Kind::kOverride, 0.0, {}}}, {1700, {Command::Kind::kOverride, 1.0, {}}},
  };

  ThreadedPlanLink link(cfg);
  Interpolator core(cfg, link);
  const FeedPolicy feed(cfg);
  std::vector<Input> record;
  record.reserve(1 << 20);  // recorded inside the guard: no growth
  std::vector<Setpoint> live;
  live.reserve(1 << 20);
  long allocations = 0, frees = 0;
  int64_t first_bad = -1;

  auto run = [&](std::vector<std::unique_ptr<program::Block>>& source, const std::map<int64_t, Command>& cmds,
                 int64_t stop_at, int64_t max_cycles) {
    auto next = [&](int64_t i) -> std::unique_ptr<program::Block> {
      return static_cast<size_t>(i) < source.size() ? std::move(source[static_cast<size_t>(i)]) : nullptr;
    };
    const int64_t start = core.cycle();
    for (int64_t k = 0; k < max_cycles; ++k) {
      // The planner is never late here: each cycle starts once it is idle (outside the guard).
      link.wait_idle();
      const int64_t cyc = core.cycle();
      test::AllocGuard g;
      const Command* c = nullptr;
      const Command stop{Command::Kind::kStop, 1.0, {}};
      if (auto it = cmds.find(cyc - start); it != cmds.end()) c = &it->second;
      if (cyc - start == stop_at) c = &stop;
      if (c != nullptr && core.apply_command(*c)) record.push_back({Input::kCommand, cyc, 0, *c});
      feed.cycle(
          core, next, [&](int64_t index) { record.push_back({Input::kBlock, cyc, index, {}}); },
          [&](int n) { record.push_back({Input::kPlans, cyc, n, {}}); });
      live.push_back(core.step());
      if ((g.allocations() != 0 || g.frees() != 0) && first_bad < 0) {
        first_bad = cyc;
        g.pause();
        std::printf("cycle %lld (run cycle %lld): %ld allocations, %ld frees; state %s, blocks done %lld, queued %zu\n",
                    static_cast<long long>(cyc), static_cast<long long>(cyc - start), g.allocations(), g.frees(),
                    to_string(core.state()), static_cast<long long>(core.blocks_done()), core.queued_blocks());
      }
      allocations += g.allocations();
      frees += g.frees();
      if (k > 2 && (core.state() == RunState::kDone || core.state() == RunState::kIdle)) break;
    }
  };

  auto make_source = [](const std::vector<program::Block>& blocks) {
    std::vector<std::unique_ptr<program::Block>> s;
    for (const auto& b : blocks) s.push_back(std::make_unique<program::Block>(b));
    return s;
  };
  auto s1 = make_source(program);
  run(s1, script, -1, 200000);
  EXPECT_EQ(core.state(), RunState::kDone);
  // The same program again, from where the first run ended.
  const auto again = load_program(cfg, "butterfly.ngc",
                                  std::vector<double>(core.last().position_mm.begin(),
                                                      core.last().position_mm.begin() + core.last().num_axes));
  auto s2 = make_source(again);
  run(s2, {{0, {Command::Kind::kLoad, 1.0, {}}}, {1, {Command::Kind::kStart, 1.0, {}}}}, 700, 200000);
  EXPECT_EQ(core.state(), RunState::kIdle);
  EXPECT_GT(core.blocks_done(), 0);

  EXPECT_EQ(allocations, 0) << "first at cycle " << first_bad;
  EXPECT_EQ(frees, 0) << "first at cycle " << first_bad;
  EXPECT_GT(live.size(), 2000u);

  // Replay with the planner inline, plans taken at the recorded cycles.
  SyncPlanLink inline_planner(cfg);
  Interpolator replay(cfg, inline_planner);
  auto r1 = make_source(program);
  auto r2 = make_source(again);
  std::vector<std::unique_ptr<program::Block>>* src = &r1;
  bool second = false;
  size_t in = 0;
  for (size_t i = 0; i < live.size(); ++i) {
    const int64_t cyc = replay.cycle();
    for (; in < record.size() && record[in].cycle == cyc; ++in) {
      const Input& e = record[in];
      switch (e.kind) {
        case Input::kPlans: ASSERT_TRUE(replay.apply_plans_exact(static_cast<int>(e.n))) << "cycle " << cyc; break;
        case Input::kCommand:
          if (e.cmd.kind == Command::Kind::kLoad && replay.next_block_index() > 0 && !second) {
            src = &r2;
            second = true;
          }
          ASSERT_TRUE(replay.apply_command(e.cmd));
          break;
        case Input::kBlock:
          ASSERT_TRUE(replay.submit_block(std::move((*src)[static_cast<size_t>(e.n)]))) << replay.last_refusal();
          break;
      }
    }
    const Setpoint& sp = replay.step();
    ASSERT_EQ(std::memcmp(sp.position_mm.data(), live[i].position_mm.data(), sizeof sp.position_mm), 0)
        << "cycle " << sp.cycle;
    ASSERT_EQ(std::memcmp(&sp.feed_mm_per_min, &live[i].feed_mm_per_min, sizeof(double)), 0) << "cycle " << sp.cycle;
    ASSERT_EQ(sp.state, live[i].state) << "cycle " << sp.cycle;
  }
}

}  // namespace
}  // namespace cnc::interp
