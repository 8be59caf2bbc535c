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

// Slices the triangles idx[0..n) of the mesh (all of them when idx is null).
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
    if (n == 2 && (ends[0].x != ends[1].x || ends[0].y != ends[1].y)) segs.push_back({ends[0], ends[1]});
  }
  Slice out;
  out.segments = segs.size();
  // Each point joins (normally) two segments; chain them.
  std::unordered_map<Key, std::vector<std::uint32_t>, KeyHash> at;
  at.reserve(2 * segs.size());
  for (std::uint32_t i = 0; i < segs.size(); ++i) {
    at[key(segs[i][0])].push_back(i);
    at[key(segs[i][1])].push_back(i);
  }
  std::vector<bool> used(segs.size(), false);
  auto next_seg = [&](const XY& p, std::uint32_t from) -> std::int64_t {
    const auto it = at.find(key(p));
    if (it == at.end()) return -1;
    for (std::uint32_t s : it->second)
      if (s != from && !used[s]) return s;
    return -1;
  };
  for (std::uint32_t i = 0; i < segs.size(); ++i) {
    if (used[i]) continue;
    used[i] = true;
    Loop fwd{segs[i][0], segs[i][1]};
    std::uint32_t cur = i;
    bool closed = false;
    for (;;) {  // forward from the second end
      const XY& p = fwd.back();
      const std::int64_t s = next_seg(p, cur);
      if (s < 0) {
        const XY& q = fwd.front();
        closed = p.x == q.x && p.y == q.y;
        break;
      }
      used[s] = true;
      cur = static_cast<std::uint32_t>(s);
      const auto& sg = segs[cur];
      const XY nxt = (key(sg[0]) == key(p)) ? sg[1] : sg[0];
      const XY& q = fwd.front();
      if (nxt.x == q.x && nxt.y == q.y) {
        closed = true;
        break;
      }
      fwd.push_back(nxt);
    }
    if (!closed) {  // backward from the first end
      std::vector<XY> back;
      XY p = fwd.front();
      cur = i;
      for (;;) {
        const std::int64_t s = next_seg(p, cur);
        if (s < 0) break;
        used[s] = true;
        cur = static_cast<std::uint32_t>(s);
        const auto& sg = segs[cur];
        p = (key(sg[0]) == key(p)) ? sg[1] : sg[0];
        back.push_back(p);
      }
      std::reverse(back.begin(), back.end());
      back.insert(back.end(), fwd.begin(), fwd.end());
      fwd.swap(back);
      ++out.open_chains;
    }
    if (fwd.size() >= 3) out.loops.push_back(std::move(fwd));
  }
  return out;
}

}  // namespace

Slice slice_mesh(const Mesh& mesh, double z) { return slice_triangles(mesh, nullptr, mesh.triangles.size(), z); }

MeshSlicer::MeshSlicer(const Mesh& mesh) : mesh_(mesh) {
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
