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

// Seed 000's process parameters for the roughness feed law. The law applies when
// all four are set (> 0) and the spindle turns.
struct ProcessParams {
  double ball_radius_mm = 0;
  int flutes = 0;
  double pick_feed_mm = 0;
  double target_rmax_um = 0;
  bool active() const { return ball_radius_mm > 0 && flutes > 0 && pick_feed_mm > 0 && target_rmax_um > 0; }
};

// Circular arc (G2/G3) in the plane of G17 (XY), G18 (ZX) or G19 (YZ); a move of
// the third axis makes it a helix. Angles follow the plane's right-hand rule.
struct ArcGeometry {
  std::vector<double> center;  // one entry per machine axis; only the plane's two matter
  int plane = 17;              // 17, 18, 19
  int turns = 0;               // extra full turns (RS274 P word), 0 for a plain arc
};

// Rational B-spline in machine X, Y, Z (the first three axes). order = degree + 1;
// knots.size() == control_points.size() + order; clamped (first and last knot
// repeated `order` times); weights > 0. The curve starts at `Block::start`.
struct NurbsGeometry {
  int order = 0;
  std::vector<double> knots;
  std::vector<std::array<double, 3>> control_points;
  std::vector<double> weights;
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
  ArcGeometry arc;      // kArcCw, kArcCcw
  NurbsGeometry nurbs;  // kNurbs
};

}  // namespace cnc::program
