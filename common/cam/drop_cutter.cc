#include "common/cam/drop_cutter.h"

#include <algorithm>
#include <atomic>
#include <cstring>
#include <unordered_map>
#include <unordered_set>
#include <cmath>
#include <stdexcept>

#include "common/util/parallel_for.h"

namespace cnc::cam {
namespace {
constexpr double kNoContact = -std::numeric_limits<double>::infinity();

float float_down(double v) {
  float f = static_cast<float>(v);
  if (static_cast<double>(f) > v) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
  return f;
}
float float_up(double v) {
  float f = static_cast<float>(v);
  if (static_cast<double>(f) < v) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}
}  // namespace

const char* contact_name(Contact c) {
  switch (c) {
    case Contact::kNone: return "none";
    case Contact::kFacet: return "facet";
    case Contact::kVertex: return "vertex";
    case Contact::kEdge: return "edge";
  }
  return "?";
}

PreparedTriangle prepare(const Triangle& t) {
  PreparedTriangle p;
  p.v = t.v;
  const Vec3 &a = t.v[0], &b = t.v[1], &c = t.v[2];
  const double ux = b.x - a.x, uy = b.y - a.y, uz = b.z - a.z;
  const double vx = c.x - a.x, vy = c.y - a.y, vz = c.z - a.z;
  double nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
  const double n = std::sqrt(nx * nx + ny * ny + nz * nz);
  if (n > 0) {
    if (nz < 0) nx = -nx, ny = -ny, nz = -nz;
    p.nx = nx / n, p.ny = ny / n, p.nz = nz / n;
    p.nxy = std::hypot(p.nx, p.ny);
  }
  p.xmin = std::min({a.x, b.x, c.x});
  p.xmax = std::max({a.x, b.x, c.x});
  p.ymin = std::min({a.y, b.y, c.y});
  p.ymax = std::max({a.y, b.y, c.y});
  p.zmax = std::max({a.z, b.z, c.z});
  return p;
}

CutterContacts::CutterContacts(const Cutter& cutter)
    : cutter_(cutter),
      R_(cutter.radius()),
      R2_(R_ * R_),
      a_(cutter.ring_radius()),
      r_(cutter.corner_radius_mm) {}

double CutterContacts::vertex(double x, double y, const Vec3& p) const {
  const double dx = p.x - x, dy = p.y - y;
  const double rho2 = dx * dx + dy * dy;
  if (rho2 > R2_) return kNoContact;
  return p.z - cutter_.height_at(std::sqrt(rho2));
}

double CutterContacts::facet(double x, double y, const PreparedTriangle& t) const {
  if (!(t.nz > 0)) return kNoContact;
  // The corner ball's centre q = (x, y, z + r) + a·u with u pointing down the plane's
  // slope touches the plane at q − r·n; the tip is then at
  //   z = v0.z + (nx (v0.x − x) + ny (v0.y − y) + r + a |nxy|) / nz − r.
  const double nxy = t.nxy;
  double cx = x, cy = y;
  if (nxy > 0) {
    const double k = a_ / nxy + r_;
    cx -= k * t.nx;
    cy -= k * t.ny;
  }
  const Vec3 &a = t.v[0], &b = t.v[1], &c = t.v[2];
  const double o0 = (b.x - a.x) * (cy - a.y) - (b.y - a.y) * (cx - a.x);
  const double o1 = (c.x - b.x) * (cy - b.y) - (c.y - b.y) * (cx - b.x);
  const double o2 = (a.x - c.x) * (cy - c.y) - (a.y - c.y) * (cx - c.x);
  const bool inside = (o0 >= 0 && o1 >= 0 && o2 >= 0) || (o0 <= 0 && o1 <= 0 && o2 <= 0);
  if (!inside) return kNoContact;
  return a.z + (t.nx * (a.x - x) + t.ny * (a.y - y) + r_ + a_ * nxy) / t.nz - r_;
}

double CutterContacts::edge(double x, double y, const Vec3& p, const Vec3& q, double floor) const {
  const double ex = q.x - p.x, ey = q.y - p.y;
  const double L2 = ex * ex + ey * ey;
  if (L2 == 0) return kNoContact;  // vertical edge: its top vertex is the highest point
  const double L = std::sqrt(L2);
  const double ux = ex / L, uy = ey / L;
  const double px = p.x - x, py = p.y - y;
  // s: signed xy distance along the edge from the foot of the perpendicular from the axis.
  const double d = ux * py - uy * px;
  const double d2 = d * d;
  if (d2 >= R2_) return kNoContact;
  const double w = std::sqrt(R2_ - d2);  // |s| <= w is within R of the axis
  const double sp = px * ux + py * uy, sq = sp + L;
  const double lo_in = std::max(sp, -w), hi_in = std::min(sq, w);
  if (lo_in > hi_in) return kNoContact;
  const double m = (q.z - p.z) / L;  // slope: z(s) = p.z + m (s − sp)
  double s;
  if (cutter_.is_flat()) {
    // h = 0 within R: z(s) is highest where the edge leaves the disc uphill.
    if (m > 0) {
      if (!(w < sq)) return kNoContact;
      s = w;
    } else if (m < 0) {
      if (!(-w > sp)) return kNoContact;
      s = -w;
    } else {
      return p.z;
    }
    return p.z + m * (s - sp);
  }
  if (cutter_.is_ball()) {
    // Cylinder of radius R around the edge: g(s) = z(s) − R + sqrt(w² − s²), g' = 0 at
    // s = m w / sqrt(1 + m²), where sqrt(w² − s²) = w / sqrt(1 + m²).
    const double k = 1 / std::sqrt(1 + m * m);
    s = m * w * k;
    if (!(s > sp && s < sq)) return kNoContact;
    return p.z + m * (s - sp) + w * k - R_;
  }
  // The edge's highest point within R, lowered by the cutter's height at the edge's
  // nearest approach, bounds the contact from above.
  if (floor > kNoContact) {
    const double s_near = std::clamp(0.0, lo_in, hi_in);
    const double rho_near = std::max(0.0, std::sqrt(d2 + s_near * s_near) - 1e-9);  // see DropCutter::drop
    if (p.z + m * ((m > 0 ? hi_in : lo_in) - sp) - cutter_.height_at(rho_near) <= floor)
      return kNoContact;
  }
  // Bull: g(s) = z(s) − h(rho(s)), rho = sqrt(d² + s²), concave on [−w, w] with
  // g'(−w) = +inf and g'(w) = −inf. Newton on g' = m − h'(rho)·s/rho, kept inside the
  // bracket of its sign change (bisection where Newton would leave it). The bracket
  // starts at the edge's ends: if g' does not change sign inside the edge, a vertex
  // holds the maximum. Each evaluation's tangent bounds g over the bracket (concavity):
  // once that bound is not above `floor`, the edge cannot win and the search stops.
  const double r2 = r_ * r_;
  double g = 0, gp = 0, gpp = 0;
  auto eval = [&](double at) {
    const double rho = std::sqrt(d2 + at * at);
    const double t = rho - a_;
    const double zs = p.z + m * (at - sp);
    if (t <= 0) {
      g = zs, gp = m, gpp = 0;
      return;
    }
    const double den2 = (r_ - t) * (r_ + t);
    if (den2 <= 0) {  // on the rim: h' infinite, only its sign matters
      g = zs - r_, gp = at > 0 ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
      gpp = 0;
      return;
    }
    const double den = std::sqrt(den2);
    const double hp = t / den, hpp = r2 / (den2 * den);
    const double c = at / rho;
    g = zs - (r_ - den);
    gp = m - hp * c;
    gpp = -(hpp * c * c + hp * d2 / (rho * rho * rho));
  };
  double lo = -w, hi = w;
  auto cannot_win = [&](double at) {
    const double ub = gp > 0 ? g + gp * (hi - at) : g + gp * (lo - at);
    return std::isfinite(ub) && ub <= floor;
  };
  if (sp > lo) {
    eval(sp);
    if (gp <= 0) return kNoContact;  // g falls from p on: vertex p is the edge's maximum
    lo = sp;
  }
  if (sq < hi) {
    eval(sq);
    if (gp >= 0) return kNoContact;  // g rises up to q: vertex q is the edge's maximum
    hi = sq;
    if (cannot_win(sq)) return kNoContact;
  }
  s = std::clamp(m * w / std::sqrt(1 + m * m), lo, hi);  // the ball's root: a good start
  const double eps = 1e-14 * R_;
  for (int it = 0; it < 200; ++it) {
    eval(s);
    if (gp > 0) {
      lo = s;
    } else if (gp < 0) {
      hi = s;
    } else {
      break;
    }
    if (cannot_win(s)) return kNoContact;
    double next = gpp < 0 ? s - gp / gpp : lo - 1;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    const double step = std::abs(next - s);
    s = next;
    if (step <= eps || hi - lo <= eps) break;
  }
  if (!(s > sp && s < sq)) return kNoContact;
  return p.z + m * (s - sp) - cutter_.height_at(std::sqrt(d2 + s * s));
}

void CutterContacts::vertices_and_facet(double x, double y, const PreparedTriangle& t, ClPoint& best) const {
  for (std::size_t k = 0; k < 3; ++k) {
    const double z = vertex(x, y, t.v[k]);
    if (z > best.z) best = {z, Contact::kVertex};
  }
  const double z = facet(x, y, t);
  if (z > best.z) best = {z, Contact::kFacet};
}

void CutterContacts::edges(double x, double y, const PreparedTriangle& t, ClPoint& best) const {
  for (std::size_t k = 0; k < 3; ++k) {
    if (!(t.edge_mask >> k & 1u)) continue;  // another triangle holds this edge
    const Vec3 &p = t.v[k], &q = t.v[(k + 1) % 3];
    if (std::max(p.z, q.z) <= best.z) continue;  // h >= 0: no contact above the edge's top
    const double z = edge(x, y, p, q, best.z);
    if (z > best.z) best = {z, Contact::kEdge};
  }
}

ClPoint CutterContacts::triangle(double x, double y, const PreparedTriangle& t, double floor) const {
  // The cheap closed forms first, so the edges' bound has the most to work with.
  ClPoint best{floor, Contact::kNone};
  vertices_and_facet(x, y, t, best);
  edges(x, y, t, best);
  return best;
}

BruteForceDropCutter::BruteForceDropCutter(const Mesh& mesh, const Cutter& cutter) : contacts_(cutter) {
  tris_.reserve(mesh.triangles.size());
  for (const Triangle& t : mesh.triangles) tris_.push_back(prepare(t));
}

ClPoint BruteForceDropCutter::drop(double x, double y) const {
  ClPoint best;
  const double R = contacts_.cutter().radius();
  for (const PreparedTriangle& t : tris_) {
    if (x < t.xmin - R || x > t.xmax + R || y < t.ymin - R || y > t.ymax + R) continue;
    const ClPoint c = contacts_.triangle(x, y, t);
    if (c.z > best.z) best = c;
  }
  return best;
}

DropCutter::DropCutter(const Mesh& mesh, const Cutter& cutter) : DropCutter(mesh, cutter, Options{}) {}

DropCutter::DropCutter(const Mesh& mesh, const Cutter& cutter, Options options)
    : contacts_(cutter), R2_(cutter.radius() * cutter.radius()), a2_(cutter.ring_radius() * cutter.ring_radius()) {
  if (mesh.triangles.size() >= std::numeric_limits<std::uint32_t>::max())
    throw std::invalid_argument("DropCutter: more than 2^32 - 1 triangles");
  tris_.reserve(mesh.triangles.size());
  for (const Triangle& t : mesh.triangles) tris_.push_back(prepare(t));
  share_edges(tris_);
  const double R = cutter.radius();
  const Bounds b = mesh_bounds(mesh);
  x0_ = b.min.x - R;
  y0_ = b.min.y - R;
  const double w = b.max.x - b.min.x + 2 * R, h = b.max.y - b.min.y + 2 * R;

  auto cells_of = [&](const PreparedTriangle& t, double cell, std::int64_t& ix0, std::int64_t& ix1,
                      std::int64_t& iy0, std::int64_t& iy1) {
    ix0 = static_cast<std::int64_t>(std::floor((t.xmin - R - x0_) / cell));
    ix1 = static_cast<std::int64_t>(std::floor((t.xmax + R - x0_) / cell));
    iy0 = static_cast<std::int64_t>(std::floor((t.ymin - R - y0_) / cell));
    iy1 = static_cast<std::int64_t>(std::floor((t.ymax + R - y0_) / cell));
  };
  cell_ = options.cell_mm > 0 ? options.cell_mm : 0.5 * R;
  // Not more than 32 entries per triangle (and 2^31 in all), nor more cells than 4 per triangle.
  const double max_entries = std::min(2e9, 32.0 * static_cast<double>(std::max<std::size_t>(tris_.size(), 1024)));
  for (;;) {
    const double cells = (std::floor(w / cell_) + 1) * (std::floor(h / cell_) + 1);
    double entries = 0;
    for (const PreparedTriangle& t : tris_) {
      std::int64_t ix0, ix1, iy0, iy1;
      cells_of(t, cell_, ix0, ix1, iy0, iy1);
      entries += static_cast<double>((ix1 - ix0 + 1) * (iy1 - iy0 + 1));
    }
    if (options.cell_mm > 0 || (entries <= max_entries && cells <= 4.0 * static_cast<double>(tris_.size()) + 1024))
      break;
    cell_ *= 1.25;
  }
  nx_ = static_cast<std::int64_t>(std::floor(w / cell_)) + 1;
  ny_ = static_cast<std::int64_t>(std::floor(h / cell_)) + 1;
  std::vector<std::uint32_t> count(static_cast<std::size_t>(nx_ * ny_) + 1, 0);
  for (const PreparedTriangle& t : tris_) {
    std::int64_t ix0, ix1, iy0, iy1;
    cells_of(t, cell_, ix0, ix1, iy0, iy1);
    for (std::int64_t iy = iy0; iy <= iy1; ++iy)
      for (std::int64_t ix = ix0; ix <= ix1; ++ix) ++count[static_cast<std::size_t>(iy * nx_ + ix)];
  }
  cell_start_.assign(count.size(), 0);
  for (std::size_t i = 1; i < count.size(); ++i) cell_start_[i] = cell_start_[i - 1] + count[i - 1];
  entries_.resize(cell_start_.back());
  std::vector<std::uint32_t> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (std::size_t i = 0; i < tris_.size(); ++i) {
    const PreparedTriangle& t = tris_[i];
    std::int64_t ix0, ix1, iy0, iy1;
    cells_of(t, cell_, ix0, ix1, iy0, iy1);
    const Entry e{float_down(t.xmin - R), float_up(t.xmax + R), float_down(t.ymin - R), float_up(t.ymax + R),
                  0.0f, static_cast<std::uint32_t>(i)};
    for (std::int64_t iy = iy0; iy <= iy1; ++iy) {
      for (std::int64_t ix = ix0; ix <= ix1; ++ix) {
        // The highest contact T can give anywhere in this cell: its top lowered by the
        // cutter's height at the nearest approach of T's bounds to the cell.
        const double cx0 = x0_ + static_cast<double>(ix) * cell_, cy0 = y0_ + static_cast<double>(iy) * cell_;
        const double gx = std::max({t.xmin - (cx0 + cell_), cx0 - t.xmax, 0.0});
        const double gy = std::max({t.ymin - (cy0 + cell_), cy0 - t.ymax, 0.0});
        // Less 1e-9 mm: h is steep near the rim, and a query point may lie an ulp
        // outside the cell it is filed in.
        const double gap = std::clamp(std::sqrt(gx * gx + gy * gy) - 1e-9, 0.0, R);
        Entry& slot = entries_[fill[static_cast<std::size_t>(iy * nx_ + ix)]++];
        slot = e;
        slot.top = float_up(t.zmax - cutter.height_at(gap));
      }
    }
  }
  for (std::size_t c = 0; c + 1 < cell_start_.size(); ++c)
    std::sort(entries_.begin() + cell_start_[c], entries_.begin() + cell_start_[c + 1],
              [](const Entry& l, const Entry& r) { return l.top > r.top || (l.top == r.top && l.tri < r.tri); });
}

void share_edges(std::vector<PreparedTriangle>& tris) {
  struct Key {
    std::uint64_t b[3];
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      std::uint64_t h = k.b[0] * 0x9E3779B97F4A7C15ull;
      h ^= (k.b[1] + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full;
      h ^= (k.b[2] + 0x85EBCA77C2B2AE63ull) * 0x165667B19E3779F9ull;
      return static_cast<std::size_t>(h ^ (h >> 29));
    }
  };
  std::unordered_map<Key, std::uint32_t, KeyHash> ids;
  ids.reserve(tris.size());
  std::unordered_set<std::uint64_t> seen;
  seen.reserve(2 * tris.size());
  for (PreparedTriangle& t : tris) {
    std::uint32_t id[3];
    for (std::size_t k = 0; k < 3; ++k) {
      Key key{};
      std::memcpy(&key.b[0], &t.v[k].x, 8);
      std::memcpy(&key.b[1], &t.v[k].y, 8);
      std::memcpy(&key.b[2], &t.v[k].z, 8);
      id[k] = ids.try_emplace(key, static_cast<std::uint32_t>(ids.size())).first->second;
    }
    t.edge_mask = 0;
    for (std::size_t k = 0; k < 3; ++k) {
      const std::uint64_t lo = std::min(id[k], id[(k + 1) % 3]), hi = std::max(id[k], id[(k + 1) % 3]);
      if (seen.insert(lo << 32 | hi).second) t.edge_mask = static_cast<std::uint8_t>(t.edge_mask | 1u << k);
    }
  }
}

ClPoint DropCutter::drop(double x, double y) const {
  ClPoint best;
  const double fx = std::floor((x - x0_) / cell_), fy = std::floor((y - y0_) / cell_);
  if (!(fx >= 0 && fy >= 0 && fx < static_cast<double>(nx_) && fy < static_cast<double>(ny_))) return best;
  const auto c = static_cast<std::size_t>(static_cast<std::int64_t>(fy) * nx_ + static_cast<std::int64_t>(fx));
  const Entry* begin = entries_.data() + cell_start_[c];
  const Entry* end = entries_.data() + cell_start_[c + 1];
  const Cutter& cutter = contacts_.cutter();
  // Two passes, as the paper's lower bound from the vertex spheres first: the closed
  // forms (vertices, facets) of every triangle that can still matter, then the edges,
  // most of which the higher floor now excludes without a root search. Entries are
  // sorted by the highest contact they can give in the cell, so the first pass stops at
  // the first one not above the best; it keeps the triangles it looked at, with their
  // own bound, for the second.
  struct Candidate {
    const PreparedTriangle* t;
    double bound;
  };
  thread_local std::vector<Candidate> candidates;
  candidates.clear();
  for (const Entry* e = begin; e != end; ++e) {
    if (static_cast<double>(e->top) <= best.z) break;
    if (x < static_cast<double>(e->xmin) || x > static_cast<double>(e->xmax) || y < static_cast<double>(e->ymin) ||
        y > static_cast<double>(e->ymax))
      continue;
    const PreparedTriangle& t = tris_[e->tri];
    // Nearest approach of T's xy bounds to the axis: beyond R, nothing; else the top
    // of T lowered by the cutter's height there bounds every contact of T.
    const double dx = std::max({t.xmin - x, x - t.xmax, 0.0}), dy = std::max({t.ymin - y, y - t.ymax, 0.0});
    const double d2 = dx * dx + dy * dy;
    if (d2 > R2_) continue;
    // (1e-9 mm nearer than computed: h is steep near the rim and the bound must hold.)
    const double bound = d2 > a2_ ? t.zmax - cutter.height_at(std::max(0.0, std::sqrt(d2) - 1e-9)) : t.zmax;
    if (bound <= best.z) continue;
    contacts_.vertices_and_facet(x, y, t, best);
    candidates.push_back({&t, bound});
  }
  for (const Candidate& cand : candidates)
    if (cand.bound > best.z) contacts_.edges(x, y, *cand.t, best);
  return best;
}

void DropCutter::drop_batch(std::span<const XY> in, std::span<ClPoint> out, int threads,
                            std::atomic<std::size_t>* done) const {
  if (out.size() != in.size()) throw std::invalid_argument("drop_batch: in and out differ in size");
  constexpr std::size_t kChunk = 256;
  util::parallel_for(
      in.size(), threads,
      [&](std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) out[i] = drop(in[i].x, in[i].y);
        if (done) done->fetch_add(e - b, std::memory_order_relaxed);
      },
      kChunk);
}

}  // namespace cnc::cam
