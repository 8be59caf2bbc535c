#pragma once
// Triangle meshes for offline CAM (Hwang): a plain list of triangles in mm, no
// connectivity. STL has none, and the drop-cutter needs none.
#include <array>
#include <cstddef>
#include <vector>

namespace cnc::cam {

struct Vec3 {
  double x = 0, y = 0, z = 0;
};

struct Triangle {
  std::array<Vec3, 3> v;
};

struct Mesh {
  std::vector<Triangle> triangles;
};

struct Bounds {
  Vec3 min, max;
};

// Bounds of all vertices; {0,0,0}-{0,0,0} for an empty mesh.
Bounds mesh_bounds(const Mesh& mesh);

// Twice the area of the triangle, |(b − a) × (c − a)|.
double twice_area(const Triangle& t);

// A triangle with no area to speak of: |(b − a) × (c − a)| <= 1e-12 · (longest edge)²,
// i.e. its height over the longest edge is under 1e-12 of that edge (collinear or
// repeated vertices, up to float rounding of the STL's coordinates).
bool is_zero_area(const Triangle& t);

}  // namespace cnc::cam
