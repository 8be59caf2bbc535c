#include "common/cam/raster.h"

#include <algorithm>
#include <cmath>
#include <atomic>
#include <stdexcept>

#include "common/util/parallel_for.h"

namespace cnc::cam {

std::vector<std::vector<XY>> raster_passes(const Bounds& b, const RasterSpec& spec) {
  if (!(spec.pick_mm > 0) || !(spec.step_mm > 0) || !std::isfinite(spec.angle_deg))
    throw std::invalid_argument("raster: pick and step must be > 0 and the angle finite");
  const double a = spec.angle_deg * M_PI / 180;
  const double ux = std::cos(a), uy = std::sin(a);  // along the passes
  const double vx = -uy, vy = ux;                   // across them
  double umin = 1e300, umax = -1e300, vmin = 1e300, vmax = -1e300;
  for (double x : {b.min.x, b.max.x})
    for (double y : {b.min.y, b.max.y}) {
      umin = std::min(umin, x * ux + y * uy), umax = std::max(umax, x * ux + y * uy);
      vmin = std::min(vmin, x * vx + y * vy), vmax = std::max(vmax, x * vx + y * vy);
    }
  const auto n_pass = static_cast<std::size_t>(std::ceil((vmax - vmin) / spec.pick_mm - 1e-9)) + 1;
  const auto n_step = static_cast<std::size_t>(std::ceil((umax - umin) / spec.step_mm - 1e-9));
  const double step = n_step > 0 ? (umax - umin) / static_cast<double>(n_step) : 0;
  std::vector<std::vector<XY>> passes(n_pass);
  for (std::size_t k = 0; k < n_pass; ++k) {
    const double v = std::min(vmax, vmin + static_cast<double>(k) * spec.pick_mm);
    std::vector<XY>& p = passes[k];
    p.reserve(n_step + 1);
    for (std::size_t i = 0; i <= n_step; ++i) {
      const double u = i == n_step ? umax : umin + static_cast<double>(i) * step;
      p.push_back({u * ux + v * vx, u * uy + v * vy});
    }
    if (k % 2 == 1) std::reverse(p.begin(), p.end());
  }
  return passes;
}

RasterPath raster_fixed_step(const DropCutter& dc, const Bounds& bounds, const RasterSpec& spec, int threads,
                             RasterProgress* progress) {
  const std::vector<std::vector<XY>> passes = raster_passes(bounds, spec);
  std::vector<XY> all;
  for (const auto& p : passes) all.insert(all.end(), p.begin(), p.end());
  std::vector<ClPoint> cl(all.size());
  dc.drop_batch(all, cl, threads, progress ? &progress->points : nullptr);
  if (progress) progress->passes = passes.size();
  RasterPath path;
  path.passes = passes.size();
  path.points_dropped = all.size();
  std::size_t i = 0;
  for (const auto& p : passes) {
    std::vector<Vec3> cut;
    for (std::size_t k = 0; k < p.size(); ++k, ++i) {
      if (cl[i].touched()) {
        cut.push_back({all[i].x, all[i].y, cl[i].z});
      } else if (!cut.empty()) {
        path.cuts.push_back(std::move(cut));
        cut.clear();
      }
    }
    if (!cut.empty()) path.cuts.push_back(std::move(cut));
  }
  return path;
}

namespace {

struct PassWalker {
  const DropCutter& dc;
  XY a, b;  // the pass from a (u = 0) to b (u = len)
  double len;
  const RasterSpec& spec;
  const AdaptiveSpec& ad;

  XY at(double u) const { return {a.x + (b.x - a.x) * u / len, a.y + (b.y - a.y) * u / len}; }
  ClPoint drop(double u) const {
    const XY p = at(u);
    return dc.drop(p.x, p.y);
  }
  Vec3 cl(double u, double z) const {
    const XY p = at(u);
    return {p.x, p.y, z};
  }

  // The boundary between u_off (touches nothing) and u_on (touches) to min_step; the
  // touching side's point.
  std::pair<double, double> edge(double u_off, double u_on, double z_on) const {
    while (std::abs(u_on - u_off) > ad.min_step_mm) {
      const double m = 0.5 * (u_off + u_on);
      const ClPoint c = drop(m);
      if (c.touched()) {
        u_on = m, z_on = c.z;
      } else {
        u_off = m;
      }
    }
    return {u_on, z_on};
  }

  // Hwang's concave corner inside the step (ua, za) - (ub, zb), where the CL surface
  // has a crease: the CL surface's slopes along the pass at the step's two ends, taken
  // inwards over d = L/4096, give two tangents; the corner is sought only if they meet
  // inside the step, the slope rises across it (the CL surface, an upper envelope, only
  // creases upwards) and the CL surface where they meet lies nearer the tangents than the
  // chord (a crease: a smooth valley lies halfway, as the chord's sag equals the
  // tangents' on a parabola). Then bisection: at the middle m of [a, b], the one-sided
  // slopes over e = (b - a)/64 on either side of m, against the mean of the two
  // tangents' slopes, say on which side of m the crease lies (or that it lies within e
  // of m), to corner_tol_mm. Accepted if the slopes just outside the final bracket still
  // differ by half the tangents' difference (a crease, not a bend); the corner point is
  // the bracket's middle with its exact CL height.
  bool corner(double ua, double za, double ub, double zb, double& uc_out, ClPoint& cc_out, std::size_t& dropped) const {
    const double L = ub - ua;
    const double d = L / 4096;
    if (!(d > 0)) return false;
    auto z_at = [&](double v, double& z) {
      const ClPoint q = drop(v);
      ++dropped;
      z = q.z;
      return q.touched();
    };
    double za_in = 0, zb_in = 0;
    if (!z_at(ua + d, za_in) || !z_at(ub - d, zb_in)) return false;
    const double sa = (za_in - za) / d, sb = (zb - zb_in) / d;
    if (!(sb > sa)) return false;
    const double ut = (zb - za - sb * ub + sa * ua) / (sa - sb);
    if (!(ut > ua + d && ut < ub - d)) return false;
    double zt = 0;
    if (!z_at(ut, zt)) return false;
    const double tangent = za + sa * (ut - ua), chord = za + (zb - za) * (ut - ua) / L;
    if (!(chord - tangent > 0) || zt - tangent > 0.25 * (chord - tangent)) return false;
    const double mid = 0.5 * (sa + sb);
    double lo = ua, hi = ub;
    while (hi - lo > ad.corner_tol_mm) {
      const double m = 0.5 * (lo + hi), e = (hi - lo) / 64;
      double zm = 0, zl = 0, zr = 0;
      if (!z_at(m, zm) || !z_at(m - e, zl) || !z_at(m + e, zr)) return false;
      const double sl = (zm - zl) / e, sr = (zr - zm) / e;
      if (sl >= mid) {
        hi = m;  // [m - e, m] already climbs the second piece: the crease is before m
      } else if (sr <= mid) {
        lo = m;  // [m, m + e] still on the first piece
      } else {
        lo = m - e, hi = m + e;
      }
    }
    double zl = 0, zr = 0, z0 = 0, z1 = 0;
    const double v = std::max(ad.corner_tol_mm, d);
    if (!z_at(lo - v, zl) || !z_at(lo, z0) || !z_at(hi, z1) || !z_at(hi + v, zr)) return false;
    if (!((zr - z1) / v - (z0 - zl) / v >= 0.5 * (sb - sa))) return false;
    const double uc = 0.5 * (lo + hi);
    if (!(uc > ua + ad.min_step_mm * 0.5 && uc < ub)) return false;
    cc_out = drop(uc);
    ++dropped;
    uc_out = uc;
    return cc_out.touched();
  }

  void walk(std::vector<std::vector<Vec3>>& cuts, std::size_t& dropped, std::size_t& corners) const {
    double u = 0;
    ClPoint c = drop(0);
    ++dropped;
    std::vector<Vec3> cut;
    // (u, z) of the last three points, for the curvature prediction.
    double pu[2] = {0, 0}, pz[2] = {0, 0};
    int history = 0;
    double h = spec.step_mm;
    while (true) {
      if (!c.touched()) {  // off the surface: find the next point on it
        double v = u;
        ClPoint d;
        do {
          v = std::min(len, v + spec.step_mm);
          d = drop(v);
          ++dropped;
        } while (!d.touched() && v < len);
        if (!d.touched()) break;
        const auto [ue, ze] = edge(u, v, d.z);
        u = ue;
        c = {ze, Contact::kVertex};
        history = 0;
        h = spec.step_mm;
      }
      if (cut.empty()) cut.push_back(cl(u, c.z));
      if (u >= len) break;
      // Predict: chord error κL²/8 = β on the circle through the last three points.
      double step = std::min(h * 2, spec.step_mm);
      if (history == 2) {
        const double x1 = pu[0], y1 = pz[0], x2 = pu[1], y2 = pz[1], x3 = u, y3 = c.z;
        const double area2 = std::abs((x2 - x1) * (y3 - y1) - (y2 - y1) * (x3 - x1));
        const double d12 = std::hypot(x2 - x1, y2 - y1), d23 = std::hypot(x3 - x2, y3 - y2),
                     d13 = std::hypot(x3 - x1, y3 - y1);
        const double kappa = d12 * d23 * d13 > 0 ? 2 * area2 / (d12 * d23 * d13) : 0;
        if (kappa > 0) step = std::min(step, std::sqrt(8 * ad.beta_mm / kappa));
      }
      step = std::max(step, ad.min_step_mm);
      double u1 = std::min(len, u + step);
      ClPoint c1 = drop(u1);
      ++dropped;
      bool off_edge = false, corner_tried = false, corner_end = false;
      while (true) {
        if (!c1.touched()) {  // the surface ends inside this step
          const auto [ue, ze] = edge(u1, u, c.z);
          if (ue <= u) {
            off_edge = true;
            break;
          }
          u1 = ue, c1 = {ze, Contact::kVertex};
          continue;
        }
        if (u1 - u <= ad.min_step_mm) break;
        // The CL points at k/n of the step (the middle first) against the chord, n = 16 at
        // least and 16 per chord length of the step's length in xy, up to 512: a steep
        // chord (a wall) gets as many probes along its length as a flat one.
        const double um = 0.5 * (u + u1);
        const ClPoint cm = drop(um);
        ++dropped;
        // The probes hold 0.9 β: between them, the CL surface of a faceted mesh still
        // wiggles (a ball over 0.25 mm facets: up to 6 % of β beyond the probes' worst).
        // Distances from the chord segment in the pass's (u, z) plane, not vertical ones:
        // on a steep wall the path is near the surface though far below it vertically.
        const double L = u1 - u, dz = c1.z - c.z, len2 = L * L + dz * dz;
        const double limit = 0.9 * ad.beta_mm;
        auto off_chord = [&](double t, double zq) {
          const double wu = t * L, wz = zq - c.z;
          const double s = std::clamp((wu * L + wz * dz) / len2, 0.0, 1.0);
          return std::hypot(wu - s * L, wz - s * dz);
        };
        bool within = cm.touched() && off_chord(0.5, cm.z) <= limit;
        bool below = cm.touched() && cm.z < c.z + 0.5 * dz;  // the failing probe under the chord
        const int n = 2 * static_cast<int>(std::clamp(std::ceil(8 * std::sqrt(len2) / L), 8.0, 256.0));
        for (int k = 1; k < n && within; ++k) {
          if (2 * k == n) continue;
          const double t = static_cast<double>(k) / n;
          const ClPoint cq = drop(u + t * L);
          ++dropped;
          within = cq.touched() && off_chord(t, cq.z) <= limit;
          below = cq.touched() && cq.z < c.z + t * dz;
        }
        if (within) break;
        // The CL surface dips under the chord: a concave corner (a crease where two CL
        // surface pieces meet) inside the step is sought once and, if found, becomes the
        // step's end; the chord up to it is checked like any other.
        if (ad.corner_search && below && !corner_tried) {
          corner_tried = true;
          double uc = 0;
          ClPoint cc;
          if (corner(u, c.z, u1, c1.z, uc, cc, dropped)) {
            u1 = uc, c1 = cc, corner_end = true;
            ++corners;
            continue;
          }
        }
        corner_end = false;
        u1 = um, c1 = cm;  // halve: the middle becomes the end
      }
      if (off_edge) {
        cuts.push_back(std::move(cut));
        cut.clear();
        // Step past the edge and look for the surface again.
        u = std::min(len, u + ad.min_step_mm);
        c = drop(u);
        ++dropped;
        if (u >= len && !c.touched()) break;
        continue;
      }
      h = u1 - u;
      pu[0] = pu[1], pz[0] = pz[1], pu[1] = u, pz[1] = c.z;
      history = std::min(history + 1, 2);
      if (corner_end) {  // from the corner on, the next piece at the normal step
        history = 0;
        h = spec.step_mm;
      }
      u = u1, c = c1;
      cut.push_back(cl(u, c.z));
    }
    if (cut.size() > 0) cuts.push_back(std::move(cut));
  }
};

}  // namespace

RasterPath raster_adaptive(const DropCutter& dc, const Bounds& bounds, const RasterSpec& spec,
                           const AdaptiveSpec& adaptive, int threads, RasterProgress* progress) {
  if (!(adaptive.beta_mm > 0) || !(adaptive.min_step_mm > 0) || !(adaptive.corner_tol_mm > 0))
    throw std::invalid_argument("raster: beta, the smallest step and the corner tolerance must be > 0");
  const std::vector<std::vector<XY>> passes = raster_passes(bounds, spec);
  std::vector<std::vector<std::vector<Vec3>>> per_pass(passes.size());
  std::vector<std::size_t> dropped(passes.size(), 0), corners(passes.size(), 0);
  util::parallel_for(passes.size(), threads, [&](std::size_t k) {
    const XY a = passes[k].front(), b = passes[k].back();
    const double len = std::hypot(b.x - a.x, b.y - a.y);
    if (len > 0) PassWalker{dc, a, b, len, spec, adaptive}.walk(per_pass[k], dropped[k], corners[k]);
    if (progress) {
      progress->points.fetch_add(dropped[k], std::memory_order_relaxed);
      progress->passes.fetch_add(1, std::memory_order_relaxed);
    }
  });
  RasterPath path;
  path.passes = passes.size();
  for (std::size_t k = 0; k < passes.size(); ++k) {
    path.points_dropped += dropped[k];
    path.corners += corners[k];
    for (auto& cut : per_pass[k])
      if (!cut.empty()) path.cuts.push_back(std::move(cut));
  }
  return path;
}

double path_deviation(const DropCutter& dc, const RasterPath& path, int samples, int threads,
                      RasterProgress* progress) {
  std::vector<double> worst(path.cuts.size(), 0);
  util::parallel_for(path.cuts.size(), threads, [&](std::size_t k) {
    const std::vector<Vec3>& cut = path.cuts[k];
    for (std::size_t i = 1; i < cut.size(); ++i) {
      for (int j = 1; j <= samples; ++j) {
        const double t = static_cast<double>(j) / (samples + 1);
        const double x = cut[i - 1].x + t * (cut[i].x - cut[i - 1].x), y = cut[i - 1].y + t * (cut[i].y - cut[i - 1].y);
        const ClPoint c = dc.drop(x, y);
        if (!c.touched()) continue;
        // Distance of the CL point from the segment, in 3-D.
        const Vec3 &p = cut[i - 1], &q = cut[i];
        const double ex = q.x - p.x, ey = q.y - p.y, ez = q.z - p.z;
        const double wx = x - p.x, wy = y - p.y, wz = c.z - p.z;
        const double e2 = ex * ex + ey * ey + ez * ez;
        const double s = e2 > 0 ? std::clamp((wx * ex + wy * ey + wz * ez) / e2, 0.0, 1.0) : 0;
        worst[k] = std::max(worst[k], std::hypot(wx - s * ex, wy - s * ey, wz - s * ez));
      }
    }
    if (progress) {
      progress->points.fetch_add((cut.size() > 0 ? cut.size() - 1 : 0) * static_cast<std::size_t>(std::max(samples, 0)),
                                 std::memory_order_relaxed);
      progress->passes.fetch_add(1, std::memory_order_relaxed);
    }
  });
  return worst.empty() ? 0 : *std::max_element(worst.begin(), worst.end());
}

}  // namespace cnc::cam
