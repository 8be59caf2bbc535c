// libFuzzer target: received datagrams through the bus (common/bus/bus.h) on an
// in-process memq:// LCM, with a typed subscriber of every message type of the cell
// (lcmtypes/*.lcm) and a raw one (as the logger), and the signature checks.
//
// Input: the first byte picks the mode, then records follow, each
//   channel byte (which message type's channel) | length (2 bytes, LE) | bytes.
//   mode 0: signing off; every record delivered as it is (the decode path).
//   mode 1: signing on with a fixed test key; records as they are (trailer
//           parsing: unsigned, unknown key, forged).
//   mode 2: signing on; each record is signed with the test key by this target
//           before it is delivered (so the fuzzer reaches the freshness and the
//           replay-window checks and the typed decode after them), and checked by
//           the offline LogVerifier too.
// A program block that decodes is also converted to a program::Block (from_msg).
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_block_request.hpp"
#include "cnc/lcmt_config.hpp"
#include "cnc/lcmt_drive_command.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_interp_input.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_logger_stats.hpp"
#include "cnc/lcmt_monitor_report.hpp"
#include "cnc/lcmt_program_block.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "cnc/lcmt_spindle_command.hpp"
#include "cnc/lcmt_spindle_status.hpp"
#include "cnc/lcmt_io_command.hpp"
#include "cnc/lcmt_io_status.hpp"
#include "cnc/lcmt_joint_status.hpp"
#include "common/bus/auth.h"
#include "common/bus/bus.h"
#include "common/program/block.h"
#include "common/program/block_msg.h"

namespace {
using namespace cnc;

const char* const kChannels[] = {"F.ALARM",     "F.AXIS_STATUS",  "F.BLOCK_REQUEST",  "F.CONFIG",
                                 "F.DRIVE_CMD", "F.HEARTBEAT",    "F.INTERP_INPUT",   "F.INTERP_STATE",
                                 "F.LOGGER",    "F.MONITOR",      "F.PROGRAM_BLOCK",  "F.PROGRAM_CMD",
                                 "F.PROGRAM_STATE", "F.SETPOINTS",     "F.SPINDLE_CMD",    "F.SPINDLE_STATUS",
                                 "F.IO_CMD",        "F.IO_STATUS",      "F.JOINT_STATUS"};
constexpr size_t kNumChannels = sizeof(kChannels) / sizeof(kChannels[0]);

bus::Key test_key() {
  bus::Key k;
  k.id = 0x0c0ffee1;
  for (size_t i = 0; i < k.secret.size(); ++i) k.secret[i] = static_cast<uint8_t>(i * 7 + 1);
  return k;
}

template <class Msg>
void sub(bus::Bus& b, size_t i) {
  b.subscribe<Msg>(kChannels[i], [](const Msg&) {});
}

void subscribe_all(bus::Bus& b) {
  size_t i = 0;
  sub<lcmt_alarm>(b, i++);
  sub<lcmt_axis_status>(b, i++);
  sub<lcmt_block_request>(b, i++);
  sub<lcmt_config>(b, i++);
  sub<lcmt_drive_command>(b, i++);
  sub<lcmt_heartbeat>(b, i++);
  sub<lcmt_interp_input>(b, i++);
  sub<lcmt_interp_state>(b, i++);
  sub<lcmt_logger_stats>(b, i++);
  sub<lcmt_monitor_report>(b, i++);
  b.subscribe<lcmt_program_block>(kChannels[i++], [](const lcmt_program_block& m) {
    program::Block blk;
    (void)program::from_msg(m, 3, &blk);
  });
  sub<lcmt_program_command>(b, i++);
  sub<lcmt_program_state>(b, i++);
  sub<lcmt_setpoint>(b, i++);
  sub<lcmt_spindle_command>(b, i++);
  sub<lcmt_spindle_status>(b, i++);
  sub<lcmt_io_command>(b, i++);
  sub<lcmt_io_status>(b, i++);
  sub<lcmt_joint_status>(b, i++);
  b.subscribe_raw("F\\..*", [](const std::string&, const void* data, size_t size, int64_t) {
    (void)bus::peek_header(data, size);
  });
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const int mode = data[0] % 3;
  bus::Security sec;
  if (mode != 0) {
    sec.enabled = true;
    sec.keys.add(test_key());
    sec.watch = false;
    sec.max_age_s = 1e9;  // about 30 years: fuzzed time stamps near now pass
  }
  bus::Bus b("memq://", 77, 1000, sec);
  subscribe_all(b);
  bus::LogVerifier verifier(sec.keys);
  const bus::Key* key = sec.keys.find(test_key().id);
  std::vector<uint8_t> buf;
  size_t at = 1;
  int records = 0;
  while (at + 3 <= size && records < 64) {
    const size_t ch = data[at] % kNumChannels;
    size_t n = static_cast<size_t>(data[at + 1]) | static_cast<size_t>(data[at + 2]) << 8;
    at += 3;
    if (n > size - at) n = size - at;
    buf.assign(data + at, data + at + n);
    at += n;
    ++records;
    if (mode == 2) {
      buf.resize(n + bus::kTrailerBytes);
      bus::sign(*key, kChannels[ch], buf.data(), n, buf.data() + n);
      (void)verifier.check(kChannels[ch], buf.data(), buf.size());
    }
    (void)b.publish_raw(kChannels[ch], buf.data(), buf.size());
    b.drain();
  }
  return 0;
}
