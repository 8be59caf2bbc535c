// libFuzzer target: our handling of Modbus responses. libmodbus parses the TCP and
// RTU frames (function code, byte count, CRC, transaction id) and hands us either
// the register values or an error code; this target stands a Link in for libmodbus
// whose every transaction returns what the fuzzer says: registers with any values,
// or any error a libmodbus link can give (timeouts, exceptions, bad CRC, bad data,
// a lost connection, unknown errno values). It drives DriveIo (the cyclic exchange
// and the state-machine steps of every shipped drive profile: sim, cia402 (TCP and
// RTU), leadshine) and reads back status, position, following error and error code.
//
// Input: byte 0 picks the profile; then per round one op byte (exchange with or
// without a target, a control step toward disable / enable / fault reset, forget),
// a target (8 bytes, a double) where one is written, and per transaction a result
// byte and, on success, 2 bytes per register read.
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <modbus.h>
#include <string>
#include <vector>

#include "common/drive/drive_io.h"
#include "common/drive/drive_profile.h"
#include "common/drive/link.h"

namespace {
using namespace cnc::drive;

struct Input {
  const uint8_t* p;
  size_t n;
  size_t at = 0;
  bool empty() const { return at >= n; }
  uint8_t byte() { return at < n ? p[at++] : 0; }
  uint16_t word() { return static_cast<uint16_t>(byte() << 8 | byte()); }
};

const int kErrors[] = {ETIMEDOUT,  EMBXILFUN,  EMBXILADD,  EMBXILVAL, EMBXSFAIL, EMBXACK,     EMBXSBUSY,
                       EMBXNACK,   EMBXMEMPAR, EMBXGPATH,  EMBXGTAR,  EMBBADCRC, EMBBADDATA,  EMBBADEXC,
                       EMBUNKEXC,  EMBMDATA,   EMBBADSLAVE, ECONNRESET, EPIPE,   ECONNREFUSED, ENOTCONN,
                       EBADF,      EIO,        ENXIO,      ENODEV,    EINVAL,    EAGAIN,      12345};

class FuzzLink final : public Link {
 public:
  explicit FuzzLink(Input& in) : Link("fuzz://"), in_(in) {}

 private:
  int result() {
    if (in_.empty()) return ETIMEDOUT;
    const uint8_t b = in_.byte();
    if (b < 192) return 0;
    return kErrors[(b - 192) % (sizeof(kErrors) / sizeof(kErrors[0]))];
  }
  static void check(int addr, int n) {
    // Modbus: at most 125 registers per read, 123 per write, addresses 16-bit.
    if (n < 1 || n > 125 || addr < 0 || addr + n > 65536) std::abort();
  }
  int do_open(std::string& error) override {
    if (!in_.empty() && in_.byte() >= 240) {
      error = "connection refused (fuzz)";
      return ECONNREFUSED;
    }
    return 0;
  }
  void do_close() override {}
  int do_read(int, int addr, int n, uint16_t* dest) override {
    check(addr, n);
    const int r = result();
    if (r == 0)
      for (int i = 0; i < n; ++i) dest[i] = in_.word();
    return r;
  }
  int do_write1(int, int addr, uint16_t) override {
    check(addr, 1);
    return result();
  }
  int do_write(int, int addr, int n, const uint16_t*) override {
    check(addr, n);
    return result();
  }
  int do_write_read(int, int waddr, int wn, const uint16_t*, int raddr, int rn, uint16_t* dest) override {
    check(waddr, wn);
    check(raddr, rn);
    const int r = result();
    if (r == 0)
      for (int i = 0; i < rn; ++i) dest[i] = in_.word();
    return r;
  }
  Input& in_;
};

const std::vector<DriveProfile>& profiles() {
  static const std::vector<DriveProfile> p = [] {
    std::vector<DriveProfile> v;
    for (const char* name : {"sim", "cia402_modbus", "leadshine_el"})
      v.push_back(load_drive_profile(std::string(CNC_SOURCE_DIR) + "/config/drives/" + name + ".yaml"));
    return v;
  }();
  return p;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  Input in{data, size};
  const DriveProfile& profile = profiles()[in.byte() % profiles().size()];
  FuzzLink link(in);
  link.set_backoff(0.0, 0.0);
  DriveIo io(profile, 1, link);
  LinkCounters c;
  double now = 0;
  for (int round = 0; round < 200 && !in.empty(); ++round) {
    now += 0.004;
    if (!link.ensure_open(now)) continue;
    const uint8_t op = in.byte();
    switch (op % 6) {
      case 0: (void)io.exchange(nullptr, c); break;
      case 1: {
        double t = 0;
        uint8_t raw[8];
        for (uint8_t& b : raw) b = in.byte();
        std::memcpy(&t, raw, sizeof t);
        (void)io.exchange(&t, c);
        break;
      }
      case 2: (void)io.control(Goal::kDisable, c); break;
      case 3: (void)io.control(Goal::kEnable, c); break;
      case 4: (void)io.control(Goal::kFaultReset, c); break;
      case 5: io.forget(); break;
    }
    if (!link.is_open()) io.forget();
    const DriveStatus st = io.status();
    (void)st;
    (void)io.actual_mm();
    (void)io.written_mm();
    (void)io.error_code();
    (void)io.drive_following_error_mm();
    (void)io.transactions_per_exchange();
  }
  return 0;
}
