#pragma once
// A fixed-bin latency histogram for the cyclic loops, in the spirit of cyclictest:
// record() is O(1) and touches only the object (no allocation, no lock, no I/O),
// so it can run in every cycle; percentiles and the JSON form are computed at the
// end of the run.
//
// Bins: 1 µs wide over [0, 1 ms), 10 µs wide over [1 ms, 20 ms), then one overflow
// bin (>= 20 ms). min, max and the mean are exact whatever the bin; a percentile is
// the upper edge of the bin holding the nearest-rank sample, clamped to [min, max]:
// it is never below the exact nearest-rank value and at most one bin width above
// it (1 µs below 1 ms, 10 µs up to 20 ms); in the overflow bin it is the maximum.
// A negative sample (a clock read before the deadline it is measured against) is
// counted in bin 0 and in negative().
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>

namespace cnc::util {

class LatencyHistogram {
 public:
  static constexpr int64_t kFineUs = 1000;        // 1 µs bins below this
  static constexpr int64_t kCoarseWidthUs = 10;   // then 10 µs bins
  static constexpr int64_t kRangeUs = 20000;      // up to this; beyond: overflow
  static constexpr int kFineBins = static_cast<int>(kFineUs);
  static constexpr int kBins = kFineBins + static_cast<int>((kRangeUs - kFineUs) / kCoarseWidthUs);

  void record_ns(int64_t ns) {
    if (ns < 0) {
      ++negative_;
      ns = 0;
    }
    ++count_;
    sum_ns_ += ns;
    min_ns_ = std::min(min_ns_, ns);
    max_ns_ = std::max(max_ns_, ns);
    const int64_t us = ns / 1000;
    if (us < kFineUs) {
      ++bins_[static_cast<size_t>(us)];
    } else if (us < kRangeUs) {
      ++bins_[static_cast<size_t>(kFineBins + (us - kFineUs) / kCoarseWidthUs)];
    } else {
      ++overflow_;
    }
  }
  void record_s(double s) { record_ns(static_cast<int64_t>(std::llround(s * 1e9))); }

  void clear() { *this = LatencyHistogram(); }

  int64_t count() const { return count_; }
  int64_t overflow() const { return overflow_; }
  int64_t negative() const { return negative_; }
  double min_us() const { return count_ ? static_cast<double>(min_ns_) * 1e-3 : 0.0; }
  double max_us() const { return count_ ? static_cast<double>(max_ns_) * 1e-3 : 0.0; }
  double mean_us() const { return count_ ? static_cast<double>(sum_ns_) * 1e-3 / static_cast<double>(count_) : 0.0; }

  // Bin i covers [lower_us(i), upper_us(i)).
  static int64_t lower_us(int i) { return i < kFineBins ? i : kFineUs + (i - kFineBins) * kCoarseWidthUs; }
  static int64_t upper_us(int i) { return i < kFineBins ? i + 1 : kFineUs + (i - kFineBins + 1) * kCoarseWidthUs; }
  int64_t bin_count(int i) const { return bins_[static_cast<size_t>(i)]; }

  // q in [0, 1]; see the file comment for what the value is.
  double percentile_us(double q) const {
    if (count_ == 0) return 0.0;
    q = std::clamp(q, 0.0, 1.0);
    const auto rank = std::max<int64_t>(1, static_cast<int64_t>(std::ceil(q * static_cast<double>(count_))));
    int64_t seen = 0;
    for (int i = 0; i < kBins; ++i) {
      seen += bins_[static_cast<size_t>(i)];
      if (seen >= rank) return std::clamp(static_cast<double>(upper_us(i)), min_us(), max_us());
    }
    return max_us();  // in the overflow bin
  }

  // {"count":..,"min_us":..,"mean_us":..,"p50_us":..,"p99_us":..,"p999_us":..,"max_us":..,
  //  "overflow":..,"negative":..,"bins":[[lower_us, upper_us, count], ...]} with the
  // non-empty bins only (the overflow bin as [20000, null, n]); times to 1 ns.
  // Allocates: call it at the end. (nlohmann-json, in realtime.cc.)
  std::string to_json() const;

 private:
  std::array<int64_t, kBins> bins_{};
  int64_t overflow_ = 0;
  int64_t negative_ = 0;
  int64_t count_ = 0;
  int64_t sum_ns_ = 0;
  int64_t min_ns_ = std::numeric_limits<int64_t>::max();
  int64_t max_ns_ = 0;
};

}  // namespace cnc::util
