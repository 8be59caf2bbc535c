#include "common/program/block.h"

namespace cnc::program {

const char* to_string(BlockKind kind) {
  switch (kind) {
    case BlockKind::kRapid: return "rapid";
    case BlockKind::kLine: return "line";
    case BlockKind::kArcCw: return "arc_cw";
    case BlockKind::kArcCcw: return "arc_ccw";
    case BlockKind::kNurbs: return "nurbs";
    case BlockKind::kDwell: return "dwell";
    case BlockKind::kEnd: return "end";
    case BlockKind::kEvent: return "event";
  }
  return "?";
}

const char* to_string(EventKind kind) {
  switch (kind) {
    case EventKind::kNone: return "none";
    case EventKind::kProgramStop: return "program_stop";
    case EventKind::kOptionalStop: return "optional_stop";
    case EventKind::kPalletShuttle: return "pallet_shuttle";
    case EventKind::kToolChange: return "tool_change";
    case EventKind::kSpindle: return "spindle";
    case EventKind::kCoolant: return "coolant";
    case EventKind::kMessage: return "message";
    case EventKind::kDigitalOutput: return "digital_output";
    case EventKind::kAnalogOutput: return "analog_output";
    case EventKind::kOverrides: return "overrides";
    case EventKind::kWaitInput: return "wait_input";
    case EventKind::kSpindleOrient: return "spindle_orient";
  }
  return "?";
}

}  // namespace cnc::program
