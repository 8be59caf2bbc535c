#include "common/service/spindle_status_msg.h"

#include "common/bus/auth.h"

namespace cnc::service {

cnc::lcmt_spindle_status from_v1(const cnc::lcmt_spindle_status_v1& v) {
  cnc::lcmt_spindle_status m{};
  m.utime = v.utime;
  m.seq = v.seq;
  m.sender = v.sender;
  m.state = v.state;
  m.command_seq = v.command_seq;
  m.at_speed_seq = v.at_speed_seq;
  m.direction = v.direction;
  m.commanded_rpm = v.commanded_rpm;
  m.actual_rpm = v.actual_rpm;
  m.current_a = v.current_a;
  m.error_code = v.error_code;
  m.fault = v.fault;
  m.transactions = v.transactions;
  m.timeouts = v.timeouts;
  m.position_rev = 0;
  m.position_valid = false;
  m.sample_playback_cycle = -1;
  m.orient_state = cnc::lcmt_spindle_status::ORIENT_NONE;
  return m;
}

namespace {
template <class Msg>
bool decode_whole(const void* data, size_t size, Msg* out) {
  try {
    const auto n = static_cast<int>(bus::payload_size(data, size));
    return out->decode(data, 0, n) == n;
  } catch (...) {
    return false;
  }
}
}  // namespace

bool decode_spindle_status(const void* data, size_t size, cnc::lcmt_spindle_status* out) {
  if (decode_whole(data, size, out)) return true;
  cnc::lcmt_spindle_status_v1 v;
  if (!decode_whole(data, size, &v)) return false;
  *out = from_v1(v);
  return true;
}

}  // namespace cnc::service
