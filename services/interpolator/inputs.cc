#include "services/interpolator/inputs.h"

#include "common/program/block_msg.h"

namespace cnc::interp {

bool to_core_command(const cnc::lcmt_program_command& m, Command* out) {
  using C = cnc::lcmt_program_command;
  switch (m.command) {
    case C::LOAD: *out = {Command::Kind::kLoad, 1.0}; return true;
    case C::START: *out = {Command::Kind::kStart, 1.0}; return true;
    case C::HOLD: *out = {Command::Kind::kHold, 1.0}; return true;
    case C::RESUME: *out = {Command::Kind::kResume, 1.0}; return true;
    case C::STOP: *out = {Command::Kind::kStop, 1.0}; return true;
    case C::OVERRIDE: *out = {Command::Kind::kOverride, m.feed_override}; return true;
    default: return false;
  }
}

std::string apply_recorded_input(Interpolator& core, const cnc::lcmt_interp_input& in, int num_axes) {
  if (in.kind == cnc::lcmt_interp_input::COMMAND) {
    Command c;
    if (!to_core_command(in.command, &c)) return "unknown command " + std::to_string(in.command.command);
    core.apply_command(c);
    return "";
  }
  if (in.kind == cnc::lcmt_interp_input::BLOCK) {
    program::Block b;
    const std::string why = program::from_msg(in.block, num_axes, &b);
    if (!why.empty()) return why;
    if (!core.apply_block(b)) return core.last_refusal();
    return "";
  }
  return "unknown input kind " + std::to_string(in.kind);
}

}  // namespace cnc::interp
