// G38.2-G38.5 straight probing, as LinuxCNC 2.9's convert_straight_probe and
// set_probe_data have it: the checks before the move, the canonical calls, and the
// result (#5061-#5070, the current point) read before the next line.
#include <cmath>
#include <stdexcept>

#include "common/rs274/interpreter_impl.h"

namespace cnc::rs274 {

using namespace interp;

void Interpreter::straight_probe(Words& w, int g, int col) {
  if (!setup_.has_probe) fail(col, g_text(g) + " probes, and this machine's config has no probe input");
  if (comp_ != 400) fail(col, "cannot probe with cutter radius compensation on");
  if (feed_mode_ == FeedMode::kInverseTime) fail(col, "cannot probe in inverse time feed mode");
  if (feed_mode_ == FeedMode::kUnitsPerRev) fail(col, "cannot probe with feed per rev mode");
  if (feed_ <= 0) fail(col, "cannot probe with zero feed rate");
  const Pose end = axis_target(w, w.g[0] == 530);
  for (size_t i = 3; i < 6; ++i)
    if (end[i] != position_[i]) fail(col, "cannot move rotary axes during probing");
  // LinuxCNC 2.9's rs274 refuses only a move of no length, and only where a missing
  // change is an error (G38.2, G38.4); a G38.3/G38.5 of no length just reads the probe.
  const bool moves = end[0] != position_[0] || end[1] != position_[1] || end[2] != position_[2];
  if (!moves && (g == 382 || g == 384)) fail(col, "start point too close to probe point");
  comp_filter_->flush();
  const SourceRef r = ref(col);
  const Pose shown = program_pose(end);
  const Pose start_machine = machine_of(position_, coord_);
  canon_.turn_probe_on(r);
  canon_.straight_probe(r, shown, g - 380);
  canon_.turn_probe_off(r);
  position_ = end;
  probe_target_machine_ = machine_of(end, coord_);
  ++probes_made_;
  probe_wait_ = true;
  if (setup_.machine_results_supplied) return;
  // rs274's simulated machine (saicanon's STRAIGHT_PROBE): not tripped, the probe at
  // the move's end, and the machine backed off 0.254 mm (0.01 in) from it towards the
  // move's start, where the next move starts.
  Pose rest = probe_target_machine_;
  double d2 = 0;
  for (size_t i = 0; i < 3; ++i) d2 += (start_machine[i] - rest[i]) * (start_machine[i] - rest[i]);
  if (d2 > 0) {
    const double backoff = 0.254, d = std::sqrt(d2);  // mm here; 0.01 in in a G20 program
    for (size_t i = 0; i < 3; ++i) rest[i] += backoff * (start_machine[i] - rest[i]) / d;
  }
  set_probe_result(false, probe_target_machine_, rest);
}

void Interpreter::set_probe_result(bool tripped, const Pose& trip_machine, const Pose& rest_machine) {
  if (!probe_wait_) throw std::logic_error("a probe result with no G38.x move waiting for it");
  probe_wait_ = false;
  const Pose trip = program_of(trip_machine, coord_);
  for (int i = 0; i < kNumAxes; ++i) params_.set(5061 + i, to_program_axis(i, trip[static_cast<size_t>(i)]));
  params_.set(5070, tripped ? 1.0 : 0.0);
  position_ = program_of(rest_machine, coord_);
  update_position_params();
}

}  // namespace cnc::rs274
