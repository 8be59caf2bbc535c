#pragma once
// The interpolator's feeding policy, one for the live node, the dry run and the
// bench: keep the planner's window full (blocks taken + blocks in planning <
// motion.block_window) and take finished plans in order while the cycle's sample
// budget (motion.plan_budget_samples) lasts. Per cycle, before step():
//   1. take the plans that are ready (within the budget),
//   2. submit the next blocks up to the window,
//   3. take again (with an inline planner these are the blocks just submitted).
// With the planner inline (dry run) this is exactly the former "apply blocks while
// the window has room and the budget lasts"; with the planner on its thread (node,
// bench) a plan is taken at the first cycle it is ready, and that cycle is recorded.
#include <memory>
#include <utility>

#include "common/config/machine_config.h"
#include "common/motion/interpolator.h"

namespace cnc::interp {

class FeedPolicy {
 public:
  explicit FeedPolicy(const config::MachineConfig& cfg)
      : window_(cfg.block_window), budget_(cfg.plan_budget_samples) {}

  // Room for more blocks: how many the caller may have requested ahead.
  int64_t room(const Interpolator& core) const {
    return window_ - static_cast<int64_t>(core.queued_blocks()) - core.blocks_in_planning();
  }

  // One cycle's feeding. next(index) gives the block with that index as a
  // std::unique_ptr<program::Block>, or null when it is not there (yet); submitted(index)
  // is told of each block handed to the planner and taken(n) of each group of n
  // plans taken, in the order they happened (the node records both as inputs).
  // False when the core refused a block (core.last_refusal() says why); nothing
  // more is submitted then.
  template <class Next, class Submitted, class Taken>
  bool cycle(Interpolator& core, Next&& next, Submitted&& submitted, Taken&& taken) const {
    int64_t used = 0;
    if (const int n = core.apply_plans(budget_, &used); n > 0) taken(n);
    bool ok = true;
    while (room(core) > 0) {
      const int64_t index = core.next_block_index();
      std::unique_ptr<program::Block> b = next(index);
      if (!b) break;
      if (!core.submit_block(std::move(b))) {
        ok = false;
        break;
      }
      submitted(index);
    }
    if (const int n = core.apply_plans(budget_, &used); n > 0) taken(n);
    return ok;
  }

  int64_t window() const { return window_; }
  int64_t budget() const { return budget_; }

 private:
  int64_t window_;
  int64_t budget_;
};

}  // namespace cnc::interp
