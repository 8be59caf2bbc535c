#pragma once
// Fault injection of the servo simulator. Commands, one per line, from the
// control FIFO (--control PATH) or scheduled with --inject "T:CMD; T:CMD" (T in s
// after start):
//   drop S           close every connection and answer nothing for S seconds
//   delay MS [S]     delay every reply by MS milliseconds (for S seconds; default until clear)
//   exception C [N]  answer the next N requests (default 1) with Modbus exception C
//   crc [N]          RTU: corrupt the CRC of the next N replies (default 1)
//   fault AXIS [C]   the drive of AXIS raises a fault (error code C, default 0x7500)
//   jam AXIS         the drive of AXIS (an axis's or a gantry joint's name) stands still
//                    while enabled, as a jammed carriage or a stalled motor: its position
//                    demand goes on, its position does not (until clear)
//   clear            end every injection
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace cnc::servo_sim {

class FaultInjector {
 public:
  using AxisFault = std::function<bool(const std::string& axis, uint16_t code)>;
  // Jams (on) the drive named `axis`, or frees (off) every drive when `axis` is "".
  using AxisJam = std::function<bool(const std::string& axis, bool on)>;
  explicit FaultInjector(AxisFault on_fault, AxisJam on_jam = [](const std::string&, bool) { return true; })
      : on_fault_(std::move(on_fault)), on_jam_(std::move(on_jam)) {}

  // Applies one command; "" when done, else what is wrong with it.
  std::string apply(const std::string& line, double now_s);
  // Parses --inject; throws std::invalid_argument naming the bad entry.
  void schedule(const std::string& spec, double start_s);
  // Applies the scheduled commands that are due.
  void poll(double now_s);

  bool dropped(double now_s) const { return now_s < drop_until_s_; }
  double reply_delay_s(double now_s) const { return now_s < delay_until_s_ ? delay_s_ : 0.0; }
  // Consumes one injected exception; 0 when none is due.
  int take_exception();
  bool take_crc();

 private:
  AxisFault on_fault_;
  AxisJam on_jam_;
  double drop_until_s_ = -1;
  double delay_s_ = 0;
  double delay_until_s_ = -1;
  int exceptions_left_ = 0;
  int exception_code_ = 0;
  int crc_left_ = 0;
  struct Scheduled {
    double at_s;
    std::string command;
  };
  std::vector<Scheduled> scheduled_;
};

}  // namespace cnc::servo_sim
