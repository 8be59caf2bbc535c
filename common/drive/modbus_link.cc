#include "common/drive/modbus_link.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <stdexcept>

namespace cnc::drive {

ModbusLink::ModbusLink(std::string host, int port, double response_timeout_s)
    : name_("tcp://" + host + ":" + std::to_string(port)) {
  ctx_ = modbus_new_tcp(host.c_str(), port);
  if (ctx_ == nullptr) throw std::runtime_error("cannot create Modbus TCP context for " + name_);
  const double t = std::max(response_timeout_s, 0.001);
  const auto sec = static_cast<uint32_t>(t);
  const auto usec = static_cast<uint32_t>(std::lround((t - sec) * 1e6));
  modbus_set_response_timeout(ctx_, sec, usec);
}

ModbusLink::~ModbusLink() {
  if (ctx_ != nullptr) {
    modbus_close(ctx_);
    modbus_free(ctx_);
  }
}

bool ModbusLink::ensure_connected(double now_s) {
  if (connected_) return true;
  if (now_s < next_attempt_s_) return false;
  if (modbus_connect(ctx_) == 0) {
    connected_ = true;
    backoff_s_ = 0.1;
    last_error_.clear();
    return true;
  }
  last_error_ = std::string("connect to ") + name_ + ": " + modbus_strerror(errno);
  next_attempt_s_ = now_s + backoff_s_;
  backoff_s_ = std::min(backoff_s_ * 2.0, 2.0);
  return false;
}

void ModbusLink::disconnect() {
  if (connected_) modbus_close(ctx_);
  connected_ = false;
}

TxResult ModbusLink::classify(int rc, LinkCounters& c) {
  ++c.transactions;
  if (rc >= 0) return TxResult::kOk;
  const int err = errno;
  last_error_ = modbus_strerror(err);
  if (err == ETIMEDOUT) {
    ++c.timeouts;
    return TxResult::kTimeout;
  }
  if (err == EMBBADCRC) {
    ++c.crc_errors;
    return TxResult::kCrc;
  }
  if (err >= MODBUS_ENOBASE && err <= EMBXGTAR) {
    ++c.exceptions;
    return TxResult::kException;
  }
  if (err == ECONNRESET || err == EPIPE || err == ECONNREFUSED || err == ENOTCONN || err == EBADF) {
    ++c.other_errors;
    disconnect();
    return TxResult::kLinkLost;
  }
  ++c.other_errors;
  return TxResult::kOther;
}

TxResult ModbusLink::write_register(int unit, int addr, uint16_t value, LinkCounters& c) {
  if (!connected_) return TxResult::kLinkLost;
  modbus_set_slave(ctx_, unit);
  return classify(modbus_write_register(ctx_, addr, value), c);
}

TxResult ModbusLink::write_and_read(int unit, int write_addr, int write_n, const uint16_t* src, int read_addr,
                                    int read_n, uint16_t* dest, LinkCounters& c) {
  if (!connected_) return TxResult::kLinkLost;
  modbus_set_slave(ctx_, unit);
  return classify(modbus_write_and_read_registers(ctx_, write_addr, write_n, src, read_addr, read_n, dest), c);
}

TxResult ModbusLink::read_registers(int unit, int addr, int n, uint16_t* dest, LinkCounters& c) {
  if (!connected_) return TxResult::kLinkLost;
  modbus_set_slave(ctx_, unit);
  return classify(modbus_read_registers(ctx_, addr, n, dest), c);
}

}  // namespace cnc::drive
