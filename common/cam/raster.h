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

}  // namespace cnc::cam
