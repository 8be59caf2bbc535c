#pragma once
// The operator-command interlock: which program command the cell takes in which
// state, and the reason it gives when it refuses one. Pure (no LCM, no clock); the
// program server decides with it and answers on PROGRAM_STATE (refusal,
// refused_sender, refused_seq), and the README's table is this function written out
// (tests/unit/interlock_test.cc checks every cell of it).
#include <cmath>
#include <cstdint>
#include <string>

#include "cnc/lcmt_program_command.hpp"

namespace cnc::pps {

enum class CellState : int8_t { kIdle, kLoaded, kRunning, kHeld, kFault };

inline const char* to_string(CellState s) {
  switch (s) {
    case CellState::kIdle: return "idle";
    case CellState::kLoaded: return "loaded";
    case CellState::kRunning: return "running";
    case CellState::kHeld: return "held";
    case CellState::kFault: return "fault";
  }
  return "?";
}

struct CellView {
  CellState state = CellState::kIdle;
  std::string program;  // the program loaded, running or held
  std::string fault;    // kFault: its cause
  std::string drives;   // "" when every drive is enabled (or no drive status is known), else e.g. "axis X is disabled"
};

// "" when `command` (lcmt_program_command::LOAD ... RESET) is allowed in `v`, else why not.
inline std::string refusal(const cnc::lcmt_program_command& c, const CellView& v) {
  using C = cnc::lcmt_program_command;
  const std::string running = "program " + v.program + " is running";
  const std::string held = "program " + v.program + " is held";
  const std::string fault = "the cell is in FAULT (" + v.fault + "): RESET first";
  switch (c.command) {
    case C::LOAD:
      switch (v.state) {
        case CellState::kIdle:
        case CellState::kLoaded: return "";
        case CellState::kRunning: return running + ": STOP it first";
        case CellState::kHeld: return held + ": STOP it first";
        case CellState::kFault: return fault;
      }
      break;
    case C::START:
      switch (v.state) {
        case CellState::kIdle: return "no program is loaded: LOAD one first";
        case CellState::kLoaded: return v.drives.empty() ? "" : v.drives + ": enable the drives first";
        case CellState::kRunning: return running + " already";
        case CellState::kHeld: return held + ": RESUME it";
        case CellState::kFault: return fault;
      }
      break;
    case C::HOLD:
      switch (v.state) {
        case CellState::kRunning:
        case CellState::kHeld: return "";
        case CellState::kIdle:
        case CellState::kLoaded: return "no program is running";
        case CellState::kFault: return "the cell is in FAULT (" + v.fault + "): nothing runs";
      }
      break;
    case C::RESUME:
      switch (v.state) {
        case CellState::kRunning:  // a hold may still be braking
        case CellState::kHeld: return "";
        case CellState::kIdle:
        case CellState::kLoaded: return "no program is held";
        case CellState::kFault: return fault;
      }
      break;
    case C::STOP: return "";
    case C::OVERRIDE:
      if (!std::isfinite(c.feed_override) || c.feed_override < 0 || c.feed_override > 1.5)
        return "feed override " + std::to_string(c.feed_override) + " is outside 0 .. 1.5";
      return "";
    case C::RESET:
      switch (v.state) {
        case CellState::kIdle:
        case CellState::kLoaded:
        case CellState::kFault: return "";
        case CellState::kRunning: return running + ": STOP it first";
        case CellState::kHeld: return held + ": STOP it first";
      }
      break;
    default: break;
  }
  return "unknown command " + std::to_string(c.command);
}

}  // namespace cnc::pps
