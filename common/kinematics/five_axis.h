#pragma once
// Five-axis machines: linear joints X, Y, Z and two rotary joints, a tilt (A about a
// line parallel to X, or B about one parallel to Y) and a rotary C about a line
// parallel to Z, each on the table's side or the spindle head's:
//
//   xyzac-trt, xyzbc-trt                the tilting table carries the rotary table C
//                                       (LinuxCNC's xyzac-trt-kins, xyzbc-trt-kins)
//   xyzac-head, xyzbc-head              the head turns about C and, below it, tilts
//   xyzac-head-table, xyzbc-head-table  the head tilts, the table turns about C
//
// Axes X, Y, Z are the tool tip in the workpiece frame, the frame carried by the
// table that is the machine's at the zero pose (every rotary joint at 0); A, B, C are
// the rotary joints' positions, passed through. Joints X, Y, Z are the linear drives:
// the spindle's gauge point where the head stands untilted. A positive angle turns
// the part it moves by the right-hand rule about +X, +Y or +Z: a head as RS274
// wants it, a table the other way (LinuxCNC's default) unless
// kinematics.conventional_directions. The equations, the solution rule and the pole
// are in docs/motion.md#five-axis-kinematics.
#include <array>
#include <string_view>

#include "common/config/machine_config.h"
#include "common/kinematics/kinematics.h"

namespace cnc::kinematics {

class FiveAxisKinematics final : public Kinematics {
 public:
  // Throws std::invalid_argument where the config is not one of these machines (no
  // such type, an axis missing or of the wrong kind; the config reader refuses the same).
  explicit FiveAxisKinematics(const config::MachineConfig& cfg);
  using Kinematics::forward;
  using Kinematics::inverse;
  std::string_view name() const override { return name_; }
  int joints() const override { return n_; }
  int axes() const override { return n_; }
  void forward(const Pose& joint_mm, Pose& axis_mm, const Tool& tool) const override;
  bool inverse(const Pose& axis_mm, Pose& joint_mm, const Tool& tool) const override;
  const std::array<JointLimits, program::kMaxAxes>& joint_limits() const override { return limits_; }
  ToolDirection tool_direction(const Pose& joint_mm) const override;
  bool orient(const ToolDirection& direction, const Pose& current_joint_mm, Orientation& out) const override;
  double pole_distance_deg(const Pose& joint_mm) const override;

 private:
  struct Vec3 {
    double x, y, z;
  };
  // Cosine and sine of the turn each rotary joint gives the part it moves.
  struct Turns {
    double ct, st;  // the tilt
    double cc, sc;  // C
  };
  enum class Preference { kNearest, kPositiveTilt, kNegativeTilt };

  Turns turns(const Pose& p) const;
  Vec3 rotate_tilt(const Vec3& v, double c, double s) const;
  Vec3 table_to_machine(const Vec3& q, const Turns& t) const;  // a workpiece point where it is on the machine
  Vec3 machine_to_table(const Vec3& m, const Turns& t) const;
  Vec3 head_axis(const Turns& t) const;  // the spindle's axis (tip towards spindle), machine frame
  int choose(const Orientation& o, const Pose& current_joint_mm) const;

  std::string_view name_;
  int n_ = 0;
  int x_ = -1, y_ = -1, z_ = -1, tilt_ = -1, c_ = -1;
  bool tilt_about_x_ = true;  // A; else B
  bool tilt_on_table_ = false;
  bool c_on_table_ = false;
  double tilt_sign_ = 1, c_sign_ = 1;  // the turn of the moved part per degree of its joint: +1 or -1
  Vec3 c_centre_{0, 0, 0};             // a point of the C axis at the zero pose (table C)
  Vec3 tilt_centre_{0, 0, 0};          // a point of the tilt axis at the zero pose (table tilt)
  double pivot_mm_ = 0;                // head: tilt axis to gauge line
  Preference preference_ = Preference::kNearest;
  double pole_tolerance_deg_ = 0;
  std::array<JointLimits, program::kMaxAxes> limits_;
};

}  // namespace cnc::kinematics
