// Probing on the live cell: the drive bridge's latch of the probe input (AXIS_STATUS)
// ends a probing move (G38.x) or faults any other move; the move's result goes to the
// program server (INTERP_STATE), which validates the rest of the program with it.
#include <spdlog/spdlog.h>

#include <cmath>

#include "cnc/lcmt_alarm.hpp"
#include "services/interpolator/interpolator_node.h"
#include "common/util/clock.h"

namespace cnc::interp {

namespace {
constexpr double kProbeStatusFresh_s = 0.05;  // older, the probe's state is not known now
bool active(RunState s) { return s == RunState::kRunning || s == RunState::kHeld || s == RunState::kStarved; }
}

void InterpolatorNode::probe_stop(const std::string& why) {
  const std::string text = probe_.file + ":" + std::to_string(probe_.line) + ": " + why;
  spdlog::error("probe: {}: the program stops", text);
  stop_program("probe", text);
  probe_.decided = true;
}

void InterpolatorNode::probe_decide(bool tripped, const double* trip_mm) {
  const ProbeMove& pm = core_.probe_move();
  const size_t n = cfg_.axes.size();
  probe_.decided = true;
  if (!tripped && (pm.kind == 2 || pm.kind == 4)) {
    probe_stop("G38." + std::to_string(pm.kind) + " move ended without the probe " +
               (pm.kind == 2 ? "tripping" : "losing contact"));
    return;
  }
  for (size_t a = 0; a < n; ++a) {
    probe_.rest[a] = core_.machine_position(static_cast<int>(a));
    probe_.trip[a] = tripped ? trip_mm[a] : probe_.rest[a];
  }
  probe_.tripped = tripped;
  probe_.result_block = pm.block_index;
  ++probe_.results;
  std::string where;
  for (size_t a = 0; a < n; ++a) where += fmt::format(" {} {:.4f}", cfg_.axes[a].name, probe_.trip[a]);
  spdlog::info("probe: G38.{} at {}:{} (block {}): {} at{}", pm.kind, probe_.file, probe_.line, pm.block_index,
               tripped ? "tripped" : "no contact", where);
  publish_state(true);
}

void InterpolatorNode::probe_cycle() {
  if (!cfg_.probe.enabled()) return;
  const cnc::lcmt_axis_status& st = axis_status_;
  const size_t n = cfg_.axes.size();
  const bool have = util::monotonic_s() - axis_status_s_ <= kProbeStatusFresh_s &&
                    st.num_probe_axes == static_cast<int32_t>(n) && st.probe >= 0;
  if (!have) {
    const ProbeMove& pm = core_.probe_move();
    if (token_ != 0 && pm.block_index >= 0 && !pm.done && active(core_.state()) && !probe_.decided)
      probe_stop("the probe input " + cfg_.io.point_label(cfg_.probe.input) +
                 " is not read (no fresh AXIS_STATUS, or its module does not answer)");
    return;
  }
  const bool first = probe_.rises < 0;
  const bool rise = !first && st.probe_rises != probe_.rises;
  const bool fall = !first && st.probe_falls != probe_.falls;
  probe_.rises = st.probe_rises;
  probe_.falls = st.probe_falls;
  const ProbeMove& pm = core_.probe_move();
  const bool running = token_ != 0 && active(core_.state());
  const bool toward = pm.kind == 2 || pm.kind == 3;
  auto latched = [&](bool rising) {
    const std::vector<double>& v = rising ? st.probe_rise_mm : st.probe_fall_mm;
    for (size_t a = 0; a < n; ++a) probe_.latch[a] = v[a] - core_.drive_offset(static_cast<int>(a));
  };
  if (running && pm.block_index >= 0 && pm.block_index != probe_.block) {
    // A probing move has come to the front.
    probe_.block = pm.block_index;
    probe_.start_cycle = core_.cycle();
    probe_.started = false;
    probe_.decided = false;
  }
  if (running && pm.block_index >= 0 && pm.block_index == probe_.block && !probe_.decided) {
    const bool edge = toward ? rise : fall;
    if (!probe_.started && st.playback_cycle >= static_cast<double>(probe_.start_cycle)) {
      // The bridge plays the move's start: the probe must stand as the move expects
      // (an edge since is the move's own).
      probe_.started = true;
      const bool touching = edge ? !toward : st.probe == 1;
      if (toward && touching) return probe_stop("G38." + std::to_string(pm.kind) + ": the probe is already tripped at the start");
      if (!toward && !touching) return probe_stop("G38." + std::to_string(pm.kind) + ": the probe is not tripped at the start");
    }
    if (!pm.done) {
      if (edge && !pm.tripped) {
        latched(toward);
        cnc::lcmt_program_command m{};
        m.command = cnc::lcmt_program_command::PROBE_TRIP;
        m.axis = static_cast<int32_t>(pm.block_index);
        m.num_axes = static_cast<int32_t>(n);
        m.position_mm.assign(probe_.latch.begin(), probe_.latch.begin() + static_cast<std::ptrdiff_t>(n));
        Command c;
        c.kind = Command::Kind::kProbeTrip;
        apply_command(c, m);  // recorded when applied
        if (!core_.probe_move().tripped) return probe_stop("the probe tripped, and the path could not stop on it");
      }
      return;
    }
    // The move has ended: tripped on the way, or the bridge has played it to its end.
    if (pm.tripped) return probe_decide(true, probe_.latch.data());
    if (edge) {
      // The edge came as the bridge played the move's last setpoints (the path was there already).
      latched(toward);
      return probe_decide(true, probe_.latch.data());
    }
    if (st.playback_cycle >= static_cast<double>(pm.end_cycle) + 1.0) probe_decide(false, nullptr);
    return;
  }
  if (rise && running && core_.last().feed_mm_per_min > 0)
    fault("probe input " + cfg_.io.point_label(cfg_.probe.input) +
          ": contact during a move that is not a probing move (line " + std::to_string(core_.last().source_line) + ")");
}

}  // namespace cnc::interp
