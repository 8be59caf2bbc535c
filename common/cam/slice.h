#pragma once
// Slices of a triangle mesh by horizontal planes, and the slopes along them (Shin et al.).
//
// slice_mesh cuts every triangle that has vertices on both sides of the plane z = h
// (a vertex at h counts as below, so a horizontal facet at h is not part of the slice
// at h: the tool's level may sit on it) into a segment whose ends are computed from the
// edge's vertices in a canonical order, so the two triangles of an edge give the same
// point bit for bit; each segment is directed by its triangle's outward normal (the
// STL's winding, counter-clockwise seen from outside) so that the part lies on its left,
// and segments are chained head to tail into loops: outer loops counter-clockwise, holes
// (a dip in the part) clockwise, read with the non-zero rule. An open surface (a height
// field, a shell) is first given a skirt: a vertical wall under each boundary edge down to
// 1 mm below the mesh, so it slices like the solid standing on it. Chains that still do
// not close are closed by their chord and counted.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "common/cam/drop_cutter.h"
#include "common/cam/mesh.h"

namespace cnc::cam {

using Loop = std::vector<XY>;

struct Slice {
  std::vector<Loop> loops;
  std::size_t open_chains = 0;  // closed by their chord
  std::size_t segments = 0;
};

Slice slice_mesh(const Mesh& mesh, double z);

// The same, many times over one mesh: triangles binned by height (each in every bin its
// z range meets), so a slice reads only the triangles of one bin.
class MeshSlicer {
 public:
  explicit MeshSlicer(const Mesh& mesh);  // copies the mesh, with its skirt
  Slice slice(double z) const;

 private:
  Mesh mesh_;
  double z0_ = 0, dz_ = 1;
  std::vector<std::uint32_t> start_, tris_;  // bin b holds tris_[start_[b] .. start_[b + 1])
};

// Signed area (counter-clockwise positive) and length of a closed loop.
double loop_area(const Loop& loop);
double loop_length(const Loop& loop);

// The smallest slope (radians from horizontal) of the facets that cross each height band
// [z0 + i·dz, z0 + (i+1)·dz], over the mesh's height, from each facet's plane (|nz|: the
// winding is not trusted); facets flatter than `flat_rad` do not count: they are flat
// areas, whose heights are listed (one entry per distinct height, to 1e-6 mm, rising;
// the part's underside at its lowest height is one, which the levels leave out).
struct SlopeProfile {
  double z0 = 0, dz = 0.01;
  std::vector<double> min_slope;  // +inf where no facet crosses the band
  std::vector<double> flat_z;
  double slope_at_band(std::size_t i) const { return min_slope[i]; }
};
SlopeProfile slope_profile(const Mesh& mesh, double dz, double flat_rad);

}  // namespace cnc::cam
