#include "common/process/live_force.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/config/yaml_reader.h"
#include "common/process/cutting_config.h"

namespace cnc::process {
namespace {
constexpr double kPi = std::numbers::pi;
constexpr int kBins = 180;

int cells(double lo, double hi, double pitch) { return std::max(1, static_cast<int>(std::ceil((hi - lo) / pitch))); }
}  // namespace

CuttingSetup load_cutting_setup(const config::MachineConfig& cfg) {
  const config::CuttingConfig& k = cfg.cutting;
  CuttingSetup s;
  auto rethrow = [&](const char* key, const std::string& file, const std::exception& e) {
    throw config::ConfigError(cfg.source_file, std::string("cutting.") + key, file + ": " + e.what());
  };
  try {
    s.tool = load_tool(k.tool_file);
  } catch (const std::exception& e) {
    rethrow("tool", k.tool_file, e);
  }
  if (s.tool.type != "flat")
    throw config::ConfigError(cfg.source_file, "cutting.tool",
                              k.tool_file + ": the force model's engagement is for a flat end mill, this is a '" +
                                  s.tool.type + "' one");
  try {
    s.material = load_material(k.material_file);
  } catch (const std::exception& e) {
    rethrow("material", k.material_file, e);
  }
  s.model = k.model.empty() ? s.material.model : force_model_from_string(k.model);
  const std::string why = s.material.validate(s.model);
  if (!why.empty()) throw config::ConfigError(cfg.source_file, "cutting.model", why);
  return s;
}

LiveForce::LiveForce(const CuttingSetup& setup, const config::CuttingConfig& cfg)
    : cfg_(cfg),
      model_(setup.tool, setup.material, setup.model, 1),
      beam_(setup.tool),
      stock_(cfg.stock_x_min_mm, cfg.stock_y_min_mm, cfg.stock_pitch_mm,
             cells(cfg.stock_x_min_mm, cfg.stock_x_max_mm, cfg.stock_pitch_mm),
             cells(cfg.stock_y_min_mm, cfg.stock_y_max_mm, cfg.stock_pitch_mm), cfg.stock_top_z_mm) {
  profile_.phi.assign(kBins, 0.0);
  profile_.depth.assign(kBins, 0.0);
  // Discs up to the flute length the engagement is clamped to (the overhang).
  const size_t max_discs = static_cast<size_t>(std::ceil(setup.tool.overhang_mm / cfg.disc_height_mm)) + 2;
  discs_.reserve(max_discs);
  heights_.reserve(max_discs);
}

void LiveForce::reset() { stock_.reset(cfg_.stock_top_z_mm); }

void LiveForce::engage(const Eigen::Vector3d& tip, const Eigen::Vector2d& feed_dir) {
  engagement_from_stock(stock_, tip, feed_dir, tool().radius(), tool().overhang_mm, kBins, 0.0, &profile_);
}

ForceEstimate LiveForce::estimate(double c) {
  ForceEstimate e;
  e.axial_depth_mm = profile_.max_depth();
  if (!(e.axial_depth_mm > 0) || !(c > 0)) return e;
  e.engaged = true;
  const double r = tool().radius();
  e.radial_depth_mm = r * (std::cos(profile_.arc_start()) - std::cos(profile_.arc_exit()));
  profile_.feed_per_tooth_mm = c;
  const int n = cfg_.angles_per_tooth;
  const double period = 2.0 * kPi / tool().flutes;
  for (int j = 0; j < n; ++j) {
    const double theta = period * j / n;
    double dz = 0;
    const Eigen::Vector3d f = force_from_profile(model_, profile_, cfg_.disc_height_mm, theta, &discs_, &dz);
    e.mean_force += f / n;
    e.peak_force_n = std::max(e.peak_force_n, f.head<2>().norm());
    heights_.resize(discs_.size());
    for (size_t i = 0; i < heights_.size(); ++i) heights_[i] = (static_cast<double>(i) + 0.5) * dz;
    e.peak_deflection_mm = std::max(e.peak_deflection_mm, beam_.deflection(0.0, heights_, discs_).norm());
  }
  return e;
}

bool LiveForce::within(const ForceEstimate& e) const {
  if (e.peak_deflection_mm > cfg_.deflection_tolerance_mm) return false;
  return !(cfg_.max_force_n > 0 && e.peak_force_n > cfg_.max_force_n);
}

double LiveForce::limit_feed_per_tooth(double c_max, bool* binding) {
  *binding = false;
  if (!(c_max > 0) || !(profile_.max_depth() > 0)) return c_max;
  if (within(estimate(c_max))) return c_max;
  *binding = true;
  // The estimate grows with c: bisection on log c between c_max·1e-3 and c_max,
  // keeping the lower end within the limits (12 halvings: 0.17 % in c).
  double lo = std::log(c_max * 1e-3), hi = std::log(c_max);
  if (!within(estimate(std::exp(lo)))) return std::exp(lo);
  for (int k = 0; k < 12; ++k) {
    const double mid = 0.5 * (lo + hi);
    if (within(estimate(std::exp(mid)))) lo = mid;
    else hi = mid;
  }
  return std::exp(lo);
}

void LiveForce::remove(const Eigen::Vector3d& tip0, const Eigen::Vector3d& tip1) {
  remove_flat_envelope(stock_, tip0, tip1, tool().radius());
}

}  // namespace cnc::process
