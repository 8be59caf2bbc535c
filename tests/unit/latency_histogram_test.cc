// The cycle-timing evidence: LatencyHistogram (percentiles of known samples within
// one bin width, overflow, no allocation), the PeriodicTimer's recording, CPU
// pinning and the timing.realtime_cpus key.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <memory>
#include <sstream>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/config/machine_config.h"
#include "common/config/yaml_reader.h"
#include "common/util/clock.h"
#include "common/util/latency_histogram.h"
#include "common/util/realtime.h"
#include "tests/unit/alloc_guard.h"

namespace {

using cnc::util::LatencyHistogram;

// The nearest-rank percentile of sorted samples, in µs.
double exact_percentile_us(const std::vector<int64_t>& sorted_ns, double q) {
  const auto n = static_cast<int64_t>(sorted_ns.size());
  const int64_t rank = std::max<int64_t>(1, static_cast<int64_t>(std::ceil(q * static_cast<double>(n))));
  return static_cast<double>(sorted_ns[static_cast<size_t>(rank - 1)]) * 1e-3;
}

// The promise of the header: never below the exact value, at most one bin width above.
void expect_percentile(const LatencyHistogram& h, const std::vector<int64_t>& sorted_ns, double q) {
  const double exact = exact_percentile_us(sorted_ns, q);
  const double got = h.percentile_us(q);
  const double width = exact < 1000 ? 1.0 : 10.0;
  EXPECT_GE(got, exact - 1e-9) << "q=" << q;
  EXPECT_LE(got, exact + width) << "q=" << q;
}

TEST(LatencyHistogram, UniformMicrosecondsGivePercentilesWithinOneMicrosecond) {
  LatencyHistogram h;
  std::vector<int64_t> ns;
  for (int i = 0; i < 1000; ++i) ns.push_back(i * 1000 + 500);  // 0.5, 1.5, ..., 999.5 µs
  for (const int64_t v : ns) h.record_ns(v);
  EXPECT_EQ(h.count(), 1000);
  EXPECT_EQ(h.overflow(), 0);
  EXPECT_DOUBLE_EQ(h.min_us(), 0.5);
  EXPECT_DOUBLE_EQ(h.max_us(), 999.5);
  EXPECT_NEAR(h.mean_us(), 500.0, 1e-9);
  // Nearest rank: the 500th sample is 499.5 µs, in bin [499, 500): 500 reported.
  EXPECT_DOUBLE_EQ(h.percentile_us(0.5), 500.0);
  EXPECT_DOUBLE_EQ(h.percentile_us(0.99), 990.0);
  EXPECT_DOUBLE_EQ(h.percentile_us(0.999), 999.0);
  EXPECT_DOUBLE_EQ(h.percentile_us(1.0), 999.5);  // clamped to the maximum
  EXPECT_DOUBLE_EQ(h.percentile_us(0.0), 1.0);
}

TEST(LatencyHistogram, RandomSamplesAcrossBothBinWidths) {
  // A long-tailed distribution from 0 to 19 ms (deterministic generator).
  uint64_t state = 12345;
  auto next = [&state] {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    return static_cast<double>(state >> 11) / static_cast<double>(1ULL << 53);
  };
  LatencyHistogram h;
  std::vector<int64_t> ns;
  for (int i = 0; i < 200000; ++i) {
    const double u = next();
    const double us = std::min(19999.0, 20.0 * std::exp(7.0 * u * u));  // 20 µs .. ~19 ms
    ns.push_back(static_cast<int64_t>(us * 1000.0));
  }
  int64_t sum = 0;
  for (const int64_t v : ns) {
    h.record_ns(v);
    sum += v;
  }
  std::sort(ns.begin(), ns.end());
  EXPECT_EQ(h.count(), 200000);
  EXPECT_EQ(h.overflow(), 0);
  EXPECT_NEAR(h.min_us(), static_cast<double>(ns.front()) * 1e-3, 1e-9);
  EXPECT_NEAR(h.max_us(), static_cast<double>(ns.back()) * 1e-3, 1e-9);
  EXPECT_NEAR(h.mean_us(), static_cast<double>(sum) * 1e-3 / 200000.0, 1e-6);
  for (const double q : {0.001, 0.1, 0.5, 0.9, 0.99, 0.999, 0.9999, 1.0}) expect_percentile(h, ns, q);
  // Both bin widths were exercised.
  EXPECT_LT(exact_percentile_us(ns, 0.5), 1000.0);
  EXPECT_GT(exact_percentile_us(ns, 0.99), 1000.0);
}

TEST(LatencyHistogram, OverflowKeepsExactExtremesAndReportsTheMaximum) {
  LatencyHistogram h;
  for (int i = 0; i < 998; ++i) h.record_ns(5'000);  // 5 µs
  h.record_ns(25'000'000);                           // 25 ms: past the range
  h.record_ns(1'000'000'000);                        // 1 s
  EXPECT_EQ(h.count(), 1000);
  EXPECT_EQ(h.overflow(), 2);
  EXPECT_DOUBLE_EQ(h.max_us(), 1e6);
  EXPECT_DOUBLE_EQ(h.min_us(), 5.0);
  EXPECT_NEAR(h.mean_us(), (998 * 5.0 + 25000.0 + 1e6) / 1000.0, 1e-9);
  EXPECT_DOUBLE_EQ(h.percentile_us(0.99), 6.0);
  EXPECT_DOUBLE_EQ(h.percentile_us(0.999), 1e6);  // the 999th sample is in the overflow bin: the maximum
  EXPECT_DOUBLE_EQ(h.percentile_us(1.0), 1e6);
  const std::string json = h.to_json();
  const auto j = nlohmann::json::parse(json);  // the same checks on the parsed form (was: on the text)
  EXPECT_EQ(j["overflow"], 2) << json;
  EXPECT_NE(std::find(j["bins"].begin(), j["bins"].end(), nlohmann::json::parse("[5, 6, 998]")), j["bins"].end()) << json;
  EXPECT_NE(std::find(j["bins"].begin(), j["bins"].end(), nlohmann::json::parse("[20000, null, 2]")), j["bins"].end())
      << json;
}

TEST(LatencyHistogram, EdgesNegativeAndEmpty) {
  LatencyHistogram h;
  EXPECT_EQ(h.count(), 0);
  EXPECT_EQ(h.percentile_us(0.99), 0.0);
  EXPECT_EQ(h.max_us(), 0.0);
  h.record_ns(-3000);  // a clock read before its deadline
  EXPECT_EQ(h.negative(), 1);
  EXPECT_EQ(h.bin_count(0), 1);
  EXPECT_EQ(h.min_us(), 0.0);
  h.record_ns(999'999);    // last 1 µs bin
  h.record_ns(1'000'000);  // first 10 µs bin
  h.record_ns(19'999'999);  // last bin
  h.record_ns(20'000'000);  // overflow
  EXPECT_EQ(h.bin_count(LatencyHistogram::kFineBins - 1), 1);
  EXPECT_EQ(h.bin_count(LatencyHistogram::kFineBins), 1);
  EXPECT_EQ(h.bin_count(LatencyHistogram::kBins - 1), 1);
  EXPECT_EQ(h.overflow(), 1);
  EXPECT_EQ(LatencyHistogram::lower_us(LatencyHistogram::kBins - 1), 19990);
  EXPECT_EQ(LatencyHistogram::upper_us(LatencyHistogram::kBins - 1), LatencyHistogram::kRangeUs);
  h.clear();
  EXPECT_EQ(h.count(), 0);
  EXPECT_EQ(h.overflow(), 0);
}

TEST(LatencyHistogram, NoAllocationAfterConstructionNorInQueries) {
  auto h = std::make_unique<LatencyHistogram>();
  cnc::test::AllocGuard g;
  for (int64_t i = 0; i < 100000; ++i) h->record_ns((i * 7919) % 30'000'000);
  double sink = h->percentile_us(0.99) + h->percentile_us(0.999) + h->mean_us() + h->min_us() + h->max_us();
  LatencyHistogram on_stack;  // construction itself allocates nothing
  on_stack.record_s(1e-6);
  sink += on_stack.max_us();
  EXPECT_EQ(g.allocations(), 0);
  EXPECT_EQ(g.frees(), 0);
  EXPECT_GT(sink, 0.0);
}

TEST(PeriodicTimer, RecordsWakeUpAndComputeWithoutAllocating) {
  auto timer = std::make_unique<cnc::util::PeriodicTimer>(0.001);
  constexpr int kCycles = 40;
  {
    cnc::test::AllocGuard g;
    for (int i = 0; i < kCycles; ++i) {
      ASSERT_TRUE(timer->wait());
      const double t0 = cnc::util::monotonic_s();
      while (cnc::util::monotonic_s() - t0 < 100e-6) {
      }  // 100 µs of "work"
    }
    EXPECT_EQ(g.allocations(), 0);
    EXPECT_EQ(g.frees(), 0);
  }
  EXPECT_EQ(timer->cycles(), kCycles);
  EXPECT_EQ(timer->wake_latency().count(), kCycles);
  EXPECT_EQ(timer->compute_time().count(), kCycles - 1);  // the last cycle's work ends at no wait()
  EXPECT_EQ(timer->wake_latency().negative(), 0);        // never woken before the deadline
  EXPECT_GE(timer->compute_time().min_us(), 100.0);
  // A deliberately overrun cycle: 3.5 periods of work show as wake-up latency and overruns.
  const double t0 = cnc::util::monotonic_s();
  while (cnc::util::monotonic_s() - t0 < 3.5e-3) {
  }
  ASSERT_TRUE(timer->wait());
  EXPECT_GE(timer->overruns(), 2);
  EXPECT_GE(timer->wake_latency().max_us(), 2400.0);
}

TEST(Realtime, CpuListAndPinning) {
  EXPECT_EQ(cnc::util::cpu_list({}), "");
  EXPECT_EQ(cnc::util::cpu_list({0, 1, 3}), "0-1,3");
  EXPECT_EQ(cnc::util::cpu_list({2}), "2");
  // On a thread of its own, so the test process keeps its CPUs.
  std::thread([] {
    std::vector<int> applied{42};
    EXPECT_EQ(cnc::util::pin_to_cpus({}, &applied), "");
    EXPECT_TRUE(applied.empty());
    const std::string why = cnc::util::pin_to_cpus({1000}, &applied);
    EXPECT_NE(why.find("CPU 1000 does not exist"), std::string::npos) << why;
    EXPECT_TRUE(applied.empty());
    EXPECT_NE(cnc::util::describe_scheduling().find("CPUs "), std::string::npos);
    // Pin to CPU 0 (every Linux machine has it, unless a cpuset forbids it).
    const std::string why0 = cnc::util::pin_to_cpus({0, 1000}, &applied);
    if (!applied.empty()) {
      EXPECT_EQ(applied, std::vector<int>{0});
      EXPECT_NE(why0.find("CPU 1000 does not exist"), std::string::npos) << why0;
      EXPECT_NE(cnc::util::describe_scheduling().find("CPUs 0"), std::string::npos);
    }
  }).join();
}

std::string sim3_text() {
  std::ifstream f(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// sim3.yaml with its realtime_cpus line replaced.
std::string with_cpus(const std::string& value) {
  std::string text = sim3_text();
  const std::string key = "realtime_cpus: []";
  const size_t at = text.find(key);
  EXPECT_NE(at, std::string::npos);
  return text.replace(at, key.size(), "realtime_cpus: " + value);
}

std::string config_error_path(const std::string& yaml) {
  try {
    cnc::config::parse_machine_config(yaml, CNC_SOURCE_DIR "/config/machines/sim3.yaml");
  } catch (const cnc::config::ConfigError& e) {
    return e.key_path();
  }
  return "";
}

TEST(RealtimeConfig, RealtimeCpusKey) {
  const auto none = cnc::config::parse_machine_config(with_cpus("[]"), CNC_SOURCE_DIR "/config/machines/sim3.yaml");
  EXPECT_TRUE(none.realtime_cpus.empty());
  const auto two = cnc::config::parse_machine_config(with_cpus("[1, 0]"), CNC_SOURCE_DIR "/config/machines/sim3.yaml");
  EXPECT_EQ(two.realtime_cpus, (std::vector<int>{1, 0}));
  EXPECT_EQ(config_error_path(with_cpus("[1, 1]")), "timing.realtime_cpus[1]");
  EXPECT_EQ(config_error_path(with_cpus("[-1]")), "timing.realtime_cpus[0]");
  EXPECT_EQ(config_error_path(with_cpus("[0, x]")), "timing.realtime_cpus[1]");
  EXPECT_EQ(config_error_path(with_cpus("[2048]")), "timing.realtime_cpus[0]");
  EXPECT_EQ(config_error_path(with_cpus("1")), "timing.realtime_cpus");
}

}  // namespace
