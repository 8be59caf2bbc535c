#include "common/drive/link.h"

#include <modbus.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "common/drive/huanyang_frame.h"

namespace cnc::drive {

const char* tx_result_name(TxResult r) {
  switch (r) {
    case TxResult::kOk: return "ok";
    case TxResult::kTimeout: return "timeout";
    case TxResult::kException: return "exception";
    case TxResult::kCrc: return "crc error";
    case TxResult::kLinkLost: return "link lost";
    case TxResult::kOther: return "error";
  }
  return "?";
}

Link::Link(std::string name) : name_(std::move(name)) {}

void Link::set_backoff(double min_s, double max_s) {
  backoff_min_s_ = min_s;
  backoff_max_s_ = std::max(min_s, max_s);
  backoff_s_ = backoff_min_s_;
}

bool Link::ensure_open(double now_s) {
  if (open_) return true;
  if (now_s < next_attempt_s_) return false;
  std::string why;
  const int err = do_open(why);
  if (err == 0) {
    open_ = true;
    backoff_s_ = backoff_min_s_;
    return true;
  }
  last_error_ = "open " + name_ + ": " + why;
  next_attempt_s_ = now_s + backoff_s_;
  backoff_s_ = std::min(backoff_s_ * 2.0, backoff_max_s_);
  return false;
}

void Link::close(double now_s) {
  if (open_) do_close();
  open_ = false;
  next_attempt_s_ = std::max(next_attempt_s_, now_s + backoff_s_);
  backoff_s_ = std::min(backoff_s_ * 2.0, backoff_max_s_);
}

TxResult Link::finish(int err, LinkCounters& c) {
  ++c.transactions;
  if (err == 0) return TxResult::kOk;
  last_error_ = modbus_strerror(err);
  if (detail_[0] != '\0') {
    last_error_.append(": ").append(detail_.data());
    detail_[0] = '\0';
  }
  if (err == ETIMEDOUT) {
    ++c.timeouts;
    discard_input();
    return TxResult::kTimeout;
  }
  if (err == EMBBADCRC) {
    ++c.crc_errors;
    discard_input();
    return TxResult::kCrc;
  }
  if (err > MODBUS_ENOBASE && err <= EMBXGTAR) {
    ++c.exceptions;
    return TxResult::kException;
  }
  if (err == ECONNRESET || err == EPIPE || err == ECONNREFUSED || err == ENOTCONN || err == EBADF || err == EIO ||
      err == ENXIO || err == ENODEV) {
    ++c.other_errors;
    do_close();
    open_ = false;
    return TxResult::kLinkLost;
  }
  ++c.other_errors;
  discard_input();
  return TxResult::kOther;
}

TxResult Link::read_registers(int unit, int addr, int n, uint16_t* dest, LinkCounters& c) {
  if (!open_) return TxResult::kLinkLost;
  return finish(do_read(unit, addr, n, dest), c);
}

TxResult Link::write_register(int unit, int addr, uint16_t value, LinkCounters& c) {
  if (!open_) return TxResult::kLinkLost;
  return finish(do_write1(unit, addr, value), c);
}

TxResult Link::write_registers(int unit, int addr, int n, const uint16_t* src, LinkCounters& c) {
  if (!open_) return TxResult::kLinkLost;
  return finish(do_write(unit, addr, n, src), c);
}

TxResult Link::write_and_read(int unit, int write_addr, int write_n, const uint16_t* src, int read_addr, int read_n,
                              uint16_t* dest, LinkCounters& c) {
  if (!open_) return TxResult::kLinkLost;
  return finish(do_write_read(unit, write_addr, write_n, src, read_addr, read_n, dest), c);
}

TxResult Link::read_coils(int unit, int addr, int n, uint8_t* dest, LinkCounters& c) {
  if (!open_) return TxResult::kLinkLost;
  return finish(do_read_bits(unit, addr, n, dest, false), c);
}

TxResult Link::read_discrete_inputs(int unit, int addr, int n, uint8_t* dest, LinkCounters& c) {
  if (!open_) return TxResult::kLinkLost;
  return finish(do_read_bits(unit, addr, n, dest, true), c);
}

TxResult Link::write_coil(int unit, int addr, bool on, LinkCounters& c) {
  if (!open_) return TxResult::kLinkLost;
  return finish(do_write_bit(unit, addr, on), c);
}

TxResult Link::write_coils(int unit, int addr, int n, const uint8_t* src, LinkCounters& c) {
  if (!open_) return TxResult::kLinkLost;
  return finish(do_write_bits(unit, addr, n, src), c);
}

TxResult Link::read_input_registers(int unit, int addr, int n, uint16_t* dest, LinkCounters& c) {
  if (!open_) return TxResult::kLinkLost;
  return finish(do_read_input_registers(unit, addr, n, dest), c);
}

TxResult Link::exchange_frame(const uint8_t* request, int request_n, uint8_t* reply, int* n, LinkCounters& c) {
  *n = 0;
  if (!open_) return TxResult::kLinkLost;
  int err = do_frame(request, request_n, reply, huanyang::kMaxFrame, n);
  if (err == 0 || err == ETIMEDOUT) {
    const huanyang::Check k = err == 0 ? huanyang::check_reply(request, reply, *n) : huanyang::Check::kNone;
    if (k != huanyang::Check::kOk) {
      huanyang::describe(k, request, reply, *n, detail_.data(), static_cast<int>(detail_.size()));
      err = k == huanyang::Check::kNone ? ETIMEDOUT : k == huanyang::Check::kCrc ? EMBBADCRC : EMBBADDATA;
    }
  } else if (err == EPROTONOSUPPORT) {
    std::snprintf(detail_.data(), detail_.size(), "%s carries no Huanyang frames (a serial line does)", name_.c_str());
  }
  return finish(err, c);
}

int Link::do_read_bits(int, int, int, uint8_t*, bool) { return EMBXILFUN; }
int Link::do_write_bit(int, int, bool) { return EMBXILFUN; }
int Link::do_write_bits(int, int, int, const uint8_t*) { return EMBXILFUN; }
int Link::do_read_input_registers(int, int, int, uint16_t*) { return EMBXILFUN; }
int Link::do_frame(const uint8_t*, int, uint8_t*, int, int*) { return EPROTONOSUPPORT; }

}  // namespace cnc::drive
