#pragma once
// The Huanyang (HY series) VFD's frames on RS-485: not Modbus registers but
// function codes of their own, each frame
//   unit, function, length n, n data bytes, CRC-16 (Modbus RTU's: low byte first)
// for requests and replies alike (LinuxCNC's hy_vfd speaks the same frames):
//   0x01 read function data   PDnnn, 0, 0           -> PDnnn, value (2 bytes, high first; some
//                                                      drives answer a one-byte value with length 2)
//   0x02 write function data  PDnnn, value          -> the same echoed
//   0x03 write control data   command (1 byte)      -> the drive's status byte (CNST)
//   0x04 read control status  index (1 byte)        -> index, value (2 bytes, high first)
//   0x05 write the frequency  value (2 bytes)       -> the same echoed
// libmodbus cannot carry them: it frames a reply by its Modbus function code, and
// 0x05's reply (7 bytes) is shorter than Modbus's write-single-coil reply (8), so
// it waits for a byte that never comes. The link frames them itself
// (Link::exchange_frame). Pure functions: no allocation, no I/O.
#include <cstdint>

#include "common/drive/rtu_crc.h"

namespace cnc::drive::huanyang {

enum Function : uint8_t {
  kReadFunctionData = 0x01,
  kWriteFunctionData = 0x02,
  kWriteControlData = 0x03,
  kReadControlStatus = 0x04,
  kWriteFrequency = 0x05,
};

inline constexpr int kMaxData = 8;
inline constexpr int kMaxFrame = 3 + kMaxData + 2;
inline constexpr int kMinFrame = 3 + 1 + 2;

// A frame of `n` data bytes into `frame` (kMaxFrame bytes); returns its length.
int encode(uint8_t unit, uint8_t function, const uint8_t* data, int n, uint8_t* frame);
// The whole frame's length from its first `have` bytes: 0 while fewer than three
// are in, -1 when the length byte is out of range.
int frame_length(const uint8_t* p, int have);
bool crc_ok(const uint8_t* frame, int n);

// A reply to `request` (both whole frames, the request well formed).
// kEcho: a reply to 0x01, 0x02 or 0x04 that names another PD or index than asked.
enum class Check : int8_t { kOk, kNone, kShort, kCrc, kUnit, kFunction, kLength, kEcho };
Check check_reply(const uint8_t* request, const uint8_t* reply, int n);
// One line naming what is wrong with a reply that is not kOk, e.g. "short reply from
// unit 1 to function 0x04: 5 of 8 bytes"; into `out` (NUL-terminated, cut to `cap`).
void describe(Check c, const uint8_t* request, const uint8_t* reply, int n, char* out, int cap);

// The value of a two-byte field, high byte first.
inline uint16_t be16(const uint8_t* p) { return static_cast<uint16_t>((p[0] << 8) | p[1]); }

}  // namespace cnc::drive::huanyang
