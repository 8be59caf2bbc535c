// Signed channels (common/bus/auth.h, Bus with Security): a signed round trip, and
// every kind of message a receiver must drop (unsigned, forged, wrong key, replayed,
// stale), key rotation with its grace period, the key file's mode, a log verified
// offline; over memq:// (one bus publishes to itself) and udpm:// (two buses).
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <memory>
#include <string>
#include <vector>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/bus/auth.h"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/config/yaml_reader.h"
#include "common/service/bus_health.h"
#include "common/util/clock.h"
#include "temp_dir.h"
#include "tests/unit/alloc_guard.h"

namespace cnc::bus {
namespace {

const std::string kCh = "T.SETPOINTS";

KeySet one_key() {
  KeySet ks;
  ks.add(generate_key());
  return ks;
}

Security signing(const KeySet& ks) {
  Security s;
  s.enabled = true;
  s.keys = ks;
  return s;
}

cnc::lcmt_setpoint setpoint(int64_t cycle) {
  cnc::lcmt_setpoint m{};
  m.cycle = cycle;
  m.period_s = 0.004;
  m.num_axes = 3;
  m.position_mm = {1.0 * static_cast<double>(cycle), 2.0, 3.0};
  return m;
}

// The message as `sender` would encode it (header stamped by hand), unsigned.
std::vector<uint8_t> encoded(cnc::lcmt_setpoint m, int64_t utime, int64_t seq, int32_t sender) {
  m.utime = utime;
  m.seq = seq;
  m.sender = sender;
  std::vector<uint8_t> b(static_cast<size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

std::vector<uint8_t> signed_with(const Key& k, const std::string& ch, std::vector<uint8_t> b) {
  const size_t n = b.size();
  b.resize(n + kTrailerBytes);
  sign(k, ch, b.data(), n, b.data() + n);
  return b;
}

struct Received {
  std::vector<cnc::lcmt_setpoint> typed;
  std::vector<std::vector<uint8_t>> raw;
};

void listen(Bus& bus, Received& r) {
  bus.subscribe<cnc::lcmt_setpoint>(kCh, [&r](const cnc::lcmt_setpoint& m) { r.typed.push_back(m); });
  bus.subscribe_raw(exact_channel(kCh), [&r](const std::string&, const void* d, size_t n, int64_t) {
    const auto* p = static_cast<const uint8_t*>(d);
    r.raw.emplace_back(p, p + n);
  });
}

TEST(BusSigning, SignedRoundTripDecodesAndKeepsTheTrailerForRawSubscribers) {
  const KeySet ks = one_key();
  Bus bus("memq://", 11, 1000, signing(ks));
  Received r;
  listen(bus, r);
  auto m = setpoint(7);
  ASSERT_TRUE(bus.publish(kCh, m));
  bus.drain();
  ASSERT_EQ(r.typed.size(), 1u);
  EXPECT_EQ(r.typed[0].cycle, 7);
  EXPECT_EQ(r.typed[0].position_mm[0], 7.0);
  EXPECT_EQ(r.typed[0].sender, 11);
  ASSERT_EQ(r.raw.size(), 1u);
  EXPECT_EQ(r.raw[0].size(), static_cast<size_t>(m.getEncodedSize()) + kTrailerBytes);
  EXPECT_TRUE(has_trailer(r.raw[0].data(), r.raw[0].size()));
  EXPECT_EQ(trailer_key_id(r.raw[0].data(), r.raw[0].size()), ks.keys[0].id);
  EXPECT_TRUE(verify(ks.keys[0], kCh, r.raw[0].data(), r.raw[0].size()));
  // The tag binds the channel: the same bytes do not verify on another one.
  EXPECT_FALSE(verify(ks.keys[0], "T.PROGRAM_CMD", r.raw[0].data(), r.raw[0].size()));
  const ChannelStats st = bus.stats(kCh);
  EXPECT_EQ(st.received, 1);
  EXPECT_EQ(st.rejected(), 0);
}

TEST(BusSigning, UnsignedIsDroppedAndCounted) {
  Bus bus("memq://", 11, 1000, signing(one_key()));
  Received r;
  listen(bus, r);
  const auto b = encoded(setpoint(1), util::wall_utime(), 0, 99);
  ASSERT_TRUE(bus.publish_raw(kCh, b.data(), b.size()));
  bus.drain();
  EXPECT_TRUE(r.typed.empty());
  EXPECT_TRUE(r.raw.empty());  // raw subscribers (the logger) see only verified messages too
  EXPECT_EQ(bus.stats(kCh).rejected_unsigned, 1);
  EXPECT_EQ(bus.stats(kCh).received, 0);
  EXPECT_EQ(bus.rejected_total(Reject::kUnsigned), 1);
  EXPECT_NE(std::string(bus.last_reject()).find("sender 99: unsigned"), std::string::npos) << bus.last_reject();
}

TEST(BusSigning, ForgedTagIsDropped) {
  const KeySet ks = one_key();
  Bus bus("memq://", 11, 1000, signing(ks));
  Received r;
  listen(bus, r);
  auto b = signed_with(ks.keys[0], kCh, encoded(setpoint(1), util::wall_utime(), 0, 99));
  b[40] ^= 0x01;  // one bit of the payload (cycle) changed after signing
  ASSERT_TRUE(bus.publish_raw(kCh, b.data(), b.size()));
  auto c = signed_with(ks.keys[0], kCh, encoded(setpoint(2), util::wall_utime(), 1, 99));
  c[c.size() - 10] ^= 0x80;  // one bit of the tag
  ASSERT_TRUE(bus.publish_raw(kCh, c.data(), c.size()));
  // Signed for another channel, sent on this one.
  const auto d = signed_with(ks.keys[0], "T.PROGRAM_CMD", encoded(setpoint(3), util::wall_utime(), 2, 99));
  ASSERT_TRUE(bus.publish_raw(kCh, d.data(), d.size()));
  bus.drain();
  EXPECT_TRUE(r.typed.empty());
  EXPECT_EQ(bus.stats(kCh).rejected_forged, 3);
}

TEST(BusSigning, WrongKeyIsDropped) {
  const KeySet ks = one_key();
  Bus bus("memq://", 11, 1000, signing(ks));
  Received r;
  listen(bus, r);
  // Another cell's key with an id this cell does not know...
  const Key stranger = one_key().keys[0];
  const auto a = signed_with(stranger, kCh, encoded(setpoint(1), util::wall_utime(), 0, 99));
  ASSERT_TRUE(bus.publish_raw(kCh, a.data(), a.size()));
  // ...and a guessed secret under this cell's key id.
  KeySet guess;
  Key g = generate_key();
  g.id = ks.keys[0].id;
  guess.add(g);
  const auto b = signed_with(guess.keys[0], kCh, encoded(setpoint(2), util::wall_utime(), 1, 99));
  ASSERT_TRUE(bus.publish_raw(kCh, b.data(), b.size()));
  bus.drain();
  EXPECT_TRUE(r.typed.empty());
  EXPECT_EQ(bus.stats(kCh).rejected_unknown_key, 1);
  EXPECT_EQ(bus.stats(kCh).rejected_forged, 1);
}

TEST(BusSigning, ReplayedBytesAreDroppedReorderedOnesAccepted) {
  const KeySet ks = one_key();
  Bus bus("memq://", 11, 1000, signing(ks));
  Received r;
  listen(bus, r);
  const int64_t now = util::wall_utime();
  std::vector<std::vector<uint8_t>> msgs;
  for (int64_t s = 0; s < 5; ++s) msgs.push_back(signed_with(ks.keys[0], kCh, encoded(setpoint(s), now, s, 99)));
  // 0, 1, 3, 2 (late, within the window: accepted), 4, then 1 and 4 again and 0.
  for (int i : {0, 1, 3, 2, 4, 1, 4, 0}) ASSERT_TRUE(bus.publish_raw(kCh, msgs[i].data(), msgs[i].size()));
  bus.drain();
  ASSERT_EQ(r.typed.size(), 5u);
  EXPECT_EQ(r.typed[3].cycle, 2);
  const ChannelStats st = bus.stats(kCh);
  EXPECT_EQ(st.rejected_replayed, 3);
  EXPECT_EQ(st.reordered, 1);
  EXPECT_EQ(st.seq_gaps, 0);  // the late one was not lost
  EXPECT_EQ(st.received, 5);
  // Far behind the window: replayed even if never seen.
  const auto old = signed_with(ks.keys[0], kCh, encoded(setpoint(9), now, 1000, 98));
  const auto older = signed_with(ks.keys[0], kCh, encoded(setpoint(9), now, 900, 98));
  bus.publish_raw(kCh, old.data(), old.size());
  bus.publish_raw(kCh, older.data(), older.size());
  bus.drain();
  EXPECT_EQ(bus.stats(kCh).rejected_replayed, 4);
}

TEST(BusSigning, ATimeStampOutsideTheFreshnessWindowIsDropped) {
  const KeySet ks = one_key();
  Security sec = signing(ks);
  sec.max_age_s = 2.0;
  Bus bus("memq://", 11, 1000, sec);
  Received r;
  listen(bus, r);
  const int64_t now = util::wall_utime();
  // A capture 10 s old from a sender this receiver never saw, one from the future,
  // and one 0.5 s old (within the window: accepted).
  const auto stale = signed_with(ks.keys[0], kCh, encoded(setpoint(1), now - 10'000'000, 0, 97));
  const auto future = signed_with(ks.keys[0], kCh, encoded(setpoint(2), now + 10'000'000, 0, 96));
  const auto fine = signed_with(ks.keys[0], kCh, encoded(setpoint(3), now - 500'000, 0, 95));
  for (const auto* b : {&stale, &future, &fine}) bus.publish_raw(kCh, b->data(), b->size());
  bus.drain();
  ASSERT_EQ(r.typed.size(), 1u);
  EXPECT_EQ(r.typed[0].cycle, 3);
  EXPECT_EQ(bus.stats(kCh).rejected_stale, 2);
}

TEST(BusSigning, RotationKeepsTheOldKeyForItsGraceThenRefusesIt) {
  cnc::test::TempDir dir;
  const std::string file = dir.path().string() + "/cell.key";
  const KeySet first = one_key();
  write_key_file(file, first);
  Security sec;
  sec.enabled = true;
  sec.key_file = file;
  sec.watch = false;  // reload_keys() by hand: no timing in the test
  Bus bus("memq://", 11, 1000, sec);
  Received r;
  listen(bus, r);
  const Key old_key = first.keys[0];
  const int64_t now = util::wall_utime();

  // Rotated: a new key signs from now on; the old one is accepted 60 s longer.
  const KeySet rotated = rotate_keys(read_key_file(file), now, 0.0, 60.0);
  ASSERT_EQ(rotated.count, 2);
  write_key_file(file, rotated);
  ASSERT_TRUE(bus.reload_keys());
  EXPECT_EQ(bus.key_reloads(), 1);
  auto m = setpoint(1);
  ASSERT_TRUE(bus.publish(kCh, m));  // the bus signs with the new key
  const auto in_grace = signed_with(old_key, kCh, encoded(setpoint(2), util::wall_utime(), 0, 90));
  bus.publish_raw(kCh, in_grace.data(), in_grace.size());
  bus.drain();
  ASSERT_EQ(r.raw.size(), 2u);
  EXPECT_EQ(trailer_key_id(r.raw[0].data(), r.raw[0].size()), rotated.keys[1].id);
  EXPECT_EQ(trailer_key_id(r.raw[1].data(), r.raw[1].size()), old_key.id);  // old key, in its grace period

  // The grace period is over (the file says it ended a second ago): refused.
  KeySet expired = rotated;
  expired.keys[0].accept_until_utime = util::wall_utime() - 1'000'000;
  write_key_file(file, expired);
  ASSERT_TRUE(bus.reload_keys());
  const auto after = signed_with(old_key, kCh, encoded(setpoint(3), util::wall_utime(), 1, 90));
  bus.publish_raw(kCh, after.data(), after.size());
  bus.drain();
  EXPECT_EQ(r.raw.size(), 2u);
  EXPECT_EQ(bus.stats(kCh).rejected_unknown_key, 1);

  // A key file that became readable by others is not taken; the keys in use stay.
  ::chmod(file.c_str(), 0644);
  EXPECT_FALSE(bus.reload_keys());
  EXPECT_NE(bus.key_error().find("0644"), std::string::npos) << bus.key_error();
  EXPECT_EQ(bus.key_reload_failures(), 1);
  auto m2 = setpoint(4);
  ASSERT_TRUE(bus.publish(kCh, m2));
  bus.drain();
  EXPECT_EQ(r.raw.size(), 3u);
}

TEST(BusSigning, RotationWithActivationLaterKeepsSigningWithTheOldKeyUntilThen) {
  const int64_t now = util::wall_utime();
  const KeySet ks = rotate_keys(one_key(), now, 30.0, 60.0);
  ASSERT_EQ(ks.count, 2);
  EXPECT_EQ(ks.signing_key(now)->id, ks.keys[0].id);                // not yet the new one
  EXPECT_NE(ks.accepting_key(ks.keys[1].id, now), nullptr);         // but it is accepted already
  EXPECT_EQ(ks.signing_key(now + 31'000'000)->id, ks.keys[1].id);   // from its start on
  EXPECT_NE(ks.accepting_key(ks.keys[0].id, now + 89'000'000), nullptr);
  EXPECT_EQ(ks.accepting_key(ks.keys[0].id, now + 91'000'000), nullptr);  // 30 + 60 s later: over
}

TEST(BusSigning, KeyFileReadableByOthersIsRefusedNamingFileAndMode) {
  cnc::test::TempDir dir;
  const std::string file = dir.path().string() + "/cell.key";
  write_key_file(file, one_key());
  struct stat st {};
  ASSERT_EQ(::stat(file.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  EXPECT_NO_THROW(read_key_file(file));
  for (mode_t mode : {0640, 0604, 0660}) {
    ::chmod(file.c_str(), mode);
    char text[8];
    std::snprintf(text, sizeof text, "0%03o", static_cast<unsigned>(mode));
    try {
      read_key_file(file);
      FAIL() << "mode " << text << " accepted";
    } catch (const KeyFileError& e) {
      EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
    }
    Security sec;
    sec.enabled = true;
    sec.key_file = file;
    EXPECT_THROW(Bus("memq://", 1, 1000, sec), KeyFileError);
  }
  EXPECT_THROW(read_key_file(dir.path().string() + "/missing.key"), KeyFileError);
  // A malformed line names its line.
  ::chmod(file.c_str(), 0600);
  {
    FILE* f = std::fopen(file.c_str(), "a");
    std::fputs("key 1234 zz 0 0\n", f);
    std::fclose(f);
  }
  try {
    read_key_file(file);
    FAIL() << "malformed key file accepted";
  } catch (const KeyFileError& e) {
    EXPECT_NE(std::string(e.what()).find("cell.key:4"), std::string::npos) << e.what();
  }
}

TEST(BusSigning, SigningAndVerifyingAllocateNothingOnceWarm) {
  // The cyclic paths publish and receive signed messages: the trailer is written
  // into the reused encode buffer, the HMAC state lives on the stack, the replay
  // window in the sender's existing entry.
  Bus bus("memq://", 11, 1000, signing(one_key()));
  int64_t got = 0;
  bus.subscribe<cnc::lcmt_setpoint>(kCh, [&got](const cnc::lcmt_setpoint&) { ++got; });
  auto m = setpoint(0);
  for (int i = 0; i < 3; ++i) {  // warm: the channel's entries and buffers exist
    ASSERT_TRUE(bus.publish(kCh, m));
    bus.drain();
  }
  {
    cnc::test::AllocGuard g;
    for (int i = 0; i < 100; ++i) {
      m.cycle = i;
      ASSERT_TRUE(bus.publish(kCh, m));
      bus.drain();
    }
    EXPECT_EQ(g.allocations(), 0);
    EXPECT_EQ(g.frees(), 0);
  }
  EXPECT_EQ(got, 103);
  EXPECT_EQ(bus.stats(kCh).received, 103);
}

TEST(BusSigning, UnsignedReceiverReadsSignedMessagesAndSignedLogsVerifyOffline) {
  // A bus without signing (tools reading a signed log) decodes the bytes before the trailer.
  const KeySet ks = one_key();
  Bus plain("memq://", 12);
  Received r;
  listen(plain, r);
  const auto b = signed_with(ks.keys[0], kCh, encoded(setpoint(5), util::wall_utime(), 0, 90));
  plain.publish_raw(kCh, b.data(), b.size());
  plain.drain();
  ASSERT_EQ(r.typed.size(), 1u);
  EXPECT_EQ(r.typed[0].cycle, 5);
  // LogVerifier: one good, the same again, one unsigned, one forged.
  LogVerifier v(ks);
  EXPECT_TRUE(v.check(kCh, b.data(), b.size()));
  EXPECT_FALSE(v.check(kCh, b.data(), b.size()));
  const auto u = encoded(setpoint(6), util::wall_utime(), 1, 90);
  EXPECT_FALSE(v.check(kCh, u.data(), u.size()));
  auto f = signed_with(ks.keys[0], kCh, encoded(setpoint(7), util::wall_utime(), 2, 90));
  f[45] ^= 4;
  EXPECT_FALSE(v.check(kCh, f.data(), f.size()));
  EXPECT_EQ(v.verified(), 1);
  EXPECT_EQ(v.bad(), 3);
  const auto& c = v.counts().at(kCh);
  EXPECT_EQ(c.bad[static_cast<size_t>(Reject::kReplayed)], 1);
  EXPECT_EQ(c.bad[static_cast<size_t>(Reject::kUnsigned)], 1);
  EXPECT_EQ(c.bad[static_cast<size_t>(Reject::kForged)], 1);
}

TEST(BusSigning, DropsRaiseAtMostOneAlarmPerCauseAndSecondWithTheCount) {
  const KeySet ks = one_key();
  Bus bus("memq://", 11, 1000, signing(ks));
  Received r;
  listen(bus, r);
  std::vector<cnc::lcmt_alarm> alarms;
  bus.subscribe<cnc::lcmt_alarm>("T.ALARM", [&](const cnc::lcmt_alarm& a) { alarms.push_back(a); });
  cnc::service::RejectAlarms ra(bus, "T.ALARM", "cnc-test");
  const auto flood = [&](int n, bool forged) {
    for (int i = 0; i < n; ++i) {
      auto b = encoded(setpoint(i), util::wall_utime(), i, 99);
      if (forged) b = signed_with(generate_key(), kCh, b);  // unknown key id
      bus.publish_raw(kCh, b.data(), b.size());
    }
    bus.drain();
  };
  EXPECT_EQ(ra.report(0.0), 0);  // nothing dropped: nothing raised
  flood(500, false);
  EXPECT_EQ(ra.report(10.0), 1);
  flood(300, false);
  EXPECT_EQ(ra.report(10.5), 0);  // within the second: counted, not raised
  EXPECT_EQ(ra.report(10.9), 0);
  flood(7, true);                 // another cause: its own alarm at once
  EXPECT_EQ(ra.report(10.95), 1);
  {
    cnc::test::AllocGuard g;      // raising an alarm (once warm) allocates nothing
    EXPECT_EQ(ra.report(11.0), 1);  // the 300 unsigned, one second after the first alarm
    EXPECT_EQ(ra.report(12.5), 0);  // nothing new
    EXPECT_EQ(g.allocations(), 0);
  }
  bus.drain();
  ASSERT_EQ(alarms.size(), 3u);
  EXPECT_EQ(alarms[0].code, "bus_unsigned");
  EXPECT_NE(alarms[0].text.find("500 unsigned message(s) dropped (total 500): T.SETPOINTS 500"), std::string::npos)
      << alarms[0].text;
  EXPECT_EQ(alarms[1].code, "bus_unknown_key");
  EXPECT_NE(alarms[1].text.find("7 unknown_key"), std::string::npos) << alarms[1].text;
  EXPECT_EQ(alarms[2].code, "bus_unsigned");
  EXPECT_NE(alarms[2].text.find("300 unsigned message(s) dropped (total 800): T.SETPOINTS 300"), std::string::npos)
      << alarms[2].text;
  EXPECT_NE(alarms[2].text.find("last: T.SETPOINTS from sender 99: unsigned"), std::string::npos) << alarms[2].text;
  EXPECT_TRUE(r.typed.empty());
}

std::string sim3_yaml() {
  std::ifstream in(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(BusSigning, ShippedConfigsSignAndTheKeyFileIsBesideTheConfig) {
  for (const char* name : {"sim3", "sim3_cia402_rtu", "sim3_cia402_tcp", "sim3_leadshine_rtu", "sim3_leadshine_tcp"}) {
    const auto cfg =
        config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/" + name + ".yaml");
    EXPECT_TRUE(cfg.security.signing) << name;
    EXPECT_EQ(cfg.security.key_file, std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.key") << name;
    EXPECT_EQ(cfg.security.max_age_s, 2.0) << name;
  }
  // Signing without a key file is a config error naming the key path.
  std::string y = sim3_yaml();
  const auto at = y.find("  key_file: sim3.key");
  ASSERT_NE(at, std::string::npos);
  y.erase(at, y.find('\n', at) - at);
  try {
    config::parse_machine_config(y, "/x/m.yaml");
    FAIL() << "signing without key_file accepted";
  } catch (const config::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("security.key_file"), std::string::npos) << e.what();
  }
  // No security section: unsigned (the services warn).
  std::string none = sim3_yaml();
  none.erase(none.find("security:"));
  EXPECT_FALSE(config::parse_machine_config(none, "/x/m.yaml").security.signing);
}

// Over UDP multicast: two buses of one cell, and a stranger's unsigned bus.
TEST(BusSigning, OverUdpmOnlyTheCellsSignedMessagesArrive) {
  const int port = 21000 + static_cast<int>(getpid() % 4000) * 2;
  const std::string url = "udpm://239.255.76.67:" + std::to_string(port) + "?ttl=0";
  const KeySet ks = one_key();
  std::unique_ptr<Bus> rx, tx, stranger;
  try {
    rx = std::make_unique<Bus>(url, 21, 1000, signing(ks));
    tx = std::make_unique<Bus>(url, 22, 1000, signing(ks));
    stranger = std::make_unique<Bus>(url, 23);
  } catch (const BusError& e) {
    GTEST_SKIP() << "no UDP multicast here: " << e.what();
  }
  std::vector<int64_t> cycles;
  rx->subscribe<cnc::lcmt_setpoint>(kCh, [&](const cnc::lcmt_setpoint& m) { cycles.push_back(m.cycle); });
  auto forged = setpoint(666);
  for (int i = 0; i < 3; ++i) {
    auto m = setpoint(i);
    ASSERT_TRUE(tx->publish(kCh, m));
    ASSERT_TRUE(stranger->publish(kCh, forged));
  }
  // Waits for the 6 datagrams (a bounded wait for delivery, no timing asserted).
  const double end = util::monotonic_s() + 5.0;
  while (util::monotonic_s() < end && rx->stats(kCh).received + rx->stats(kCh).rejected() < 6) rx->handle(100);
  if (rx->stats(kCh).received + rx->stats(kCh).rejected() == 0) GTEST_SKIP() << "multicast does not loop back here";
  EXPECT_EQ(cycles, (std::vector<int64_t>{0, 1, 2}));
  EXPECT_EQ(rx->stats(kCh).rejected_unsigned, 3);
}

}  // namespace
}  // namespace cnc::bus
