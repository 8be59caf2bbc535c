#include "common/cam/slice.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <unordered_map>

namespace cnc::cam {
namespace {

bool less_xyz(const Vec3& p, const Vec3& q) {
  if (p.x != q.x) return p.x < q.x;
  if (p.y != q.y) return p.y < q.y;
  return p.z < q.z;
}

// The point where edge p–q crosses z, from the edge's vertices in a canonical order.
XY crossing(Vec3 p, Vec3 q, double z) {
  if (less_xyz(q, p)) std::swap(p, q);
  const double t = (z - p.z) / (q.z - p.z);
  return {p.x + t * (q.x - p.x), p.y + t * (q.y - p.y)};
}

struct Key {
  std::uint64_t x, y;
  bool operator==(const Key& o) const { return x == o.x && y == o.y; }
};
struct KeyHash {
  std::size_t operator()(const Key& k) const {
    return static_cast<std::size_t>(k.x * 0x9E3779B97F4A7C15ull ^ (k.y + 0x632BE59BD9B4E019ull + (k.x << 6)));
  }
};
Key key(const XY& p) { return {std::bit_cast<std::uint64_t>(p.x + 0.0), std::bit_cast<std::uint64_t>(p.y + 0.0)}; }

}  // namespace

namespace {

// Slices the triangles idx[0..n) of the mesh (all of them when idx is null). Each segment
// is directed so that the part (the side its triangle's outward normal points away from)
// lies on its left: t = (−n_y, n_x).
Slice slice_triangles(const Mesh& mesh, const std::uint32_t* idx, std::size_t n_tris, double z) {
  std::vector<std::array<XY, 2>> segs;
  for (std::size_t ti = 0; ti < n_tris; ++ti) {
    const Triangle& t = mesh.triangles[idx ? idx[ti] : ti];
    int above = 0;
    for (const Vec3& v : t.v) above += v.z > z;
    if (above == 0 || above == 3) continue;
    XY ends[2];
    int n = 0;
    for (int k = 0; k < 3; ++k) {
      const Vec3 &p = t.v[k], &q = t.v[(k + 1) % 3];
      if ((p.z > z) != (q.z > z)) ends[n++] = crossing(p, q, z);
    }
    if (n != 2 || (ends[0].x == ends[1].x && ends[0].y == ends[1].y)) continue;
    const Vec3 &a = t.v[0], &b = t.v[1], &c = t.v[2];
    const double nx = (b.y - a.y) * (c.z - a.z) - (b.z - a.z) * (c.y - a.y);
    const double ny = (b.z - a.z) * (c.x - a.x) - (b.x - a.x) * (c.z - a.z);
    if ((ends[1].x - ends[0].x) * -ny + (ends[1].y - ends[0].y) * nx < 0) std::swap(ends[0], ends[1]);
    segs.push_back({ends[0], ends[1]});
  }
  Slice out;
  out.segments = segs.size();
  // Chain head to tail: each point is normally the end of one segment and the start of one.
  std::unordered_map<Key, std::vector<std::uint32_t>, KeyHash> starts;
  starts.reserve(2 * segs.size());
  for (std::uint32_t i = 0; i < segs.size(); ++i) starts[key(segs[i][0])].push_back(i);
  std::vector<bool> used(segs.size(), false);
  auto next_from = [&](const XY& p) -> std::int64_t {
    const auto it = starts.find(key(p));
    if (it == starts.end()) return -1;
    for (std::uint32_t s : it->second)
      if (!used[s]) return s;
    return -1;
  };
  // Open chains first from their true beginnings (points no segment ends at), then loops.
  std::unordered_map<Key, int, KeyHash> ends_at;
  ends_at.reserve(segs.size());
  for (const auto& sg : segs) ++ends_at[key(sg[1])];
  auto walk = [&](std::uint32_t i) {
    used[i] = true;
    Loop chain{segs[i][0], segs[i][1]};
    bool closed = false;
    for (;;) {
      const XY p = chain.back();
      const XY& q = chain.front();
      if (p.x == q.x && p.y == q.y) {
        chain.pop_back();
        closed = true;
        break;
      }
      const std::int64_t s = next_from(p);
      if (s < 0) break;
      used[s] = true;
      chain.push_back(segs[s][1]);
    }
    if (!closed) ++out.open_chains;
    if (chain.size() >= 3) out.loops.push_back(std::move(chain));
  };
  for (std::uint32_t i = 0; i < segs.size(); ++i)
    if (!used[i] && ends_at.find(key(segs[i][0])) == ends_at.end()) walk(i);
  for (std::uint32_t i = 0; i < segs.size(); ++i)
    if (!used[i]) walk(i);
  return out;
}

// The mesh with a skirt: every boundary edge (used by one triangle only) gets a vertical
// wall down to 1 mm under the mesh, wound so that its normal points away from the
// triangle, so an open surface slices into closed loops like a solid standing on it.
Mesh with_skirt(const Mesh& mesh) {
  struct EdgeKey {
    std::uint64_t a[3], b[3];
    bool operator==(const EdgeKey& o) const {
      for (int k = 0; k < 3; ++k)
        if (a[k] != o.a[k] || b[k] != o.b[k]) return false;
      return true;
    }
  };
  struct EdgeHash {
    std::size_t operator()(const EdgeKey& e) const {
      std::uint64_t h = 1469598103934665603ull;
      for (int k = 0; k < 3; ++k) h = (h ^ e.a[k]) * 1099511628211ull, h = (h ^ e.b[k]) * 1099511628211ull;
      return static_cast<std::size_t>(h);
    }
  };
  auto bits = [](const Vec3& v, std::uint64_t* out) {
    out[0] = std::bit_cast<std::uint64_t>(v.x + 0.0);
    out[1] = std::bit_cast<std::uint64_t>(v.y + 0.0);
    out[2] = std::bit_cast<std::uint64_t>(v.z + 0.0);
  };
  auto edge_key = [&](const Vec3& p, const Vec3& q) {
    EdgeKey e{};
    const bool swap = less_xyz(q, p);
    bits(swap ? q : p, e.a);
    bits(swap ? p : q, e.b);
    return e;
  };
  std::unordered_map<EdgeKey, int, EdgeHash> count;
  count.reserve(3 * mesh.triangles.size());
  for (const Triangle& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) ++count[edge_key(t.v[k], t.v[(k + 1) % 3])];
  Mesh out = mesh;
  const double low = mesh_bounds(mesh).min.z - 1;
  for (const Triangle& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const Vec3 &u = t.v[k], &v = t.v[(k + 1) % 3];
      if (count[edge_key(u, v)] != 1) continue;
      const Vec3 ul{u.x, u.y, low}, vl{v.x, v.y, low};
      if (u.x == v.x && u.y == v.y) continue;  // a vertical boundary edge: no wall to add
      out.triangles.push_back({{v, u, ul}});
      out.triangles.push_back({{v, ul, vl}});
    }
  return out;
}

}  // namespace

Slice slice_mesh(const Mesh& mesh, double z) { return MeshSlicer(mesh).slice(z); }

MeshSlicer::MeshSlicer(const Mesh& part) : mesh_(with_skirt(part)) {
  const Mesh& mesh = mesh_;
  const Bounds b = mesh_bounds(mesh);
  const std::size_t n = mesh.triangles.size();
  const std::size_t bins = std::clamp<std::size_t>(n / 8, 1, 4096);
  z0_ = b.min.z;
  dz_ = std::max((b.max.z - b.min.z) / static_cast<double>(bins), 1e-9);
  auto bin = [&](double z) {
    return static_cast<std::size_t>(std::clamp((z - z0_) / dz_, 0.0, static_cast<double>(bins - 1)));
  };
  std::vector<std::uint32_t> count(bins + 1, 0);
  for (const Triangle& t : mesh.triangles) {
    const double lo = std::min({t.v[0].z, t.v[1].z, t.v[2].z}), hi = std::max({t.v[0].z, t.v[1].z, t.v[2].z});
    for (std::size_t k = bin(lo); k <= bin(hi); ++k) ++count[k + 1];
  }
  for (std::size_t k = 0; k < bins; ++k) count[k + 1] += count[k];
  start_ = count;
  tris_.resize(count[bins]);
  for (std::uint32_t i = 0; i < n; ++i) {
    const Triangle& t = mesh.triangles[i];
    const double lo = std::min({t.v[0].z, t.v[1].z, t.v[2].z}), hi = std::max({t.v[0].z, t.v[1].z, t.v[2].z});
    for (std::size_t k = bin(lo); k <= bin(hi); ++k) tris_[count[k]++] = i;
  }
}

Slice MeshSlicer::slice(double z) const {
  const std::size_t bins = start_.size() - 1;
  const double f = (z - z0_) / dz_;
  if (!(f >= -1e-9) || f > static_cast<double>(bins) + 1e-9) return {};
  const auto k = static_cast<std::size_t>(std::clamp(f, 0.0, static_cast<double>(bins - 1)));
  return slice_triangles(mesh_, tris_.data() + start_[k], start_[k + 1] - start_[k], z);
}

double loop_area(const Loop& loop) {
  double a = 0;
  for (std::size_t i = 0, n = loop.size(); i < n; ++i) {
    const XY &p = loop[i], &q = loop[(i + 1) % n];
    a += p.x * q.y - q.x * p.y;
  }
  return 0.5 * a;
}

double loop_length(const Loop& loop) {
  double l = 0;
  for (std::size_t i = 0, n = loop.size(); i < n; ++i) {
    const XY &p = loop[i], &q = loop[(i + 1) % n];
    l += std::hypot(q.x - p.x, q.y - p.y);
  }
  return l;
}

SlopeProfile slope_profile(const Mesh& mesh, double dz, double flat_rad) {
  SlopeProfile sp;
  sp.dz = dz;
  const Bounds b = mesh_bounds(mesh);
  sp.z0 = b.min.z;
  const auto bands = static_cast<std::size_t>(std::ceil((b.max.z - b.min.z) / dz)) + 1;
  sp.min_slope.assign(bands, std::numeric_limits<double>::infinity());
  std::vector<double> flats;
  for (const Triangle& t : mesh.triangles) {
    const Vec3 &p = t.v[0], &q = t.v[1], &r = t.v[2];
    const double ux = q.x - p.x, uy = q.y - p.y, uz = q.z - p.z, vx = r.x - p.x, vy = r.y - p.y, vz = r.z - p.z;
    double nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    const double len = std::sqrt(nx * nx + ny * ny + nz * nz);
    if (!(len > 0)) continue;
    nx /= len, ny /= len, nz /= len;
    // Winding is not trusted: a facet faces down only if it is the underside of the part,
    // which the slope of its plane alone cannot tell; take |nz| and the facet's plane.
    const double slope = std::atan2(std::hypot(nx, ny), std::fabs(nz));
    const double zlo = std::min({p.z, q.z, r.z}), zhi = std::max({p.z, q.z, r.z});
    if (slope < flat_rad) {
      flats.push_back((p.z + q.z + r.z) / 3);
      continue;
    }
    const auto i0 = static_cast<std::size_t>(std::max(0.0, std::floor((zlo - sp.z0) / dz)));
    const auto i1 = std::min(bands - 1, static_cast<std::size_t>(std::max(0.0, std::floor((zhi - sp.z0) / dz))));
    for (std::size_t i = i0; i <= i1; ++i) sp.min_slope[i] = std::min(sp.min_slope[i], slope);
  }
  std::sort(flats.begin(), flats.end());
  for (double z : flats)
    if (sp.flat_z.empty() || z - sp.flat_z.back() > 1e-6) sp.flat_z.push_back(z);
  return sp;
}

}  // namespace cnc::cam
