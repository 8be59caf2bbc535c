#include "common/cam/terrain.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace cnc::cam {

Mesh make_terrain(const TerrainSpec& spec) {
  struct Bump {
    double x, y, sigma, h;
  };
  std::mt19937_64 rng(spec.seed);
  const double w = spec.cols * spec.step_mm, d = spec.rows * spec.step_mm;
  std::uniform_real_distribution<double> ux(0, w), uy(0, d), us(0.05, 0.25), uh(-0.5, 1.0);
  std::vector<Bump> bumps(static_cast<std::size_t>(spec.bumps));
  for (Bump& b : bumps) b = {ux(rng), uy(rng), us(rng) * std::min(w, d), uh(rng) * spec.height_mm};
  const auto nx = static_cast<std::size_t>(spec.cols) + 1, ny = static_cast<std::size_t>(spec.rows) + 1;
  std::vector<Vec3> grid(nx * ny);
  for (std::size_t j = 0; j < ny; ++j) {
    for (std::size_t i = 0; i < nx; ++i) {
      const double x = static_cast<double>(i) * spec.step_mm, y = static_cast<double>(j) * spec.step_mm;
      double z = 0;
      for (const Bump& b : bumps) {
        const double dx = x - b.x, dy = y - b.y;
        z += b.h * std::exp(-(dx * dx + dy * dy) / (2 * b.sigma * b.sigma));
      }
      grid[j * nx + i] = {x, y, z};
    }
  }
  Mesh mesh;
  mesh.triangles.reserve(2 * (nx - 1) * (ny - 1));
  for (std::size_t j = 0; j + 1 < ny; ++j) {
    for (std::size_t i = 0; i + 1 < nx; ++i) {
      const Vec3 &a = grid[j * nx + i], &b = grid[j * nx + i + 1], &c = grid[(j + 1) * nx + i + 1],
                 &e = grid[(j + 1) * nx + i];
      mesh.triangles.push_back({{a, b, c}});
      mesh.triangles.push_back({{a, c, e}});
    }
  }
  return mesh;
}

}  // namespace cnc::cam
