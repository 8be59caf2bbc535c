// Input waits on the live cell (M66): the input the path waits on, read from the drive
// bridge's IO_STATUS, ends the wait as a recorded INPUT_VALUE when it meets the wait's
// mode; the program server reads the value (INTERP_STATE) and serves the rest of the
// program made with it.
#include <spdlog/spdlog.h>

#include "cnc/lcmt_alarm.hpp"
#include "common/util/clock.h"
#include "services/interpolator/interpolator_node.h"

namespace cnc::interp {

namespace {
constexpr double kIoStatusFresh_s = 0.05;  // older, the input's state is not known now
constexpr double kInputStale_s = 0.25;     // not read for this long during a wait: the program stops
}  // namespace

void InterpolatorNode::input_cycle() {
  const InputWaitState& w = core_.input_wait();
  if (w.results != input_watch_.published) {
    // A wait ended (a value, or the core's timeout): the program server reads it.
    input_watch_.published = w.results;
    spdlog::info("M66 (block {}, line {}): #5399 = {}{}", w.block_index, core_.last().source_line, w.value,
                 w.value == -1 ? " (timed out)" : "");
    publish_state(true);
  }
  if (!w.waiting || token_ == 0) return;
  if (w.start_cycle != input_watch_.start_cycle) {
    input_watch_ = InputWatch{w.start_cycle, InputWaitCondition(w.wait.mode), -1, input_watch_.published};
  }
  const auto& list = w.wait.analog ? cfg_.io.analog_inputs : cfg_.io.digital_inputs;
  const std::string letter = w.wait.analog ? "E" : "P";
  if (w.wait.index < 0 || static_cast<size_t>(w.wait.index) >= list.size()) {
    // The program server's interpreter refuses such an index; a block that has one anyway stops here.
    fault("M66 " + letter + std::to_string(w.wait.index) + " at line " + std::to_string(core_.last().source_line) +
          ": no such input in io." + (w.wait.analog ? "analog_inputs" : "digital_inputs"));
    return;
  }
  const auto point = static_cast<size_t>(list[static_cast<size_t>(w.wait.index)]);
  const double now = util::monotonic_s();
  const bool read = now - io_status_s_ <= kIoStatusFresh_s && point < io_status_.valid.size() && io_status_.valid[point];
  if (!read) {
    if (input_watch_.unread_s < 0) input_watch_.unread_s = now;
    if (now - input_watch_.unread_s >= kInputStale_s) {
      const std::string text = program_path_ + ":" + std::to_string(core_.last().source_line) + ": M66 " + letter +
                               std::to_string(w.wait.index) + " waits on input " + cfg_.io.point_label(static_cast<int>(point)) +
                               ", which is not read (no fresh IO_STATUS, or its module does not answer)";
      spdlog::error("{}: the program stops", text);
      stop_program("input", text);
    }
    return;
  }
  input_watch_.unread_s = -1;
  const double v = io_status_.value[point];
  if (!input_watch_.condition.met(v)) return;
  cnc::lcmt_program_command m{};
  m.command = cnc::lcmt_program_command::INPUT_VALUE;
  m.axis = static_cast<int32_t>(w.block_index);
  m.value = w.wait.analog ? v : (v != 0 ? 1.0 : 0.0);
  Command c;
  c.kind = Command::Kind::kInputValue;
  c.value = m.value;
  apply_command(c, m);  // recorded when applied
}

}  // namespace cnc::interp
