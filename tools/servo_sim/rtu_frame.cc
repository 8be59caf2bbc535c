#include "tools/servo_sim/rtu_frame.h"

#include "common/drive/rtu_crc.h"

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

bool rtu_crc_ok(const uint8_t* frame, int n) { return n >= 4 && drive::rtu_crc_ok(frame, n); }

}  // namespace cnc::servo_sim
