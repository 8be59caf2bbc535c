// The drive layer end to end on the loopback link: every shipped profile's state
// machine (master side against the drive side) enables, follows, disables and
// resets a fault; the cyclic exchange takes as few transactions as its profile
// allows and puts 32-bit values on the wire in the profile's word order; failed
// transactions are counted by kind and never fatal; a lost link is reopened only
// on the back-off schedule.
#include <gtest/gtest.h>
#include <modbus.h>

#include <string>

#include "common/drive/cia402_profile.h"
#include "common/drive/drive_io.h"
#include "common/drive/drive_profile.h"
#include "common/drive/link_factory.h"
#include "common/drive/loopback_link.h"

namespace cnc::drive {
namespace {

const std::string kDrives = std::string(CNC_SOURCE_DIR) + "/config/drives/";

struct Rig {
  explicit Rig(const std::string& name, double start_mm = 12.5)
      : profile(load_drive_profile(kDrives + name + ".yaml")), io(profile, 3, link) {
    link.add_drive(3, profile, start_mm);
    EXPECT_TRUE(link.ensure_open(0.0));
  }
  // Cyclic rounds as the bridge runs them: exchange (holding the target where the
  // drive is until it is enabled), then one state-machine step.
  int rounds_until_enabled(Goal goal, int max_rounds = 20) {
    for (int i = 0; i < max_rounds; ++i) {
      const double hold = io.have_status() ? io.actual_mm() : 0.0;
      EXPECT_EQ(io.exchange(io.have_status() ? &hold : nullptr, c), TxResult::kOk);
      if (io.status().enabled == (goal == Goal::kEnable) && !io.status().fault) return i;
      EXPECT_EQ(io.control(goal, c), TxResult::kOk);
    }
    return -1;
  }
  DriveProfile profile;
  LoopbackLink link;
  DriveIo io;
  LinkCounters c;
};

class EveryProfile : public ::testing::TestWithParam<std::string> {};

TEST_P(EveryProfile, EnablesFollowsDisablesAndResetsAFault) {
  Rig r(GetParam());
  DriveEmulator& drive = *r.link.drive(3);
  EXPECT_FALSE(drive.follows());
  const int rounds = r.rounds_until_enabled(Goal::kEnable);
  ASSERT_GE(rounds, 0) << GetParam() << " never enabled; drive state " << drive.state_name();
  EXPECT_TRUE(drive.follows());
  EXPECT_NEAR(r.io.actual_mm(), 12.5, 1e-3);
  // Follows the target: the actual position read answers the previous command.
  for (double t : {12.6, 12.7, 12.8}) ASSERT_EQ(r.io.exchange(&t, r.c), TxResult::kOk);
  EXPECT_NEAR(r.io.actual_mm(), 12.7, 1e-3);
  const double t = 12.8;
  ASSERT_EQ(r.io.exchange(&t, r.c), TxResult::kOk);
  EXPECT_NEAR(r.io.actual_mm(), 12.8, 1e-3);
  // A drive fault: the master sees it and the enable goal resets it first.
  drive.inject_fault(0x7305);
  ASSERT_EQ(r.io.exchange(nullptr, r.c), TxResult::kOk);
  EXPECT_TRUE(r.io.status().fault);
  EXPECT_FALSE(r.io.status().enabled);
  if (r.profile.has(Role::kErrorCode)) {
    EXPECT_EQ(r.io.error_code(), 0x7305);
  }
  ASSERT_GE(r.rounds_until_enabled(Goal::kEnable), 0) << "not re-enabled after a fault: " << drive.state_name();
  EXPECT_TRUE(drive.follows());
  ASSERT_GE(r.rounds_until_enabled(Goal::kDisable), 0);
  EXPECT_FALSE(drive.follows());
  EXPECT_EQ(r.c.timeouts + r.c.exceptions + r.c.crc_errors + r.c.other_errors, 0);
}

INSTANTIATE_TEST_SUITE_P(Shipped, EveryProfile, ::testing::Values("sim", "cia402_modbus", "leadshine_el"));

TEST(Cia402, EnableSequenceIsModeThenShutdownSwitchOnEnableOperation) {
  Rig r("cia402_modbus");
  DriveEmulator& drive = *r.link.drive(3);
  std::vector<std::string> states;
  std::vector<int> modes;
  for (int i = 0; i < 8 && !drive.follows(); ++i) {
    const double hold = r.io.have_status() ? r.io.actual_mm() : 0.0;
    ASSERT_EQ(r.io.exchange(r.io.have_status() ? &hold : nullptr, r.c), TxResult::kOk);
    ASSERT_EQ(r.io.control(Goal::kEnable, r.c), TxResult::kOk);
    states.push_back(drive.state_name());
    modes.push_back(drive.state().mode);
  }
  const std::vector<std::string> expected = {"switch on disabled", "ready to switch on", "switched on",
                                             "operation enabled"};
  EXPECT_EQ(states, expected);
  EXPECT_EQ(modes.front(), 8);  // cyclic synchronous position, written before the first transition
  // Fault reset is a rising edge of bit 7: after a 0x80 the master writes 0 before the next 0x80.
  drive.inject_fault(0x2310);
  ASSERT_EQ(r.io.exchange(nullptr, r.c), TxResult::kOk);
  EXPECT_EQ(cia402::state_of(r.io.statusword()), cia402::kFault);
  ASSERT_EQ(r.io.control(Goal::kFaultReset, r.c), TxResult::kOk);
  EXPECT_STREQ(drive.state_name(), "switch on disabled");
}

TEST(DriveIo, TransactionsPerExchangeFollowTheProfile) {
  EXPECT_EQ(Rig("sim").io.transactions_per_exchange(), 1);            // function 23, reads 1..7 in one
  EXPECT_EQ(Rig("cia402_modbus").io.transactions_per_exchange(), 2);  // 23 with the statusword, 3 for the position
  EXPECT_EQ(Rig("leadshine_el").io.transactions_per_exchange(), 2);   // 16 for the target, 3 for the monitor block
  Rig r("leadshine_el");
  const double t = 12.5;
  ASSERT_EQ(r.io.exchange(nullptr, r.c), TxResult::kOk);
  EXPECT_EQ(r.c.transactions, 1);
  ASSERT_EQ(r.io.exchange(&t, r.c), TxResult::kOk);
  EXPECT_EQ(r.c.transactions, 3);
}

TEST(DriveIo, WordOrderOnTheWire) {
  Rig ls("leadshine_el", 0.0);
  const double t = -100.0;  // -100000 counts = 0xFFFE7960, high word first at 0x6201
  ASSERT_EQ(ls.io.exchange(&t, ls.c), TxResult::kOk);
  uint16_t w[2];
  ASSERT_EQ(ls.link.drive(3)->read(0x6201, 2, w), 0);
  EXPECT_EQ(w[0], 0xFFFE);
  EXPECT_EQ(w[1], 0x7960);
  Rig cia("cia402_modbus", 0.0);
  const double u = 1.0;  // 26214 counts = 0x00006666, low word first at 0x607A
  ASSERT_EQ(cia.io.exchange(&u, cia.c), TxResult::kOk);
  ASSERT_EQ(cia.link.drive(3)->read(0x607A, 2, w), 0);
  EXPECT_EQ(w[0], 0x6666);
  EXPECT_EQ(w[1], 0x0000);
}

TEST(Link, FailedTransactionsAreCountedByKindAndNotFatal) {
  Rig r("sim");
  r.link.inject_exceptions(3, MODBUS_EXCEPTION_SLAVE_OR_SERVER_BUSY);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(r.io.exchange(nullptr, r.c), TxResult::kException);
  r.link.inject_timeouts(2);
  for (int i = 0; i < 2; ++i) EXPECT_EQ(r.io.exchange(nullptr, r.c), TxResult::kTimeout);
  EXPECT_EQ(r.io.exchange(nullptr, r.c), TxResult::kOk);
  EXPECT_EQ(r.c.exceptions, 3);
  EXPECT_EQ(r.c.timeouts, 2);
  EXPECT_EQ(r.c.transactions, 6);
  EXPECT_TRUE(r.link.is_open());
  // A unit nobody answers for times out.
  DriveIo ghost(r.profile, 9, r.link);
  EXPECT_EQ(ghost.exchange(nullptr, r.c), TxResult::kTimeout);
}

TEST(Link, LostLinkIsReopenedOnTheBackOffSchedule) {
  Rig r("sim");
  r.link.set_backoff(0.1, 0.4);
  r.link.set_reachable(false);
  EXPECT_EQ(r.io.exchange(nullptr, r.c), TxResult::kLinkLost);
  EXPECT_FALSE(r.link.is_open());
  EXPECT_EQ(r.io.exchange(nullptr, r.c), TxResult::kLinkLost);  // no transaction on a closed link
  EXPECT_EQ(r.c.transactions, 1);
  // Attempts at 1.0 (fails; next in 0.1 s), 1.1 (fails; next in 0.2 s), then not before 1.3.
  EXPECT_FALSE(r.link.ensure_open(1.0));
  EXPECT_FALSE(r.link.ensure_open(1.05));
  EXPECT_FALSE(r.link.ensure_open(1.1));
  r.link.set_reachable(true);
  EXPECT_FALSE(r.link.ensure_open(1.29));  // reachable, but still backing off
  EXPECT_TRUE(r.link.ensure_open(1.31));
  EXPECT_EQ(r.io.exchange(nullptr, r.c), TxResult::kOk);
}

// One factory for every transport the config accepts; each link is made closed.
TEST(LinkFactory, MakesTheLinkOfEachTransport) {
  config::DriveConfig d;
  d.transport = "modbus_tcp";
  d.host = "127.0.0.1";
  d.port = 1502;
  EXPECT_EQ(make_link(d)->name(), "tcp://127.0.0.1:1502");
  d.transport = "modbus_rtu";
  d.device = "/tmp/none";
  d.baud = 19200;
  d.parity = "even";
  d.stop_bits = 1;
  EXPECT_EQ(make_link(d)->name(), "rtu:///tmp/none@19200-8E1");
  d.transport = "loopback";
  auto lb = make_link(d);
  EXPECT_NE(dynamic_cast<LoopbackLink*>(lb.get()), nullptr);
  EXPECT_FALSE(lb->is_open());
  for (const auto& [t, name] : kTransports) {
    EXPECT_EQ(transport_named(name), t);
    EXPECT_EQ(transport_name(t), name);
  }
  d.transport = "ethercat";
  EXPECT_THROW(make_link(d), std::invalid_argument);
}

}  // namespace
}  // namespace cnc::drive
