#pragma once
// Modbus RTU request framing for the simulator's serial server. libmodbus's RTU
// server answers one slave id per context and drops the rest; a line with several
// drives needs every request, so the simulator frames the requests itself (length
// from the function code, CRC-16) and answers with modbus_reply per unit.
#include <cstdint>

namespace cnc::servo_sim {

// The length of the request at `buf` (unit id first) once its length is known
// from the bytes there; 0 while more bytes are needed; -1 for a function the
// simulator does not frame.
int rtu_request_length(const uint8_t* buf, int n);
// A whole request (at least unit, function and CRC) whose last two bytes are the
// CRC-16 of the rest (low byte first).
bool rtu_crc_ok(const uint8_t* frame, int n);

}  // namespace cnc::servo_sim
