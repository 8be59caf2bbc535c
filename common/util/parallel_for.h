#pragma once
// The one parallel loop of the CAM and prediction libraries: indices [0, n) handed
// out in chunks, in increasing order, to up to `threads` threads (the caller's among
// them). Results stay deterministic when each index writes only its own output.
// A body that throws does not stop the others; the first exception is rethrown
// once every chunk has run.
#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <type_traits>
#include <vector>

namespace cnc::util {

// body(i) for each index, or body(begin, end) for each chunk [begin, end).
template <class F>
void parallel_for(std::size_t n, int threads, F&& body, std::size_t chunk = 1) {
  chunk = std::max<std::size_t>(chunk, 1);
  const std::size_t chunks = (n + chunk - 1) / chunk;
  const auto nthreads = static_cast<std::size_t>(std::max(1, threads));
  const std::size_t workers = std::min(nthreads, std::max<std::size_t>(chunks, 1));
  std::atomic<std::size_t> next{0};
  std::mutex failed;
  std::exception_ptr failure;
  auto work = [&] {
    for (std::size_t b; (b = next.fetch_add(chunk, std::memory_order_relaxed)) < n;) {
      const std::size_t e = std::min(n, b + chunk);
      try {
        if constexpr (std::is_invocable_v<F&, std::size_t, std::size_t>) {
          body(b, e);
        } else {
          for (std::size_t i = b; i < e; ++i) body(i);
        }
      } catch (...) {
        const std::lock_guard<std::mutex> lock(failed);
        if (!failure) failure = std::current_exception();
      }
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (std::size_t k = 1; k < workers; ++k) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  if (failure) std::rethrow_exception(failure);
}

}  // namespace cnc::util
