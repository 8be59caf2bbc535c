#pragma once
// The drive bridge's I/O logic, a pure core (no LCM, no clock, no threads): the
// interpolator's IO_CMD (coolant bits, digital outputs, analog outputs) turned into the
// coils and holding registers wanted on each module, and the points' values read back
// turned into numbers.
//  * Each change is taken once (command_seq larger than any before); a repeat
//    changes nothing.
//  * The coolant runs only while the bridge follows setpoints: any stop or fault of
//    the bridge turns it off, and a command from before that stop never turns it on
//    again (as the spindle's). The digital and analog outputs follow the newest command.
//  * An analog output's raw count is value / scale, rounded, held to the register's
//    range (0..65535, or -32768..32767 when signed). Its register is written only once
//    a command has given it a value (until then the module keeps its own).
// No allocation after construction: the servo tick runs it.
#include <cstdint>
#include <vector>

#include "common/config/machine_config.h"

namespace cnc::bridge {

class IoControl {
 public:
  // `module_coils[m]`: the coil points of module m, in the order of its bits;
  // `module_holding[m]`: its holding-register points, in the order of its slots.
  IoControl(const config::IoConfig& io, const std::vector<std::vector<int>>& module_coils,
            const std::vector<std::vector<int>>& module_holding = {});

  // A command from the interpolator; `following`: the bridge follows setpoints now;
  // `analog`: io.analog_outputs' values (fewer: the rest kept). True when it was a new change.
  bool on_command(int64_t seq, int coolant, uint64_t outputs, const std::vector<double>& analog, bool following);
  bool on_command(int64_t seq, int coolant, uint64_t outputs, bool following) {
    return on_command(seq, coolant, outputs, {}, following);
  }
  // The bridge stopped following (a stop, a fault, disabled): the coolant off.
  void stop();

  int64_t command_seq() const { return seq_; }
  int coolant() const { return coolant_on_ ? coolant_ : 0; }  // as commanded to the modules
  uint64_t outputs() const { return outputs_; }
  // The coils wanted on module m (bit i: its i-th coil point).
  uint64_t module_coils(size_t m) const;
  // Whether a coil point is wanted on.
  bool wanted(int point) const;
  // The raw counts wanted in module m's holding-register slots (raw[i] for slot i, at
  // most 64); returns the mask of the slots that are analog outputs with a value (written).
  uint64_t module_holding(size_t m, uint16_t* raw) const;
  double analog(size_t n) const { return analog_[n]; }
  uint16_t analog_raw(size_t n) const { return raw_[n]; }
  // Analog values held to their register's range so far.
  int64_t clamped() const { return clamped_; }

  // A point's value from its raw read: a bit 0 or 1, a register's count x scale.
  static double value(const config::IoPointConfig& p, uint16_t raw);

 private:
  const config::IoConfig& io_;
  std::vector<std::vector<int>> module_coils_;
  std::vector<std::vector<int>> module_holding_;
  std::vector<int8_t> role_;   // per point: -1 none, -2 mist, -3 flood, n >= 0 digital output n
  std::vector<int8_t> analog_role_;  // per point: -1 none, n >= 0 analog output n
  std::vector<double> analog_;
  std::vector<uint16_t> raw_;
  std::vector<bool> analog_set_;  // given a value by a command
  int64_t clamped_ = 0;
  int64_t seq_ = 0;
  int coolant_ = 0;
  bool coolant_on_ = false;
  uint64_t outputs_ = 0;
};

}  // namespace cnc::bridge
