#pragma once
// Latest-value exchange between one writer thread and one reader thread, wait-free
// on both sides and allocation-free: three slots, one the writer fills, one the
// reader holds, one in between; publishing and taking are a single atomic exchange
// of the slot index. The reader always gets the newest complete value and never a
// torn one; values the reader did not take in time are overwritten (the servo loop
// wants the newest drive report, the link worker the newest command). T must be
// trivially copyable. Used between the drive bridge's servo thread and its link
// workers, instead of a mutex both sides took every tick.
#include <atomic>
#include <cstdint>
#include <type_traits>

namespace cnc::util {

template <class T>
class TripleBuffer {
  static_assert(std::is_trivially_copyable_v<T>, "TripleBuffer holds plain data");

 public:
  TripleBuffer() = default;
  explicit TripleBuffer(const T& initial) {
    for (T& s : slots_) s = initial;
  }
  TripleBuffer(const TripleBuffer&) = delete;
  TripleBuffer& operator=(const TripleBuffer&) = delete;

  // Writer: the slot to fill, then publish().
  T& back() { return slots_[back_]; }
  void publish() { back_ = middle_.exchange(back_ | kFresh, std::memory_order_acq_rel) & kIndex; }
  void write(const T& v) {
    back() = v;
    publish();
  }

  // Reader: takes the newest published value if there is one since the last take,
  // and returns the value held (the previous one otherwise).
  const T& read() {
    if (middle_.load(std::memory_order_relaxed) & kFresh)
      front_ = middle_.exchange(front_, std::memory_order_acq_rel) & kIndex;
    return slots_[front_];
  }

 private:
  static constexpr uint32_t kIndex = 3;
  static constexpr uint32_t kFresh = 4;
  T slots_[3]{};
  // Each index is owned by one side except middle_, which both exchange.
  alignas(64) uint32_t back_ = 0;
  alignas(64) std::atomic<uint32_t> middle_{1};
  alignas(64) uint32_t front_ = 2;
};

}  // namespace cnc::util
