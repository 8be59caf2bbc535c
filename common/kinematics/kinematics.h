#pragma once
// Kinematics: the map between the joints (what the drives move) and the axes (where
// the tool is, the space programs and the path are in), and the joints' limits.
// LinuxCNC's kinematicsForward / kinematicsInverse with joint and axis spaces kept
// apart, so that the planner can limit joints while the path is planned in tool
// coordinates. Today's machines are identity: joint i is axis i.
//
// forward and inverse run in the cycle: fixed-size arrays, no allocation, no state
// beyond what the config gives (replay stays bit for bit).
#include <array>
#include <memory>
#include <string>
#include <string_view>

#include "common/config/machine_config.h"
#include "common/program/block.h"

namespace cnc::kinematics {

// Positions of up to program::kMaxAxes joints or axes (mm); entries past the
// machine's count are left as they are.
using Pose = std::array<double, program::kMaxAxes>;

// One joint's limits (travel, velocity, acceleration, jerk) and its name in messages.
struct JointLimits {
  std::string name;
  double min_mm = 0;
  double max_mm = 0;
  double max_velocity_mm_s = 0;
  double max_accel_mm_s2 = 0;
  double max_jerk_mm_s3 = 0;
};

class Kinematics {
 public:
  virtual ~Kinematics() = default;
  virtual std::string_view name() const = 0;
  virtual int joints() const = 0;
  virtual int axes() const = 0;
  // Joint positions -> axis (tool) positions; every joint position has one.
  virtual void forward(const Pose& joint_mm, Pose& axis_mm) const = 0;
  // Axis positions -> joint positions; false (and `joint_mm` unchanged) where the
  // machine cannot reach the pose.
  virtual bool inverse(const Pose& axis_mm, Pose& joint_mm) const = 0;
  // The joints' limits, joints() of them.
  virtual const std::array<JointLimits, program::kMaxAxes>& joint_limits() const = 0;
};

// Joints are the axes, one to one, with the axes' limits (axes[] of the machine config).
class IdentityKinematics final : public Kinematics {
 public:
  explicit IdentityKinematics(const config::MachineConfig& cfg);
  std::string_view name() const override { return "identity"; }
  int joints() const override { return n_; }
  int axes() const override { return n_; }
  void forward(const Pose& joint_mm, Pose& axis_mm) const override;
  bool inverse(const Pose& axis_mm, Pose& joint_mm) const override;
  const std::array<JointLimits, program::kMaxAxes>& joint_limits() const override { return limits_; }

 private:
  int n_;
  std::array<JointLimits, program::kMaxAxes> limits_;
};

// The machine's kinematics, as `kinematics.type` names it (config::kKinematicsTypes):
// a new geometry adds its class here and its name there.
std::unique_ptr<Kinematics> make_kinematics(const config::MachineConfig& cfg);

}  // namespace cnc::kinematics
