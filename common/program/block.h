#pragma once
// A program block as the interpolator core sees it: plain data, no LCM.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace cnc::program {

constexpr int kMaxAxes = 9;

enum class BlockKind : int8_t { kRapid = 0, kLine = 1, kArcCw = 2, kArcCcw = 3, kNurbs = 4, kDwell = 5, kEnd = 6 };

const char* to_string(BlockKind kind);

struct ProcessParams {
  double ball_radius_mm = 0;
  int flutes = 0;
  double pick_feed_mm = 0;
  double target_rmax_um = 0;
};

struct Block {
  int64_t index = 0;
  int32_t source_line = 0;
  BlockKind kind = BlockKind::kLine;
  std::vector<double> start;  // one entry per machine axis, mm
  std::vector<double> end;
  double feed_mm_per_min = 0;
  double dwell_s = 0;
  double spindle_rpm = 0;
  ProcessParams process;
};

}  // namespace cnc::program
