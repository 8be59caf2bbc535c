#pragma once
// Modbus RTU's CRC-16 (polynomial 0xA001 reflected, initial 0xFFFF; sent low byte
// first): Modbus RTU frames and the Huanyang VFD's own frames carry it alike.
#include <cstdint>

namespace cnc::drive {

inline uint16_t rtu_crc16(const uint8_t* p, int n) {
  uint16_t crc = 0xFFFF;
  for (int i = 0; i < n; ++i) {
    crc ^= p[i];
    for (int b = 0; b < 8; ++b) crc = (crc & 1) ? static_cast<uint16_t>((crc >> 1) ^ 0xA001) : static_cast<uint16_t>(crc >> 1);
  }
  return crc;
}

// The frame's last two bytes are the CRC of the bytes before them.
inline bool rtu_crc_ok(const uint8_t* frame, int n) {
  if (n < 2) return false;
  const uint16_t crc = rtu_crc16(frame, n - 2);
  return frame[n - 2] == (crc & 0xFF) && frame[n - 1] == (crc >> 8);
}

}  // namespace cnc::drive
