#include "common/process/roughness.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

namespace cnc::process {

double feed_inclination_angle(const Eigen::Vector3d& tangent) {
  const double len = tangent.norm();
  if (!(len > 0.0) || !std::isfinite(len)) return 0.0;
  return std::asin(std::min(1.0, std::abs(tangent.z()) / len));
}

double rmax_classic(double r, double f_t, double f_p, double rho_f, double rho_p) {
  return f_t * f_t / (8.0 * r) * (1.0 - r / (rho_f + r)) + f_p * f_p / (8.0 * r) * (1.0 - r / (rho_p + r));
}

double phase_feed_law(double f_p) { return f_p / (2.0 * std::numbers::pi); }

double phase_general(double r, double f_t, double f_p, double alpha) {
  const double s = std::abs(std::sin(alpha));
  const double limit = 0.5 * f_t;
  if (s == 0.0) return limit;
  return std::clamp(f_t / std::numbers::pi * f_p / (r * s), 0.0, limit);
}

double rmax_region2(double r, double f_t, double f_p, double phase) {
  const double q = (f_t - phase) / f_p;
  return f_p * f_p / (8.0 * r) * (1.0 + q * q);
}

double rmax_region1(double r, double f_t, double alpha) {
  // r·(1 − sqrt(1 − x)) = r·x / (1 + sqrt(1 − x)): R_max is ~1e-3 of r, and the
  // direct form would lose three digits to cancellation.
  const double s = std::sin(alpha);
  const double ratio = f_t / r;
  const double x = ratio * ratio - s * s;
  return r * x / (1.0 + std::sqrt(std::max(0.0, 1.0 - x)));
}

double critical_angle(double r, double f_t, double f_p) {
  const double q = f_t - phase_feed_law(f_p);
  const double a = f_p * f_p + q * q;
  const double b = a / (8.0 * r);
  const double radicand = b * b - 0.25 * a + f_t * f_t;
  if (!(radicand > 0.0)) return 0.0;
  return std::asin(std::min(1.0, std::sqrt(radicand) / r));
}

double rmax_extended(double r, double f_t, double f_p, double alpha) {
  if (std::abs(alpha) < critical_angle(r, f_t, f_p)) return rmax_region1(r, f_t, alpha);
  return rmax_region2(r, f_t, f_p, phase_feed_law(f_p));
}

double feed_per_tooth_for_rmax(double r, double f_p, double rmax, double alpha) {
  const double target = std::clamp(rmax, f_p * f_p / (8.0 * r), r);
  const double f_t2 = phase_feed_law(f_p) + std::sqrt(std::max(0.0, 8.0 * r * target - f_p * f_p));  // eq. 5
  if (std::abs(alpha) >= critical_angle(r, f_t2, f_p)) return f_t2;
  const double rs = r * std::sin(alpha);
  return std::sqrt(rs * rs + 2.0 * r * target - target * target);  // eq. 6
}

double isotropic_target_rmax(double r, double f_p) { return f_p * f_p / (4.0 * r); }

std::string RoughnessLaw::validate() const {
  std::ostringstream os;
  os.precision(6);
  if (!(ball_radius_mm > 0.0) || !std::isfinite(ball_radius_mm)) {
    os << "ball_radius_mm must be positive and finite, got " << ball_radius_mm;
  } else if (flutes < 1) {
    os << "flutes must be at least 1, got " << flutes;
  } else if (!(pick_feed_mm > 0.0) || !std::isfinite(pick_feed_mm)) {
    os << "pick_feed_mm must be positive and finite, got " << pick_feed_mm;
  } else if (!std::isfinite(target_rmax_mm)) {
    os << "target_rmax_mm must be finite, got " << target_rmax_mm;
  } else if (const double cusp = pick_feed_mm * pick_feed_mm / (8.0 * ball_radius_mm); target_rmax_mm < cusp) {
    os << "target_rmax_mm " << target_rmax_mm << " is below the cusp height f_p^2/(8r) = " << cusp
       << " mm that the pick feed alone leaves";
  } else if (!(target_rmax_mm < ball_radius_mm)) {
    os << "target_rmax_mm " << target_rmax_mm << " is not below the ball radius " << ball_radius_mm;
  }
  return os.str();
}

double RoughnessLaw::feed_mm_per_min(double spindle_rpm, double alpha) const {
  return flutes * spindle_rpm * feed_per_tooth_for_rmax(ball_radius_mm, pick_feed_mm, target_rmax_mm, alpha);
}

}  // namespace cnc::process
