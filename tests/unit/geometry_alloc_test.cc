// The per-cycle functions of geometry (NURBS evaluation, chord error) and process
// (roughness feed law) never allocate: a test-only replacement of the global
// operator new counts allocations inside a window around the calls.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <new>

#include "common/geometry/chord.h"
#include "common/geometry/nurbs.h"
#include "common/process/roughness.h"

namespace {
bool g_counting = false;
long g_allocations = 0;

void* counted_alloc(std::size_t size) {
  if (g_counting) ++g_allocations;
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
}  // namespace

void* operator new(std::size_t size) { return counted_alloc(size); }
void* operator new[](std::size_t size) { return counted_alloc(size); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace cnc::geometry {
namespace {

class AllocationWindow {
 public:
  AllocationWindow() {
    g_allocations = 0;
    g_counting = true;
  }
  ~AllocationWindow() { g_counting = false; }
  long count() const { return g_allocations; }
};

TEST(NoAllocation, GuardSeesAnAllocation) {
  AllocationWindow w;
  void* p = ::operator new(16);  // a direct call, which the compiler may not elide
  ::operator delete(p);
  EXPECT_EQ(w.count(), 1);
}

TEST(NoAllocation, NurbsEvaluationAndChordError) {
  const NurbsCurve c(5, {0, 0, 0, 0, 0, 0.4, 0.4, 1, 1, 1, 1, 1},
                     {{0, 0, 0}, {1, 2, 0}, {2, -1, 1}, {3, 0, 2}, {4, 4, 1}, {5, 1, 0}, {7, 0, 0}},
                     {1, 0.5, 2, 1, 0.8, 1.5, 1});
  double sink = 0.0;
  AllocationWindow w;
  for (int i = 0; i <= 100; ++i) {
    const double u = i / 100.0;
    Vec3 d[4];
    c.derivatives(u, 3, d);
    sink += d[3].x() + c.point(u).y() + c.curvature(u) + c.find_span(u);
    sink += chord_error_of_step(c, u, u + 0.01);
    sink += chord_feed_limit_mm_per_min(1.0 / c.curvature(u), 1e-3, 0.004);
  }
  sink += arc_length(c, 0.1, 0.9);
  EXPECT_EQ(w.count(), 0);
  EXPECT_TRUE(std::isfinite(sink));
}

TEST(NoAllocation, RoughnessFeedLaw) {
  const process::RoughnessLaw law{5.0, 2, 0.5, 0.0102};
  double sink = 0.0;
  AllocationWindow w;
  for (int i = -90; i <= 90; ++i) {
    const double alpha = i * 3.141592653589793 / 180;
    sink += law.feed_mm_per_min(10000, alpha) + process::rmax_extended(5.0, 0.4, 0.5, alpha);
    sink += process::feed_inclination_angle({1.0, 0.5, std::sin(alpha)});
  }
  EXPECT_EQ(w.count(), 0);
  EXPECT_TRUE(std::isfinite(sink));
}

}  // namespace
}  // namespace cnc::geometry
