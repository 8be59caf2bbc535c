#include "common/drive/modbus_link.h"

#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <ctime>
#include <stdexcept>

#include "common/drive/huanyang_frame.h"

namespace cnc::drive {
namespace {
int rc_to_err(int rc) { return rc >= 0 ? 0 : (errno != 0 ? errno : EIO); }
}  // namespace

std::unique_ptr<ModbusLink> ModbusLink::tcp(const std::string& host, int port, double response_timeout_s) {
  modbus_t* ctx = modbus_new_tcp(host.c_str(), port);
  if (ctx == nullptr) throw std::runtime_error("cannot create a Modbus TCP context for " + host);
  return std::unique_ptr<ModbusLink>(
      new ModbusLink("tcp://" + host + ":" + std::to_string(port), ctx, response_timeout_s, false));
}

std::unique_ptr<ModbusLink> ModbusLink::rtu(const std::string& device, int baud, char parity, int stop_bits,
                                            double response_timeout_s) {
  modbus_t* ctx = modbus_new_rtu(device.c_str(), baud, parity, 8, stop_bits);
  if (ctx == nullptr) throw std::runtime_error("cannot create a Modbus RTU context for " + device);
  auto link = std::unique_ptr<ModbusLink>(new ModbusLink(
      "rtu://" + device + "@" + std::to_string(baud) + "-8" + parity + std::to_string(stop_bits), ctx,
      response_timeout_s, true));
  // A character: start bit, 8 data bits, the parity bit, the stop bits.
  link->set_byte_time_s((1 + 8 + (parity == 'N' ? 0 : 1) + stop_bits) / static_cast<double>(baud));
  return link;
}

ModbusLink::ModbusLink(std::string name, modbus_t* ctx, double response_timeout_s, bool serial)
    : Link(std::move(name)), ctx_(ctx), serial_(serial), timeout_s_(std::max(response_timeout_s, 0.001)) {
  const double t = timeout_s_;
  const auto sec = static_cast<uint32_t>(t);
  const auto usec = static_cast<uint32_t>(std::lround((t - sec) * 1e6));
  modbus_set_response_timeout(ctx_, sec, usec);
  // Recovery is ours (discard_input, close and back-off), never libmodbus's sleeps.
  modbus_set_error_recovery(ctx_, MODBUS_ERROR_RECOVERY_NONE);
}

ModbusLink::~ModbusLink() {
  modbus_close(ctx_);
  modbus_free(ctx_);
}

int ModbusLink::do_open(std::string& error) {
  errno = 0;
  if (modbus_connect(ctx_) == 0) {
    if (serial_) modbus_flush(ctx_);
    return 0;
  }
  const int err = errno != 0 ? errno : EIO;
  error = modbus_strerror(err);
  modbus_close(ctx_);
  return err;
}

void ModbusLink::do_close() { modbus_close(ctx_); }

void ModbusLink::discard_input() {
  if (serial_) {
    // A late reply may still be on its way: let the line fall quiet (one response
    // timeout), then drop what came, so it is not taken for the next answer.
    timespec quiet{static_cast<time_t>(timeout_s_), static_cast<long>((timeout_s_ - std::floor(timeout_s_)) * 1e9)};
    nanosleep(&quiet, nullptr);
    modbus_flush(ctx_);
    return;
  }
  // A reply that comes after its timeout would be read as the answer to the next
  // request (a transaction-id mismatch, and the next, and the next): Modbus TCP
  // connections "break" that way. A fresh connection has no stale replies. If it
  // cannot be made, the next transaction fails and the link counts as lost.
  modbus_close(ctx_);
  modbus_connect(ctx_);
}

int ModbusLink::do_read(int unit, int addr, int n, uint16_t* dest) {
  modbus_set_slave(ctx_, unit);
  errno = 0;
  return rc_to_err(modbus_read_registers(ctx_, addr, n, dest));
}

int ModbusLink::do_write1(int unit, int addr, uint16_t value) {
  modbus_set_slave(ctx_, unit);
  errno = 0;
  return rc_to_err(modbus_write_register(ctx_, addr, value));
}

int ModbusLink::do_write(int unit, int addr, int n, const uint16_t* src) {
  modbus_set_slave(ctx_, unit);
  errno = 0;
  return rc_to_err(modbus_write_registers(ctx_, addr, n, src));
}

int ModbusLink::do_write_read(int unit, int waddr, int wn, const uint16_t* src, int raddr, int rn, uint16_t* dest) {
  modbus_set_slave(ctx_, unit);
  errno = 0;
  return rc_to_err(modbus_write_and_read_registers(ctx_, waddr, wn, src, raddr, rn, dest));
}

int ModbusLink::do_read_bits(int unit, int addr, int n, uint8_t* dest, bool discrete_inputs) {
  modbus_set_slave(ctx_, unit);
  errno = 0;
  return rc_to_err(discrete_inputs ? modbus_read_input_bits(ctx_, addr, n, dest) : modbus_read_bits(ctx_, addr, n, dest));
}

int ModbusLink::do_write_bit(int unit, int addr, bool on) {
  modbus_set_slave(ctx_, unit);
  errno = 0;
  return rc_to_err(modbus_write_bit(ctx_, addr, on ? 1 : 0));
}

int ModbusLink::do_write_bits(int unit, int addr, int n, const uint8_t* src) {
  modbus_set_slave(ctx_, unit);
  errno = 0;
  return rc_to_err(modbus_write_bits(ctx_, addr, n, src));
}

int ModbusLink::do_read_input_registers(int unit, int addr, int n, uint16_t* dest) {
  modbus_set_slave(ctx_, unit);
  errno = 0;
  return rc_to_err(modbus_read_input_registers(ctx_, addr, n, dest));
}

int ModbusLink::do_frame(const uint8_t* request, int n, uint8_t* reply, int cap, int* got) {
  *got = 0;
  if (!serial_) return EPROTONOSUPPORT;
  const int fd = modbus_get_socket(ctx_);
  if (fd < 0) return EBADF;
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + std::chrono::microseconds(std::lround(timeout_s_ * 1e6));
  auto wait = [&](short events) {
    for (;;) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
      if (left < 0) return 0;
      pollfd p{fd, events, 0};
      const int r = ::poll(&p, 1, static_cast<int>(left) + 1);
      if (r >= 0) return r;
      if (errno != EINTR) return -1;
    }
  };
  for (int sent = 0; sent < n;) {
    const ssize_t w = ::write(fd, request + sent, static_cast<size_t>(n - sent));
    if (w > 0) {
      sent += static_cast<int>(w);
      continue;
    }
    if (w < 0 && errno != EAGAIN && errno != EINTR) return errno;
    const int r = wait(POLLOUT);
    if (r < 0) return errno;
    if (r == 0) return ETIMEDOUT;
  }
  // The reply's length is in its third byte: read the header, then the rest.
  for (;;) {
    const int whole = huanyang::frame_length(reply, *got);
    if (whole < 0 || (whole > 0 && *got >= whole)) return 0;
    const int want = std::min(whole > 0 ? whole - *got : 3 - *got, cap - *got);
    if (want <= 0) return 0;
    const int r = wait(POLLIN);
    if (r < 0) return errno;
    if (r == 0) return 0;  // what came in time (none: a timeout), judged by the caller
    const ssize_t k = ::read(fd, reply + *got, static_cast<size_t>(want));
    if (k > 0) {
      *got += static_cast<int>(k);
    } else if (k == 0 || (errno != EAGAIN && errno != EINTR)) {
      return k == 0 ? EIO : errno;
    }
  }
}

}  // namespace cnc::drive
