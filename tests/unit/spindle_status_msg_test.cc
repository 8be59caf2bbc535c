// SPINDLE_STATUS across log formats (common/service/spindle_status_msg.h): a message as
// logs of formats 1 to 3 hold it (lcmt_spindle_status_v1, bytes as that version encoded
// them) is not the current message (its fingerprint differs) and decodes as one with
// the encoder and the orientation unknown; a current message, signed or not, decodes
// as itself; anything else is neither.
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <vector>

#include "cnc/lcmt_spindle_status.hpp"
#include "cnc/lcmt_spindle_status_v1.hpp"
#include "common/service/spindle_status_msg.h"

namespace cnc::service {
namespace {

template <class Msg>
std::vector<uint8_t> encoded(const Msg& m) {
  std::vector<uint8_t> b(static_cast<size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(b.data(), 0, static_cast<int>(b.size())), static_cast<int>(b.size()));
  return b;
}

TEST(SpindleStatusMsg, AFormat3MessageDecodesWithoutTheEncoder) {
  cnc::lcmt_spindle_status_v1 v{};
  v.utime = 1'700'000'000'000'000;
  v.seq = 42;
  v.sender = 7;
  v.state = 2;  // RUNNING
  v.command_seq = 1001;
  v.at_speed_seq = 1001;
  v.direction = 1;
  v.commanded_rpm = 6000;
  v.actual_rpm = 5990.5;
  v.current_a = 2.25;
  v.error_code = 0;
  v.fault = "";
  v.transactions = 12345;
  v.timeouts = 3;
  const std::vector<uint8_t> bytes = encoded(v);
  cnc::lcmt_spindle_status plain{};
  EXPECT_LT(plain.decode(bytes.data(), 0, static_cast<int>(bytes.size())), 0) << "another fingerprint";
  cnc::lcmt_spindle_status m{};
  m.position_valid = true;
  ASSERT_TRUE(decode_spindle_status(bytes.data(), bytes.size(), &m));
  EXPECT_EQ(m.utime, v.utime);
  EXPECT_EQ(m.seq, 42);
  EXPECT_EQ(m.sender, 7);
  EXPECT_EQ(m.state, 2);
  EXPECT_EQ(m.command_seq, 1001);
  EXPECT_EQ(m.at_speed_seq, 1001);
  EXPECT_EQ(m.direction, 1);
  EXPECT_DOUBLE_EQ(m.commanded_rpm, 6000);
  EXPECT_DOUBLE_EQ(m.actual_rpm, 5990.5);
  EXPECT_DOUBLE_EQ(m.current_a, 2.25);
  EXPECT_EQ(m.transactions, 12345);
  EXPECT_EQ(m.timeouts, 3);
  EXPECT_FALSE(m.position_valid);
  EXPECT_DOUBLE_EQ(m.sample_playback_cycle, -1);
  EXPECT_EQ(m.orient_state, 0);  // ORIENT_NONE
}

TEST(SpindleStatusMsg, AFormat4MessageDecodesAsItselfSignedOrNot) {
  cnc::lcmt_spindle_status s{};
  s.command_seq = 9;
  s.position_rev = -12.375;
  s.position_valid = true;
  s.sample_playback_cycle = 1234.75;
  s.orient_state = 2;  // ORIENTED
  std::vector<uint8_t> bytes = encoded(s);
  cnc::lcmt_spindle_status m{};
  ASSERT_TRUE(decode_spindle_status(bytes.data(), bytes.size(), &m));
  EXPECT_DOUBLE_EQ(m.position_rev, -12.375);
  EXPECT_TRUE(m.position_valid);
  EXPECT_DOUBLE_EQ(m.sample_playback_cycle, 1234.75);
  EXPECT_EQ(m.orient_state, 2);
  // A signed cell's datagram: the 40-byte trailer (key id, tag, "CNM" 1) after the message.
  for (int i = 0; i < 36; ++i) bytes.push_back(static_cast<uint8_t>(i));
  for (const uint8_t c : std::array<uint8_t, 4>{'C', 'N', 'M', 1}) bytes.push_back(c);
  cnc::lcmt_spindle_status t{};
  ASSERT_TRUE(decode_spindle_status(bytes.data(), bytes.size(), &t));
  EXPECT_DOUBLE_EQ(t.position_rev, -12.375);
  // Neither: a truncated message.
  bytes.resize(20);
  EXPECT_FALSE(decode_spindle_status(bytes.data(), bytes.size(), &t));
}

}  // namespace
}  // namespace cnc::service
