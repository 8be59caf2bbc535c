#pragma once
// Parallel-pass (raster) finishing paths over a mesh with a fixed step along each
// pass: the first half of seed 003's paths, before its step control. Passes run along
// `angle_deg` (from +X, counter-clockwise), `pick_mm` apart, covering the mesh's xy
// bounds, alternately forward and back (zig-zag); along each pass the CL points are
// `step_mm` apart at most (the step is shrunk to fit the pass exactly). Points whose
// cutter touches nothing split a pass into separate cuts.
#include <cstddef>
#include <vector>

#include "common/cam/drop_cutter.h"
#include "common/cam/mesh.h"

namespace cnc::cam {

struct RasterSpec {
  double pick_mm = 1;
  double step_mm = 0.1;
  double angle_deg = 0;
};

struct RasterPath {
  std::vector<std::vector<Vec3>> cuts;  // in cutting order
  std::size_t passes = 0;
  std::size_t points_dropped = 0;       // CL points computed, touched or not
};

// The XY points of each pass, in cutting order. Throws std::invalid_argument for a
// pick or step that is not > 0.
std::vector<std::vector<XY>> raster_passes(const Bounds& bounds, const RasterSpec& spec);

RasterPath raster_fixed_step(const DropCutter& dc, const Bounds& bounds, const RasterSpec& spec, int threads);

// Seed 003's step control along each pass (same passes as above): the next step is
// predicted from the circle through the last three CL points (chord error κL²/8 = β),
// at most `spec.step_mm`; the CL points at k/n of the step (n = 16, more on steep chords
// so that their spacing along the chord stays that of a flat one, up to 512) are computed and
// the step halved (the middle becoming its end) while the distance of any of them from
// the chord (normal to it) exceeds 0.9·`beta_mm` (a margin for the CL surface between
// the probes), down to `min_step_mm` — which also walks into
// concave corners, where the curvature has no bound, by bisection. Surface edges (a
// step whose end touches nothing) are found by bisection to `min_step_mm`, so a cut
// starts and ends on the surface's last CL points.
struct AdaptiveSpec {
  double beta_mm = 0.01;
  double min_step_mm = 1e-3;
};
RasterPath raster_adaptive(const DropCutter& dc, const Bounds& bounds, const RasterSpec& spec,
                           const AdaptiveSpec& adaptive, int threads);

// The largest distance between the path's segments and the exact CL surface along
// them: of `samples` CL points inside each segment from the segment (3-D); 0 for none.
double path_deviation(const DropCutter& dc, const RasterPath& path, int samples, int threads);

}  // namespace cnc::cam
