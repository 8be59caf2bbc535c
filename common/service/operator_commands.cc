#include "common/service/operator_commands.h"

#include <algorithm>
#include <map>

namespace cnc::service {

std::optional<int8_t> program_command_by_name(const std::string& name) {
  using C = lcmt_program_command;
  // The constants by value (+): a pair binding LCM's in-class constants by reference
  // needs their definitions, which lcm-gen does not emit (clang -O1 would not link).
  static const std::map<std::string, int> kNames = {
      {"load", +C::LOAD},   {"start", +C::START},   {"hold", +C::HOLD},       {"resume", +C::RESUME},
      {"stop", +C::STOP},   {"override", +C::OVERRIDE}, {"rapid-override", +C::RAPID_OVERRIDE},
      {"spindle-override", +C::SPINDLE_OVERRIDE}, {"reset", +C::RESET}, {"home", +C::HOME},
      {"jog", +C::JOG},     {"jog-keepalive", +C::JOG_KEEPALIVE},            {"touch-off", +C::TOUCH_OFF},
      {"mdi", +C::MDI},     {"single-block", +C::SINGLE_BLOCK}, {"optional-stop", +C::OPTIONAL_STOP},
      {"block-delete", +C::BLOCK_DELETE}, {"confirm", +C::CONFIRM}};
  const auto it = kNames.find(name);
  if (it == kNames.end()) return std::nullopt;
  return static_cast<int8_t>(it->second);
}

int64_t send_program_command(bus::Bus& bus, const config::MachineConfig& cfg, const OperatorCommand& op) {
  lcmt_program_command c{};
  c.command = op.command;
  c.program_path = op.program_path;
  c.feed_override = op.feed_override;
  c.axis = op.axis;
  c.value = op.value;
  c.feed_mm_per_min = op.feed_mm_per_min;
  c.jog_continuous = op.jog_continuous;
  c.text = op.text;
  c.from_line = op.from_line;
  if (!bus.publish(cfg.channel(config::channels::kProgramCmd), c)) return -1;
  return c.seq;
}

bool send_drive_command(bus::Bus& bus, const config::MachineConfig& cfg, int8_t command) {
  lcmt_drive_command c{};
  c.command = command;
  return bus.publish(cfg.channel(config::channels::kDriveCmd), c);
}

std::string refusal_of(const lcmt_program_state& state, int32_t sender, int64_t seq) {
  if (seq < 0 || state.refused_sender != sender || state.refused_seq != seq) return "";
  return state.refusal;
}

bool answer_of(const lcmt_command_answers& answers, int32_t sender, int64_t seq, std::string* refusal) {
  if (seq < 0) return false;
  const auto n = static_cast<size_t>(std::max(0, answers.num_answers));
  for (size_t i = 0; i < n && i < answers.answer_sender.size() && i < answers.answer_seq.size() &&
                     i < answers.refusal.size();
       ++i) {
    if (answers.answer_sender[i] != sender || answers.answer_seq[i] != seq) continue;
    if (refusal != nullptr) *refusal = answers.refusal[i];
    return true;
  }
  return false;
}

std::string mdi_program_suffix(int32_t sender, int64_t seq) {
  return "/mdi-" + std::to_string(static_cast<uint32_t>(sender)) + "-" + std::to_string(seq) + ".ngc";
}

}  // namespace cnc::service
