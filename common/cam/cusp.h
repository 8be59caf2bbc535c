#pragma once
// Shin et al.: the cusp (scallop) a z-level roughing path leaves on a slope between two
// levels, and the largest z-step that keeps it under a limit.
//
// The cross-section normal to the contour: the part's surface is a line rising at θ
// (from horizontal, 0 < θ <= 90°); two consecutive levels put the cutter's tip Δz
// apart, each position tangent to the line, so the second is the first moved by
// s = Δz / sin θ along the line (d = Δz·cot θ across). Each level clears everything
// outside its cutter (pocketing), so what stays between the part and the two profiles
// is a cusp whose height h is measured normal to the surface, at the corner where the
// lower cutter's profile (its corner arc of radius r, or its side above it) meets the
// upper one's (its flat bottom, or its corner arc). With a = R − r the flat half-width:
//   floor, Δz <= r (arc meets the upper bottom, sqrt(2rΔz − Δz²) <= d):
//       h = r + (Δz − r) cos θ − sin θ sqrt(2rΔz − Δz²)
//   floor, Δz > r (side meets the upper bottom, r <= d):  h = r(1 − sin θ) + (Δz − r) cos θ
//       (flat, r = 0: h = Δz cos θ)
//   arc meets arc (both on their lower-outer quarter):     h = r − sqrt(r² − s²/4)
//       (ball: Δz = 2 sin θ sqrt(2Rh − h²))
//   side meets the upper arc (d < r):                      h = r(1 − sin θ) + z_t cos θ,
//       z_t = Δz − sqrt(r² − (r − d)²)
// h grows with Δz. zstep_for_cusp inverts h(Δz) in closed form where the case has one
// (flat, the two floor cases, arc meets arc) and by bisection where it has none (side
// meets arc), and checks every closed form by evaluating h again.
#include <cstdint>

#include "common/cam/cutter.h"

namespace cnc::cam {

enum class CuspCase : std::uint8_t { kFloorArc, kFloorSide, kArcArc, kSideArc, kNone };
const char* cusp_case_name(CuspCase c);

struct Cusp {
  double h = 0;
  CuspCase kind = CuspCase::kNone;
};

// θ in radians, 0 < θ <= π/2; dz >= 0. θ = π/2 (a wall) leaves no cusp once Δz >= r.
Cusp cusp_height(const Cutter& cutter, double theta, double dz);

// The largest Δz in (0, dz_max] with cusp_height(θ, Δz) <= h (dz_max where every
// Δz up to it holds: steep walls). `closed_form`, if given, tells whether a closed form
// gave it (else bisection to 1e-12 mm).
double zstep_for_cusp(const Cutter& cutter, double theta, double h, double dz_max, bool* closed_form = nullptr);

// The same by bisection on cusp_height only (the reference of the closed forms).
double zstep_bisect(const Cutter& cutter, double theta, double h, double dz_max);

}  // namespace cnc::cam
