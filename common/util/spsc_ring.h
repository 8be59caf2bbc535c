#pragma once
// A bounded single-producer/single-consumer ring, lock-free and allocation-free
// after construction: one thread pushes, one other thread pops. Used between the
// interpolator's cyclic thread and its planner thread, the servo simulator and its writer.
#include <atomic>
#include <cstddef>
#include <memory>
#include <new>

namespace cnc::util {

template <class T>
class SpscRing {
 public:
  // Holds up to `capacity` elements (rounded up to a power of two).
  explicit SpscRing(size_t capacity) : mask_(round_up(capacity) - 1), slots_(new T[mask_ + 1]()) {}  // value-initialised: the pages are touched here
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  size_t capacity() const { return mask_ + 1; }

  // Producer: false when full (nothing is written).
  bool push(const T& v) {
    const size_t h = head_.load(std::memory_order_relaxed);
    if (h - tail_cache_ > mask_) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (h - tail_cache_ > mask_) return false;
    }
    slots_[h & mask_] = v;
    head_.store(h + 1, std::memory_order_release);
    return true;
  }

  // Consumer: the oldest element, or nullptr when empty; stays until pop().
  T* front() {
    const size_t t = tail_.load(std::memory_order_relaxed);
    if (t == head_cache_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (t == head_cache_) return nullptr;
    }
    return &slots_[t & mask_];
  }
  // Consumer: drops front() (which must have returned an element).
  void pop() { tail_.store(tail_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

  // Either side: a snapshot, exact only when the other side is quiet.
  size_t size() const { return head_.load(std::memory_order_acquire) - tail_.load(std::memory_order_acquire); }

 private:
  static size_t round_up(size_t n) {
    size_t p = 1;
    while (p < n) p <<= 1;
    return p;
  }
  static constexpr size_t kLine = 64;
  const size_t mask_;
  const std::unique_ptr<T[]> slots_;
  alignas(kLine) std::atomic<size_t> head_{0};  // written by the producer
  alignas(kLine) size_t tail_cache_ = 0;         // the producer's view of tail_
  alignas(kLine) std::atomic<size_t> tail_{0};  // written by the consumer
  alignas(kLine) size_t head_cache_ = 0;         // the consumer's view of head_
};

}  // namespace cnc::util
