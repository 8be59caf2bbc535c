#pragma once
// M66's condition on the readings of its input, from the wait's start, as LinuxCNC's
// task decides it (WAITING_FOR_DELAY): an immediate read is met at once; RISE waits
// for the input low, then high (an input already high must fall first); FALL the
// reverse; HIGH and LOW by the reading alone. A digital reading is high when not 0.
#include "common/program/block.h"

namespace cnc::interp {

class InputWaitCondition {
 public:
  explicit InputWaitCondition(int mode = program::InputWait::kImmediate) : mode_(mode) {}
  // One reading; true once the condition holds (and for every reading after).
  bool met(double value) {
    const bool high = value != 0;
    seen_low_ = seen_low_ || !high;
    seen_high_ = seen_high_ || high;
    switch (mode_) {
      case program::InputWait::kImmediate: met_ = true; break;
      case program::InputWait::kRise: met_ = met_ || (high && seen_low_); break;
      case program::InputWait::kFall: met_ = met_ || (!high && seen_high_); break;
      case program::InputWait::kHigh: met_ = met_ || high; break;
      case program::InputWait::kLow: met_ = met_ || !high; break;
      default: break;
    }
    return met_;
  }

 private:
  int mode_;
  bool seen_low_ = false, seen_high_ = false, met_ = false;
};

}  // namespace cnc::interp
