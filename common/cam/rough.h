#pragma once
// Shin et al.: z-level roughing. Levels are chosen bottom-up: from the part's lowest
// height, the next level is as high as the cusp limit allows at the smallest slope the
// part shows anywhere between the two (slope_profile's bands, cusp.h's z-step), capped
// at the cutter's largest step-down; heights of flat areas are levels of their own, and
// the march ends once the next level would be at or above the part's top.
//
// At each level z the tool centre must stay out of the keep-out region: every point of
// the part above the tip's height z + h lies within the cutter's radius at that height
// ρ(h) (the flat bottom and the corner arc) — for a flat cutter the part's slice at z
// grown by R; for a corner radius r, the union over n sub-levels 0 = h_0 < … < h_n = r
// (equal steps r/n in ρ) of the slice at z + h_i grown by ρ(h_{i+1}). That union holds
// the exact keep-out (the part above z + h_i holds all of it above z + h for h >= h_i,
// for a part whose cross-sections shrink upwards; an overhang, whose material sticks out
// beyond the sections under it, is not kept out and would be cut) and lies at most
// r/n + arc_tol outside it. Polygons and offsets are
// Clipper's (libpolyclipping), in integers of 1e-5 mm; round joins grown by arc_tol so
// their chords stay outside the true arc.
//
// Pocketing: the tool centres' region is the stock's outline grown by R (beyond it the
// tool cuts nothing) less the keep-out; its inward offsets by 0, stepover, 2·stepover, …
// give rings, cut from the stock's edge inwards (outer rings by rising offset), then
// from the middle to the part (hole rings by falling offset), so each level ends on the
// exact tool-offset contour. Rings at offset 0 lose their stretches along the grown
// outline (air; where the keep-out reaches it, what is left are open pieces of the
// contour), so the outermost whole ring bites `stepover` into the stock. Consecutive
// pieces are joined by a feed move at the level when the straight link stays off the
// keep-out and is no longer than 3·stepover; otherwise the tool retracts to the
// clearance plane. Levels are cut top-down.
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "common/cam/cusp.h"
#include "common/cam/cutter.h"
#include "common/cam/gcode_writer.h"
#include "common/cam/mesh.h"
#include "common/cam/slice.h"

namespace cnc::cam {

struct Stock {
  double xmin = 0, ymin = 0, zmin = 0, xmax = 0, ymax = 0, zmax = 0;
};
// "box": the mesh's bounds; "margin" or "margin:MM": the bounds grown by MM (default
// 2) in x, y and at the top. Throws std::invalid_argument naming the spec.
Stock parse_stock(const std::string& spec, const Bounds& part);

struct RoughSpec {
  Cutter cutter;
  double cusp_mm = 0.1;
  double stepover_frac = 0.4;   // ring spacing as a fraction of the diameter, (0, 0.9]
  double max_stepdown_mm = 0;   // 0: the cutter's flute length
  double band_mm = 0.01;        // height bands of the slope profile
  double flat_deg = 0.5;        // facets flatter than this are flat areas
  int corner_samples = 0;       // n, sub-levels of the corner arc; 0: r / (0.02 cusp), within [16, 64]
  double arc_tol_mm = 0.002;    // Clipper's round joins
  int threads = 1;              // levels planned side by side (the result does not depend on it)
};

enum class LevelKind { kSlope, kFlat, kFloor, kFacing };
const char* level_kind_name(LevelKind k);

struct Level {
  double z = 0;
  LevelKind kind = LevelKind::kSlope;
  double min_slope_rad = 0;  // smallest slope in the band below (kSlope), +inf if none
  double step_mm = 0;        // z − previous level
};

// The levels, bottom-up, for a part spanning [zbot, ztop] under a stock whose top is
// stock_top: cusp-limited levels and flat areas above zbot (not the part's base itself),
// then facing levels from ztop up to the stock's top when the stock stands above the
// part (at most max_stepdown apart). The floor level at zbot is plan_roughing's call.
// `slack_mm`: how far the contours may stand outside the exact ones (r/n + arc_tol);
// the tool standing that much farther out raises the cusp by at most slack·sin θ, so the
// step at slope θ is the one for a cusp of h − slack·sin θ (at least h/10).
// `wall_at_base`: no level is cut at zbot (the part fills the stock there), so below the
// first level the cusp is bounded by the stock's side, a vertical line where the part
// meets its base, not by a cutter's corner: the first step is then at most a flat
// cutter's (an upper bound of that cusp: equal where the upper cutter's flat bottom
// reaches the side).
std::vector<Level> choose_levels(const SlopeProfile& profile, const Cutter& cutter, double cusp_mm,
                                 double max_stepdown_mm, double zbot, double ztop, double stock_top,
                                 bool wall_at_base = false, double slack_mm = 0);

using Polygons = std::vector<Loop>;  // closed loops, outer counter-clockwise, holes clockwise

// The tool centre's keep-out region at level z (see above), oriented.
Polygons keep_out(const Mesh& mesh, const Cutter& cutter, double z, int corner_samples, double arc_tol_mm);
Polygons keep_out(const MeshSlicer& slicer, const Cutter& cutter, double z, int corner_samples, double arc_tol_mm);

struct Ring {
  Loop points;
  int offset_index = 0;  // offset by offset_index·stepover from the region's boundary
  bool hole = false;     // around the part (true) or along the stock (false)
  bool closed = true;    // false: an open piece of an offset-0 ring (the contour near the stock's edge)
};
// The rings of one level, in cutting order.
std::vector<Ring> pocket_rings(const Polygons& keepout, const Stock& stock, const Cutter& cutter, double stepover_mm,
                               double arc_tol_mm, Polygons* region = nullptr);

struct LevelPath {
  double z = 0;
  double approach_z = 0;  // rapids come down to here (1 mm above the level cut before), then plunge
  LevelKind kind = LevelKind::kSlope;
  std::vector<std::vector<XY>> chains;  // each cut at the level without a retract
  std::vector<std::size_t> ring_end;    // per chain: chain[ring_end] closes its first ring
                                        // (== chain[0]); 0 when it starts with an open piece
  std::size_t rings = 0;
  double contour_mm = 0;  // length of the exact tool-offset contour (the offset-0 hole rings)
};

struct RoughPlan {
  Stock stock;
  std::vector<Level> levels;       // bottom-up, as chosen (the floor first if there is one)
  std::vector<LevelPath> paths;    // top-down, the cutting order; levels with nothing to cut (at the
                                   // stock's top, or wholly inside the keep-out) left out
  double feed_mm = 0;              // at the levels: rings and links
  double contour_mm = 0;           // the tool-offset contours alone
  std::size_t retracts = 0;        // chains
};

// progress(levels done, levels) after each level, if given (from one worker at a time).
RoughPlan plan_roughing(const Mesh& mesh, const Stock& stock, const RoughSpec& spec,
                        const std::function<void(std::size_t, std::size_t)>& progress = {});

// A ramp into a chain that starts with a closed ring: the ring walked backwards from its
// start for the length a descent of z_from − z_to needs at `ramp_rad` (around it again
// if it is short, at most 20 times), returned forwards: from its first point at z_from
// down the ring's own path to the chain's start at z_to. The ring is off the keep-out at
// z_to, so it is at every height above (sections shrink upwards). Empty when the chain
// starts with an open piece, the ring is too short, or ramp_rad <= 0.
std::vector<Vec3> ramp_into(const std::vector<XY>& chain, std::size_t ring_end, double z_from, double z_to,
                            double ramp_rad);

// The plan as G-code through GcodeWriter (setup.safe_z_mm is the clearance plane): per
// chain a rapid at the clearance plane, a rapid down to its approach height, then either
// a ramp down the chain's first ring at `ramp_deg` (> 0, where there is a ring) at the
// cutting feed or a plunge at the plunge feed, the chain at the cutting feed, a rapid
// back up. Coordinates minus `zero`.
std::string rough_gcode(const RoughPlan& plan, const GcodeSetup& setup, const Vec3& zero, double ramp_deg = 0);

// The machining time of a plan under a constant-speed model: feed at the levels,
// plunges from `approach_mm` above the level, rapids at `rapid_mm_per_min` between
// chains via the clearance plane `clear_z`; no acceleration.
struct TimeModel {
  double feed_mm_per_min = 1000, plunge_mm_per_min = 300, rapid_mm_per_min = 15000;
};
struct PlanTime {
  double feed_mm = 0, ramp_mm = 0, plunge_mm = 0, rapid_mm = 0, seconds = 0;  // ramps at the cutting feed
};
PlanTime plan_time(const RoughPlan& plan, double clear_z, const TimeModel& model, double ramp_deg = 0);

}  // namespace cnc::cam
