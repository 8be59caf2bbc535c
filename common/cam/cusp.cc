#include "common/cam/cusp.h"

#include <algorithm>
#include <cmath>

namespace cnc::cam {

const char* cusp_case_name(CuspCase c) {
  switch (c) {
    case CuspCase::kFloorArc: return "floor-arc";
    case CuspCase::kFloorSide: return "floor-side";
    case CuspCase::kArcArc: return "arc-arc";
    case CuspCase::kSideArc: return "side-arc";
    case CuspCase::kNone: break;
  }
  return "none";
}

Cusp cusp_height(const Cutter& cutter, double theta, double dz) {
  const double R = cutter.radius(), r = cutter.corner_radius_mm, a = R - r;
  const double st = std::sin(theta), ct = std::cos(theta);
  if (dz <= 0) return {0, CuspCase::kNone};
  const double d = ct > 0 ? dz * ct / st : 0;  // the upper position's shift across
  // Height of P above the surface line, measured normal to it: the line lies r below the
  // lower cutter's corner centre (a, r) along n = (−sin θ, cos θ).
  auto height = [&](double px, double pz) { return std::max(0.0, (px - a) * -st + (pz - r) * ct + r); };
  // The lower cutter's outer profile at the upper tip's height.
  const double xk = dz >= r ? R : a + std::sqrt(std::max(0.0, 2 * r * dz - dz * dz));
  if (xk <= d + a) {  // it meets the upper cutter's flat bottom
    return {height(xk, dz), dz <= r && r > 0 ? CuspCase::kFloorArc : CuspCase::kFloorSide};
  }
  // Here d < r: the upper corner arc crosses the lower profile; first try the lower side.
  const double w = std::sqrt(std::max(0.0, r * r - (r - d) * (r - d)));
  if (dz >= w) return {height(R, dz + r - w), CuspCase::kSideArc};
  // Both corner arcs: centres s apart along the line, crossing q from their midpoint.
  const double s = dz / st;
  const double q = std::sqrt(std::max(0.0, r * r - 0.25 * s * s));
  return {std::max(0.0, r - q), CuspCase::kArcArc};
}

double zstep_bisect(const Cutter& cutter, double theta, double h, double dz_max) {
  if (cusp_height(cutter, theta, dz_max).h <= h) return dz_max;
  double lo = 0, hi = dz_max;
  while (hi - lo > 1e-12) {
    const double mid = 0.5 * (lo + hi);
    if (mid <= lo || mid >= hi) break;
    (cusp_height(cutter, theta, mid).h <= h ? lo : hi) = mid;
  }
  return lo;
}

double zstep_for_cusp(const Cutter& cutter, double theta, double h, double dz_max, bool* closed_form) {
  if (closed_form) *closed_form = false;
  if (cusp_height(cutter, theta, dz_max).h <= h) {
    if (closed_form) *closed_form = true;
    return dz_max;
  }
  const double r = cutter.corner_radius_mm, st = std::sin(theta), ct = std::cos(theta);
  double cand[5];
  int n = 0;
  if (ct > 0) cand[n++] = r + (h - r * (1 - st)) / ct;  // floor-side (flat: h / cos θ)
  if (r > 0 && h <= 2 * r) {
    const double root = st * std::sqrt(std::max(0.0, r * r - (r - h) * (r - h)));
    cand[n++] = r - (r - h) * ct + root;  // floor-arc, u = Δz − r
    cand[n++] = r - (r - h) * ct - root;
  }
  if (r > 0 && h <= r) cand[n++] = 2 * st * std::sqrt(2 * r * h - h * h);  // arc-arc
  double best = -1;
  for (int i = 0; i < n; ++i) {
    const double dz = cand[i];
    if (!(dz > 0) || dz > dz_max) continue;
    const Cusp c = cusp_height(cutter, theta, dz);
    if (std::fabs(c.h - h) <= 1e-9 * std::max(1.0, h) && c.kind != CuspCase::kSideArc) best = std::max(best, dz);
  }
  if (best > 0) {
    if (closed_form) *closed_form = true;
    return best;
  }
  return zstep_bisect(cutter, theta, h, dz_max);
}

}  // namespace cnc::cam
