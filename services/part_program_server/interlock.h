#pragma once
// The operator-command interlock: which program command the cell takes in which
// state, and the reason it gives when it refuses one. Pure (no LCM, no clock); the
// program server decides with it and answers on PROGRAM_STATE (refusal,
// refused_sender, refused_seq), and the README's table is this function written out
// (tests/unit/interlock_test.cc checks every cell of it).
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>

#include "cnc/lcmt_program_command.hpp"
#include "common/motion/feed_override.h"

namespace cnc::pps {

// kJogging, kHoming: the interpolator runs an operator move (a jog, the homing sequence).
enum class CellState : int8_t { kIdle, kLoaded, kRunning, kHeld, kFault, kJogging, kHoming };

inline const char* to_string(CellState s) {
  switch (s) {
    case CellState::kIdle: return "idle";
    case CellState::kLoaded: return "loaded";
    case CellState::kRunning: return "running";
    case CellState::kHeld: return "held";
    case CellState::kFault: return "fault";
    case CellState::kJogging: return "jogging";
    case CellState::kHoming: return "homing";
  }
  return "?";
}

struct CellView {
  CellState state = CellState::kIdle;
  std::string program;  // the program loaded, running or held
  std::string fault;    // kFault: its cause
  std::string drives;   // "" when every drive is enabled (or no drive status is known), else e.g. "axis X is disabled"
  std::string motion;   // kJogging, kHoming: what moves, e.g. "jog X+ continuous"
  // "" when program motion is allowed, else e.g. "axis Z is not homed" (operator.homing_required).
  std::string unhomed;
  // kLoaded from line N: the approach waiting for CONFIRM ("" when none waits).
  std::string approach;
  // "" when the guard door (safety.door) is shut or there is none, else e.g. "the guard door (input door_closed) is open".
  std::string door;
  // A hard-limit switch that reads 0 (IO_STATUS: on it, tripped or disabled by it): its
  // axis, its end (-1 the min end, +1 the max end) and its name. A jog towards it is
  // refused here, before the drive bridge would fault on it; away from it is allowed.
  int limit_axis = -1;
  int limit_side = 0;
  std::string limit_switch;
  // The spindle override's range (spindle.min_override .. max_override).
  double spindle_min_override = 0.5;
  double spindle_max_override = 1.0;
};

// The operator commands in `v`: "" allowed, else why not.
inline std::string operator_refusal(const cnc::lcmt_program_command& c, const CellView& v) {
  using C = cnc::lcmt_program_command;
  const std::string running = "program " + v.program + " is running: STOP it first";
  const std::string held = "program " + v.program + " is held: STOP it first";
  const std::string fault = "the cell is in FAULT (" + v.fault + "): RESET first";
  const std::string moving = v.motion + " runs: STOP it first";
  if (c.command == C::JOG_KEEPALIVE) return "";
  if (c.command == C::HOMED) return "HOMED is the interpolator's own input, never a command";
  if (c.command == C::JOG && !(std::isfinite(c.value) && c.value != 0))
    return "jog " + std::to_string(c.value) + ": the increment (or direction) must be a non-zero number";
  if (c.command == C::JOG && !(std::isfinite(c.feed_mm_per_min) && c.feed_mm_per_min >= 0))
    return "jog feed " + std::to_string(c.feed_mm_per_min) + " mm/min is not a speed";
  if (c.command == C::JOG && v.limit_axis >= 0 && c.axis == v.limit_axis && (c.value > 0 ? 1 : -1) == v.limit_side)
    return "jog towards the limit switch " + v.limit_switch + ", which is open: jog the axis away from it";
  if (c.command == C::TOUCH_OFF && !std::isfinite(c.value)) return "touch-off: the value is not a number";
  if (c.command == C::TOUCH_OFF && c.jog_continuous != 0 && c.jog_continuous != 2)
    return "touch-off: jog_continuous " + std::to_string(c.jog_continuous) +
           " is neither 0 (the work offset) nor 2 (the tool's length)";
  if (c.command == C::MDI && c.text.empty()) return "MDI: the line is empty";
  if (c.command == C::MDI && c.text.find_first_of("\n\r") != std::string::npos) return "MDI: one line only";
  switch (v.state) {
    case CellState::kIdle:
    case CellState::kLoaded:
      if (!v.drives.empty() && c.command != C::TOUCH_OFF) return v.drives + ": enable the drives first";
      if (!v.door.empty() && c.command != C::TOUCH_OFF) return v.door + ": shut it first";
      if (c.command == C::MDI && !v.unhomed.empty()) return v.unhomed + ": HOME first";
      return "";
    case CellState::kRunning: return running;
    case CellState::kHeld: return held;
    case CellState::kJogging:
    case CellState::kHoming: return moving;
    case CellState::kFault: return fault;
  }
  return "?";
}

// "" when `command` (lcmt_program_command::LOAD ... RESET) is allowed in `v`, else why not.
inline std::string refusal(const cnc::lcmt_program_command& c, const CellView& v) {
  using C = cnc::lcmt_program_command;
  const std::string running = "program " + v.program + " is running";
  const std::string held = "program " + v.program + " is held";
  const std::string fault = "the cell is in FAULT (" + v.fault + "): RESET first";
  if (c.command >= C::HOME && c.command <= C::HOMED) return operator_refusal(c, v);
  if (c.command == C::SPINDLE_AT_SPEED) return "SPINDLE_AT_SPEED is the interpolator's own input, never a command";
  if (c.command == C::SPINDLE_POSITION) return "SPINDLE_POSITION is the interpolator's own input, never a command";
  if (c.command == C::SPINDLE_SPEED) return "SPINDLE_SPEED is the interpolator's own input, never a command";
  if (c.command == C::CONFIRM) {
    if (v.state == CellState::kLoaded && !v.approach.empty()) return "";
    if (v.state == CellState::kFault) return fault;
    return "no approach waits for confirmation (LOAD with a line to run from makes one)";
  }
  if (c.command == C::SINGLE_BLOCK || c.command == C::OPTIONAL_STOP || c.command == C::BLOCK_DELETE) {
    const char* name = c.command == C::SINGLE_BLOCK ? "single block" : c.command == C::OPTIONAL_STOP ? "optional stop"
                                                                                                      : "block delete";
    if (!(c.value == 0 || c.value == 1)) return std::string(name) + " " + std::to_string(c.value) + ": the value is 1 (on) or 0 (off)";
    // Block delete is read as the program is interpreted, at its load: set it before.
    if (c.command == C::BLOCK_DELETE && (v.state == CellState::kRunning || v.state == CellState::kHeld))
      return (v.state == CellState::kRunning ? running : held) +
             ": block delete is read when a program is loaded: STOP it, switch, and load it again";
    return "";
  }
  // An operator move runs: nothing of a program until it ends (STOP ends it).
  const bool manual = v.state == CellState::kJogging || v.state == CellState::kHoming;
  if (manual) {
    switch (c.command) {
      case C::LOAD:
      case C::START:
      case C::RESET: return v.motion + " runs: STOP it first";
      case C::HOLD: return "no program is running";
      case C::RESUME: return "no program is held";
      default: break;
    }
  }
  switch (c.command) {
    case C::LOAD:
      switch (v.state) {
        case CellState::kIdle:
        case CellState::kLoaded: return "";
        case CellState::kRunning: return running + ": STOP it first";
        case CellState::kHeld: return held + ": STOP it first";
        case CellState::kFault: return fault;
        default: break;
      }
      break;
    case C::START:
      switch (v.state) {
        case CellState::kIdle: return "no program is loaded: LOAD one first";
        case CellState::kLoaded:
          if (!v.drives.empty()) return v.drives + ": enable the drives first";
          if (!v.door.empty()) return v.door + ": shut it first";
          if (!v.unhomed.empty()) return v.unhomed + ": HOME first";
          return v.approach.empty() ? "" : "program " + v.program + " runs " + v.approach + ": CONFIRM the approach first";
        case CellState::kRunning: return running + " already";
        case CellState::kHeld: return held + ": RESUME it";
        case CellState::kFault: return fault;
        default: break;
      }
      break;
    case C::HOLD:
      switch (v.state) {
        case CellState::kRunning:
        case CellState::kHeld: return "";
        case CellState::kIdle:
        case CellState::kLoaded: return "no program is running";
        case CellState::kFault: return "the cell is in FAULT (" + v.fault + "): nothing runs";
        default: break;
      }
      break;
    case C::RESUME:
      switch (v.state) {
        case CellState::kRunning:  // a hold may still be braking
        case CellState::kHeld: return v.door.empty() ? "" : v.door + ": shut it first";
        case CellState::kIdle:
        case CellState::kLoaded: return "no program is held";
        case CellState::kFault: return fault;
        default: break;
      }
      break;
    case C::STOP: return "";
    case C::OVERRIDE:
      if (!std::isfinite(c.feed_override) || c.feed_override < 0 || c.feed_override > motion::kMaxFeedOverride) {
        char most[32];
        std::snprintf(most, sizeof most, "%g", motion::kMaxFeedOverride);
        return "feed override " + std::to_string(c.feed_override) + " is outside 0 .. " + most;
      }
      return "";
    case C::RAPID_OVERRIDE:
      if (!std::isfinite(c.feed_override) || c.feed_override < 0 || c.feed_override > 1)
        return "rapid override " + std::to_string(c.feed_override) + " is outside 0 .. 1";
      return "";
    case C::SPINDLE_OVERRIDE:
      if (!std::isfinite(c.feed_override) || c.feed_override < v.spindle_min_override ||
          c.feed_override > v.spindle_max_override) {
        char range[64];
        std::snprintf(range, sizeof range, "%g .. %g", v.spindle_min_override, v.spindle_max_override);
        return "spindle override " + std::to_string(c.feed_override) + " is outside " + range +
               " (spindle.min_override .. max_override)";
      }
      return "";
    case C::RESET:
      switch (v.state) {
        case CellState::kIdle:
        case CellState::kLoaded:
        case CellState::kFault: return "";
        case CellState::kRunning: return running + ": STOP it first";
        case CellState::kHeld: return held + ": STOP it first";
        default: break;
      }
      break;
    default: break;
  }
  return "unknown command " + std::to_string(c.command);
}

}  // namespace cnc::pps
