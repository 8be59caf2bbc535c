// libFuzzer target: the Huanyang frames read off the wire (huanyang_frame.h), which
// the link frames itself (no libmodbus). Two ends:
//  * the master: a Link whose every frame exchange answers with the fuzzer's bytes
//    (any length up to a whole frame, any content, or an error), driving the spindle
//    device (HuanyangSpindleDevice: its setup reads, frequency, command and status
//    reads) through Link::exchange_frame's checks; every value it reports is finite;
//  * the drive: the emulator's answer_frame (the simulator's side) on fuzzed requests,
//    whose replies must be whole, well-formed frames.
//
// Input: byte 0 chooses the end; the master then takes per exchange an op byte
// (read-only exchange, a command with a frequency, forget) and per frame a length
// byte and that many bytes; the drive takes frames of a length byte and its bytes.
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include "common/drive/drive_profile.h"
#include "common/drive/huanyang_device.h"
#include "common/drive/huanyang_frame.h"
#include "common/drive/link.h"
#include "common/drive/vfd_emulator.h"

namespace {
using namespace cnc::drive;

struct Input {
  const uint8_t* p;
  size_t n;
  size_t at = 0;
  bool empty() const { return at >= n; }
  uint8_t byte() { return at < n ? p[at++] : 0; }
};

const DriveProfile& profile() {
  static const DriveProfile p = load_drive_profile(std::string(CNC_SOURCE_DIR) + "/config/drives/huanyang.yaml");
  return p;
}

class FuzzLink final : public Link {
 public:
  explicit FuzzLink(Input& in) : Link("fuzz://"), in_(in) {}

 private:
  int do_open(std::string&) override { return 0; }
  void do_close() override {}
  int do_read(int, int, int, uint16_t*) override { return EIO; }
  int do_write1(int, int, uint16_t) override { return EIO; }
  int do_write(int, int, int, const uint16_t*) override { return EIO; }
  int do_write_read(int, int, int, const uint16_t*, int, int, uint16_t*) override { return EIO; }
  int do_frame(const uint8_t* request, int n, uint8_t* reply, int cap, int* got) override {
    if (n < huanyang::kMinFrame || n > huanyang::kMaxFrame || !huanyang::crc_ok(request, n)) std::abort();
    const uint8_t len = in_.byte();
    if (len >= 240) return (len & 1) ? EIO : ETIMEDOUT;
    // A reply as the fuzzer says; with bit 7 its CRC made right (to reach the checks after it).
    *got = len % (cap + 1);
    for (int i = 0; i < *got; ++i) reply[i] = in_.byte();
    if ((len & 0x80) && *got >= huanyang::kMinFrame) {
      const uint16_t crc = rtu_crc16(reply, *got - 2);
      reply[*got - 2] = static_cast<uint8_t>(crc & 0xFF);
      reply[*got - 1] = static_cast<uint8_t>(crc >> 8);
    }
    return 0;
  }
  Input& in_;
};

void master(Input& in) {
  FuzzLink link(in);
  link.set_backoff(0.0, 0.0);
  HuanyangSpindleDevice dev(profile(), 1, link, 400.0, 60.0);
  ProcessImage image;
  const std::size_t s = image.add(dev.layout());
  LinkCounters c;
  double now = 0;
  for (int round = 0; round < 100 && !in.empty(); ++round) {
    now += 0.01;
    if (!link.ensure_open(now)) continue;
    const uint8_t op = in.byte();
    if (op % 4 == 3) {
      dev.forget(image.inputs(s));
      continue;
    }
    put_pdo(image.outputs(s), SpindleOutputs{op % 4 != 0, static_cast<int8_t>(op % 3 - 1), (op >> 2) * 7.5});
    (void)dev.exchange(image.outputs(s), image.inputs(s), c);
    const auto r = get_pdo<SpindleInputs>(image.inputs(s));
    if (!std::isfinite(r.output_hz) || !std::isfinite(r.current_a)) std::abort();
    if (std::memchr(r.setup_error.data(), '\0', r.setup_error.size()) == nullptr) std::abort();
  }
}

void drive(Input& in) {
  cnc::config::SpindleSimConfig sim;
  VfdEmulator vfd(profile(), sim, 400.0, 60.0);
  uint8_t request[64], reply[huanyang::kMaxFrame];
  while (!in.empty()) {
    const int n = in.byte() % 20;
    for (int i = 0; i < n; ++i) request[i] = in.byte();
    if (n >= huanyang::kMinFrame && (in.byte() & 1)) {
      const uint16_t crc = rtu_crc16(request, n - 2);
      request[n - 2] = static_cast<uint8_t>(crc & 0xFF);
      request[n - 1] = static_cast<uint8_t>(crc >> 8);
    }
    const int m = vfd.answer_frame(request, n, reply);
    if (m == 0) continue;
    if (m != huanyang::frame_length(reply, m) || !huanyang::crc_ok(reply, m) || reply[0] != request[0] ||
        reply[1] != request[1] || huanyang::check_reply(request, reply, m) != huanyang::Check::kOk)
      std::abort();
    vfd.step(0.01);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  Input in{data, size};
  if (in.byte() & 1) {
    drive(in);
  } else {
    master(in);
  }
  return 0;
}
