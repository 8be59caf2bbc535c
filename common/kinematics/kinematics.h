#pragma once
// Kinematics: the map between the joints (what the drives move) and the axes (where
// the tool is, the space programs and the path are in), and the joints' limits.
// LinuxCNC's kinematicsForward / kinematicsInverse with joint and axis spaces kept
// apart, so that the planner can limit joints while the path is planned in tool
// coordinates. Identity (joint i is axis i) is the default; five-axis machines with
// trunnion tables, spindle heads or both are in five_axis.h.
//
// Everything here runs in the cycle: fixed-size arrays, const methods, no allocation,
// no state beyond what the config gives (replay stays bit for bit). What changes
// while a program runs (the active tool, the joints where the machine stands) is an
// argument of the call.
#include <array>
#include <memory>
#include <string>
#include <string_view>

#include "common/config/machine_config.h"
#include "common/program/block.h"

namespace cnc::kinematics {

// Positions of up to program::kMaxAxes joints or axes (mm, rotary ones in degrees);
// entries past the machine's count are left as they are. Joint i and axis i are
// axes[i] of the machine config in every kinematics.
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

// The active tool. Joints carry the spindle's gauge point (the tip of a tool of length
// 0), axes the tool's tip: with a length L, the tip is L from the gauge point along the
// tool, away from the spindle. Length 0 (the default) is how every caller of today
// transforms, with the program's G43 applied to Z before the kinematics, as LinuxCNC does.
struct Tool {
  double length_mm = 0;
};

// A direction along the tool from its tip towards the spindle, in the workpiece frame
// (CAM's tool vector; (0, 0, 1) at the zero pose). Any length but 0.
struct ToolDirection {
  double i = 0;
  double j = 0;
  double k = 1;
};

// One way to point the tool along a direction: the tilt joint (A or B) and the rotary
// joint (C), each the representative modulo 360 nearest the current joint within its
// travel (or, where none is in travel, nearest the current joint, and in_travel false).
struct RotaryAngles {
  double tilt_deg = 0;
  double rotary_deg = 0;
  bool in_travel = false;
};

// Both ways to point the tool along a direction, and the one the machine's rule chose.
struct Orientation {
  int tilt_joint = -1;    // the joints the angles are for (indices into a Pose)
  int rotary_joint = -1;
  std::array<RotaryAngles, 2> solution{};  // [0]: tilt >= 0 at its principal value, [1]: tilt <= 0
  int chosen = -1;  // index into solution by kinematics.solution; -1: neither is in travel
  // The angle between the tool and the C axis (0 .. 90°). Near 0, C turns by the
  // tool's change of direction divided by sin(distance): a planner slows down there.
  double pole_distance_deg = 0;
  // Within kinematics.pole_tolerance_deg of the C axis, C is indeterminate: both
  // solutions keep the current C joint.
  bool at_pole = false;
};

class Kinematics {
 public:
  virtual ~Kinematics() = default;
  virtual std::string_view name() const = 0;
  virtual int joints() const = 0;
  virtual int axes() const = 0;
  // Joint positions -> axis (tool tip) positions; every joint position has one.
  virtual void forward(const Pose& joint_mm, Pose& axis_mm, const Tool& tool) const = 0;
  // Axis positions -> joint positions; false (and `joint_mm` unchanged) where the
  // machine cannot reach the pose. Travel is not checked here: in_travel().
  virtual bool inverse(const Pose& axis_mm, Pose& joint_mm, const Tool& tool) const = 0;
  void forward(const Pose& joint_mm, Pose& axis_mm) const { forward(joint_mm, axis_mm, Tool{}); }
  bool inverse(const Pose& axis_mm, Pose& joint_mm) const { return inverse(axis_mm, joint_mm, Tool{}); }
  // The joints' limits, joints() of them.
  virtual const std::array<JointLimits, program::kMaxAxes>& joint_limits() const = 0;
  // Every joint within its travel.
  bool in_travel(const Pose& joint_mm) const;

  // The tool's direction in the workpiece frame at these joints.
  virtual ToolDirection tool_direction(const Pose& joint_mm) const = 0;
  // The rotary joints that point the tool along `direction`, near `current_joint_mm`;
  // false where the machine cannot turn the tool (no rotary joints, a zero vector) or
  // neither solution is in travel (out.chosen -1).
  virtual bool orient(const ToolDirection& direction, const Pose& current_joint_mm, Orientation& out) const = 0;
  // The angle between the tool and the axis about which its rotary joint turns it
  // (Orientation::pole_distance_deg) at these joints; infinity for a machine without one.
  virtual double pole_distance_deg(const Pose& joint_mm) const = 0;

  // How fast the joints move when the axes move at `axis_rate` (per second, or per mm
  // of path: the unit is the rate's): the derivative of inverse along the rate, by
  // central differences (two inverse transforms). Accurate to about 1e-9 of the rate's
  // largest entry, times the distance from the origin in metres.
  virtual void joint_rate(const Pose& axis_mm, const Pose& axis_rate, const Tool& tool, Pose& joint_rate) const;
};

// Joints are the axes, one to one, with the axes' limits (axes[] of the machine config).
// A tool length moves joint Z (the axis named Z) above the tip by that length.
class IdentityKinematics final : public Kinematics {
 public:
  explicit IdentityKinematics(const config::MachineConfig& cfg);
  using Kinematics::forward;
  using Kinematics::inverse;
  std::string_view name() const override { return "identity"; }
  int joints() const override { return n_; }
  int axes() const override { return n_; }
  void forward(const Pose& joint_mm, Pose& axis_mm, const Tool& tool) const override;
  bool inverse(const Pose& axis_mm, Pose& joint_mm, const Tool& tool) const override;
  const std::array<JointLimits, program::kMaxAxes>& joint_limits() const override { return limits_; }
  ToolDirection tool_direction(const Pose&) const override { return {}; }
  bool orient(const ToolDirection& direction, const Pose& current_joint_mm, Orientation& out) const override;
  double pole_distance_deg(const Pose& joint_mm) const override;
  void joint_rate(const Pose& axis_mm, const Pose& axis_rate, const Tool& tool, Pose& joint_rate) const override;

 private:
  int n_;
  int z_ = -1;  // the linear axis Z, -1: none
  std::array<JointLimits, program::kMaxAxes> limits_;
};

// The joints' limits of a machine whose joint i is axes[i].
std::array<JointLimits, program::kMaxAxes> axes_as_joints(const config::MachineConfig& cfg);

// The machine's kinematics, as `kinematics.type` names it (config::kKinematicsTypes):
// a new geometry adds its class here and its name there.
std::unique_ptr<Kinematics> make_kinematics(const config::MachineConfig& cfg);

}  // namespace cnc::kinematics
