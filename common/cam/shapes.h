#pragma once
// Analytic parts as meshes, for tests and for Shin et al.'s Table 1: height fields over a
// rectangle (a grid, two triangles per cell, counter-clockwise seen from above), a box,
// a square pyramid or frustum, a hemisphere cap, and the two symmetric parts of
// Shin et al.'s simulation (50 × 50 base, heights 43.9 and 32.4).
#include <functional>
#include <string>

#include "common/cam/mesh.h"

namespace cnc::cam {

Mesh make_height_field(const std::function<double(double, double)>& z, double x0, double y0, double x1, double y1,
                       int nx, int ny);

// A closed box (12 triangles, outward normals).
Mesh make_box(double x0, double y0, double z0, double x1, double y1, double z1);

// A square frustum on [−L/2, L/2]², base at z = 0, flat top of side `top_side` at height
// h (top_side 0: a pyramid), its four faces planar (two triangles each), open below.
Mesh make_frustum(double base_side, double top_side, double h);

// The upper half of a sphere of radius R centred at the origin: `rings` latitude bands
// of `segments` quads (two triangles each; the top band is a fan), open at z = 0.
Mesh make_hemisphere(double R, int rings, int segments);

// Shin et al.'s Table 1 parts, which the paper shows only as a picture (its figure 6): a
// symmetric bump on a 50 × 50 square base, centred at the origin, z = 0 on the base's
// border, with a flat top at the stated height (both tools put their last level there).
// The profile is z = min(H, 1.25 H·c(x)·c(y)) with c(t) = cos(π t / 50), H = 43.9 for "a"
// and 32.4 for "b" — "b" is "a" lowered, so it has the smaller slopes the paper says it
// has; the plateau is where c(x)·c(y) >= 0.8. `n` cells per side.
Mesh make_table1_part(const std::string& which, int n);

}  // namespace cnc::cam
