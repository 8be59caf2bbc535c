#pragma once
// Smooth random height fields as meshes, for tests and benches: a grid of
// (cols + 1) × (rows + 1) vertices at `step_mm`, two triangles per cell, heights a
// sum of `bumps` Gaussian hills and dips with a fixed seed (same seed, same mesh).
#include <cstdint>

#include "common/cam/mesh.h"

namespace cnc::cam {

struct TerrainSpec {
  int cols = 100, rows = 100;
  double step_mm = 0.5;
  int bumps = 40;
  double height_mm = 10;  // largest bump height
  std::uint64_t seed = 1;
};

Mesh make_terrain(const TerrainSpec& spec);

}  // namespace cnc::cam
