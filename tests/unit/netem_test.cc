// cnc-netem's core: the loss rate and the delay distribution it draws, its
// determinism, the order it keeps or not, and the bounded queue.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "tools/netem/impairment.h"

namespace cnc::netem {
namespace {

constexpr int64_t kMs = 1'000'000;

struct Draws {
  std::vector<bool> kept;
  std::vector<double> delay_ms;  // of the kept ones
  std::vector<int64_t> release;  // of the kept ones, in arrival order
};

// n datagrams arriving every gap_ns.
Draws run(const Params& p, int n, int64_t gap_ns) {
  Impairment imp(p);
  Draws d;
  for (int i = 0; i < n; ++i) {
    const int64_t t = 1'000'000'000 + i * gap_ns;
    int64_t r = 0;
    const bool k = imp.admit(t, &r);
    d.kept.push_back(k);
    if (k) {
      EXPECT_GE(r, t) << "datagram " << i << " released before it arrived";
      d.delay_ms.push_back(static_cast<double>(r - t) / kMs);
      d.release.push_back(r);
    }
  }
  return d;
}

TEST(Impairment, LossRateWithinBinomialTolerance) {
  for (double loss : {0.0, 0.05, 0.2, 1.0}) {
    Params p;
    p.loss = loss;
    p.seed = 42;
    const int n = 200'000;
    const Draws d = run(p, n, kMs);
    const double lost = static_cast<double>(n - static_cast<int>(d.delay_ms.size())) / n;
    // 6 standard deviations of a binomial share (0.29 points at 5 %), and at least 0.05 points.
    const double tol = std::max(6.0 * std::sqrt(loss * (1 - loss) / n), 5e-4);
    EXPECT_NEAR(lost, loss, tol) << "loss " << loss;
  }
}

TEST(Impairment, LossesAreIndependentNotBunched) {
  // Runs of consecutive losses at 5 %: a run of k has probability 0.05^k; about
  // n * 0.05^2 * 0.95 pairs. A generator that bunched losses would show far more.
  Params p;
  p.loss = 0.05;
  p.seed = 7;
  const int n = 200'000;
  const Draws d = run(p, n, kMs);
  int runs2 = 0, longest = 0, cur = 0;
  for (bool k : d.kept) {
    cur = k ? 0 : cur + 1;
    longest = std::max(longest, cur);
    if (cur == 2) ++runs2;  // runs of at least two
  }
  const double expected = n * 0.05 * 0.05 * 0.95;  // ~475
  EXPECT_NEAR(runs2, expected, 6 * std::sqrt(expected));
  EXPECT_LE(longest, 7);  // P(a run of 8 somewhere) ~ n * 0.05^8 = 8e-6
}

TEST(Impairment, DelayIsUniformOverMeanPlusMinusSpread) {
  Params p;
  p.delay_ms = 2.0;
  p.jitter_ms = 1.0;
  p.seed = 3;
  const Draws d = run(p, 100'000, 10 * kMs);
  ASSERT_EQ(d.delay_ms.size(), 100'000u);
  double sum = 0, sq = 0;
  std::vector<int> bins(10, 0);  // 0.2 ms wide over [1, 3)
  for (double x : d.delay_ms) {
    ASSERT_GE(x, 1.0 - 1e-6);
    ASSERT_LE(x, 3.0 + 1e-6);
    sum += x;
    sq += x * x;
    ++bins[static_cast<size_t>(std::min(9.0, (x - 1.0) / 0.2))];
  }
  const double count = static_cast<double>(d.delay_ms.size());
  const double mean = sum / count;
  const double sd = std::sqrt(sq / count - mean * mean);
  EXPECT_NEAR(mean, 2.0, 0.01);
  EXPECT_NEAR(sd, 2.0 / std::sqrt(12.0), 0.01);  // uniform over 2 ms: 0.577 ms
  for (int b : bins) EXPECT_NEAR(b, 10'000, 600);  // each tenth of the range holds ~10 %
}

TEST(Impairment, DelayNeverNegative) {
  Params p;
  p.delay_ms = 0.5;
  p.jitter_ms = 1.0;  // draws below 0 are clamped to 0
  const Draws d = run(p, 10'000, kMs);
  const auto zero = std::count_if(d.delay_ms.begin(), d.delay_ms.end(), [](double x) { return x == 0.0; });
  EXPECT_NEAR(static_cast<double>(zero) / static_cast<double>(d.delay_ms.size()), 0.25, 0.03);
  EXPECT_LE(*std::max_element(d.delay_ms.begin(), d.delay_ms.end()), 1.5 + 1e-6);
}

TEST(Impairment, SameSeedSameDrawsAndLossPatternIndependentOfDelay) {
  Params a;
  a.loss = 0.2;
  a.delay_ms = 2;
  a.jitter_ms = 1;
  a.seed = 99;
  const Draws x = run(a, 5000, kMs), y = run(a, 5000, kMs);
  EXPECT_EQ(x.kept, y.kept);
  EXPECT_EQ(x.release, y.release);
  Params b = a;
  b.delay_ms = 0;
  b.jitter_ms = 0;
  b.keep_order = true;
  EXPECT_EQ(run(b, 5000, kMs).kept, x.kept);
  Params c = a;
  c.seed = 100;
  EXPECT_NE(run(c, 5000, kMs).kept, x.kept);
}

TEST(Impairment, OrderKeptOrNot) {
  Params p;
  p.delay_ms = 2;
  p.jitter_ms = 1;  // spread 2 ms against datagrams 0.25 ms apart: many overtake
  const Draws free = run(p, 4000, kMs / 4);
  int overtaken = 0;
  for (size_t i = 1; i < free.release.size(); ++i) overtaken += free.release[i] < free.release[i - 1];
  EXPECT_GT(overtaken, 400);
  p.keep_order = true;
  const Draws fifo = run(p, 4000, kMs / 4);
  EXPECT_TRUE(std::is_sorted(fifo.release.begin(), fifo.release.end()));
  double sum = 0;
  for (double x : fifo.delay_ms) sum += x;
  // FIFO holds a datagram behind a later draw of the one before: the mean rises, the
  // spread stays within [1, 3] ms.
  EXPECT_GT(sum / static_cast<double>(fifo.delay_ms.size()), 2.0);
  EXPECT_LE(*std::max_element(fifo.delay_ms.begin(), fifo.delay_ms.end()), 3.0 + 1e-6);
  EXPECT_GE(*std::min_element(fifo.delay_ms.begin(), fifo.delay_ms.end()), 1.0 - 1e-6);
}

TEST(Impairment, ValidateNamesTheFlag) {
  Params p;
  EXPECT_EQ(validate(p), "");
  p.loss = 1.5;
  EXPECT_NE(validate(p).find("--loss"), std::string::npos);
  p.loss = 0;
  p.delay_ms = -1;
  EXPECT_NE(validate(p).find("--delay"), std::string::npos);
  p.delay_ms = 0;
  p.jitter_ms = NAN;
  EXPECT_NE(validate(p).find("--jitter"), std::string::npos);
}

TEST(DelayQueue, ReleasesByTimeThenArrivalAndIsBounded) {
  DelayQueue q(4, 64);
  const int64_t rel[] = {30, 10, 20, 10};
  for (int i = 0; i < 4; ++i) {
    char* b = q.reserve();
    ASSERT_NE(b, nullptr);
    std::memcpy(b, &i, sizeof i);
    q.commit(b, sizeof i, 0, rel[i]);
  }
  EXPECT_TRUE(q.full());
  EXPECT_EQ(q.reserve(), nullptr);
  std::vector<int> order;
  while (q.size() > 0) {
    int v = 0;
    std::memcpy(&v, q.front().data, sizeof v);
    order.push_back(v);
    q.pop();
  }
  EXPECT_EQ(order, (std::vector<int>{1, 3, 2, 0}));
  EXPECT_EQ(q.next_release_ns(), INT64_MAX);
  // The slots come back: four more fit, and no two held datagrams share a buffer.
  std::vector<char*> seen;
  for (int i = 0; i < 4; ++i) {
    char* b = q.reserve();
    ASSERT_NE(b, nullptr);
    EXPECT_EQ(std::count(seen.begin(), seen.end(), b), 0);
    seen.push_back(b);
    q.commit(b, 1, 0, i);
  }
}

TEST(Counters, CountsReorderingAndHeldTime) {
  Counters c;
  Held a{5 * kMs, 0, 0, 1, nullptr}, b{3 * kMs, 1 * kMs, 1, 1, nullptr}, d{9 * kMs, 2 * kMs, 2, 1, nullptr};
  c.on_sent(b, 3 * kMs);  // number 1 first
  c.on_sent(a, 5 * kMs);  // number 0 after 1: reordered
  c.on_sent(d, 9 * kMs);
  EXPECT_EQ(c.sent, 3);
  EXPECT_EQ(c.reordered, 1);
  EXPECT_DOUBLE_EQ(c.delay_min_ms, 2.0);
  EXPECT_DOUBLE_EQ(c.delay_max_ms, 7.0);
  EXPECT_NE(c.summary("a -> b").find("reordered 1"), std::string::npos);
}

}  // namespace
}  // namespace cnc::netem
