#pragma once
// A malloc-counting guard for tests of cyclic (real-time) paths. Include this header
// in exactly ONE translation unit of a test executable: it replaces the global
// operator new / delete of that executable with counting versions. Counting is per
// thread: an AllocGuard counts the allocations and frees made by the thread that
// created it while it lives, so a helper thread (a planner, LCM's receive thread)
// does not disturb the count.
//
//   {
//     cnc::test::AllocGuard g;
//     core.step();
//     EXPECT_EQ(g.allocations(), 0);
//     EXPECT_EQ(g.frees(), 0);
//   }
#include <cstddef>
#include <cstdlib>
#include <new>

namespace cnc::test {

struct AllocCounts {
  bool on = false;
  long allocations = 0;
  long frees = 0;
};

inline AllocCounts& alloc_counts() {
  static thread_local AllocCounts c;
  return c;
}

class AllocGuard {
 public:
  AllocGuard() : saved_(alloc_counts()) {
    alloc_counts() = AllocCounts{true, 0, 0};
  }
  ~AllocGuard() { alloc_counts() = saved_; }
  AllocGuard(const AllocGuard&) = delete;
  AllocGuard& operator=(const AllocGuard&) = delete;
  long allocations() const { return alloc_counts().allocations; }
  long frees() const { return alloc_counts().frees; }
  // Stops counting before the end of the scope (for assertions that allocate).
  void pause() { alloc_counts().on = false; }
  void resume() { alloc_counts().on = true; }

 private:
  AllocCounts saved_;
};

namespace detail {
inline void* counted_alloc(std::size_t size) {
  AllocCounts& c = alloc_counts();
  if (c.on) ++c.allocations;
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
inline void* counted_alloc_aligned(std::size_t size, std::align_val_t al) {
  AllocCounts& c = alloc_counts();
  if (c.on) ++c.allocations;
  const std::size_t a = static_cast<std::size_t>(al);
  if (void* p = std::aligned_alloc(a, (size + a - 1) / a * a)) return p;
  throw std::bad_alloc();
}
inline void counted_free(void* p) {
  if (p == nullptr) return;
  AllocCounts& c = alloc_counts();
  if (c.on) ++c.frees;
  std::free(p);
}
}  // namespace detail

}  // namespace cnc::test

void* operator new(std::size_t size) { return cnc::test::detail::counted_alloc(size); }
void* operator new[](std::size_t size) { return cnc::test::detail::counted_alloc(size); }
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return cnc::test::detail::counted_alloc(size);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return cnc::test::detail::counted_alloc(size);
  } catch (...) {
    return nullptr;
  }
}
void* operator new(std::size_t size, std::align_val_t al) { return cnc::test::detail::counted_alloc_aligned(size, al); }
void* operator new[](std::size_t size, std::align_val_t al) { return cnc::test::detail::counted_alloc_aligned(size, al); }
void operator delete(void* p) noexcept { cnc::test::detail::counted_free(p); }
void operator delete[](void* p) noexcept { cnc::test::detail::counted_free(p); }
void operator delete(void* p, std::size_t) noexcept { cnc::test::detail::counted_free(p); }
void operator delete[](void* p, std::size_t) noexcept { cnc::test::detail::counted_free(p); }
void operator delete(void* p, std::align_val_t) noexcept { cnc::test::detail::counted_free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { cnc::test::detail::counted_free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { cnc::test::detail::counted_free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { cnc::test::detail::counted_free(p); }
