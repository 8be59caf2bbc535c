// Telling a stalled delivery from a stalled publisher in a log (common/bus/delivery.h).
#include "common/bus/delivery.h"

#include <gtest/gtest.h>

namespace cnc::bus {
namespace {

// A cell's two periodic streams: setpoints every 4 ms (sender 1), statuses every 4 ms
// 0.5 ms later (sender 2), each received `lat` µs after its stamp.
void stream(std::vector<DeliveryEvent>& ev, int64_t t0, int n, int64_t lat) {
  for (int k = 0; k < n; ++k) {
    const int64_t t = t0 + 4000 * k;
    ev.push_back({"T.SETPOINTS", 1, t, t + lat});
    ev.push_back({"T.AXIS_STATUS", 2, t + 500, t + 500 + lat});
  }
}

const DeliveryStall* only_stall(const DeliveryReport& r) { return r.stalls.size() == 1 ? &r.stalls.front() : nullptr; }

TEST(Delivery, ASteadyStreamHasNoStall) {
  std::vector<DeliveryEvent> ev;
  stream(ev, 1'000'000, 500, 150);
  const DeliveryReport r = analyse_delivery(ev, 20);
  EXPECT_TRUE(r.stalls.empty());
  ASSERT_EQ(r.channels.size(), 2u);
  for (const auto& c : r.channels) {
    EXPECT_TRUE(c.periodic) << c.channel;
    EXPECT_NEAR(c.max_ms, 0.15, 1e-9) << c.channel;
    EXPECT_NEAR(c.longest_publish_gap_ms, 4.0, 1e-9) << c.channel;
  }
}

// The order of events of the CI failure of 2026-11-28 (integration.replay): both
// publishers stamp on time, nothing is received for ~100 ms, then everything at once.
TEST(Delivery, MessagesPublishedInASilenceThatArriveTogetherAreADeliveryStall) {
  std::vector<DeliveryEvent> ev;
  stream(ev, 1'000'000, 100, 150);  // until 1.396 s
  const int64_t held_from = 1'400'000, released = 1'503'800;
  for (int k = 0; k < 26; ++k) {
    const int64_t t = held_from + 4000 * k;
    ev.push_back({"T.SETPOINTS", 1, t, released});
    ev.push_back({"T.AXIS_STATUS", 2, t + 500, released});
  }
  stream(ev, 1'504'000, 100, 150);
  const DeliveryReport r = analyse_delivery(ev, 20);
  const DeliveryStall* s = only_stall(r);
  ASSERT_NE(s, nullptr) << r.stalls.size();
  EXPECT_TRUE(s->delivery);
  EXPECT_EQ(s->published_in, 48);  // the last two of each sender were held under half the threshold
  EXPECT_EQ(s->senders_in, 2);
  EXPECT_NEAR(s->length_ms, (released - (1'396'500 + 150)) / 1e3, 1e-9);
  // The publishers kept their 4 ms inside it.
  EXPECT_NE(s->publisher_gaps.find("T.SETPOINTS 4.0 ms"), std::string::npos) << s->publisher_gaps;
  EXPECT_NE(format_delivery(r, 1'000'000, 20).find("the delivery stalled"), std::string::npos);
}

TEST(Delivery, APublisherThatStopsIsNotADeliveryStall) {
  std::vector<DeliveryEvent> ev;
  stream(ev, 1'000'000, 100, 150);
  stream(ev, 1'000'000 + 4000 * 100 + 60'000, 100, 150);  // both silent for 60 ms, delivered on time
  const DeliveryReport r = analyse_delivery(ev, 20);
  const DeliveryStall* s = only_stall(r);
  ASSERT_NE(s, nullptr);
  EXPECT_FALSE(s->delivery);
  EXPECT_EQ(s->published_in, 0);
  EXPECT_NE(s->publisher_gaps.find("T.SETPOINTS 64.0 ms"), std::string::npos) << s->publisher_gaps;
  EXPECT_NE(format_delivery(r, 1'000'000, 20).find("a pause of the publishers"), std::string::npos);
  for (const auto& c : r.channels) EXPECT_NEAR(c.longest_publish_gap_ms, 64.0, 1e-9) << c.channel;
}

TEST(Delivery, ASilenceUnderTheThresholdIsNoStall) {
  std::vector<DeliveryEvent> ev;
  stream(ev, 1'000'000, 50, 150);
  for (int k = 0; k < 4; ++k) ev.push_back({"T.SETPOINTS", 1, 1'200'000 + 4000 * k, 1'215'000});  // held 15 ms
  const DeliveryReport r = analyse_delivery(ev, 20);
  EXPECT_TRUE(r.stalls.empty());
  EXPECT_EQ(analyse_delivery(ev, 10).stalls.size(), 1u);
}

}  // namespace
}  // namespace cnc::bus
