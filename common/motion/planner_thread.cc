#include "common/motion/planner_thread.h"

#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <chrono>

namespace cnc::interp {

namespace {
size_t ring_capacity(const config::MachineConfig& cfg, size_t capacity) {
  if (capacity > 0) return capacity;
  return std::max<size_t>(1024, 2 * static_cast<size_t>(std::max(cfg.block_window, 1)));
}
}  // namespace

ThreadedPlanLink::ThreadedPlanLink(const config::MachineConfig& cfg, size_t capacity)
    : planner_(cfg),
      requests_(ring_capacity(cfg, capacity)),
      updates_(ring_capacity(cfg, capacity)),
      returned_(ring_capacity(cfg, capacity)),
      thread_([this] { run(); }) {}

ThreadedPlanLink::~ThreadedPlanLink() {
  stop_.store(true, std::memory_order_release);
  wake_.fetch_add(1, std::memory_order_release);
  wake_.notify_one();
  thread_.join();
  // Blocks pushed but never planned are still owned by their requests.
  while (PlanRequest* r = requests_.front()) {
    delete r->block;
    requests_.pop();
  }
}

bool ThreadedPlanLink::push(const PlanRequest& r) {
  if (!requests_.push(r)) return false;
  pushed_.fetch_add(1, std::memory_order_release);
  wake_.fetch_add(1, std::memory_order_release);
  wake_.notify_one();
  return true;
}

PlanUpdate* ThreadedPlanLink::front() {
  PlanUpdate** u = updates_.front();
  return u == nullptr ? nullptr : *u;
}

void ThreadedPlanLink::pop() {
  PlanUpdate* u = *updates_.front();
  updates_.pop();
  // Cannot be full: the planner keeps fewer updates out than the ring holds.
  returned_.push(u);
  wake_.fetch_add(1, std::memory_order_release);
  wake_.notify_one();
}

void ThreadedPlanLink::retire(uint64_t serial_below) { retired_below_.store(serial_below, std::memory_order_release); }

void ThreadedPlanLink::wait_idle() const {
  while (!idle()) std::this_thread::sleep_for(std::chrono::microseconds(20));
}

void ThreadedPlanLink::run() {
  // Planning is background work: normal scheduling, whatever the process got.
  sched_param sp{};
  sp.sched_priority = 0;
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &sp);
  pthread_setname_np(pthread_self(), "cnc-planner");
  while (!stop_.load(std::memory_order_acquire)) {
    const uint32_t seen = wake_.load(std::memory_order_acquire);
    bool worked = false;
    while (PlanUpdate** u = returned_.front()) {
      planner_.recycle(*u);
      returned_.pop();
      --outstanding_;
      worked = true;
    }
    planner_.retire(retired_below_.load(std::memory_order_acquire));
    if (outstanding_ + 1 < updates_.capacity()) {
      if (PlanRequest* r = requests_.front()) {
        const PlanRequest req = *r;
        requests_.pop();
        if (PlanUpdate* u = planner_.process(req)) {
          updates_.push(u);  // room: outstanding_ < capacity
          ++outstanding_;
        }
        processed_.fetch_add(1, std::memory_order_release);
        worked = true;
      }
    }
    if (!worked) wake_.wait(seen, std::memory_order_acquire);
  }
}

}  // namespace cnc::interp
