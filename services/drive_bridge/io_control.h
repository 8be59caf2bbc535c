#pragma once
// The drive bridge's I/O logic, a pure core (no LCM, no clock, no threads): the
// interpolator's IO_CMD (coolant bits, digital outputs) turned into the coils wanted
// on each module, and the points' values read back turned into numbers.
//  * Each change is taken once (command_seq larger than any before); a repeat
//    changes nothing.
//  * The coolant runs only while the bridge follows setpoints: any stop or fault of
//    the bridge turns it off, and a command from before that stop never turns it on
//    again (as the spindle's). The digital outputs follow the newest command.
// No allocation after construction: the servo tick runs it.
#include <cstdint>
#include <vector>

#include "common/config/machine_config.h"

namespace cnc::bridge {

class IoControl {
 public:
  // `module_coils[m]`: the coil points of module m, in the order of its bits.
  IoControl(const config::IoConfig& io, const std::vector<std::vector<int>>& module_coils);

  // A command from the interpolator; `following`: the bridge follows setpoints now.
  // True when it was a new change.
  bool on_command(int64_t seq, int coolant, uint64_t outputs, bool following);
  // The bridge stopped following (a stop, a fault, disabled): the coolant off.
  void stop();

  int64_t command_seq() const { return seq_; }
  int coolant() const { return coolant_on_ ? coolant_ : 0; }  // as commanded to the modules
  uint64_t outputs() const { return outputs_; }
  // The coils wanted on module m (bit i: its i-th coil point).
  uint64_t module_coils(size_t m) const;
  // Whether a coil point is wanted on.
  bool wanted(int point) const;

  // A point's value from its raw read: a bit 0 or 1, a register's count x scale.
  static double value(const config::IoPointConfig& p, uint16_t raw);

 private:
  const config::IoConfig& io_;
  std::vector<std::vector<int>> module_coils_;
  std::vector<int8_t> role_;   // per point: -1 none, -2 mist, -3 flood, n >= 0 digital output n
  int64_t seq_ = 0;
  int coolant_ = 0;
  bool coolant_on_ = false;
  uint64_t outputs_ = 0;
};

}  // namespace cnc::bridge
