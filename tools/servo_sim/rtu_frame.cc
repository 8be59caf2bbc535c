#include "tools/servo_sim/rtu_frame.h"

namespace cnc::servo_sim {

int rtu_request_length(const uint8_t* buf, int n) {
  if (n < 2) return 0;
  switch (buf[1]) {
    case 1: case 2: case 3: case 4: case 5: case 6: return 8;
    case 15: case 16: return n < 7 ? 0 : 9 + buf[6];
    case 23: return n < 11 ? 0 : 13 + buf[10];
    default: return -1;
  }
}

uint16_t modbus_crc16(const uint8_t* buf, int n) {
  uint16_t crc = 0xFFFF;
  for (int i = 0; i < n; ++i) {
    crc ^= buf[i];
    for (int b = 0; b < 8; ++b) crc = (crc & 1) ? static_cast<uint16_t>((crc >> 1) ^ 0xA001) : static_cast<uint16_t>(crc >> 1);
  }
  return crc;
}

bool rtu_crc_ok(const uint8_t* frame, int n) {
  if (n < 4) return false;
  const uint16_t crc = modbus_crc16(frame, n - 2);
  return frame[n - 2] == (crc & 0xFF) && frame[n - 1] == (crc >> 8);
}

}  // namespace cnc::servo_sim
