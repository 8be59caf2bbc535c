// service::PeerWatch: a peer whose heartbeat is missing for the timeout is reported
// lost once (peer_lost, naming it), back once (peer_back), a new pid as a restart
// (peer_restarted); a clean stop (STOPPING) and a peer never seen raise nothing. The
// checks on the cyclic paths (check(), the heartbeat handler) allocate nothing.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "common/bus/bus.h"
#include "common/service/peer_watch.h"
#include "tests/unit/alloc_guard.h"

namespace cnc::service {
namespace {

double g_now = 0;
double fake_clock() { return g_now; }

cnc::lcmt_heartbeat heartbeat(const std::string& service, int32_t pid, int8_t state) {
  cnc::lcmt_heartbeat hb{};
  hb.service = service;
  hb.pid = pid;
  hb.state = state;
  hb.num_channels = 0;
  return hb;
}

struct Fixture {
  bus::Bus bus{"memq://"};
  std::vector<cnc::lcmt_alarm> alarms;
  PeerWatch watch{bus, "T.HEARTBEAT", "T.ALARM", 1.0, "cnc-test", {"cnc-a", "cnc-b"}, &fake_clock};
  Fixture() {
    bus.subscribe<cnc::lcmt_alarm>("T.ALARM", [this](const cnc::lcmt_alarm& m) { alarms.push_back(m); });
  }
  // The alarms raised by the last check.
  std::vector<cnc::lcmt_alarm> take() {
    alarms.clear();
    bus.drain();
    return alarms;
  }
};

TEST(PeerWatch, LostOnceBackOnceRestartedAndCleanStopsSilent) {
  Fixture f;
  f.watch.on_heartbeat(heartbeat("cnc-a", 10, cnc::lcmt_heartbeat::RUNNING), 0.0);
  f.watch.on_heartbeat(heartbeat("cnc-other", 99, cnc::lcmt_heartbeat::RUNNING), 0.0);  // not watched
  EXPECT_EQ(f.watch.check(0.99), 0);
  EXPECT_TRUE(f.take().empty());
  EXPECT_FALSE(f.watch.lost(0));
  // 1 s without a heartbeat: lost, once; cnc-b was never seen: nothing about it.
  EXPECT_EQ(f.watch.check(1.01), 1);
  auto a = f.take();
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0].code, "peer_lost");
  EXPECT_EQ(a[0].source, "cnc-test");
  EXPECT_EQ(a[0].severity, int8_t{cnc::lcmt_alarm::WARNING});
  EXPECT_NE(a[0].text.find("no heartbeat from cnc-a (pid 10"), std::string::npos) << a[0].text;
  EXPECT_TRUE(f.watch.lost(0));
  EXPECT_FALSE(f.watch.lost(1));
  EXPECT_NE(std::string(f.watch.last_lost_text()).find("cnc-a"), std::string::npos);
  EXPECT_EQ(f.watch.check(5.0), 0);
  EXPECT_TRUE(f.take().empty()) << "reported once";
  // Back (same pid): peer_back.
  f.watch.on_heartbeat(heartbeat("cnc-a", 10, cnc::lcmt_heartbeat::RUNNING), 5.5);
  EXPECT_EQ(f.watch.check(5.5), 0);
  a = f.take();
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0].code, "peer_back");
  EXPECT_EQ(a[0].severity, int8_t{cnc::lcmt_alarm::INFO});
  EXPECT_FALSE(f.watch.lost(0));
  // A new pid within the timeout: it restarted.
  f.watch.on_heartbeat(heartbeat("cnc-a", 11, cnc::lcmt_heartbeat::RUNNING), 5.9);
  f.watch.check(5.9);
  a = f.take();
  ASSERT_EQ(a.size(), 1u);
  EXPECT_EQ(a[0].code, "peer_restarted");
  EXPECT_NE(a[0].text.find("new pid 11"), std::string::npos) << a[0].text;
  // A clean stop: its last heartbeat says STOPPING; silence after it is no alarm.
  f.watch.on_heartbeat(heartbeat("cnc-a", 11, cnc::lcmt_heartbeat::STOPPING), 6.0);
  EXPECT_EQ(f.watch.check(60.0), 0);
  EXPECT_TRUE(f.take().empty());
  EXPECT_TRUE(f.watch.stopped(0));
  EXPECT_FALSE(f.watch.lost(0));
}

TEST(PeerWatch, HeartbeatsThroughTheBusAndNoAllocationOnTheCyclicPath) {
  Fixture f;
  cnc::lcmt_heartbeat hb = heartbeat("cnc-b", 7, cnc::lcmt_heartbeat::RUNNING);
  g_now = 100.0;
  ASSERT_TRUE(f.bus.publish("T.HEARTBEAT", hb));
  f.bus.drain();
  EXPECT_TRUE(f.watch.seen(1));
  EXPECT_FALSE(f.watch.seen(0));
  // Warm up the alarm path once (the bus's publish buffer for the ALARM channel).
  f.watch.check(101.5);
  f.take();
  f.watch.on_heartbeat(hb, 102.0);
  f.watch.check(102.0);
  f.take();
  {
    test::AllocGuard g;
    for (int k = 0; k < 1000; ++k) {
      f.watch.on_heartbeat(hb, 102.0 + k * 0.004);  // the handler: a name compare and a time stamp
      f.watch.check(102.0 + k * 0.004);
    }
    f.watch.check(110.0);  // lost: formats and publishes its alarm
    f.watch.on_heartbeat(hb, 110.5);
    f.watch.check(110.5);  // back
    EXPECT_EQ(g.allocations(), 0);
    EXPECT_EQ(g.frees(), 0);
  }
  const auto a = f.take();
  ASSERT_EQ(a.size(), 2u);
  EXPECT_EQ(a[0].code, "peer_lost");
  EXPECT_EQ(a[1].code, "peer_back");
}

TEST(PeerWatch, AnyMessageFromAPeersSenderIsASignOfLife) {
  // cnc-a's heartbeats (sender 42) stop at t = 10 while its other messages go on
  // until t = 13: it is lost only 1 s after its last message, not its last
  // heartbeat. Messages of another sender, or of sender 0, keep nothing alive.
  Fixture f;
  cnc::lcmt_heartbeat hb = heartbeat("cnc-a", 5, cnc::lcmt_heartbeat::RUNNING);
  hb.sender = 42;
  f.watch.on_heartbeat(hb, 10.0);
  for (double t = 10.0; t <= 13.0; t += 0.004) {
    f.watch.on_message(42, t);
    f.watch.on_message(43, t + 5);  // another process
    f.watch.on_message(0, t + 5);
    EXPECT_EQ(f.watch.check(t), 0) << t;
  }
  EXPECT_EQ(f.watch.check(13.9), 0);
  EXPECT_EQ(f.watch.check(14.1), 1);
  EXPECT_TRUE(f.watch.lost(0));
  f.watch.on_message(42, 14.2);  // it speaks again: back
  f.watch.check(14.2);
  EXPECT_FALSE(f.watch.lost(0));
  const auto a = f.take();
  ASSERT_EQ(a.size(), 2u);
  EXPECT_EQ(a[0].code, "peer_lost");
  EXPECT_EQ(a[1].code, "peer_back");
  // Allocation-free, like the heartbeat handler.
  test::AllocGuard g;
  for (int k = 0; k < 1000; ++k) f.watch.on_message(42, 15.0 + k * 0.001);
  EXPECT_EQ(g.allocations() + g.frees(), 0);
}

}  // namespace
}  // namespace cnc::service
