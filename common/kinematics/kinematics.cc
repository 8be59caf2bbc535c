#include "common/kinematics/kinematics.h"

#include <stdexcept>

namespace cnc::kinematics {

IdentityKinematics::IdentityKinematics(const config::MachineConfig& cfg) : n_(static_cast<int>(cfg.axes.size())) {
  if (n_ > program::kMaxAxes) throw std::invalid_argument("more axes than the kinematics can hold");
  for (int j = 0; j < n_; ++j) {
    const auto& ax = cfg.axes[static_cast<size_t>(j)];
    limits_[static_cast<size_t>(j)] = {ax.name, ax.min_mm, ax.max_mm, ax.max_velocity_mm_s, ax.max_accel_mm_s2,
                                       ax.max_jerk_mm_s3};
  }
}

void IdentityKinematics::forward(const Pose& joint_mm, Pose& axis_mm) const {
  for (int i = 0; i < n_; ++i) axis_mm[static_cast<size_t>(i)] = joint_mm[static_cast<size_t>(i)];
}

bool IdentityKinematics::inverse(const Pose& axis_mm, Pose& joint_mm) const {
  for (int i = 0; i < n_; ++i) joint_mm[static_cast<size_t>(i)] = axis_mm[static_cast<size_t>(i)];
  return true;
}

std::unique_ptr<Kinematics> make_kinematics(const config::MachineConfig& cfg) {
  if (cfg.kinematics.type == "identity") return std::make_unique<IdentityKinematics>(cfg);
  // The config reader accepts only config::kKinematicsTypes.
  throw std::invalid_argument("kinematics.type: unknown kinematics '" + cfg.kinematics.type + "'");
}

}  // namespace cnc::kinematics
