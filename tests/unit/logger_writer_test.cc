// The logger's writer and node: rotation (every file readable by LCM's own reader,
// events in order, none lost), a file readable up to the last flush while the
// writer still holds it (what SIGKILL leaves), failed writes cut back to a whole
// event and counted per channel, and the stats the node writes into the log.
#include <gtest/gtest.h>
#include <lcm/eventlog.h>
#include <sys/resource.h>

#include <csignal>
#include <cstring>
#include <filesystem>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "cnc/lcmt_interp_input.hpp"
#include "cnc/lcmt_logger_stats.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/bus/bus.h"
#include "common/bus/log_format.h"
#include "common/util/install.h"
#include "services/logger/log_writer.h"
#include "services/logger/logger_node.h"

namespace fs = std::filesystem;
using cnc::logger::LogWriter;

namespace {

struct Event {
  int64_t eventnum;
  int64_t timestamp;
  std::string channel;
  std::vector<uint8_t> data;
};

// Reads a file with LCM's own reader, the one lcm-logplayer uses.
std::vector<Event> read_log(const std::string& path) {
  std::vector<Event> out;
  lcm_eventlog_t* log = lcm_eventlog_create(path.c_str(), "r");
  if (log == nullptr) return out;
  while (lcm_eventlog_event_t* ev = lcm_eventlog_read_next_event(log)) {
    const auto* d = static_cast<const uint8_t*>(ev->data);
    out.push_back({ev->eventnum, ev->timestamp, std::string(ev->channel, static_cast<size_t>(ev->channellen)),
                   std::vector<uint8_t>(d, d + ev->datalen)});
    lcm_eventlog_free_event(ev);
  }
  lcm_eventlog_destroy(log);
  return out;
}

std::string part(const std::string& base, int i) {
  return i == 0 ? base + ".lcmlog" : base + "." + std::to_string(i) + ".lcmlog";
}

class LoggerWriterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("cnc-logger-test-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    base_ = (dir_ / "run").string();
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Payload: the event's index in 8 bytes, then filler up to `size`.
  static std::vector<uint8_t> payload(int64_t index, size_t size) {
    std::vector<uint8_t> p(std::max<size_t>(size, 8), static_cast<uint8_t>(index * 7));
    std::memcpy(p.data(), &index, 8);
    return p;
  }
  static int64_t index_of(const Event& e) {
    int64_t i = -1;
    if (e.data.size() >= 8) std::memcpy(&i, e.data.data(), 8);
    return i;
  }

  fs::path dir_;
  std::string base_;
};

TEST_F(LoggerWriterTest, RotatesIntoReadableFilesWithEveryEventInOrder) {
  constexpr double kRotateBytes = 4096;
  constexpr int kEvents = 3000;
  std::mt19937 rng(42);
  std::uniform_int_distribution<size_t> size_of(8, 300);
  std::vector<size_t> sizes;
  {
    LogWriter w(base_, kRotateBytes, 1024);
    for (int i = 0; i < kEvents; ++i) {
      sizes.push_back(size_of(rng));
      const auto p = payload(i, sizes.back());
      ASSERT_TRUE(w.write(i % 3 ? "T.SETPOINTS" : "T.AXIS_STATUS", p.data(), p.size(), 1000 + i));
    }
    w.close();
    EXPECT_EQ(w.events(), kEvents);
    EXPECT_EQ(w.dropped(), 0);
    EXPECT_EQ(w.write_errors(), 0);
    EXPECT_GT(w.files(), 50);
    EXPECT_EQ(w.channels().at("T.SETPOINTS").logged + w.channels().at("T.AXIS_STATUS").logged, kEvents);
    EXPECT_EQ(w.current_path(), part(base_, w.files() - 1));
    EXPECT_FALSE(fs::exists(part(base_, w.files())));
  }
  int64_t next = 0;
  uintmax_t total_bytes = 0;
  for (int f = 0; fs::exists(part(base_, f)); ++f) {
    const auto size = fs::file_size(part(base_, f));
    total_bytes += size;
    EXPECT_LE(size, kRotateBytes) << part(base_, f);
    const auto events = read_log(part(base_, f));
    ASSERT_FALSE(events.empty()) << part(base_, f);
    for (size_t k = 0; k < events.size(); ++k) {
      const Event& e = events[k];
      EXPECT_EQ(e.eventnum, static_cast<int64_t>(k)) << "event numbers restart in each file";
      ASSERT_EQ(index_of(e), next) << part(base_, f) << " event " << k;
      EXPECT_EQ(e.timestamp, 1000 + next);
      EXPECT_EQ(e.channel, next % 3 ? "T.SETPOINTS" : "T.AXIS_STATUS");
      EXPECT_EQ(e.data.size(), sizes[static_cast<size_t>(next)]);
      EXPECT_EQ(e.data, payload(next, sizes[static_cast<size_t>(next)]));
      ++next;
    }
  }
  EXPECT_EQ(next, kEvents) << "events lost across rotation";
  EXPECT_GT(total_bytes, 0u);
}

TEST_F(LoggerWriterTest, EveryFileBeginsWithTheFormatEvent) {
  // Rotation at 2 kB: every file, not only the first, names its format, stamped
  // with the time of the event after it (lcm-logplayer plays from the first stamp).
  const std::string header = cnc::bus::log_format_record();
  {
    LogWriter w(base_, 2048, 512, header);
    for (int i = 0; i < 200; ++i) {
      const auto p = payload(i, 100);
      ASSERT_TRUE(w.write("T.SETPOINTS", p.data(), p.size(), 5000 + i));
    }
    w.close();
    EXPECT_GT(w.files(), 5);
    EXPECT_EQ(w.channels().at(cnc::bus::kLogFormatChannel).logged, w.files());
  }
  int64_t next = 0;
  for (int f = 0; fs::exists(part(base_, f)); ++f) {
    const auto events = read_log(part(base_, f));
    ASSERT_GE(events.size(), 2u) << part(base_, f);
    EXPECT_EQ(events[0].channel, cnc::bus::kLogFormatChannel);
    EXPECT_EQ(events[0].timestamp, events[1].timestamp);
    cnc::bus::LogFormat fmt;
    ASSERT_TRUE(cnc::bus::parse_log_format(events[0].data.data(), events[0].data.size(), &fmt));
    EXPECT_EQ(fmt.format, cnc::bus::kLogFormat);
    EXPECT_EQ(fmt.version, cnc::util::version());
    EXPECT_EQ(fmt.motion, cnc::bus::kMotionRevision);
    EXPECT_EQ(cnc::bus::unreadable_log_format(fmt), "");
    for (size_t k = 1; k < events.size(); ++k) EXPECT_EQ(index_of(events[k]), next++);
  }
  EXPECT_EQ(next, 200);
}

TEST(LogFormat, FormatsThisBuildCannotReadAreRefusedWithTheVersionAndWhatToDo) {
  cnc::bus::LogFormat f;
  const std::string text = "cnc-log-format 99 0.9.0+5.gabc";
  ASSERT_TRUE(cnc::bus::parse_log_format(text.data(), text.size(), &f));
  EXPECT_EQ(f.format, 99);
  EXPECT_EQ(f.version, "0.9.0+5.gabc");
  const std::string why = cnc::bus::unreadable_log_format(f);
  EXPECT_NE(why.find("format 99 (recorded by cnc 0.9.0+5.gabc), newer than"), std::string::npos) << why;
  EXPECT_NE(why.find("read it with the version that recorded it"), std::string::npos) << why;
  cnc::bus::LogFormat old;  // no format event: format 1, readable
  EXPECT_EQ(cnc::bus::unreadable_log_format(old), "");
  const std::string junk = "cnc-log-format x";
  EXPECT_FALSE(cnc::bus::parse_log_format(junk.data(), junk.size(), &f));
}

TEST(LogFormat, TheMotionRevisionIsReadAfterTheVersionAndIsOneWhereNoneIsNamed) {
  cnc::bus::LogFormat f;
  const std::string text = "cnc-log-format 3 0.1.0+380.gabc motion 7";
  ASSERT_TRUE(cnc::bus::parse_log_format(text.data(), text.size(), &f));
  EXPECT_EQ(f.format, 3);
  EXPECT_EQ(f.version, "0.1.0+380.gabc");
  EXPECT_EQ(f.motion, 7);
  const std::string before = "cnc-log-format 2 0.1.0+306.ga886325";
  ASSERT_TRUE(cnc::bus::parse_log_format(before.data(), before.size(), &f));
  EXPECT_EQ(f.version, "0.1.0+306.ga886325");
  EXPECT_EQ(f.motion, 1);
  const std::string odd = "cnc-log-format 3 v motion 2x";  // not a revision: part of the version
  ASSERT_TRUE(cnc::bus::parse_log_format(odd.data(), odd.size(), &f));
  EXPECT_EQ(f.version, "v motion 2x");
  EXPECT_EQ(f.motion, 1);
}

TEST_F(LoggerWriterTest, AnEventLargerThanTheRotateSizeGetsAFileOfItsOwn) {
  {
    LogWriter w(base_, 1000, 256);
    const auto small = payload(0, 100), big = payload(1, 5000), after = payload(2, 100);
    w.write("T.A", small.data(), small.size(), 1);
    w.write("T.B", big.data(), big.size(), 2);
    w.write("T.A", after.data(), after.size(), 3);
    w.close();
    EXPECT_EQ(w.files(), 3);
    EXPECT_EQ(w.dropped(), 0);
  }
  for (int f = 0; f < 3; ++f) {
    const auto events = read_log(part(base_, f));
    ASSERT_EQ(events.size(), 1u);
    EXPECT_EQ(index_of(events[0]), f);
  }
}

TEST_F(LoggerWriterTest, WhileOpenTheFileHoldsEveryFlushedEventAndEndsOnAWholeEvent) {
  // What a SIGKILL leaves: the events handed to the kernel, nothing torn.
  LogWriter w(base_, 1e9, 4096);
  int64_t written = 0;
  for (int round = 0; round < 20; ++round) {
    for (int i = 0; i < 37; ++i, ++written) {
      const auto p = payload(written, 120);
      w.write("T.SETPOINTS", p.data(), p.size(), written);
    }
    // Between flushes the buffer hands over whole events only.
    const auto before = read_log(base_ + ".lcmlog");
    EXPECT_EQ(static_cast<int64_t>(before.size()), w.events());
    EXPECT_EQ(fs::file_size(base_ + ".lcmlog"), static_cast<uintmax_t>(w.bytes()));
    ASSERT_TRUE(w.flush());
    const auto after = read_log(base_ + ".lcmlog");
    ASSERT_EQ(static_cast<int64_t>(after.size()), written);
    for (size_t k = 0; k < after.size(); ++k) ASSERT_EQ(index_of(after[k]), static_cast<int64_t>(k));
  }
}

TEST_F(LoggerWriterTest, ARestartedLoggerWritesANewFileAndLeavesTheOldOne) {
  // A logger killed and started again with the same base (or twice in one second):
  // NAME.lcmlog is kept as it is, the new one writes NAME-2.lcmlog, then NAME-3.
  {
    LogWriter w(base_, 1e9, 4096);
    for (int64_t i = 0; i < 10; ++i) {
      const auto p = payload(i, 64);
      w.write("T.SETPOINTS", p.data(), p.size(), i);
    }
  }
  const auto before = fs::file_size(base_ + ".lcmlog");
  for (int n = 2; n <= 3; ++n) {
    LogWriter w(base_, 1e9, 4096);
    EXPECT_EQ(w.current_path(), base_ + "-" + std::to_string(n) + ".lcmlog");
    const auto p = payload(100, 64);
    w.write("T.SETPOINTS", p.data(), p.size(), 100);
  }
  EXPECT_EQ(fs::file_size(base_ + ".lcmlog"), before);
  EXPECT_EQ(read_log(base_ + ".lcmlog").size(), 10u);
  EXPECT_EQ(read_log(base_ + "-2.lcmlog").size(), 1u);
  EXPECT_EQ(read_log(base_ + "-3.lcmlog").size(), 1u);
}

TEST_F(LoggerWriterTest, AFailedWriteIsCutBackToAWholeEventAndCountedPerChannel) {
  // RLIMIT_FSIZE makes write(2) short and then fail with EFBIG, like a full disk.
  constexpr rlim_t kLimit = 20000;
  rlimit old{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit lim = old;
  lim.rlim_cur = kLimit;
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &lim), 0);
  int64_t written = 0, events = 0, dropped = 0, a_dropped = 0, b_dropped = 0, write_errors = 0;
  {
    LogWriter w(base_, 1e9, 1000);
    for (; written < 400; ++written) {
      const auto p = payload(written, 90);
      w.write(written % 2 ? "T.A" : "T.B", p.data(), p.size(), written);
    }
    w.close();
    events = w.events();
    dropped = w.dropped();
    write_errors = w.write_errors();
    a_dropped = w.channels().at("T.A").dropped;
    b_dropped = w.channels().at("T.B").dropped;
  }
  setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, old_handler);

  EXPECT_GT(events, 0);
  EXPECT_GT(dropped, 0);
  EXPECT_GT(write_errors, 0);
  EXPECT_EQ(events + dropped, written) << "every event is either in the file or counted as dropped";
  EXPECT_EQ(a_dropped + b_dropped, dropped);
  EXPECT_GT(a_dropped, 0);
  EXPECT_GT(b_dropped, 0);
  EXPECT_LE(fs::file_size(base_ + ".lcmlog"), kLimit);
  const auto read = read_log(base_ + ".lcmlog");
  ASSERT_EQ(static_cast<int64_t>(read.size()), events);
  for (size_t k = 0; k < read.size(); ++k) EXPECT_EQ(index_of(read[k]), static_cast<int64_t>(k));
}

TEST_F(LoggerWriterTest, NodeWritesItsStatsIntoTheLogAndTheClosingStatsLast) {
  cnc::config::MachineConfig cfg;
  cfg.channel_prefix = "T.";
  cfg.log_flush_period_s = 0.5;
  cnc::bus::Bus bus("memq://");
  LogWriter writer(base_, 1e9);
  cnc::logger::LoggerNode node(cfg, bus, writer);
  node.tick(100.0);

  cnc::lcmt_setpoint sp{};
  sp.num_axes = 3;
  sp.position_mm = {1, 2, 3};
  for (int i = 0; i < 10; ++i) bus.publish("T.SETPOINTS", sp);
  // A message from another sender, seq 0 then 6: five lost upstream.
  for (int64_t seq : {0, 6}) {
    sp.seq = seq;
    sp.sender = 4242;
    std::vector<uint8_t> buf(static_cast<size_t>(sp.getEncodedSize()));
    sp.encode(buf.data(), 0, static_cast<int>(buf.size()));
    bus.publish_raw("T.SETPOINTS", buf.data(), buf.size());
  }
  // Not the cell's prefix: not recorded.
  bus.publish("OTHER.SETPOINTS", sp);
  while (bus.handle(0) > 0) {
  }
  node.tick(101.1);  // the periodic stats, published too; memq brings our copy back
  while (bus.handle(0) > 0) {
  }
  node.close();

  const auto events = read_log(base_ + ".lcmlog");
  std::vector<cnc::lcmt_logger_stats> stats;
  int setpoints = 0;
  for (const auto& e : events) {
    EXPECT_NE(e.channel, "OTHER.SETPOINTS");
    if (e.channel == "T.SETPOINTS") ++setpoints;
    if (e.channel != "T.LOGGER_STATS") continue;
    cnc::lcmt_logger_stats m;
    ASSERT_EQ(m.decode(e.data.data(), 0, static_cast<int>(e.data.size())), static_cast<int>(e.data.size()));
    stats.push_back(m);
  }
  EXPECT_EQ(setpoints, 12);
  ASSERT_EQ(stats.size(), 2u) << "one periodic and one closing report, the loopback copy not written twice";
  EXPECT_EQ(events.back().channel, "T.LOGGER_STATS");
  EXPECT_FALSE(stats[0].closing);
  const auto& last = stats[1];
  EXPECT_TRUE(last.closing);
  EXPECT_EQ(last.seq, stats[0].seq + 1);
  EXPECT_EQ(last.sender, bus.sender());
  EXPECT_EQ(last.path, base_ + ".lcmlog");
  EXPECT_EQ(last.files, 1);
  EXPECT_EQ(last.events, static_cast<int64_t>(events.size()) - 1);
  EXPECT_EQ(last.events_dropped, 0);
  bool found = false;
  for (int i = 0; i < last.num_channels; ++i) {
    if (last.channel[i] != "T.SETPOINTS") continue;
    found = true;
    EXPECT_EQ(last.received[i], 12);
    EXPECT_EQ(last.logged[i], 12);
    EXPECT_EQ(last.seq_gaps[i], 5);
    EXPECT_EQ(last.dropped[i], 0);
  }
  EXPECT_TRUE(found);
}

TEST_F(LoggerWriterTest, StatsConfirmTheInterpolatorInputsWrittenWithoutAGap) {
  // INTERP_INPUT indices 0, 1, 3, 1 (a copy), 4 from one interpolator, 0 from
  // another: the first is confirmed up to 2 (2 is missing, 3 and 4 wait above it),
  // the second up to 1. After 2 comes (sent again), up to 5.
  cnc::config::MachineConfig cfg;
  cfg.channel_prefix = "T.";
  cnc::bus::Bus bus("memq://");
  LogWriter writer(base_, 1e9);
  cnc::logger::LoggerNode node(cfg, bus, writer);
  node.tick(100.0);
  int64_t seq = 0;
  auto input = [&](int32_t sender, int64_t index) {
    cnc::lcmt_interp_input in{};
    in.seq = seq++;
    in.sender = sender;
    in.index = index;
    in.kind = cnc::lcmt_interp_input::PLAN;
    in.plans = 1;
    std::vector<uint8_t> buf(static_cast<size_t>(in.getEncodedSize()));
    in.encode(buf.data(), 0, static_cast<int>(buf.size()));
    bus.publish_raw("T.INTERP_INPUT", buf.data(), buf.size());
    while (bus.handle(0) > 0) {
    }
  };
  cnc::lcmt_logger_stats got{};
  bool have = false;
  bus.subscribe<cnc::lcmt_logger_stats>("T.LOGGER_STATS", [&](const cnc::lcmt_logger_stats& m) {
    got = m;
    have = true;
  });
  auto confirmed = [&](double t) {
    std::map<int32_t, int64_t> out;
    have = false;
    node.tick(t);
    while (bus.handle(0) > 0) {
    }
    EXPECT_TRUE(have);
    for (int i = 0; i < got.num_input_senders; ++i) out[got.input_sender[i]] = got.input_next[i];
    return out;
  };
  for (int64_t i : {0, 1, 3, 1, 4}) input(7, i);
  input(8, 0);
  auto c = confirmed(101.1);
  EXPECT_EQ(c[7], 2);
  EXPECT_EQ(c[8], 1);
  input(7, 2);
  c = confirmed(102.2);
  EXPECT_EQ(c[7], 5);
  EXPECT_EQ(c[8], 1);
  node.close();
}

TEST(LoggerReceiveUrl, AddsTheReceiveBufferToUdpmUrlsThatSetNone) {
  using cnc::logger::receive_url;
  EXPECT_EQ(receive_url("udpm://239.255.76.67:7667?ttl=0", 4096), "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4096");
  EXPECT_EQ(receive_url("udpm://239.255.76.67:7667", 4096), "udpm://239.255.76.67:7667?recv_buf_size=4096");
  EXPECT_EQ(receive_url("udpm://239.255.76.67:7667?recv_buf_size=1000", 4096), "udpm://239.255.76.67:7667?recv_buf_size=1000");
  EXPECT_EQ(receive_url("memq://", 4096), "memq://");
  EXPECT_EQ(receive_url("", 4096), "");
}

TEST(LoggerSocketDrops, ReadsTheKernelCountersOfThisProcess) {
  // No socket of ours has dropped anything here; the point is that it is readable.
  EXPECT_GE(cnc::logger::udp_socket_drops(), 0);
}

}  // namespace
