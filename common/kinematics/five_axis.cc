#include "common/kinematics/five_axis.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace cnc::kinematics {
namespace {
constexpr double kRadPerDeg = std::numbers::pi / 180.0;

// cos and sin of an angle in degrees; whole turns are taken off first (exactly), so
// that a wrapped C far from 0 turns as precisely as near it.
void cos_sin_deg(double deg, double& c, double& s) {
  const double rad = std::fmod(deg, 360.0) * kRadPerDeg;
  c = std::cos(rad);
  s = std::sin(rad);
}

// `deg` + 360 k nearest `current_deg` within [min, max]; where no k is within, the
// one nearest `current_deg`.
double nearest_turn(double deg, double current_deg, double min, double max) {
  const double k_near = std::round((current_deg - deg) / 360.0);
  const double k_min = std::ceil((min - deg) / 360.0);
  const double k_max = std::floor((max - deg) / 360.0);
  return deg + 360.0 * (k_min <= k_max ? std::clamp(k_near, k_min, k_max) : k_near);
}

// (x, y) turned about +Z by the angle whose cosine and sine these are.
void rotate_z(double& x, double& y, double c, double s) {
  const double x0 = x;
  x = c * x0 - s * y;
  y = s * x0 + c * y;
}

int axis_named(const config::MachineConfig& cfg, const std::string& name, bool rotary, const std::string& type) {
  const int i = cfg.axis_index(name);
  if (i < 0) throw std::invalid_argument("kinematics " + type + " needs an axis " + name);
  if (cfg.axes[static_cast<size_t>(i)].rotary != rotary)
    throw std::invalid_argument("kinematics " + type + ": axis " + name + " must be " +
                                (rotary ? "rotary" : "linear"));
  return i;
}
}  // namespace

FiveAxisKinematics::FiveAxisKinematics(const config::MachineConfig& cfg)
    : n_(static_cast<int>(cfg.axes.size())), limits_(axes_as_joints(cfg)) {
  const config::KinematicsConfig& k = cfg.kinematics;
  for (const char* type : config::kKinematicsTypes)
    if (k.type == type && k.type != "identity") name_ = type;  // static storage, unlike k.type
  if (name_.empty()) throw std::invalid_argument("kinematics.type: '" + k.type + "' is no five-axis machine");
  // "xyz" + tilt letter + "c-" + mounting
  tilt_about_x_ = name_[3] == 'a';
  const std::string_view mounting = name_.substr(6);
  tilt_on_table_ = mounting == "trt";
  c_on_table_ = mounting != "head";
  x_ = axis_named(cfg, "X", false, k.type);
  y_ = axis_named(cfg, "Y", false, k.type);
  z_ = axis_named(cfg, "Z", false, k.type);
  tilt_ = axis_named(cfg, tilt_about_x_ ? "A" : "B", true, k.type);
  c_ = axis_named(cfg, "C", true, k.type);
  const double table_sign = k.conventional_directions ? -1.0 : 1.0;
  tilt_sign_ = tilt_on_table_ ? table_sign : 1.0;
  c_sign_ = c_on_table_ ? table_sign : 1.0;
  if (c_on_table_) c_centre_ = {k.x_rot_point_mm, k.y_rot_point_mm, k.z_rot_point_mm};
  if (tilt_on_table_)
    tilt_centre_ = {c_centre_.x + k.x_offset_mm, c_centre_.y + k.y_offset_mm, c_centre_.z + k.z_offset_mm};
  if (!tilt_on_table_) pivot_mm_ = k.pivot_mm;
  if (k.solution == "nearest") preference_ = Preference::kNearest;
  else if (k.solution == "positive_tilt") preference_ = Preference::kPositiveTilt;
  else if (k.solution == "negative_tilt") preference_ = Preference::kNegativeTilt;
  else throw std::invalid_argument("kinematics.solution: '" + k.solution + "' is not nearest, positive_tilt or negative_tilt");
  pole_tolerance_deg_ = k.pole_tolerance_deg;
}

FiveAxisKinematics::Turns FiveAxisKinematics::turns(const Pose& p) const {
  Turns t{};
  cos_sin_deg(p[static_cast<size_t>(tilt_)], t.ct, t.st);
  cos_sin_deg(p[static_cast<size_t>(c_)], t.cc, t.sc);
  t.st *= tilt_sign_;
  t.sc *= c_sign_;
  return t;
}

FiveAxisKinematics::Vec3 FiveAxisKinematics::rotate_tilt(const Vec3& v, double c, double s) const {
  if (tilt_about_x_) return {v.x, c * v.y - s * v.z, s * v.y + c * v.z};
  return {c * v.x + s * v.z, v.y, -s * v.x + c * v.z};
}

// A table's C turns the workpiece about the C axis, and the tilting table carrying it
// turns both about the tilt axis: the C turn first, as it is nearest the workpiece.
FiveAxisKinematics::Vec3 FiveAxisKinematics::table_to_machine(const Vec3& q, const Turns& t) const {
  Vec3 v = q;
  if (c_on_table_) {
    double dx = v.x - c_centre_.x, dy = v.y - c_centre_.y;
    rotate_z(dx, dy, t.cc, t.sc);
    v = {c_centre_.x + dx, c_centre_.y + dy, v.z};
  }
  if (tilt_on_table_) {
    const Vec3 r = rotate_tilt({v.x - tilt_centre_.x, v.y - tilt_centre_.y, v.z - tilt_centre_.z}, t.ct, t.st);
    v = {tilt_centre_.x + r.x, tilt_centre_.y + r.y, tilt_centre_.z + r.z};
  }
  return v;
}

FiveAxisKinematics::Vec3 FiveAxisKinematics::machine_to_table(const Vec3& m, const Turns& t) const {
  Vec3 v = m;
  if (tilt_on_table_) {
    const Vec3 r = rotate_tilt({v.x - tilt_centre_.x, v.y - tilt_centre_.y, v.z - tilt_centre_.z}, t.ct, -t.st);
    v = {tilt_centre_.x + r.x, tilt_centre_.y + r.y, tilt_centre_.z + r.z};
  }
  if (c_on_table_) {
    double dx = v.x - c_centre_.x, dy = v.y - c_centre_.y;
    rotate_z(dx, dy, t.cc, -t.sc);
    v = {c_centre_.x + dx, c_centre_.y + dy, v.z};
  }
  return v;
}

// The head's C carries the tilt: the spindle's axis is tilted first, then turned about Z.
FiveAxisKinematics::Vec3 FiveAxisKinematics::head_axis(const Turns& t) const {
  Vec3 d{0, 0, 1};
  if (!tilt_on_table_) d = rotate_tilt(d, t.ct, t.st);
  if (!c_on_table_) rotate_z(d.x, d.y, t.cc, t.sc);
  return d;
}

// The gauge point is pivot_mm below the tilt axis's point on the spindle axis, and
// the tip the tool's length below the gauge point, both along the spindle axis: tip =
// joint + pivot·Z - (pivot + L)·axis (a table machine has no pivot: tip = joint - L·Z).
void FiveAxisKinematics::forward(const Pose& joint_mm, Pose& axis_mm, const Tool& tool) const {
  const Turns t = turns(joint_mm);
  const Vec3 d = head_axis(t);
  const double reach = pivot_mm_ + tool.length_mm;
  const Vec3 tip{joint_mm[static_cast<size_t>(x_)] - reach * d.x, joint_mm[static_cast<size_t>(y_)] - reach * d.y,
                 joint_mm[static_cast<size_t>(z_)] + pivot_mm_ - reach * d.z};
  const Vec3 q = machine_to_table(tip, t);
  for (int i = 0; i < n_; ++i) axis_mm[static_cast<size_t>(i)] = joint_mm[static_cast<size_t>(i)];
  axis_mm[static_cast<size_t>(x_)] = q.x;
  axis_mm[static_cast<size_t>(y_)] = q.y;
  axis_mm[static_cast<size_t>(z_)] = q.z;
}

bool FiveAxisKinematics::inverse(const Pose& axis_mm, Pose& joint_mm, const Tool& tool) const {
  const Turns t = turns(axis_mm);
  const Vec3 d = head_axis(t);
  const double reach = pivot_mm_ + tool.length_mm;
  const Vec3 tip =
      table_to_machine({axis_mm[static_cast<size_t>(x_)], axis_mm[static_cast<size_t>(y_)], axis_mm[static_cast<size_t>(z_)]}, t);
  for (int i = 0; i < n_; ++i) joint_mm[static_cast<size_t>(i)] = axis_mm[static_cast<size_t>(i)];
  joint_mm[static_cast<size_t>(x_)] = tip.x + reach * d.x;
  joint_mm[static_cast<size_t>(y_)] = tip.y + reach * d.y;
  joint_mm[static_cast<size_t>(z_)] = tip.z - pivot_mm_ + reach * d.z;
  return true;
}

ToolDirection FiveAxisKinematics::tool_direction(const Pose& joint_mm) const {
  const Turns t = turns(joint_mm);
  // A direction turns as a point about centres at the origin.
  Vec3 d = head_axis(t);
  if (tilt_on_table_) d = rotate_tilt(d, t.ct, -t.st);
  if (c_on_table_) rotate_z(d.x, d.y, t.cc, -t.sc);
  return {d.x, d.y, d.z};
}

double FiveAxisKinematics::pole_distance_deg(const Pose& joint_mm) const {
  return std::fabs(std::remainder(joint_mm[static_cast<size_t>(tilt_)], 180.0));
}

// In the workpiece frame every mounting points the tool along
//   k = Rz(e_c·C) · R_tilt(e_t·T) · (0, 0, 1),
// with e = +1 for a joint in the head (it turns the tool) and e = -(its sign) for one
// in the table (it turns the workpiece under the tool). So k_z = cos T, and (k_x, k_y)
// is sin(e_t·T) times the tilt's direction at C = 0, (0, -1) about X or (1, 0) about Y,
// turned by e_c·C: T = ±atan2(|k_xy|, k_z), and C from the angle of ±(k_x, k_y).
bool FiveAxisKinematics::orient(const ToolDirection& direction, const Pose& current_joint_mm, Orientation& out) const {
  out = Orientation{};
  out.tilt_joint = tilt_;
  out.rotary_joint = c_;
  const double across = std::hypot(direction.i, direction.j);
  const double along = direction.k;
  if (!(std::isfinite(across) && std::isfinite(along)) || (across == 0 && along == 0)) return false;
  out.pole_distance_deg = std::atan2(across, std::fabs(along)) / kRadPerDeg;
  out.at_pole = out.pole_distance_deg <= pole_tolerance_deg_;
  const double tilt_deg = std::atan2(across, along) / kRadPerDeg;  // 0 .. 180
  const double e_tilt = tilt_on_table_ ? -tilt_sign_ : tilt_sign_;
  const double e_c = c_on_table_ ? -c_sign_ : c_sign_;
  const double tilt_zero_deg = tilt_about_x_ ? -90.0 : 0.0;  // the angle of the tilt's direction at C = 0
  const double current_tilt = current_joint_mm[static_cast<size_t>(tilt_)];
  const double current_c = current_joint_mm[static_cast<size_t>(c_)];
  const JointLimits& tl = limits_[static_cast<size_t>(tilt_)];
  const JointLimits& cl = limits_[static_cast<size_t>(c_)];
  for (int s = 0; s < 2; ++s) {
    const double sign = s == 0 ? 1.0 : -1.0;
    double c_deg = current_c;
    if (!out.at_pole) {
      // sin(e_t·T) has the sign e_t·sign: (k_x, k_y) points along the tilt's direction or against it.
      const double flip = e_tilt * sign;
      const double angle = std::atan2(flip * direction.j, flip * direction.i) / kRadPerDeg;
      c_deg = e_c * (angle - tilt_zero_deg);
    }
    RotaryAngles& r = out.solution[static_cast<size_t>(s)];
    r.tilt_deg = nearest_turn(sign * tilt_deg, current_tilt, tl.min_mm, tl.max_mm);
    r.rotary_deg = nearest_turn(c_deg, current_c, cl.min_mm, cl.max_mm);
    r.in_travel = r.tilt_deg >= tl.min_mm && r.tilt_deg <= tl.max_mm && r.rotary_deg >= cl.min_mm &&
                  r.rotary_deg <= cl.max_mm;
  }
  out.chosen = choose(out, current_joint_mm);
  return out.chosen >= 0;
}

// nearest: of the solutions in travel, the one the rotary joints reach first at their
// velocity limits (the longer of the two joints' times), the tilt >= 0 one on a tie.
// positive_tilt / negative_tilt: that one where it is in travel, else the other.
int FiveAxisKinematics::choose(const Orientation& o, const Pose& current_joint_mm) const {
  const bool in0 = o.solution[0].in_travel, in1 = o.solution[1].in_travel;
  switch (preference_) {
    case Preference::kPositiveTilt: return in0 ? 0 : (in1 ? 1 : -1);
    case Preference::kNegativeTilt: return in1 ? 1 : (in0 ? 0 : -1);
    case Preference::kNearest: break;
  }
  if (!in0 || !in1) return in0 ? 0 : (in1 ? 1 : -1);
  const double v_tilt = limits_[static_cast<size_t>(tilt_)].max_velocity_mm_s;
  const double v_c = limits_[static_cast<size_t>(c_)].max_velocity_mm_s;
  const double tilt_now = current_joint_mm[static_cast<size_t>(tilt_)];
  const double c_now = current_joint_mm[static_cast<size_t>(c_)];
  auto time_s = [&](const RotaryAngles& r) {
    return std::max(std::fabs(r.tilt_deg - tilt_now) / v_tilt, std::fabs(r.rotary_deg - c_now) / v_c);
  };
  return time_s(o.solution[1]) < time_s(o.solution[0]) ? 1 : 0;
}

}  // namespace cnc::kinematics
