#include "common/process/deflection.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace cnc::process {
namespace {
constexpr double kPi = std::numbers::pi;
}

CantileverTool::CantileverTool(const EndMill& tool)
    : length_(tool.overhang_mm),
      inertia_(kPi * std::pow(tool.effective_diameter_ratio * tool.diameter_mm, 4) / 64.0),
      ei_(tool.youngs_modulus_n_mm2 * inertia_) {}

double CantileverTool::influence(double u, double l) const {
  const double bracket = std::max(0.0, u - l);
  return (bracket * bracket * bracket - u * u * u + 3.0 * u * u * l) / (6.0 * ei_);  // eq. 13
}

Eigen::Vector2d CantileverTool::deflection(double z, const std::vector<double>& load_heights,
                                           const std::vector<Eigen::Vector3d>& loads) const {
  Eigen::Vector2d d = Eigen::Vector2d::Zero();
  const double u = length_ - z;
  for (size_t i = 0; i < loads.size() && i < load_heights.size(); ++i) {
    d += influence(u, length_ - load_heights[i]) * loads[i].head<2>();
  }
  return d;
}

double wall_angle(const Engagement& e) { return e.phi_start <= 0.0 ? e.phi_start : e.phi_exit; }

std::vector<WallErrorPoint> wall_surface_error(const CuttingForceModel& model, const Engagement& e, int points,
                                               double wall_phi) {
  const CantileverTool beam(model.tool());
  const double tan_h = std::tan(model.tool().helix_deg * kPi / 180.0);
  const double r = model.tool().radius();
  const double dz = model.disc_height(e);
  std::vector<double> heights(static_cast<size_t>(model.discs()));
  for (size_t i = 0; i < heights.size(); ++i) heights[i] = (static_cast<double>(i) + 0.5) * dz;
  const Eigen::Vector2d normal(std::sin(wall_phi), std::cos(wall_phi));  // tool centre towards the wall
  std::vector<Eigen::Vector3d> loads;
  std::vector<WallErrorPoint> out;
  points = std::max(1, points);
  for (int p = 0; p < points; ++p) {
    WallErrorPoint w;
    w.height_mm = (p + 0.5) * e.axial_depth_mm / points;
    w.theta = wall_phi + w.height_mm * tan_h / r;  // eq. 15
    model.disc_forces(e, w.theta, loads);
    w.force = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& f : loads) w.force += f;
    w.deflection = beam.deflection(w.height_mm, heights, loads);
    w.surface_error_mm = -w.deflection.dot(normal);
    out.push_back(w);
  }
  return out;
}

WallErrorMap wall_error_map(const CuttingForceModel& model, const std::vector<WallSection>& sections, int points) {
  WallErrorMap m;
  double amax = 0;
  for (const WallSection& s : sections) {
    m.x_mm.push_back(s.x_mm);
    const std::vector<WallErrorPoint> prof =
        wall_surface_error(model, s.engagement, points, wall_angle(s.engagement));
    std::vector<double> col;
    for (const WallErrorPoint& w : prof) {
      col.push_back(w.surface_error_mm);
      amax = std::max(amax, std::abs(w.surface_error_mm));
    }
    if (m.height_mm.empty()) {
      for (const WallErrorPoint& w : prof) m.height_mm.push_back(w.height_mm);
    }
    m.error_mm.push_back(std::move(col));
  }
  m.max_abs_mm = amax;
  return m;
}

}  // namespace cnc::process
