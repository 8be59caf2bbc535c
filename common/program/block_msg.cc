#include "common/program/block_msg.h"

#include <cmath>

namespace cnc::program {

cnc::lcmt_program_block to_msg(const Block& b, int64_t program_token) {
  cnc::lcmt_program_block m{};
  m.program_token = program_token;
  m.block_index = b.index;
  m.source_line = b.source_line;
  m.kind = static_cast<int8_t>(b.kind);
  m.num_axes = static_cast<int32_t>(b.end.size());
  m.start = b.start;
  m.end = b.end;
  m.center.assign(b.end.size(), 0.0);
  m.plane = 17;
  m.turns = 0;
  m.order = 0;
  m.num_knots = 0;
  m.num_control_points = 0;
  m.feed_mm_per_min = b.feed_mm_per_min;
  m.dwell_s = b.dwell_s;
  m.spindle_rpm = b.spindle_rpm;
  m.ball_radius_mm = b.process.ball_radius_mm;
  m.flutes = b.process.flutes;
  m.pick_feed_mm = b.process.pick_feed_mm;
  m.target_rmax_um = b.process.target_rmax_um;
  return m;
}

std::string from_msg(const cnc::lcmt_program_block& m, int num_axes, Block* out) {
  if (m.num_axes != num_axes) return "block has " + std::to_string(m.num_axes) + " axes, machine has " + std::to_string(num_axes);
  if (m.kind < 0 || m.kind > static_cast<int8_t>(BlockKind::kEnd)) return "unknown block kind " + std::to_string(m.kind);
  for (int a = 0; a < num_axes; ++a)
    if (!std::isfinite(m.start[a]) || !std::isfinite(m.end[a])) return "non-finite coordinate";
  if (!std::isfinite(m.feed_mm_per_min) || m.feed_mm_per_min < 0) return "bad feed";
  if (!std::isfinite(m.dwell_s) || m.dwell_s < 0) return "bad dwell time";
  Block b;
  b.index = m.block_index;
  b.source_line = m.source_line;
  b.kind = static_cast<BlockKind>(m.kind);
  b.start = m.start;
  b.end = m.end;
  b.feed_mm_per_min = m.feed_mm_per_min;
  b.dwell_s = m.dwell_s;
  b.spindle_rpm = m.spindle_rpm;
  b.process = ProcessParams{m.ball_radius_mm, m.flutes, m.pick_feed_mm, m.target_rmax_um};
  *out = std::move(b);
  return {};
}

}  // namespace cnc::program
