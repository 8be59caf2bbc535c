#include "common/drive/huanyang_frame.h"

#include <cstdio>

namespace cnc::drive::huanyang {

int encode(uint8_t unit, uint8_t function, const uint8_t* data, int n, uint8_t* frame) {
  frame[0] = unit;
  frame[1] = function;
  frame[2] = static_cast<uint8_t>(n);
  for (int i = 0; i < n; ++i) frame[3 + i] = data[i];
  const uint16_t crc = rtu_crc16(frame, 3 + n);
  frame[3 + n] = static_cast<uint8_t>(crc & 0xFF);
  frame[4 + n] = static_cast<uint8_t>(crc >> 8);
  return 5 + n;
}

int frame_length(const uint8_t* p, int have) {
  if (have < 3) return 0;
  if (p[2] < 1 || p[2] > kMaxData) return -1;
  return 5 + p[2];
}

bool crc_ok(const uint8_t* frame, int n) {
  return n >= kMinFrame && rtu_crc_ok(frame, n);
}

namespace {
// The reply's data length for each request; 0: any of 1 .. kMaxData.
int reply_data_length(uint8_t function) {
  switch (function) {
    case kWriteControlData: return 1;
    case kWriteFrequency: return 2;
    case kReadFunctionData:
    case kWriteFunctionData:
    case kReadControlStatus: return 3;
    default: return 0;
  }
}
}  // namespace

Check check_reply(const uint8_t* request, const uint8_t* reply, int n) {
  if (n <= 0) return Check::kNone;
  const int whole = frame_length(reply, n);
  if (whole < 0) return Check::kLength;
  if (whole == 0 || n < whole) return Check::kShort;
  if (n > whole || !crc_ok(reply, whole)) return Check::kCrc;
  if (reply[0] != request[0]) return Check::kUnit;
  if (reply[1] != request[1]) return Check::kFunction;
  const int want = reply_data_length(request[1]);
  const bool one_byte_pd = request[1] == kReadFunctionData && reply[2] == 2;
  if (want != 0 && reply[2] != want && !one_byte_pd) return Check::kLength;
  const bool echoes = request[1] == kReadFunctionData || request[1] == kWriteFunctionData ||
                      request[1] == kReadControlStatus;
  if (echoes && reply[3] != request[3]) return Check::kEcho;
  return Check::kOk;
}

void describe(Check c, const uint8_t* request, const uint8_t* reply, int n, char* out, int cap) {
  const unsigned unit = request[0], fn = request[1];
  const int whole = n >= 3 ? frame_length(reply, n) : 5 + reply_data_length(request[1]);
  switch (c) {
    case Check::kOk: std::snprintf(out, static_cast<size_t>(cap), "ok"); return;
    case Check::kNone:
      std::snprintf(out, static_cast<size_t>(cap), "no reply from unit %u to function 0x%02X", unit, fn);
      return;
    case Check::kShort:
      std::snprintf(out, static_cast<size_t>(cap), "short reply from unit %u to function 0x%02X: %d of %d bytes", unit,
                    fn, n, whole);
      return;
    case Check::kCrc:
      std::snprintf(out, static_cast<size_t>(cap), "reply from unit %u to function 0x%02X: %d bytes, CRC wrong", unit,
                    fn, n);
      return;
    case Check::kUnit:
      std::snprintf(out, static_cast<size_t>(cap), "reply to function 0x%02X from unit %u, asked unit %u", fn,
                    static_cast<unsigned>(reply[0]), unit);
      return;
    case Check::kFunction:
      std::snprintf(out, static_cast<size_t>(cap), "reply from unit %u with function 0x%02X to function 0x%02X", unit,
                    static_cast<unsigned>(reply[1]), fn);
      return;
    case Check::kEcho:
      std::snprintf(out, static_cast<size_t>(cap), "reply from unit %u to function 0x%02X for %u, asked %u", unit, fn,
                    static_cast<unsigned>(reply[3]), static_cast<unsigned>(request[3]));
      return;
    case Check::kLength:
      std::snprintf(out, static_cast<size_t>(cap), "malformed reply from unit %u to function 0x%02X: %u data bytes",
                    unit, fn, static_cast<unsigned>(reply[2]));
      return;
  }
}

}  // namespace cnc::drive::huanyang
