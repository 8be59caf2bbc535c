#include "common/program/block_msg.h"

#include <cmath>

#include "common/program/block_check.h"

namespace cnc::program {

namespace {

// Anything beyond these is not a program block but garbage or an attack.
constexpr int32_t kMaxMsgAxes = kMaxAxes;

bool finite(const std::vector<double>& v) {
  for (double x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

}  // namespace

cnc::lcmt_program_block to_msg(const Block& b, int64_t program_token) {
  cnc::lcmt_program_block m{};
  m.program_token = program_token;
  m.block_index = b.index;
  m.source_line = b.source_line;
  m.source_column = b.source_column;
  m.source_file = b.source_file;
  m.kind = static_cast<int8_t>(b.kind);
  m.num_axes = static_cast<int32_t>(b.end.size());
  m.start = b.start;
  m.end = b.end;
  const bool arc = b.kind == BlockKind::kArcCw || b.kind == BlockKind::kArcCcw;
  if (arc && b.arc.center.size() == b.end.size()) {
    m.center = b.arc.center;
  } else {
    m.center.assign(b.end.size(), 0.0);
  }
  m.plane = static_cast<int8_t>(arc ? b.arc.plane : 17);
  m.turns = arc ? b.arc.turns : 0;
  if (b.kind == BlockKind::kNurbs) {
    m.order = b.nurbs.order;
    m.num_knots = static_cast<int32_t>(b.nurbs.knots.size());
    m.knots = b.nurbs.knots;
    m.num_control_points = static_cast<int32_t>(b.nurbs.control_points.size());
    m.control_points.reserve(b.nurbs.control_points.size());
    for (const auto& p : b.nurbs.control_points) m.control_points.push_back({p[0], p[1], p[2]});
    m.weights = b.nurbs.weights;
  } else {
    m.order = 0;
    m.num_knots = 0;
    m.num_control_points = 0;
  }
  m.feed_mm_per_min = b.feed_mm_per_min;
  m.dwell_s = b.dwell_s;
  m.spindle_rpm = b.spindle_rpm;
  m.ball_radius_mm = b.process.ball_radius_mm;
  m.flutes = b.process.flutes;
  m.pick_feed_mm = b.process.pick_feed_mm;
  m.target_rmax_um = b.process.target_rmax_um;
  m.path_tolerance_mm = b.path_tolerance_mm;
  m.event_kind = static_cast<int8_t>(b.event.kind);
  m.event_number = b.event.number;
  m.event_value = b.event.value;
  m.event_text = b.event.text;
  if (b.kind == BlockKind::kLine && b.probe != 0) {
    m.event_kind = kProbeWire;
    m.event_number = b.probe;
  }
  if (b.kind == BlockKind::kLine && b.sync != kSyncNone) {
    m.event_kind = static_cast<int8_t>(kSyncWire + b.sync);
    m.event_value = b.sync_pitch_mm;
    m.dwell_s = b.tap_retract_scale;
  }
  return m;
}

std::string from_msg(const cnc::lcmt_program_block& m, int num_axes, Block* out) {
  if (m.num_axes != num_axes) return "block has " + std::to_string(m.num_axes) + " axes, machine has " + std::to_string(num_axes);
  if (m.num_axes < 1 || m.num_axes > kMaxMsgAxes) return "bad axis count " + std::to_string(m.num_axes);
  // A message built in memory (not decoded) may disagree with its own counts.
  const auto n = static_cast<size_t>(m.num_axes);
  if (m.start.size() != n || m.end.size() != n || m.center.size() != n) return "axis arrays disagree with num_axes";
  if (m.kind < 0 || m.kind > static_cast<int8_t>(BlockKind::kEvent)) return "unknown block kind " + std::to_string(m.kind);
  if (m.block_index < 0) return "negative block index";
  if (!finite(m.start) || !finite(m.end)) return "non-finite coordinate";
  if (!std::isfinite(m.feed_mm_per_min) || m.feed_mm_per_min < 0) return "bad feed";
  if (!std::isfinite(m.dwell_s) || m.dwell_s < 0) return "bad dwell time";
  if (!std::isfinite(m.spindle_rpm) || m.spindle_rpm < 0) return "bad spindle speed";
  if (!std::isfinite(m.ball_radius_mm) || m.ball_radius_mm < 0 || m.flutes < 0 || m.flutes > kMaxFlutes || !std::isfinite(m.pick_feed_mm) ||
      m.pick_feed_mm < 0 || !std::isfinite(m.target_rmax_um) || m.target_rmax_um < 0)
    return "bad process parameters";
  if (!std::isfinite(m.path_tolerance_mm) || m.path_tolerance_mm < 0) return "bad path tolerance";
  if (m.kind == static_cast<int8_t>(BlockKind::kEvent) &&
      (m.event_kind <= 0 || m.event_kind > static_cast<int8_t>(EventKind::kLast) || !std::isfinite(m.event_value)))
    return "bad event";
  if (m.kind == static_cast<int8_t>(BlockKind::kEvent) && m.event_kind == static_cast<int8_t>(EventKind::kWaitInput)) {
    const InputWait w = InputWait::of(m.event_number);
    if (m.event_number < 0 || m.event_number >= 20000 || w.index >= 64 || w.mode > InputWait::kLow ||
        (w.analog && w.mode != InputWait::kImmediate) || m.event_value < 0)
      return "bad input wait (M66)";
  }
  if (m.kind == static_cast<int8_t>(BlockKind::kEvent) && m.event_kind == static_cast<int8_t>(EventKind::kSpindleOrient) &&
      (m.event_number < 0 || m.event_number > 2))
    return "bad spindle orientation (M19 P" + std::to_string(m.event_number) + ")";
  if (m.source_file.size() > 4096 || m.event_text.size() > 4096) return "source file or event text too long";
  Block b;
  b.index = m.block_index;
  b.source_line = m.source_line;
  b.source_column = m.source_column;
  b.source_file = m.source_file;
  if (b.index >= 0 && m.kind == static_cast<int8_t>(BlockKind::kEvent)) {
    b.event.kind = static_cast<EventKind>(m.event_kind);
    b.event.number = m.event_number;
    b.event.value = m.event_value;
    b.event.text = m.event_text;
  }
  if (m.kind == static_cast<int8_t>(BlockKind::kEnd)) {
    if (m.event_number != kEndOfProgram && m.event_number != kEndOfOperatorLine)
      return "bad end (" + std::to_string(m.event_number) + ": 0 a program's, 1 an operator line's)";
    b.event.number = m.event_number;
  }
  if (m.kind == static_cast<int8_t>(BlockKind::kLine) && m.event_kind == kProbeWire) {
    if (m.event_number < 2 || m.event_number > 5) return "bad probing move (G38." + std::to_string(m.event_number) + ")";
    b.probe = static_cast<int8_t>(m.event_number);
  }
  if (m.kind == static_cast<int8_t>(BlockKind::kLine) && (m.event_kind == kSyncWire + kSyncG33 || m.event_kind == kSyncWire + kSyncRigidTap)) {
    if (!std::isfinite(m.event_value) || !(m.event_value > 0)) return "bad spindle-synchronised move (pitch)";
    if (m.event_kind == kSyncWire + kSyncRigidTap && !(m.dwell_s >= 1)) return "bad rigid tap (retract scale below 1)";
    b.sync = static_cast<int8_t>(m.event_kind - kSyncWire);
    b.sync_pitch_mm = m.event_value;
    b.tap_retract_scale = m.event_kind == kSyncWire + kSyncRigidTap ? m.dwell_s : 1.0;
  }
  b.kind = static_cast<BlockKind>(m.kind);
  b.start = m.start;
  b.end = m.end;
  b.feed_mm_per_min = m.feed_mm_per_min;
  b.dwell_s = b.sync != kSyncNone ? 0.0 : m.dwell_s;  // a synchronised move's dwell_s is its retract scale
  b.spindle_rpm = m.spindle_rpm;
  b.process = ProcessParams{m.ball_radius_mm, m.flutes, m.pick_feed_mm, m.target_rmax_um};
  b.path_tolerance_mm = m.path_tolerance_mm;
  const bool feed_move = b.kind == BlockKind::kLine || b.kind == BlockKind::kArcCw || b.kind == BlockKind::kArcCcw ||
                         b.kind == BlockKind::kNurbs;
  if (feed_move && !(b.feed_mm_per_min > 0)) return std::string(to_string(b.kind)) + " without a feed";
  if (b.kind == BlockKind::kArcCw || b.kind == BlockKind::kArcCcw) {
    b.arc.center = m.center;
    b.arc.plane = m.plane;
    b.arc.turns = m.turns;
    const std::string why = check_arc_block(b);
    if (!why.empty()) return why;
  }
  if (b.kind == BlockKind::kNurbs) {
    if (m.num_control_points < 0 || m.num_control_points > kMaxNurbsControlPoints || m.num_knots < 0 ||
        m.num_knots > kMaxNurbsControlPoints + kMaxNurbsOrder)
      return "NURBS counts out of range";
    if (m.knots.size() != static_cast<size_t>(m.num_knots) ||
        m.control_points.size() != static_cast<size_t>(m.num_control_points) ||
        m.weights.size() != static_cast<size_t>(m.num_control_points))
      return "NURBS arrays disagree with their counts";
    b.nurbs.order = m.order;
    b.nurbs.knots = m.knots;
    b.nurbs.weights = m.weights;
    b.nurbs.control_points.reserve(m.control_points.size());
    for (const auto& p : m.control_points) {
      if (p.size() != 3) return "NURBS control point without exactly 3 coordinates";
      b.nurbs.control_points.push_back({p[0], p[1], p[2]});
    }
    const std::string why = check_nurbs_block(b);
    if (!why.empty()) return "NURBS: " + why;
  }
  *out = std::move(b);
  return {};
}

cnc::lcmt_program_block from_v2(const cnc::lcmt_program_block_v2& v) {
  cnc::lcmt_program_block m;
  m.utime = v.utime;
  m.seq = v.seq;
  m.sender = v.sender;
  m.program_token = v.program_token;
  m.block_index = v.block_index;
  m.source_line = v.source_line;
  m.source_column = v.source_column;
  m.source_file = v.source_file;
  m.kind = v.kind;
  m.num_axes = v.num_axes;
  m.start = v.start;
  m.end = v.end;
  m.center = v.center;
  m.plane = v.plane;
  m.turns = v.turns;
  m.order = v.order;
  m.num_knots = v.num_knots;
  m.knots = v.knots;
  m.num_control_points = v.num_control_points;
  m.control_points = v.control_points;
  m.weights = v.weights;
  m.feed_mm_per_min = v.feed_mm_per_min;
  m.dwell_s = v.dwell_s;
  m.spindle_rpm = v.spindle_rpm;
  m.ball_radius_mm = v.ball_radius_mm;
  m.flutes = v.flutes;
  m.pick_feed_mm = v.pick_feed_mm;
  m.target_rmax_um = v.target_rmax_um;
  m.event_kind = v.event_kind;
  m.event_number = v.event_number;
  m.event_value = v.event_value;
  m.event_text = v.event_text;
  m.path_tolerance_mm = 0;
  return m;
}

}  // namespace cnc::program
