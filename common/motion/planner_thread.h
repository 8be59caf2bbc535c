#pragma once
// The planner on a thread of its own (normal scheduling), linked to the cyclic core
// by three bounded lock-free single-producer/single-consumer rings: requests in,
// finished updates out, applied updates back (the planner frees what it allocated,
// the cyclic thread never allocates or frees). The content of every update is the
// Planner's pure function of the request order; only the cycle at which the core
// takes an update depends on timing, and the core's caller records that cycle.
#include <atomic>
#include <cstdint>
#include <thread>

#include "common/motion/planner.h"
#include "common/util/spsc_ring.h"

namespace cnc::interp {

class ThreadedPlanLink final : public PlanLink {
 public:
  // capacity 0: twice motion.block_window, at least 1024. The rings must hold a whole
  // window of blocks submitted in one cycle (a window of 4096 in rings of 1024 stopped
  // a program with "the planner is busy" at its 1025th block).
  explicit ThreadedPlanLink(const config::MachineConfig& cfg, size_t capacity = 0);
  ~ThreadedPlanLink() override;  // stops and joins the thread; frees the requests left

  // Cyclic side (one thread).
  bool push(const PlanRequest& r) override;
  PlanUpdate* front() override;
  void pop() override;
  void retire(uint64_t serial_below) override;

  // Any thread: true when every request pushed so far has its update out (tests and
  // the bench wait on it to take plans at chosen cycles).
  bool idle() const { return processed_.load(std::memory_order_acquire) == pushed_.load(std::memory_order_acquire); }
  void wait_idle() const;
  // Planner-thread figures (read at the end of a run).
  int64_t requests_processed() const { return processed_.load(std::memory_order_acquire); }

 private:
  void run();

  Planner planner_;
  util::SpscRing<PlanRequest> requests_;
  util::SpscRing<PlanUpdate*> updates_;
  util::SpscRing<PlanUpdate*> returned_;
  size_t outstanding_ = 0;  // planner thread: updates out, not yet returned
  std::atomic<uint64_t> retired_below_{0};
  std::atomic<int64_t> pushed_{0};
  std::atomic<int64_t> processed_{0};
  std::atomic<uint32_t> wake_{0};
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace cnc::interp
