// M66, wait on an input, as LinuxCNC 2.9's convert_m and read_inputs have it: the
// checks, the canonical call (WAIT) and the value read into #5399 before the next line.
#include <cmath>
#include <stdexcept>
#include <string>

#include "common/program/block.h"
#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

void Interpreter::wait_input(const Words& w) {
  const int col = w.mcol[5];
  // LinuxCNC's messages, in its order.
  if (w.on('P') && w.on('E')) fail(col, "invalid to select both a digital and an analog input with M66");
  const long mode = w.on('L') ? std::lround(w['L']) : 0;
  if (mode > 0 && !(w.on('Q') && w['Q'] > 0))
    fail(w.column('L'), "zero timeout with wait type != immediate return (M66 L" + std::to_string(mode) + " needs Q > 0)");
  if (w.on('E') && mode != 0) fail(w.column('L'), "can't select analog input with wait type != immediate return");
  if ((w.on('P') && std::lround(w['P']) < 0) || (w.on('E') && std::lround(w['E']) < 0) || (!w.on('P') && !w.on('E')))
    fail(col, "need to have either a valid P or a valid E word with M66");
  // LinuxCNC's task stops at an unknown mode ("Unknown Wait Mode") once the machine gets
  // there; here the program is refused before it runs.
  if (mode < 0 || mode > program::InputWait::kLow)
    fail(w.column('L'), "M66 L" + std::to_string(mode) + ": the wait mode is 0 (immediate), 1 (rise), 2 (fall), 3 (high) or 4 (low)");
  const bool analog = w.on('E');
  if (comp_ != 400)
    fail(col, std::string("cannot wait for ") + (analog ? "analog" : "digital") + " input with cutter radius compensation on");
  const long index = std::lround(analog ? w['E'] : w['P']);
  const int n = analog ? setup_.analog_inputs : setup_.digital_inputs;
  if (index >= n)
    fail(w.column(analog ? 'E' : 'P'),
         std::string(analog ? "analog" : "digital") + " input selected out of bounds: M66 " + (analog ? "E" : "P") +
             std::to_string(index) + ", and this machine has " +
             (n == 0 ? std::string("none") : std::to_string(n) + " (0.." + std::to_string(n - 1) + ")") +
             (analog ? " (io.analog_inputs)" : " (io.digital_inputs)"));
  const double timeout_s = mode > 0 ? w['Q'] : 0.0;
  comp_filter_->flush();
  canon_.wait_input(ref(col), static_cast<int>(index), analog, static_cast<int>(mode), timeout_s);
  ++input_waits_;
  input_wait_ = true;
  input_analog_ = analog;
  if (!setup_.machine_results_supplied) set_input_result(simulated_input());
}

double Interpreter::simulated_input() const {
  const double v = params_.get(5399);
  return input_analog_ ? v : (v != 0.0 ? 1.0 : 0.0);
}

void Interpreter::set_input_result(double value) {
  if (!input_wait_) throw std::logic_error("an input value with no M66 waiting for it");
  input_wait_ = false;
  params_.set(5399, value);
}

}  // namespace cnc::rs274
