#pragma once
// Parallel-pass (raster) finishing paths over a mesh with a fixed step along each
// pass: the first half of Hwang's paths, before its step control. Passes run along
// `angle_deg` (from +X, counter-clockwise), `pick_mm` apart, covering the mesh's xy
// bounds, alternately forward and back (zig-zag); along each pass the CL points are
// `step_mm` apart at most (the step is shrunk to fit the pass exactly). Points whose
// cutter touches nothing split a pass into separate cuts.
#include <atomic>
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
  std::size_t corners = 0;              // concave corners found by the step control's search
};

// Counters a caller may poll from another thread for progress reports: passes walked
// and CL points computed so far (the step control adds a pass's points when it ends).
struct RasterProgress {
  std::atomic<std::size_t> passes{0}, points{0};
};

// The XY points of each pass, in cutting order. Throws std::invalid_argument for a
// pick or step that is not > 0.
std::vector<std::vector<XY>> raster_passes(const Bounds& bounds, const RasterSpec& spec);

RasterPath raster_fixed_step(const DropCutter& dc, const Bounds& bounds, const RasterSpec& spec, int threads,
                             RasterProgress* progress = nullptr);

// Hwang's step control along each pass (same passes as above): the next step is
// predicted from the circle through the last three CL points (chord error κL²/8 = β),
// at most `spec.step_mm`; the CL points at k/n of the step (n = 16, more on steep chords
// so that their spacing along the chord stays that of a flat one, up to 512) are computed and
// the step halved (the middle becoming its end) while the distance of any of them from
// the chord (normal to it) exceeds 0.9·`beta_mm` (a margin for the CL surface between
// the probes), down to `min_step_mm`.
// Concave corners (`corner_search`, the paper's): when a step fails with the CL surface
// under the chord, and the tangents of the CL surface at the step's ends meet inside it
// close to the CL surface (a crease, where the tool touches two faces, not a smooth
// valley), the crease is found by bisection on the one-sided slopes to `corner_tol_mm`
// along the pass and becomes the step's end: the tool sits in the corner (its CL height
// exact there) and the walk goes on from it at the longest step. Without the search,
// the halving alone closes in on a corner until the chord over it holds β.
// Surface edges (a step whose end touches nothing) are found by bisection to
// `min_step_mm`, so a cut starts and ends on the surface's last CL points.
struct AdaptiveSpec {
  double beta_mm = 0.01;
  double min_step_mm = 1e-3;
  bool corner_search = true;
  double corner_tol_mm = 1e-7;
};
RasterPath raster_adaptive(const DropCutter& dc, const Bounds& bounds, const RasterSpec& spec,
                           const AdaptiveSpec& adaptive, int threads, RasterProgress* progress = nullptr);

// The largest distance between the path's segments and the exact CL surface along
// them: of `samples` CL points inside each segment from the segment (3-D); 0 for none.
// `progress`, if given, counts the CL points computed.
double path_deviation(const DropCutter& dc, const RasterPath& path, int samples, int threads,
                      RasterProgress* progress = nullptr);

}  // namespace cnc::cam
