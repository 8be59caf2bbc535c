#pragma once
// The coolant and the digital outputs as the program has them where the path stands
// (M7/M8/M9, M62-M65) and the analog outputs (M67/M68), taken from the block stream's
// events when the path reaches them, as the spindle's are. The path rests at every event, so the motion before one
// has ended when it is taken:
//  * the coolant, M64/M65 and M68 ("immediate") change there, as LinuxCNC's do once
//    its motion queue has run empty (they break blending);
//  * M62/M63 and M67 ("synchronised with motion") are queued and change when the path
//    next moves; a later one for the same output overwrites an earlier one, and queued
//    changes that no motion follows are dropped at the program's end (LinuxCNC's rule).
// Program end, a finished STOP, LOAD and RESET turn the coolant off and drop the
// queue; the digital and analog outputs keep their state. Every change gets a new seq.
// Plain data and no allocation: the interpolator core owns one.
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>

#include "common/program/block.h"

namespace cnc::interp {

struct MachineOutputs {
  int64_t seq = 0;
  int coolant = 0;        // bit 0 mist (M7), bit 1 flood (M8)
  uint64_t outputs = 0;   // bit n: digital output P n
  uint64_t queued_on = 0;   // M62 waiting for the next motion
  uint64_t queued_off = 0;  // M63 waiting for the next motion
  std::array<double, 64> analog{};         // analog output E n (M67/M68)
  uint64_t analog_queued = 0;              // bit n: an M67 for E n waiting for the next motion
  std::array<double, 64> analog_next{};    // ...its value

  // An event at the front, reached (once per event).
  void take(const program::Event& e) {
    if (e.kind == program::EventKind::kCoolant) {
      set(e.number & 3, outputs);
    } else if (e.kind == program::EventKind::kDigitalOutput && e.number >= 0 && e.number < 64) {
      const uint64_t bit = uint64_t{1} << e.number;
      const int v = static_cast<int>(e.value);
      const bool on = (v & 1) != 0;
      if (v & 2) {  // synchronised: with the next motion
        queued_on = on ? queued_on | bit : queued_on & ~bit;
        queued_off = on ? queued_off & ~bit : queued_off | bit;
      } else {
        queued_on &= ~bit;
        queued_off &= ~bit;
        set(coolant, on ? outputs | bit : outputs & ~bit);
      }
    } else if (e.kind == program::EventKind::kAnalogOutput && e.number % 1000 >= 0 && e.number % 1000 < 64 &&
               std::isfinite(e.value)) {
      const auto n = static_cast<size_t>(e.number % 1000);
      const uint64_t bit = uint64_t{1} << n;
      if (e.number >= 1000) {  // M67: with the next motion
        analog_queued |= bit;
        analog_next[n] = e.value;
      } else {
        analog_queued &= ~bit;
        set_analog(n, e.value);
      }
    }
  }
  // The path moves: the queued changes happen.
  void motion() {
    for (uint64_t q = analog_queued; q != 0; q &= q - 1) {
      const auto n = static_cast<size_t>(std::countr_zero(q));
      set_analog(n, analog_next[n]);
    }
    analog_queued = 0;
    if ((queued_on | queued_off) == 0) return;
    const uint64_t next = (outputs | queued_on) & ~queued_off;
    queued_on = queued_off = 0;
    set(coolant, next);
  }
  // Program end, STOP, LOAD, RESET.
  void end() {
    queued_on = queued_off = 0;
    analog_queued = 0;
    set(0, outputs);
  }

 private:
  void set_analog(size_t n, double v) {
    if (analog[n] == v) return;
    analog[n] = v;
    ++seq;
  }
  void set(int c, uint64_t o) {
    if (c == coolant && o == outputs) return;
    coolant = c;
    outputs = o;
    ++seq;
  }
};

}  // namespace cnc::interp
