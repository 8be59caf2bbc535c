#pragma once
// Reference NURBS curves for tests, benchmarks and demonstrations: the paper's
// Fig. 11 valley (Choi et al. 2005), a butterfly-like closed curve, an exact circle, a
// non-uniform rational spiral, a 3-D space curve and a degree-5 wave. All in mm,
// clamped, and valid for NurbsCurve.
#include <string>
#include <vector>

#include "common/geometry/nurbs.h"

namespace cnc::geometry {

struct SampleCurve {
  std::string name;
  int order = 0;
  std::vector<double> knots;
  std::vector<Vec3> control_points;
  std::vector<double> weights;
  NurbsCurve curve() const { return NurbsCurve(order, knots, control_points, weights); }
};

// Choi et al. 2005 Fig. 11: cubic, knots 0 0 0 0 .2 .4 .6 .8 1 1 1 1, a valley in XZ
// (8 control points at y = y0), starting at (x0, y0, z0).
SampleCurve fig11_valley(double x0 = 0, double y0 = 0, double z0 = 0);
// A butterfly-like closed curve (Fay's butterfly r = e^cosθ − 2cos4θ, scaled),
// cubic, 48 control points, starting and ending at the same point.
SampleCurve butterfly(double scale_mm = 12.0);
// A full circle of the given radius as a rational quadratic (9 points, w = √2/2).
SampleCurve circle(double radius_mm = 20.0);
// A rational cubic spiral with non-uniform knots and varying weights.
SampleCurve spiral();
// A cubic space curve winding up in Z (varying curvature and torsion).
SampleCurve space_curve();
// A degree-5 (order 6) wave along X with amplitude in Y.
SampleCurve wave();

// All of the above.
std::vector<SampleCurve> all_sample_curves();

// Clamped knot vector with uniform interior knots for n control points.
std::vector<double> clamped_uniform_knots(int order, int n);

}  // namespace cnc::geometry
