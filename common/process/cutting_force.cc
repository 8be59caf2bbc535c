#include "common/process/cutting_force.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

namespace cnc::process {
namespace {
constexpr double kPi = std::numbers::pi;
constexpr double kTwoPi = 2.0 * std::numbers::pi;

double wrap_2pi(double a) {
  double w = std::fmod(a, kTwoPi);
  if (w < 0) w += kTwoPi;
  return w;
}
}  // namespace

const char* to_string(ForceModel m) { return m == ForceModel::kLinearEdge ? "linear_edge" : "chip_thickness_law"; }

double CoefficientLaw::operator()(double t) const {
  return form == Form::kPower ? c * std::pow(t, exponent) : c * std::exp(exponent * t);
}

std::string Material::validate(ForceModel m) const {
  if (m == ForceModel::kLinearEdge && !has_linear) return "material '" + name + "' has no linear_edge coefficients";
  if (m == ForceModel::kChipThicknessLaw && !has_chip_law)
    return "material '" + name + "' has no chip_thickness_law coefficients";
  if (m == ForceModel::kChipThicknessLaw && !(chip_law.t_floor_mm > 0.0)) return "chip_thickness_law.t_floor_mm must be positive";
  return "";
}

std::string EndMill::validate() const {
  std::ostringstream os;
  if (flutes < 1) os << "flutes must be at least 1, got " << flutes;
  else if (!(diameter_mm > 0.0)) os << "diameter_mm must be positive, got " << diameter_mm;
  else if (!(helix_deg >= 0.0 && helix_deg < 80.0)) os << "helix_deg must be in [0, 80), got " << helix_deg;
  else if (!(overhang_mm > 0.0)) os << "overhang_mm must be positive, got " << overhang_mm;
  else if (!(youngs_modulus_n_mm2 > 0.0)) os << "youngs_modulus_n_mm2 must be positive";
  else if (!(effective_diameter_ratio > 0.0 && effective_diameter_ratio <= 1.0))
    os << "effective_diameter_ratio must be in (0, 1]";
  else if (type != "flat" && type != "ball") os << "type must be flat or ball, got '" << type << "'";
  return os.str();
}

Engagement Engagement::slot(double axial_depth, double feed_per_tooth) {
  return {0.0, kPi, axial_depth, feed_per_tooth};
}

Engagement Engagement::up_milling(double diameter, double radial_depth, double axial_depth, double feed_per_tooth) {
  const double arc = std::acos(std::clamp(1.0 - 2.0 * radial_depth / diameter, -1.0, 1.0));
  return {0.0, arc, axial_depth, feed_per_tooth};
}

Engagement Engagement::down_milling(double diameter, double radial_depth, double axial_depth, double feed_per_tooth) {
  const double arc = std::acos(std::clamp(1.0 - 2.0 * radial_depth / diameter, -1.0, 1.0));
  return {kPi - arc, kPi, axial_depth, feed_per_tooth};
}

ElementForce element_force(const Material& mat, ForceModel model, double h, double dz) {
  if (model == ForceModel::kLinearEdge) {
    const LinearEdgeCoefficients& k = mat.linear;
    return {(k.ktc * h + k.kte) * dz, (k.krc * h + k.kre) * dz, (k.kac * h + k.kae) * dz};
  }
  const ChipThicknessLaw& law = mat.chip_law;
  const double t = std::max(h, law.t_floor_mm);
  const double ft = law.kt(t) * dz * h;  // eq. 12
  return {ft, law.kr(t) * ft, law.ka * ft};
}

Eigen::Vector3d project(const ElementForce& f, double phi) {
  const double s = std::sin(phi);
  const double c = std::cos(phi);
  return {-f.ft * c - f.fr * s, f.ft * s - f.fr * c, f.fa};
}

Eigen::Vector3d ForceHistory::mean() const {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& f : force) sum += f;
  return force.empty() ? sum : Eigen::Vector3d(sum / static_cast<double>(force.size()));
}

CuttingForceModel::CuttingForceModel(EndMill tool, Material material, ForceModel model, int discs)
    : tool_(std::move(tool)), material_(std::move(material)), model_(model), discs_(std::max(1, discs)) {}

double CuttingForceModel::lag_per_disc(const Engagement& e) const {
  return disc_height(e) * std::tan(tool_.helix_deg * kPi / 180.0) / tool_.radius();
}

void CuttingForceModel::disc_forces(const Engagement& e, double theta, std::vector<Eigen::Vector3d>& out) const {
  out.assign(static_cast<size_t>(discs_), Eigen::Vector3d::Zero());
  const double dz = disc_height(e);
  const double lag = lag_per_disc(e);
  const double pitch = kTwoPi / tool_.flutes;
  for (int i = 0; i < discs_; ++i) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (int k = 0; k < tool_.flutes; ++k) {
      const double phi = wrap_2pi(theta + k * pitch - (i + 0.5) * lag);  // eq. 3
      if (phi < e.phi_start || phi > e.phi_exit) continue;
      const double h = e.feed_per_tooth_mm * std::sin(phi);  // eq. 1
      if (!(h > 0.0)) continue;
      sum += project(element_force(material_, model_, h, dz), phi);
    }
    out[static_cast<size_t>(i)] = sum;
  }
}

Eigen::Vector3d CuttingForceModel::force(const Engagement& e, double theta) const {
  const double dz = disc_height(e);
  const double lag = lag_per_disc(e);
  const double pitch = kTwoPi / tool_.flutes;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int i = 0; i < discs_; ++i) {
    for (int k = 0; k < tool_.flutes; ++k) {
      const double phi = wrap_2pi(theta + k * pitch - (i + 0.5) * lag);
      if (phi < e.phi_start || phi > e.phi_exit) continue;
      const double h = e.feed_per_tooth_mm * std::sin(phi);
      if (!(h > 0.0)) continue;
      sum += project(element_force(material_, model_, h, dz), phi);
    }
  }
  return sum;
}

int CuttingForceModel::paper_steps_per_rev(const Engagement& e) const {
  const int n = tool_.flutes;
  const double lag = lag_per_disc(e);
  if (!(lag > 0.0)) return 90 * n;
  const double per_flute = std::round(kTwoPi / lag / n);
  return n * static_cast<int>(std::clamp(per_flute, 1.0, 1e6));
}

ForceHistory CuttingForceModel::simulate_revolution(const Engagement& e, int steps) const {
  ForceHistory h;
  steps = std::max(1, steps);
  h.theta.reserve(static_cast<size_t>(steps));
  h.force.reserve(static_cast<size_t>(steps));
  for (int j = 0; j < steps; ++j) {
    const double theta = kTwoPi * j / steps;
    h.theta.push_back(theta);
    h.force.push_back(force(e, theta));
  }
  return h;
}

Eigen::Vector3d slot_mean_force_closed_form(const LinearEdgeCoefficients& k, int flutes, double a, double c) {
  const double na = flutes * a;
  return {-na * c * k.krc / 4.0 - na * k.kre / kPi, na * c * k.ktc / 4.0 + na * k.kte / kPi,
          na * c * k.kac / kPi + na * k.kae / 2.0};
}

}  // namespace cnc::process
