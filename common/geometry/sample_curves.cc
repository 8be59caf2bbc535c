#include "common/geometry/sample_curves.h"

#include <cmath>
#include <numbers>

namespace cnc::geometry {

std::vector<double> clamped_uniform_knots(int order, int n) {
  std::vector<double> k;
  const int inner = n - order;
  for (int i = 0; i < order; ++i) k.push_back(0.0);
  for (int i = 1; i <= inner; ++i) k.push_back(static_cast<double>(i) / (inner + 1));
  for (int i = 0; i < order; ++i) k.push_back(1.0);
  return k;
}

SampleCurve fig11_valley(double x0, double y0, double z0) {
  SampleCurve c;
  c.name = "fig11_valley";
  c.order = 4;
  c.knots = {0, 0, 0, 0, 0.2, 0.4, 0.6, 0.8, 1, 1, 1, 1};
  const double pts[8][2] = {{0, 0}, {10, 0}, {20, -10}, {30, -20}, {40, -20}, {50, -10}, {60, 0}, {70, 0}};
  for (const auto& p : pts) c.control_points.emplace_back(x0 + p[0], y0, z0 + p[1]);
  c.weights.assign(8, 1.0);
  return c;
}

SampleCurve butterfly(double scale_mm) {
  SampleCurve c;
  c.name = "butterfly";
  c.order = 4;
  const int n = 48;
  for (int i = 0; i < n; ++i) {
    // Closed: the last control point repeats the first.
    const double th = 2 * std::numbers::pi * (i == n - 1 ? 0 : i) / (n - 1);
    const double r = std::exp(std::cos(th)) - 2 * std::cos(4 * th);
    c.control_points.emplace_back(scale_mm * r * std::sin(th), scale_mm * r * std::cos(th), 0.0);
  }
  c.knots = clamped_uniform_knots(c.order, n);
  c.weights.assign(n, 1.0);
  return c;
}

SampleCurve circle(double radius_mm) {
  SampleCurve c;
  c.name = "circle";
  c.order = 3;
  const double R = radius_mm, w = std::sqrt(0.5);
  const double pts[9][2] = {{R, 0}, {R, R}, {0, R}, {-R, R}, {-R, 0}, {-R, -R}, {0, -R}, {R, -R}, {R, 0}};
  for (const auto& p : pts) c.control_points.emplace_back(p[0], p[1], 0.0);
  c.weights = {1, w, 1, w, 1, w, 1, w, 1};
  c.knots = {0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1};
  return c;
}

SampleCurve spiral() {
  SampleCurve c;
  c.name = "spiral";
  c.order = 4;
  const int n = 14;
  for (int i = 0; i < n; ++i) {
    const double th = 0.55 * i;
    const double r = 4.0 + 2.2 * i;
    c.control_points.emplace_back(r * std::cos(th), r * std::sin(th), 0.0);
    c.weights.push_back(1.0 + 0.6 * std::sin(1.3 * i));
  }
  // Non-uniform interior knots.
  c.knots = {0, 0, 0, 0, 0.05, 0.12, 0.2, 0.31, 0.4, 0.52, 0.6, 0.73, 0.81, 0.9, 1, 1, 1, 1};
  return c;
}

SampleCurve space_curve() {
  SampleCurve c;
  c.name = "space_curve";
  c.order = 4;
  const int n = 16;
  for (int i = 0; i < n; ++i) {
    const double th = 0.8 * i;
    c.control_points.emplace_back(15 * std::cos(th) + 2.0 * i, 15 * std::sin(th), -1.5 * i);
  }
  c.knots = clamped_uniform_knots(c.order, n);
  c.weights.assign(n, 1.0);
  return c;
}

SampleCurve wave() {
  SampleCurve c;
  c.name = "wave";
  c.order = 6;
  const int n = 20;
  for (int i = 0; i < n; ++i) c.control_points.emplace_back(5.0 * i, (i % 2 ? 6.0 : -6.0) * (i > 0 && i < n - 1), 0.0);
  c.knots = clamped_uniform_knots(c.order, n);
  c.weights.assign(n, 1.0);
  return c;
}

std::vector<SampleCurve> all_sample_curves() {
  return {fig11_valley(), butterfly(), circle(), spiral(), space_curve(), wave()};
}

}  // namespace cnc::geometry
