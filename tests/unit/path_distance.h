#pragma once
// The largest distance of a polyline from a set of straight segments, with bounds
// (issue 31): the G64 P property test (path_tolerance_property_test.cc) and the
// machining-time bench (tools/bench/path_deviation.cc) measure paths with it.
//
// For a path chord c and a set of straight segments S_i, f(x) = min_i d(x, S_i) is
// what is wanted, max over x in c. Each d(., S_i) is convex along c (the distance to a
// convex set), so on any piece [x0, x1] of c: max f <= min_i max(d(x0, S_i),
// d(x1, S_i)) =: U, and max f >= max(f(x0), f(x1)) =: L. A piece is halved until
// U - L <= eps (U stays an upper bound if the depth limit stops it first); the halving
// ends because every d(., S_i) is 1-Lipschitz (U - L <= the piece's length). Only
// segments within a reach of the chord take part (a grid finds them); where U exceeds
// the reach a wider one is tried, at last all segments. Arcs enter S as inscribed
// polylines (the caller's), which moves any distance by at most their sagitta.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

namespace cnc::pathdist {

using V3 = std::array<double, 3>;

inline V3 sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
inline double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline double norm(const V3& a) { return std::sqrt(dot(a, a)); }
// Pieces of an arc (sweep in rad, largest radius r) whose chords leave it by at most
// `sagitta`: a piece of angle a leaves the circle by r (1 - cos(a/2)) <= r a^2 / 8,
// and a spiral's radius changes by a few um over the arc: 1.5x for it.
inline int arc_pieces(double sweep_rad, double r, double sagitta) {
  return std::max(1, static_cast<int>(std::ceil(1.5 * std::fabs(sweep_rad) * std::sqrt(r / (8 * sagitta)))));
}
inline V3 lerp(const V3& a, const V3& b, double t) {
  return {a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t};
}

// ---- the distance to a set of segments ---------------------------------------------

// Straight segments with a uniform grid for "which segments come near this box".
// A segment is entered in the cell of each of its points sampled at spacing
// <= cell/2, so its nearest point to any x lies within cell/4 of a sample: a segment
// within r of a box is in a cell that overlaps the box grown by r + cell/4.
class SegmentSet {
 public:
  explicit SegmentSet(double cell_mm) : cell_(cell_mm) {}

  void add(const V3& a, const V3& b) {
    const V3 d = sub(b, a);
    segs_.push_back({a, d, dot(d, d)});
    const int i = static_cast<int>(segs_.size()) - 1;
    const int m = std::max(1, static_cast<int>(std::ceil(std::sqrt(segs_.back().len2) / (0.5 * cell_))));
    uint64_t last = ~uint64_t{0};
    for (int k = 0; k <= m; ++k) {
      const uint64_t key = key_of(lerp(a, b, static_cast<double>(k) / m));
      if (key != last) grid_[key].push_back(i);
      last = key;
    }
  }
  size_t size() const { return segs_.size(); }
  const V3& start(int i) const { return segs_[static_cast<size_t>(i)].a; }
  V3 end(int i) const {
    const Seg& s = segs_[static_cast<size_t>(i)];
    return {s.a[0] + s.d[0], s.a[1] + s.d[1], s.a[2] + s.d[2]};
  }

  double dist(int i, const V3& x) const {
    const Seg& s = segs_[static_cast<size_t>(i)];
    const V3 w = sub(x, s.a);
    const double t = s.len2 > 0 ? std::clamp(dot(w, s.d) / s.len2, 0.0, 1.0) : 0.0;
    const V3 e{w[0] - t * s.d[0], w[1] - t * s.d[1], w[2] - t * s.d[2]};
    return norm(e);
  }

  // Every segment within `reach` of some point of the box [lo, hi] (and maybe others).
  void near(const V3& lo, const V3& hi, double reach, std::vector<int>* out) const {
    out->clear();
    const double grow = reach + 0.25 * cell_;
    std::array<int64_t, 3> c0{}, c1{};
    int64_t cells = 1;
    for (int a = 0; a < 3; ++a) {
      c0[a] = static_cast<int64_t>(std::floor((lo[a] - grow) / cell_));
      c1[a] = static_cast<int64_t>(std::floor((hi[a] + grow) / cell_));
      cells *= c1[a] - c0[a] + 1;
    }
    if (cells > 4096) {
      all(out);
      return;
    }
    if (stamp_.size() < segs_.size()) stamp_.assign(segs_.size(), 0);
    ++epoch_;
    for (int64_t x = c0[0]; x <= c1[0]; ++x)
      for (int64_t y = c0[1]; y <= c1[1]; ++y)
        for (int64_t z = c0[2]; z <= c1[2]; ++z) {
          const auto it = grid_.find(pack(x, y, z));
          if (it == grid_.end()) continue;
          for (int i : it->second)
            if (stamp_[static_cast<size_t>(i)] != epoch_) {
              stamp_[static_cast<size_t>(i)] = epoch_;
              out->push_back(i);
            }
        }
  }
  void all(std::vector<int>* out) const {
    out->resize(segs_.size());
    for (size_t i = 0; i < segs_.size(); ++i) (*out)[i] = static_cast<int>(i);
  }

 private:
  struct Seg {
    V3 a, d;
    double len2;
  };
  static uint64_t pack(int64_t x, int64_t y, int64_t z) {
    constexpr int64_t kOff = int64_t{1} << 20;
    return (static_cast<uint64_t>(x + kOff) << 42) | (static_cast<uint64_t>(y + kOff) << 21) |
           static_cast<uint64_t>(z + kOff);
  }
  uint64_t key_of(const V3& p) const {
    return pack(static_cast<int64_t>(std::floor(p[0] / cell_)), static_cast<int64_t>(std::floor(p[1] / cell_)),
                static_cast<int64_t>(std::floor(p[2] / cell_)));
  }
  double cell_;
  std::vector<Seg> segs_;
  std::unordered_map<uint64_t, std::vector<int>> grid_;
  mutable std::vector<uint32_t> stamp_;
  mutable uint32_t epoch_ = 0;
};

// The largest distance of a point of the segment p-q from a set: the truth lies in [lo, hi].
struct Range {
  double lo = 0, hi = 0;
  double at_q = 0;  // the distance of q itself
};

class FarthestPoint {
 public:
  // `eps`: how far apart the bounds of a chord's largest distance may end (mm);
  // `reaches`: the candidate radii tried in turn (mm) before all segments take part.
  explicit FarthestPoint(const SegmentSet& set, double eps = 1e-6, std::vector<double> reaches = {0.25})
      : set_(set), eps_(eps), reaches_(std::move(reaches)) {}

  Range of(const V3& p, const V3& q) {
    // Candidates within a reach of the segment; if the answer is farther than that,
    // a segment outside them may be nearer: then a wider reach, at last all of them.
    const V3 lo{std::min(p[0], q[0]), std::min(p[1], q[1]), std::min(p[2], q[2])};
    const V3 hi{std::max(p[0], q[0]), std::max(p[1], q[1]), std::max(p[2], q[2])};
    for (const double reach : reaches_) {
      set_.near(lo, hi, reach, &ids_);
      const Range r = ids_.empty() ? Range{1e300, 1e300, 1e300} : search(p, q);
      if (r.hi <= reach) return r;
    }
    set_.all(&ids_);
    return search(p, q);
  }

 private:
  Range search(const V3& p, const V3& q) {
    std::vector<double> d0(ids_.size()), d1(ids_.size());
    for (size_t k = 0; k < ids_.size(); ++k) {
      d0[k] = set_.dist(ids_[k], p);
      d1[k] = set_.dist(ids_[k], q);
    }
    Range r = piece(p, q, ids_, d0, d1, 0);
    r.at_q = *std::min_element(d1.begin(), d1.end());
    return r;
  }

  Range piece(const V3& p, const V3& q, const std::vector<int>& ids, const std::vector<double>& d0,
              const std::vector<double>& d1, int depth) {
    double f0 = 1e300, f1 = 1e300, u = 1e300;
    for (size_t k = 0; k < ids.size(); ++k) {
      f0 = std::min(f0, d0[k]);
      f1 = std::min(f1, d1[k]);
      u = std::min(u, std::max(d0[k], d1[k]));
    }
    const double l = std::max(f0, f1);
    if (u - l <= eps_ || depth >= 60) return {l, u, 0};
    // Only segments that can be the nearest somewhere on the piece go on: d >= (d0 + d1 - len) / 2 there.
    const double len = norm(sub(q, p));
    std::vector<int> keep;
    std::vector<double> k0, k1, km;
    const V3 m = lerp(p, q, 0.5);
    for (size_t k = 0; k < ids.size(); ++k) {
      if (0.5 * (d0[k] + d1[k] - len) > u) continue;
      keep.push_back(ids[k]);
      k0.push_back(d0[k]);
      k1.push_back(d1[k]);
      km.push_back(set_.dist(ids[k], m));
    }
    const Range a = piece(p, m, keep, k0, km, depth + 1);
    const Range b = piece(m, q, keep, km, k1, depth + 1);
    return {std::max(a.lo, b.lo), std::max(a.hi, b.hi), 0};
  }

  const SegmentSet& set_;
  double eps_;
  std::vector<double> reaches_;
  std::vector<int> ids_;
};

}  // namespace cnc::pathdist
