#pragma once
// A Modbus link: one connection (a TCP endpoint, a serial line, or the in-process
// loopback) shared by the drives behind it, told apart by unit id. The link is
// kept apart from the register transactions (DriveIo) as LinuxCNC's mb2hal keeps
// them: a failed transaction is counted by kind and is never fatal; a broken
// connection is closed and reopened with exponential back-off.
#include <array>
#include <cstdint>
#include <string>

namespace cnc::drive {

struct LinkCounters {
  int64_t transactions = 0;
  int64_t timeouts = 0;
  int64_t exceptions = 0;  // the drive answered with a Modbus exception
  int64_t crc_errors = 0;
  int64_t other_errors = 0;  // malformed or mismatched answers, I/O errors
  int64_t reconnects = 0;    // the drive answered again after its link was lost
};

enum class TxResult : int8_t { kOk, kTimeout, kException, kCrc, kLinkLost, kOther };
const char* tx_result_name(TxResult r);

class Link {
 public:
  explicit Link(std::string name);
  virtual ~Link() = default;
  Link(const Link&) = delete;
  Link& operator=(const Link&) = delete;

  // Opens the link when closed and the back-off allows it; whether it is open.
  bool ensure_open(double now_s);
  bool is_open() const { return open_; }
  // Closes it; the next attempt waits for the back-off.
  void close(double now_s);
  void set_backoff(double min_s, double max_s);
  const std::string& name() const { return name_; }
  const std::string& last_error() const { return last_error_; }
  // A serial line's time per byte (its character), 0 where the link has no line
  // (TCP, loopback): how long a reply of n bytes is on its way, n times this.
  double byte_time_s() const { return byte_time_s_; }
  void set_byte_time_s(double s) { byte_time_s_ = s; }

  TxResult read_registers(int unit, int addr, int n, uint16_t* dest, LinkCounters& c);
  TxResult write_register(int unit, int addr, uint16_t value, LinkCounters& c);
  TxResult write_registers(int unit, int addr, int n, const uint16_t* src, LinkCounters& c);
  // Function 23: the write happens before the read.
  TxResult write_and_read(int unit, int write_addr, int write_n, const uint16_t* src, int read_addr, int read_n,
                          uint16_t* dest, LinkCounters& c);
  // The I/O modules' tables: coils (function 1 read, 5 write one, 15 write many),
  // discrete inputs (2) and input registers (4). Bits are one byte each, 0 or 1.
  TxResult read_coils(int unit, int addr, int n, uint8_t* dest, LinkCounters& c);
  TxResult read_discrete_inputs(int unit, int addr, int n, uint8_t* dest, LinkCounters& c);
  TxResult write_coil(int unit, int addr, bool on, LinkCounters& c);
  TxResult write_coils(int unit, int addr, int n, const uint8_t* src, LinkCounters& c);
  TxResult read_input_registers(int unit, int addr, int n, uint16_t* dest, LinkCounters& c);
  // A Huanyang frame (huanyang_frame.h, not Modbus): `request` out (a whole frame),
  // the reply into `reply` (huanyang::kMaxFrame bytes), `*n` its length. kOk only for a
  // whole reply with its CRC, the request's unit and function and the right length;
  // a short or malformed one is kOther, none kTimeout, each named in last_error().
  TxResult exchange_frame(const uint8_t* request, int request_n, uint8_t* reply, int* n, LinkCounters& c);

 protected:
  // Each returns 0 on success or the errno of the failure (libmodbus codes for
  // exceptions, CRC and protocol errors).
  virtual int do_open(std::string& error) = 0;
  virtual void do_close() = 0;
  virtual int do_read(int unit, int addr, int n, uint16_t* dest) = 0;
  virtual int do_write1(int unit, int addr, uint16_t value) = 0;
  virtual int do_write(int unit, int addr, int n, const uint16_t* src) = 0;
  virtual int do_write_read(int unit, int waddr, int wn, const uint16_t* src, int raddr, int rn, uint16_t* dest) = 0;
  // A link without the bit tables or input registers answers as a drive does that
  // has none: an exception (illegal function).
  virtual int do_read_bits(int unit, int addr, int n, uint8_t* dest, bool discrete_inputs);
  virtual int do_write_bit(int unit, int addr, bool on);
  virtual int do_write_bits(int unit, int addr, int n, const uint8_t* src);
  virtual int do_read_input_registers(int unit, int addr, int n, uint16_t* dest);
  // Sends a frame and reads what comes back within the response timeout (`*got`
  // bytes, as many as a whole frame's length byte asks for); 0 or an I/O errno.
  // A link that cannot carry such frames answers EPROTONOSUPPORT.
  virtual int do_frame(const uint8_t* request, int n, uint8_t* reply, int cap, int* got);
  // After a failed transaction that may leave bytes in flight (timeouts, garbage):
  // a serial line is flushed, a TCP connection made afresh.
  virtual void discard_input() {}

 private:
  TxResult finish(int err, LinkCounters& c);
  std::string name_;
  bool open_ = false;
  double next_attempt_s_ = 0;
  double backoff_min_s_ = 0.1;
  double backoff_max_s_ = 2.0;
  double backoff_s_ = 0.1;
  std::string last_error_;
  double byte_time_s_ = 0;
  std::array<char, 96> detail_{};  // what a failed frame exchange found, for last_error_
};

}  // namespace cnc::drive
