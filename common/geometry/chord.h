#pragma once
// Kim, Song & Kwon's chord-error feed limit: a step of length L along a curve of radius of
// curvature ρ leaves the chord at most h = ρ − sqrt(ρ² − L²/4) from the curve
// (≈ L²/(8ρ), the paper's eq. 5); holding h <= ε bounds the step, and the step per
// interpolation period bounds the feed.
#include "common/geometry/nurbs.h"

namespace cnc::geometry {

// The longest chord whose sagitta on a circle of radius rho is eps:
// 2·sqrt(2ρε − ε²). +inf for ρ = +inf (a straight line); 0 for ρ <= 0 (a corner),
// eps <= 0 or NaN. For eps >= ρ every chord up to the diameter meets the tolerance,
// so the result is 2ρ there (the formula's maximum, reached at eps = ρ); this keeps
// the step non-decreasing in eps, where the bare formula would fall back to zero at
// eps = 2ρ and turn imaginary beyond.
double chord_step_length(double radius_of_curvature, double eps);

// 60·chord_step_length(rho, eps)/period_s: the feed [mm/min] at which one period's
// step has chord error eps. period_s > 0.
double chord_feed_limit_mm_per_min(double radius_of_curvature, double eps, double period_s);

// The largest distance between the curve on [u0, u1] (either order, clamped to the
// domain) and the chord segment P(u0)P(u1). Samples the step at 16 sub-intervals and
// refines each sampled local maximum by golden-section search. The search leaves
// about 1e-9 of the result; below that, the rounding of the evaluated points (a few
// ulp of the coordinates, ~1e-15 mm at 5 mm) dominates, e.g. 1e-6 of a 2 nm error.
// Assumes the step's bulges are wider than 1/16 of it, which holds for
// interpolation steps. No allocation.
double chord_error_of_step(const NurbsCurve& curve, double u0, double u1);

}  // namespace cnc::geometry
