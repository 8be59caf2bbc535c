#pragma once
// One Modbus connection (a TCP endpoint or a serial line) shared by the drives
// behind it, which are told apart by unit id. The link is kept apart from the
// register transactions (as LinuxCNC's mb2hal does): a failed transaction is
// counted and classified, never fatal; a broken connection is closed and retried
// with exponential back-off by the caller's schedule.
#include <modbus.h>

#include <cstdint>
#include <string>

namespace cnc::drive {

struct LinkCounters {
  int64_t transactions = 0;
  int64_t timeouts = 0;
  int64_t exceptions = 0;  // the drive answered with a Modbus exception
  int64_t crc_errors = 0;
  int64_t other_errors = 0;
  int64_t reconnects = 0;
};

enum class TxResult : int8_t { kOk, kTimeout, kException, kCrc, kLinkLost, kOther };

class ModbusLink {
 public:
  // TCP link.
  ModbusLink(std::string host, int port, double response_timeout_s);
  ~ModbusLink();
  ModbusLink(const ModbusLink&) = delete;
  ModbusLink& operator=(const ModbusLink&) = delete;

  // Connects if not connected and the back-off allows; returns whether connected.
  bool ensure_connected(double now_s);
  bool connected() const { return connected_; }
  void disconnect();
  const std::string& name() const { return name_; }

  TxResult write_register(int unit, int addr, uint16_t value, LinkCounters& c);
  TxResult write_and_read(int unit, int write_addr, int write_n, const uint16_t* src, int read_addr, int read_n,
                          uint16_t* dest, LinkCounters& c);
  TxResult read_registers(int unit, int addr, int n, uint16_t* dest, LinkCounters& c);
  std::string last_error() const { return last_error_; }

 private:
  TxResult classify(int rc, LinkCounters& c);
  modbus_t* ctx_ = nullptr;
  std::string name_;
  bool connected_ = false;
  double next_attempt_s_ = 0;
  double backoff_s_ = 0.1;
  bool ever_connected_ = false;
  std::string last_error_;
};

}  // namespace cnc::drive
