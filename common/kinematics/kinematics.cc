#include "common/kinematics/kinematics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "common/kinematics/five_axis.h"

namespace cnc::kinematics {
namespace {
// joint_rate's step along the rate, over the rate's largest entry: the central
// difference's truncation (h² times the third derivative, (π/180)³ x radius for a
// rotation in degrees) and its rounding (1e-16 x position / h) are both near 1e-9 of
// the rate for positions of a metre.
constexpr double kRateStep = 1e-3;
}  // namespace

std::array<JointLimits, program::kMaxAxes> axes_as_joints(const config::MachineConfig& cfg) {
  if (cfg.axes.size() > static_cast<size_t>(program::kMaxAxes))
    throw std::invalid_argument("more axes than the kinematics can hold");
  std::array<JointLimits, program::kMaxAxes> limits;
  for (size_t j = 0; j < cfg.axes.size(); ++j) {
    const auto& ax = cfg.axes[j];
    limits[j] = {ax.name, ax.min_mm, ax.max_mm, ax.max_velocity_mm_s, ax.max_accel_mm_s2, ax.max_jerk_mm_s3};
  }
  return limits;
}

bool Kinematics::in_travel(const Pose& joint_mm) const {
  const auto& l = joint_limits();
  for (int j = 0; j < joints(); ++j) {
    const auto i = static_cast<size_t>(j);
    if (!(joint_mm[i] >= l[i].min_mm && joint_mm[i] <= l[i].max_mm)) return false;
  }
  return true;
}

void Kinematics::joint_rate(const Pose& axis_mm, const Pose& axis_rate, const Tool& tool, Pose& joint_rate) const {
  double largest = 0;
  for (int a = 0; a < axes(); ++a) largest = std::max(largest, std::fabs(axis_rate[static_cast<size_t>(a)]));
  if (largest == 0) {
    for (int j = 0; j < joints(); ++j) joint_rate[static_cast<size_t>(j)] = 0;
    return;
  }
  const double h = kRateStep / largest;
  Pose ahead = axis_mm, behind = axis_mm;
  for (int a = 0; a < axes(); ++a) {
    const auto i = static_cast<size_t>(a);
    ahead[i] += h * axis_rate[i];
    behind[i] -= h * axis_rate[i];
  }
  Pose q_ahead{}, q_behind{};
  inverse(ahead, q_ahead, tool);
  inverse(behind, q_behind, tool);
  for (int j = 0; j < joints(); ++j) {
    const auto i = static_cast<size_t>(j);
    joint_rate[i] = (q_ahead[i] - q_behind[i]) / (2 * h);
  }
}

IdentityKinematics::IdentityKinematics(const config::MachineConfig& cfg)
    : n_(static_cast<int>(cfg.axes.size())), limits_(axes_as_joints(cfg)) {
  for (int j = 0; j < n_; ++j) {
    const auto& ax = cfg.axes[static_cast<size_t>(j)];
    if (ax.name == "Z" && !ax.rotary) z_ = j;
  }
}

void IdentityKinematics::forward(const Pose& joint_mm, Pose& axis_mm, const Tool& tool) const {
  for (int i = 0; i < n_; ++i) axis_mm[static_cast<size_t>(i)] = joint_mm[static_cast<size_t>(i)];
  // Only a tool moves Z: adding 0 would turn a -0 into +0, and identity is bit for bit.
  if (tool.length_mm != 0 && z_ >= 0) axis_mm[static_cast<size_t>(z_)] -= tool.length_mm;
}

bool IdentityKinematics::inverse(const Pose& axis_mm, Pose& joint_mm, const Tool& tool) const {
  for (int i = 0; i < n_; ++i) joint_mm[static_cast<size_t>(i)] = axis_mm[static_cast<size_t>(i)];
  if (tool.length_mm != 0 && z_ >= 0) joint_mm[static_cast<size_t>(z_)] += tool.length_mm;
  return true;
}

bool IdentityKinematics::orient(const ToolDirection&, const Pose&, Orientation& out) const {
  out = Orientation{};
  out.pole_distance_deg = std::numeric_limits<double>::infinity();
  return false;
}

double IdentityKinematics::pole_distance_deg(const Pose&) const { return std::numeric_limits<double>::infinity(); }

void IdentityKinematics::joint_rate(const Pose&, const Pose& axis_rate, const Tool&, Pose& joint_rate) const {
  for (int i = 0; i < n_; ++i) joint_rate[static_cast<size_t>(i)] = axis_rate[static_cast<size_t>(i)];
}

std::unique_ptr<Kinematics> make_kinematics(const config::MachineConfig& cfg) {
  if (cfg.kinematics.type == "identity") return std::make_unique<IdentityKinematics>(cfg);
  for (const char* type : config::kKinematicsTypes)
    if (cfg.kinematics.type == type) return std::make_unique<FiveAxisKinematics>(cfg);
  // The config reader accepts only config::kKinematicsTypes.
  throw std::invalid_argument("kinematics.type: unknown kinematics '" + cfg.kinematics.type + "'");
}

}  // namespace cnc::kinematics
