#include "services/interpolator/inputs.h"

#include <cmath>

#include "common/program/block_msg.h"

namespace cnc::interp {

bool to_core_command(const cnc::lcmt_program_command& m, Command* out) {
  using C = cnc::lcmt_program_command;
  switch (m.command) {
    case C::LOAD: *out = {Command::Kind::kLoad, 1.0, {}}; return true;
    case C::START: *out = {Command::Kind::kStart, 1.0, {}}; return true;
    case C::HOLD:
      *out = {Command::Kind::kHold, 1.0, {}};
      out->value = m.value == 1 ? 1 : 0;  // 1: the guard door's hold
      return true;
    case C::RESUME: *out = {Command::Kind::kResume, 1.0, {}}; return true;
    case C::STOP: *out = {Command::Kind::kStop, 1.0, {}}; return true;
    case C::OVERRIDE: *out = {Command::Kind::kOverride, m.feed_override, {}}; return true;
    case C::RAPID_OVERRIDE: *out = {Command::Kind::kRapidOverride, m.feed_override, {}}; return true;
    case C::SPINDLE_OVERRIDE: *out = {Command::Kind::kSpindleOverride, m.feed_override, {}}; return true;
    case C::HOMED:
      if (!std::isfinite(m.value) || m.axis < 0 || m.axis >= program::kMaxAxes) return false;
      *out = Command{};
      out->kind = Command::Kind::kHomed;
      out->axis = m.axis;
      out->value = m.value;
      return true;
    case C::SPINDLE_AT_SPEED:
      if (!std::isfinite(m.value) || m.value < 0) return false;
      *out = Command{};
      out->kind = Command::Kind::kSpindleAtSpeed;
      out->value = m.value;
      return true;
    case C::SPINDLE_POSITION:
      if (m.num_axes != 3 || m.position_mm.size() != 3) return false;
      *out = Command{};
      out->kind = Command::Kind::kSpindlePosition;
      for (size_t i = 0; i < 3; ++i) {
        if (!std::isfinite(m.position_mm[i])) return false;
        out->position_mm[i] = m.position_mm[i];
      }
      return true;
    case C::SPINDLE_SPEED:
      if (!std::isfinite(m.value) || m.value < 0) return false;
      *out = Command{};
      out->kind = Command::Kind::kSpindleSpeed;
      out->value = m.value;
      return true;
    case C::INPUT_VALUE:
      if (!std::isfinite(m.value)) return false;
      *out = Command{};
      out->kind = Command::Kind::kInputValue;
      out->value = m.value;
      return true;
    case C::PROBE_TRIP:
      *out = Command{};
      out->kind = Command::Kind::kProbeTrip;
      for (int a = 0; a < m.num_axes && a < program::kMaxAxes && static_cast<size_t>(a) < m.position_mm.size(); ++a) out->position_mm[static_cast<size_t>(a)] = m.position_mm[static_cast<size_t>(a)];
      return true;
    case C::SINGLE_BLOCK:
    case C::OPTIONAL_STOP:
      if (!(m.value == 0 || m.value == 1)) return false;
      *out = Command{};
      out->kind = m.command == C::SINGLE_BLOCK ? Command::Kind::kSingleBlock : Command::Kind::kOptionalStop;
      out->value = m.value;
      return true;
    case C::RESET: {
      // As applied, a reset carries the position taken, one finite value per axis.
      if (m.num_axes <= 0 || m.num_axes > program::kMaxAxes || m.position_mm.size() != static_cast<size_t>(m.num_axes))
        return false;
      *out = {Command::Kind::kReset, 1.0, {}};
      for (int a = 0; a < m.num_axes; ++a) {
        if (!std::isfinite(m.position_mm[static_cast<size_t>(a)])) return false;
        out->position_mm[static_cast<size_t>(a)] = m.position_mm[static_cast<size_t>(a)];
      }
      return true;
    }
    default: return false;
  }
}

std::string apply_recorded_input(Interpolator& core, const cnc::lcmt_interp_input& in, int num_axes) {
  if (in.kind == cnc::lcmt_interp_input::COMMAND) {
    Command c;
    if (!to_core_command(in.command, &c)) return "unknown or malformed command " + std::to_string(in.command.command);
    if (c.kind == Command::Kind::kReset && in.command.num_axes != num_axes)
      return "reset with " + std::to_string(in.command.num_axes) + " axes, the machine has " + std::to_string(num_axes);
    if (!core.apply_command(c)) return "the planner could not take the command";
    return "";
  }
  if (in.kind == cnc::lcmt_interp_input::BLOCK) {
    program::Block b;
    const std::string why = program::from_msg(in.block, num_axes, &b);
    if (!why.empty()) return why;
    if (!core.apply_block(b)) return core.last_refusal();
    return "";
  }
  if (in.kind == cnc::lcmt_interp_input::PLAN) {
    if (in.plans <= 0) return "a PLAN input of " + std::to_string(in.plans) + " plans";
    if (!core.apply_plans_exact(in.plans)) return "fewer than " + std::to_string(in.plans) + " plans are ready";
    core.take_plan_failure();  // a plan that failed stops the program inside the core, as live
    return "";
  }
  return "unknown input kind " + std::to_string(in.kind);
}

}  // namespace cnc::interp
