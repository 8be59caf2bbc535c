// The LCM wrapper over memq:// and file://: typed round trips, sequence stamping,
// corrupted messages and throwing handlers contained, sequence accounting.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "cnc/lcmt_setpoint.hpp"
#include "common/bus/bus.h"

namespace cnc::bus {
namespace {

// Offset of lcmt_setpoint.num_axes in the encoding: fingerprint, utime, seq,
// sender, cycle, period_s.
constexpr size_t kNumAxesOffset = 8 + 8 + 8 + 4 + 8 + 8;

cnc::lcmt_setpoint make_setpoint(int64_t cycle, int64_t seq = 0, int32_t sender = 0) {
  cnc::lcmt_setpoint m{};
  m.utime = 1'700'000'000'000'000 + cycle;
  m.seq = seq;
  m.sender = sender;
  m.cycle = cycle;
  m.period_s = 0.004;
  m.num_axes = 3;
  m.position_mm = {1.5 * static_cast<double>(cycle), -2.25, 100.0};
  m.feed_mm_per_min = 1200;
  m.program_token = 77;
  m.block_index = 4;
  m.source_line = 12;
  m.u = 0.5;
  m.limit = cnc::lcmt_setpoint::LIMIT_PROGRAM;
  m.state = cnc::lcmt_setpoint::RUNNING;
  return m;
}

std::vector<uint8_t> encode(const cnc::lcmt_setpoint& m) {
  std::vector<uint8_t> buf(static_cast<size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  return buf;
}

void put_be32(uint8_t* p, int32_t value) {
  const auto v = static_cast<uint32_t>(value);
  for (int i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * (3 - i)));
}

TEST(ExactChannel, EscapesRegexCharacters) {
  EXPECT_EQ(exact_channel("A.B"), "A\\.B");
  EXPECT_EQ(exact_channel("SIM3.SETPOINTS"), "SIM3\\.SETPOINTS");
  EXPECT_EQ(exact_channel("a+b*(c)"), "a\\+b\\*\\(c\\)");
  EXPECT_EQ(exact_channel("PLAIN_NAME"), "PLAIN_NAME");
}

TEST(PeekHeader, ReadsUtimeSeqSender) {
  const auto buf = encode(make_setpoint(0, 0x0102030405060708, -7));
  const auto h = peek_header(buf.data(), buf.size());
  ASSERT_TRUE(h.has_value());
  EXPECT_EQ(h->utime, 1'700'000'000'000'000);
  EXPECT_EQ(h->seq, 0x0102030405060708);
  EXPECT_EQ(h->sender, -7);
}

TEST(PeekHeader, NeedsTheWholeHeader) {
  const auto buf = encode(make_setpoint(0, 5, 9));
  EXPECT_FALSE(peek_header(buf.data(), 27).has_value());
  const auto h = peek_header(buf.data(), 28);
  ASSERT_TRUE(h.has_value());
  EXPECT_EQ(h->seq, 5);
  EXPECT_EQ(h->sender, 9);
}

TEST(Bus, TypedRoundTrip) {
  Bus bus("memq://", 1234);
  EXPECT_EQ(bus.sender(), 1234);
  std::vector<cnc::lcmt_setpoint> got;
  bus.subscribe<cnc::lcmt_setpoint>("SIM3.SETPOINTS", [&](const cnc::lcmt_setpoint& m) { got.push_back(m); });
  cnc::lcmt_setpoint m = make_setpoint(42);
  bus.publish("SIM3.SETPOINTS", m);
  EXPECT_EQ(bus.drain(), 1);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].cycle, 42);
  EXPECT_EQ(got[0].sender, 1234);
  EXPECT_EQ(got[0].num_axes, 3);
  EXPECT_EQ(got[0].position_mm, m.position_mm);
  EXPECT_EQ(got[0].feed_mm_per_min, 1200);
  EXPECT_EQ(got[0].program_token, 77);
  EXPECT_EQ(got[0].limit, int8_t{cnc::lcmt_setpoint::LIMIT_PROGRAM});  // a copy: the constant has no definition
  EXPECT_GT(got[0].utime, 1'600'000'000'000'000);  // stamped with the wall clock
  EXPECT_EQ(got[0].utime, m.utime);                // and written back into the message
  const ChannelStats st = bus.stats("SIM3.SETPOINTS");
  EXPECT_EQ(st.published, 1);
  EXPECT_EQ(st.received, 1);
  EXPECT_EQ(st.decode_failures, 0);
}

TEST(Bus, HandleTimesOutWithoutMessages) {
  Bus bus("memq://", 1);
  EXPECT_EQ(bus.handle(0), 0);
  EXPECT_EQ(bus.drain(), 0);
}

TEST(Bus, StampsSequencePerChannel) {
  Bus bus("memq://", 5);
  std::map<std::string, std::vector<int64_t>> seqs;
  bus.subscribe<cnc::lcmt_setpoint>("A", [&](const cnc::lcmt_setpoint& m) { seqs["A"].push_back(m.seq); });
  bus.subscribe<cnc::lcmt_setpoint>("B", [&](const cnc::lcmt_setpoint& m) { seqs["B"].push_back(m.seq); });
  for (int i = 0; i < 3; ++i) {
    cnc::lcmt_setpoint m = make_setpoint(i, 1000, 99);  // seq and sender are overwritten
    bus.publish("A", m);
    EXPECT_EQ(m.seq, i);
    EXPECT_EQ(m.sender, 5);
  }
  cnc::lcmt_setpoint b = make_setpoint(0);
  bus.publish("B", b);
  EXPECT_EQ(bus.drain(), 4);
  EXPECT_EQ(seqs["A"], (std::vector<int64_t>{0, 1, 2}));
  EXPECT_EQ(seqs["B"], (std::vector<int64_t>{0}));
  EXPECT_EQ(bus.stats("A").seq_gaps, 0);
  EXPECT_EQ(bus.stats("A").seq_restarts, 0);
}

TEST(Bus, ExactChannelSubscriptionIgnoresLookalikes) {
  Bus bus("memq://", 1);
  int count = 0;
  bus.subscribe<cnc::lcmt_setpoint>("A.B", [&](const cnc::lcmt_setpoint&) { ++count; });
  cnc::lcmt_setpoint m = make_setpoint(1);
  bus.publish("AxB", m);
  bus.publish("A.B", m);
  bus.publish("A.BC", m);
  bus.drain();
  EXPECT_EQ(count, 1);
}

TEST(Bus, CorruptedMessagesAreCountedAndDropped) {
  Bus bus("memq://", 1);
  std::vector<int64_t> cycles;
  bus.subscribe<cnc::lcmt_setpoint>("SP", [&](const cnc::lcmt_setpoint& m) { cycles.push_back(m.cycle); });

  const auto good = encode(make_setpoint(1, 0, 3));
  ASSERT_GT(good.size(), kNumAxesOffset + 4);

  const std::vector<uint8_t> truncated(good.begin(), good.begin() + static_cast<long>(good.size() / 2));
  std::vector<uint8_t> wrong_fingerprint = good;
  wrong_fingerprint[3] ^= 0x5A;
  std::vector<uint8_t> negative_length = good;
  put_be32(negative_length.data() + kNumAxesOffset, -5);
  std::vector<uint8_t> huge_length = good;
  put_be32(huge_length.data() + kNumAxesOffset, 0x7fffffff);
  // Check the patch hit num_axes: the decode refuses it before any allocation (the
  // generated code is patched by lcmtypes/bound_arrays.cmake; LCM 1.3.1's own threw
  // on a negative length and allocated up to 16 GB for a huge one).
  cnc::lcmt_setpoint probe;
  EXPECT_LT(probe.decode(negative_length.data(), 0, static_cast<int>(negative_length.size())), 0);
  EXPECT_LT(probe.decode(huge_length.data(), 0, static_cast<int>(huge_length.size())), 0);
  EXPECT_EQ(probe.position_mm.capacity(), 0u);

  bus.publish_raw("SP", truncated.data(), truncated.size());
  bus.publish_raw("SP", wrong_fingerprint.data(), wrong_fingerprint.size());
  bus.publish_raw("SP", negative_length.data(), negative_length.size());
  bus.publish_raw("SP", huge_length.data(), huge_length.size());
  cnc::lcmt_setpoint later = make_setpoint(2);
  bus.publish("SP", later);
  EXPECT_EQ(bus.drain(), 5);

  const ChannelStats st = bus.stats("SP");
  EXPECT_EQ(st.decode_failures, 4);
  EXPECT_EQ(st.received, 5);
  EXPECT_EQ(st.handler_errors, 0);
  EXPECT_EQ(cycles, (std::vector<int64_t>{2}));
}

// Found by fuzz_bus_decode (UBSan): sequence numbers are whatever a sender writes;
// the gap and replay arithmetic overflowed int64 between INT64_MIN and INT64_MAX.
TEST(Bus, ExtremeSequenceNumbersAreCountedWithoutOverflow) {
  Bus bus("memq://", 1);
  int count = 0;
  bus.subscribe<cnc::lcmt_setpoint>("SP", [&](const cnc::lcmt_setpoint&) { ++count; });
  for (int64_t seq : {INT64_MIN, INT64_MAX, INT64_MIN, int64_t{0}, INT64_MAX}) {
    const auto buf = encode(make_setpoint(1, seq, 5));
    bus.publish_raw("SP", buf.data(), buf.size());
  }
  EXPECT_EQ(bus.drain(), 5);
  EXPECT_EQ(count, 5);
  const ChannelStats st = bus.stats("SP");
  EXPECT_EQ(st.seq_gaps, INT64_MAX);  // 2^64 - 2 missing, saturated, then more
  EXPECT_EQ(st.seq_restarts, 1);      // INT64_MAX -> INT64_MIN
}

TEST(Bus, TrailingBytesAreADecodeFailure) {
  Bus bus("memq://", 1);
  int count = 0;
  bus.subscribe<cnc::lcmt_setpoint>("SP", [&](const cnc::lcmt_setpoint&) { ++count; });
  auto buf = encode(make_setpoint(1));
  buf.push_back(0);
  bus.publish_raw("SP", buf.data(), buf.size());
  bus.drain();
  EXPECT_EQ(count, 0);
  EXPECT_EQ(bus.stats("SP").decode_failures, 1);
}

TEST(Bus, ThrowingHandlerIsContained) {
  Bus bus("memq://", 1);
  std::vector<int64_t> cycles;
  bus.subscribe<cnc::lcmt_setpoint>("SP", [&](const cnc::lcmt_setpoint& m) {
    if (m.cycle == 1) throw std::runtime_error("handler fault");
    cycles.push_back(m.cycle);
  });
  int raw_calls = 0;
  bus.subscribe_raw("RAW", [&](const std::string&, const void*, size_t, int64_t) {
    ++raw_calls;
    throw 42;  // not even a std::exception
  });
  for (int i = 0; i < 3; ++i) {
    cnc::lcmt_setpoint m = make_setpoint(i);
    bus.publish("SP", m);
  }
  cnc::lcmt_setpoint r = make_setpoint(9);
  bus.publish("RAW", r);
  bus.publish("RAW", r);
  EXPECT_EQ(bus.drain(), 5);
  EXPECT_EQ(cycles, (std::vector<int64_t>{0, 2}));
  EXPECT_EQ(bus.stats("SP").handler_errors, 1);
  EXPECT_EQ(bus.stats("SP").decode_failures, 0);
  EXPECT_EQ(raw_calls, 2);
  EXPECT_EQ(bus.stats("RAW").handler_errors, 2);
}

class SeqAccounting : public ::testing::Test {
 protected:
  SeqAccounting() : bus_("memq://", 1) {
    bus_.subscribe_raw("SP", [this](const std::string&, const void*, size_t, int64_t) { ++received_; });
  }
  void send(int32_t sender, int64_t seq) {
    const auto buf = encode(make_setpoint(seq, seq, sender));
    bus_.publish_raw("SP", buf.data(), buf.size());
  }
  Bus bus_;
  int received_ = 0;
};

TEST_F(SeqAccounting, GapsAreCounted) {
  for (int64_t s : {0, 1, 2, 5, 6}) send(7, s);
  bus_.drain();
  EXPECT_EQ(received_, 5);
  EXPECT_EQ(bus_.stats("SP").seq_gaps, 2);
  EXPECT_EQ(bus_.stats("SP").seq_restarts, 0);
}

TEST_F(SeqAccounting, SendersAreTrackedSeparately) {
  for (int64_t s = 0; s < 4; ++s) {
    send(7, s);
    send(8, s + 100);
  }
  bus_.drain();
  EXPECT_EQ(received_, 8);
  EXPECT_EQ(bus_.stats("SP").seq_gaps, 0);
  EXPECT_EQ(bus_.stats("SP").seq_restarts, 0);
}

TEST_F(SeqAccounting, BackwardsIsARestartNotAGap) {
  for (int64_t s : {0, 1, 2, 3, 0, 1, 2}) send(7, s);
  bus_.drain();
  EXPECT_EQ(bus_.stats("SP").seq_gaps, 0);
  EXPECT_EQ(bus_.stats("SP").seq_restarts, 1);
}

TEST_F(SeqAccounting, ARepeatedSeqIsARestart) {
  for (int64_t s : {0, 1, 1, 2}) send(7, s);
  bus_.drain();
  EXPECT_EQ(bus_.stats("SP").seq_gaps, 0);
  EXPECT_EQ(bus_.stats("SP").seq_restarts, 1);
}

TEST(Bus, TwoSubscriptionsOnOneChannelCountOnce) {
  Bus bus("memq://", 1);
  int typed = 0;
  int raw = 0;
  bus.subscribe<cnc::lcmt_setpoint>("SP", [&](const cnc::lcmt_setpoint&) { ++typed; });
  bus.subscribe_raw("S.*", [&](const std::string&, const void*, size_t, int64_t) { ++raw; });
  for (int64_t s : {0, 1, 3}) {
    const auto buf = encode(make_setpoint(s, s, 7));
    bus.publish_raw("SP", buf.data(), buf.size());
  }
  bus.drain();
  EXPECT_EQ(typed, 3);
  EXPECT_EQ(raw, 3);
  EXPECT_EQ(bus.stats("SP").received, 3);
  EXPECT_EQ(bus.stats("SP").seq_gaps, 1);
}

TEST(Bus, ReadsALogFile) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("cnc_bus_test_" + std::to_string(getpid()) + ".lcmlog"))
                               .string();
  std::vector<std::vector<uint8_t>> payloads;
  {
    lcm::LogFile log(path, "w");
    ASSERT_TRUE(log.good());
    int64_t setpoints = 0;
    for (int i = 0; i < 8; ++i) {
      const bool setpoint = i % 4 != 3;  // 6 setpoints (cycles 0 1 2 4 5 6), 2 others
      // Setpoint seq 0 1 2 4 5 6: one missing.
      const int64_t seq = setpoints < 3 ? setpoints : setpoints + 1;
      if (setpoint) ++setpoints;
      std::vector<uint8_t> data = setpoint ? encode(make_setpoint(i, seq, 11))
                                           : std::vector<uint8_t>{1, 2, 3, static_cast<uint8_t>(i)};
      lcm::LogEvent ev;
      ev.eventnum = i;
      ev.timestamp = 1'700'000'000'000'000 + i * 4000;
      ev.channel = setpoint ? "SIM3.SETPOINTS" : "SIM3.OTHER";
      ev.datalen = static_cast<int32_t>(data.size());
      ev.data = data.data();
      ASSERT_EQ(log.writeEvent(&ev), 0);
      payloads.push_back(std::move(data));
    }
  }
  std::map<std::string, int> counts;
  std::vector<int64_t> cycles;
  std::vector<int64_t> recv_utimes;
  bool first_payload_matches = false;
  {
    Bus bus("file://" + path + "?speed=0", 1);
    bus.subscribe_raw(".*", [&](const std::string& ch, const void* data, size_t size, int64_t recv_utime) {
      if (counts[ch]++ == 0 && ch == "SIM3.SETPOINTS")
        first_payload_matches = size == payloads[0].size() && std::memcmp(data, payloads[0].data(), size) == 0;
      recv_utimes.push_back(recv_utime);
    });
    bus.subscribe<cnc::lcmt_setpoint>("SIM3.SETPOINTS",
                                      [&](const cnc::lcmt_setpoint& m) { cycles.push_back(m.cycle); });
    int rc = 0;
    int calls = 0;
    while (calls < 1000 && (rc = bus.handle(1000)) >= 0) ++calls;
    EXPECT_EQ(rc, -1) << "the log did not end";
    EXPECT_EQ(bus.stats("SIM3.SETPOINTS").received, 6);
    EXPECT_EQ(bus.stats("SIM3.SETPOINTS").decode_failures, 0);
    EXPECT_EQ(bus.stats("SIM3.SETPOINTS").seq_gaps, 1);
    EXPECT_EQ(bus.stats("SIM3.OTHER").received, 2);
  }
  std::filesystem::remove(path);
  EXPECT_EQ(counts["SIM3.SETPOINTS"], 6);
  EXPECT_EQ(counts["SIM3.OTHER"], 2);
  EXPECT_TRUE(first_payload_matches);
  EXPECT_EQ(cycles, (std::vector<int64_t>{0, 1, 2, 4, 5, 6}));
  ASSERT_EQ(recv_utimes.size(), 8u);
  // LCM 1.3.1's file provider hands out the dispatch time, not the logged timestamp:
  // replay must take time from each message's utime.
  EXPECT_TRUE(std::is_sorted(recv_utimes.begin(), recv_utimes.end()));
}

}  // namespace
}  // namespace cnc::bus
