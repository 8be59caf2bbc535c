#pragma once
// A NURBS curve in 3-D (Kim, Song & Kwon, eq. 1 and 2), evaluated with the algorithms of
// Piegl & Tiller, The NURBS Book: span search (A2.1), basis functions and their
// derivatives (A2.3) and rational derivatives (A4.2). The evaluation functions run
// in the interpolator's cycle, so they use fixed-size arrays and never allocate.
// Geometry, not just Core: with Core alone Vec3::cross compiles but does not link.
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace cnc::geometry {

using Vec3 = Eigen::Vector3d;

class NurbsCurve {
 public:
  static constexpr int kMaxOrder = 8;
  static constexpr int kMaxDerivative = 3;

  // order = degree + 1 (2..8); knots.size() == ctrl.size() + order; the knot
  // vector is clamped (the first and the last `order` knots equal), non-decreasing,
  // with no interior knot of multiplicity above the degree (which would break the
  // curve); weights > 0. Throws std::invalid_argument with validate()'s message, or
  // naming the first control point that is not finite.
  NurbsCurve(int order, std::vector<double> knots, std::vector<Vec3> ctrl, std::vector<double> weights);

  // "" when the definition is usable, else what is wrong with it (the first fault).
  static std::string validate(int order, const std::vector<double>& knots, size_t n_ctrl,
                              const std::vector<double>& weights);

  int order() const { return order_; }
  int degree() const { return order_ - 1; }
  double u_min() const { return knots_[order_ - 1]; }
  double u_max() const { return knots_[ctrl_.size()]; }
  const std::vector<double>& knots() const { return knots_; }
  const std::vector<Vec3>& control_points() const { return ctrl_; }
  const std::vector<double>& weights() const { return weights_; }

  // A2.1: the index i of the knot span [knots[i], knots[i+1]) holding u, with u
  // clamped to [u_min, u_max]; u_max maps to the last non-empty span.
  int find_span(double u) const;

  Vec3 point(double u) const;

  // C^(k)(u) for k = 0..d into out[0..d], 0 <= d <= kMaxDerivative (a larger d is a
  // programming error and aborts). Derivatives above the degree are zero.
  void derivatives(double u, int d, Vec3* out) const;

  // |C' x C''| / |C'|^3; +inf where C' vanishes (a cusp is treated as a corner).
  double curvature(double u) const;

  // The distinct knot values in [u_min, u_max], both ends included: the spans'
  // boundaries, where the curve may lose smoothness.
  std::vector<double> breakpoints() const;

 private:
  int order_;
  std::vector<double> knots_;
  std::vector<Vec3> ctrl_;
  std::vector<double> weights_;
  std::vector<Eigen::Vector4d> weighted_;  // (w·P, w): the homogeneous control points
};

// Arc length of the curve from u0 to u1 (clamped to the domain; negative when
// u1 < u0) by adaptive Gauss–Legendre quadrature, knot span by knot span, to an
// absolute tolerance tol in mm. Allocates nothing, but is not meant for the cycle.
double arc_length(const NurbsCurve& c, double u0, double u1, double tol = 1e-9);

}  // namespace cnc::geometry
