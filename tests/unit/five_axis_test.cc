// Five-axis kinematics (common/kinematics/five_axis.h) on the example machines of
// tests/unit/kinematics_machines: both transforms round trip within 1e-9 mm over
// random poses in travel; the trunnion tables agree with the equations of LinuxCNC's
// 5-axis-kinematics.adoc, transcribed below; the heads with their closed forms; both
// solutions of a tool direction reproduce it, the rule and the travel pick among
// them; C is kept at the pole; joint_rate matches closed-form derivatives; nothing
// allocates.
#include "common/kinematics/five_axis.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <utility>

#include "common/config/machine_config.h"
#include "common/kinematics/kinematics.h"
#include "tests/unit/alloc_guard.h"

namespace cnc::kinematics {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr const char* kTypes[] = {"xyzac-trt",  "xyzbc-trt",        "xyzac-head",
                                  "xyzbc-head", "xyzac-head-table", "xyzbc-head-table"};

config::MachineConfig machine(const std::string& type) {
  return config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/tests/unit/kinematics_machines/" + type + ".yaml");
}

struct V3 {
  double x, y, z;
};
double dist(const V3& a, const V3& b) { return std::hypot(a.x - b.x, a.y - b.y, a.z - b.z); }

// The joints of a machine: X, Y, Z, the tilt (A or B) and C.
struct Joints {
  size_t x, y, z, t, c;
  explicit Joints(const config::MachineConfig& cfg)
      : x(index(cfg, "X")), y(index(cfg, "Y")), z(index(cfg, "Z")),
        t(cfg.axis_index("A") >= 0 ? index(cfg, "A") : index(cfg, "B")), c(index(cfg, "C")) {}
  static size_t index(const config::MachineConfig& cfg, const char* name) {
    const int i = cfg.axis_index(name);
    EXPECT_GE(i, 0) << name;
    return static_cast<size_t>(std::max(i, 0));
  }
  V3 xyz(const Pose& p) const { return {p[x], p[y], p[z]}; }
};

// A joint position uniformly within its travel; a wrapped axis within two turns either way.
double in_travel(std::mt19937_64& rng, const JointLimits& l) {
  const double lo = std::max(l.min_mm, -720.0), hi = std::min(l.max_mm, 720.0);
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}
Pose random_joints(std::mt19937_64& rng, const Kinematics& k) {
  Pose p{};
  for (int j = 0; j < k.joints(); ++j) p[static_cast<size_t>(j)] = in_travel(rng, k.joint_limits()[static_cast<size_t>(j)]);
  return p;
}
double random_tool(std::mt19937_64& rng) { return std::uniform_real_distribution<double>(0.0, 150.0)(rng); }

TEST(FiveAxis, ExampleMachinesLoadAsTheirType) {
  for (const char* type : kTypes) {
    const config::MachineConfig cfg = machine(type);
    EXPECT_EQ(cfg.kinematics.type, type);
    const auto k = make_kinematics(cfg);
    EXPECT_EQ(k->name(), type);
    EXPECT_EQ(k->joints(), 5);
    EXPECT_EQ(k->axes(), 5);
    for (size_t j = 0; j < cfg.axes.size(); ++j) {
      EXPECT_EQ(k->joint_limits()[j].name, cfg.axes[j].name);
      EXPECT_EQ(k->joint_limits()[j].min_mm, cfg.axes[j].min_mm);
      EXPECT_EQ(k->joint_limits()[j].max_mm, cfg.axes[j].max_mm);
      EXPECT_EQ(k->joint_limits()[j].max_velocity_mm_s, cfg.axes[j].max_velocity_mm_s);
    }
  }
}

// joints -> axes -> joints from random joints in travel, and axes -> joints -> axes from
// random axes whose joints are in travel, each with a random tool length.
TEST(FiveAxis, EveryKindRoundTripsBothWaysWithinANanometre) {
  constexpr int kPoses = 5000;
  for (const char* type : kTypes) {
    const config::MachineConfig cfg = machine(type);
    const auto k = make_kinematics(cfg);
    const Joints j(cfg);
    std::mt19937_64 rng(3301);
    double worst_joint_mm = 0, worst_axis_mm = 0, worst_deg = 0;
    for (int n = 0; n < kPoses; ++n) {
      const Tool tool{random_tool(rng)};
      const Pose joints = random_joints(rng, *k);
      Pose axes{}, back{};
      k->forward(joints, axes, tool);
      ASSERT_TRUE(k->inverse(axes, back, tool));
      worst_joint_mm = std::max(worst_joint_mm, dist(j.xyz(back), j.xyz(joints)));
      worst_deg = std::max({worst_deg, std::fabs(back[j.t] - joints[j.t]), std::fabs(back[j.c] - joints[j.c]),
                            std::fabs(axes[j.t] - joints[j.t]), std::fabs(axes[j.c] - joints[j.c])});
    }
    std::uniform_real_distribution<double> box(-300.0, 300.0);
    int accepted = 0, drawn = 0;
    while (accepted < kPoses) {
      ASSERT_LT(++drawn, 100 * kPoses) << type << ": too few random axis poses reach joints in travel";
      const Tool tool{random_tool(rng)};
      Pose axes = random_joints(rng, *k);  // the angles; the tip anywhere in a box
      axes[j.x] = box(rng);
      axes[j.y] = box(rng);
      axes[j.z] = box(rng);
      Pose joints{}, back{};
      ASSERT_TRUE(k->inverse(axes, joints, tool));
      if (!k->in_travel(joints)) continue;
      ++accepted;
      k->forward(joints, back, tool);
      worst_axis_mm = std::max(worst_axis_mm, dist(j.xyz(back), j.xyz(axes)));
      worst_deg = std::max({worst_deg, std::fabs(back[j.t] - axes[j.t]), std::fabs(back[j.c] - axes[j.c])});
    }
    std::printf("[ five-axis ] %-17s %d + %d poses: worst joints %.3g mm, axes %.3g mm, angles %.3g deg\n", type,
                kPoses, kPoses, worst_joint_mm, worst_axis_mm, worst_deg);
    EXPECT_LE(worst_joint_mm, 1e-9) << type;
    EXPECT_LE(worst_axis_mm, 1e-9) << type;
    EXPECT_LE(worst_deg, 1e-9) << type;
  }
}

// ---- LinuxCNC's docs/src/motion/5-axis-kinematics.adoc, transcribed ---------------------
// In the document's symbols: P the joint coordinates, Q the tool position in the
// workpiece frame, D the offsets of the tilt axis (D_y, D_z for A; D_x, D_z for B),
// S_A = sin θ_A, C_A = cos θ_A and so on; no rot-point (the C axis through the origin),
// no tool offset. Forward: the adoc's Q = QA_P · P ("xyzac-trt machine with rotary axis
// offsets", "xyzbc-trt machine with rotary axis offsets"); inverse: its P = ... equations.
V3 adoc_xyzac_forward(const V3& P, double a_deg, double c_deg, double Dy, double Dz) {
  const double SA = std::sin(a_deg * kDeg), CA = std::cos(a_deg * kDeg);
  const double SC = std::sin(c_deg * kDeg), CC = std::cos(c_deg * kDeg);
  return {CC * P.x + SC * CA * P.y + SC * SA * P.z - SC * CA * Dy - SC * SA * Dz + SC * Dy,
          -SC * P.x + CC * CA * P.y + CC * SA * P.z - CC * CA * Dy - CC * SA * Dz + CC * Dy,
          -SA * P.y + CA * P.z + SA * Dy - CA * Dz + Dz};
}
V3 adoc_xyzac_inverse(const V3& Q, double a_deg, double c_deg, double Dy, double Dz) {
  const double SA = std::sin(a_deg * kDeg), CA = std::cos(a_deg * kDeg);
  const double SC = std::sin(c_deg * kDeg), CC = std::cos(c_deg * kDeg);
  return {CC * Q.x - SC * Q.y,
          SC * CA * Q.x + CC * CA * Q.y - SA * Q.z - CA * Dy + SA * Dz + Dy,
          SC * SA * Q.x + CC * SA * Q.y + CA * Q.z - SA * Dy - CA * Dz + Dz};
}
V3 adoc_xyzac_tool_vector(double a_deg, double c_deg) {  // K, the third column
  const double SA = std::sin(a_deg * kDeg), CA = std::cos(a_deg * kDeg);
  const double SC = std::sin(c_deg * kDeg), CC = std::cos(c_deg * kDeg);
  return {SC * SA, CC * SA, CA};
}
V3 adoc_xyzbc_forward(const V3& P, double b_deg, double c_deg, double Dx, double Dz) {
  const double SB = std::sin(b_deg * kDeg), CB = std::cos(b_deg * kDeg);
  const double SC = std::sin(c_deg * kDeg), CC = std::cos(c_deg * kDeg);
  return {CC * CB * P.x + SC * P.y - CC * SB * P.z - CC * CB * Dx + CC * SB * Dz + CC * Dx,
          -SC * CB * P.x + CC * P.y + SC * SB * P.z + SC * CB * Dx - SC * SB * Dz - SC * Dx,
          SB * P.x + CB * P.z - SB * Dx - CB * Dz + Dz};
}
V3 adoc_xyzbc_inverse(const V3& Q, double b_deg, double c_deg, double Dx, double Dz) {
  const double SB = std::sin(b_deg * kDeg), CB = std::cos(b_deg * kDeg);
  const double SC = std::sin(c_deg * kDeg), CC = std::cos(c_deg * kDeg);
  return {CC * CB * Q.x - SC * CB * Q.y + SB * Q.z - CB * Dx - SB * Dz + Dx,
          SC * Q.x + CC * Q.y,
          -CC * SB * Q.x + SC * SB * Q.y + CB * Q.z + SB * Dx - CB * Dz + Dz};
}
V3 adoc_xyzbc_tool_vector(double b_deg, double c_deg) {
  const double SB = std::sin(b_deg * kDeg), CB = std::cos(b_deg * kDeg);
  const double SC = std::sin(c_deg * kDeg), CC = std::cos(c_deg * kDeg);
  return {-CC * SB, SC * SB, CB};
}

// LinuxCNC's kinematics with its rot-point R (the C axis's centre relative to machine
// zero: the document's equations about R) and its tool-offset T (added to D_z, the
// document's "Tool-Length Compensation"): its world position is the tip plus T along Z.
struct LinuxCncTrt {
  bool about_x;
  V3 R;
  double D_tilt, Dz;  // D_y (A) or D_x (B), D_z
  V3 world(const V3& J, double tilt, double c, double T) const {
    const V3 P{J.x - R.x, J.y - R.y, J.z - R.z};
    const V3 Q = about_x ? adoc_xyzac_forward(P, tilt, c, D_tilt, Dz + T) : adoc_xyzbc_forward(P, tilt, c, D_tilt, Dz + T);
    return {Q.x + R.x, Q.y + R.y, Q.z + R.z};
  }
  V3 joints(const V3& W, double tilt, double c, double T) const {
    const V3 Q{W.x - R.x, W.y - R.y, W.z - R.z};
    const V3 P = about_x ? adoc_xyzac_inverse(Q, tilt, c, D_tilt, Dz + T) : adoc_xyzbc_inverse(Q, tilt, c, D_tilt, Dz + T);
    return {P.x + R.x, P.y + R.y, P.z + R.z};
  }
};

LinuxCncTrt linuxcnc_of(const config::MachineConfig& cfg) {
  const auto& k = cfg.kinematics;
  const bool about_x = cfg.kinematics.type == "xyzac-trt";
  return {about_x, {k.x_rot_point_mm, k.y_rot_point_mm, k.z_rot_point_mm}, about_x ? k.y_offset_mm : k.x_offset_mm,
          k.z_offset_mm};
}

// The adoc's equations first checked against themselves: its inverse undoes its forward.
TEST(FiveAxisLinuxCnc, TheTranscribedEquationsAreEachOthersInverse) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-300, 300), angle(-180, 180);
  for (int n = 0; n < 1000; ++n) {
    const V3 P{u(rng), u(rng), u(rng)};
    const double t = angle(rng), c = angle(rng), d = u(rng), dz = u(rng);
    EXPECT_LE(dist(adoc_xyzac_inverse(adoc_xyzac_forward(P, t, c, d, dz), t, c, d, dz), P), 1e-9);
    EXPECT_LE(dist(adoc_xyzbc_inverse(adoc_xyzbc_forward(P, t, c, d, dz), t, c, d, dz), P), 1e-9);
  }
}

// Our trunnions against LinuxCNC's equations at random joints in travel, with the
// example machines' rot-points and offsets and random tool lengths: the same joints
// for the same world position (ours is the tip: LinuxCNC's world less T along Z),
// and the same tool vector.
TEST(FiveAxisLinuxCnc, TrunnionsAgreeWithTheDocumentsEquations) {
  for (const char* type : {"xyzac-trt", "xyzbc-trt"}) {
    const config::MachineConfig cfg = machine(type);
    ASSERT_FALSE(cfg.kinematics.conventional_directions);
    const auto k = make_kinematics(cfg);
    const Joints j(cfg);
    const LinuxCncTrt lcnc = linuxcnc_of(cfg);
    std::mt19937_64 rng(2016);
    double worst_joint = 0, worst_axis = 0, worst_vector = 0;
    constexpr int kPoses = 5000;
    for (int n = 0; n < kPoses; ++n) {
      const double L = n % 4 == 0 ? 0.0 : random_tool(rng);
      const Pose joints = random_joints(rng, *k);
      const double t = joints[j.t], c = joints[j.c];
      Pose axes{};
      k->forward(joints, axes, Tool{L});
      const V3 world = lcnc.world(j.xyz(joints), t, c, L);
      worst_axis = std::max(worst_axis, dist(j.xyz(axes), {world.x, world.y, world.z - L}));
      // inverse: from a world position of LinuxCNC's, independently of our forward
      const V3 w{world.x + 0.5 * (n % 7), world.y - 0.25 * (n % 5), world.z + 0.125 * (n % 3)};
      Pose target = joints, ours{};
      target[j.x] = w.x;
      target[j.y] = w.y;
      target[j.z] = w.z - L;
      ASSERT_TRUE(k->inverse(target, ours, Tool{L}));
      worst_joint = std::max(worst_joint, dist(j.xyz(ours), lcnc.joints(w, t, c, L)));
      EXPECT_EQ(ours[j.t], t);
      EXPECT_EQ(ours[j.c], c);
      const ToolDirection d = k->tool_direction(joints);
      const V3 K = lcnc.about_x ? adoc_xyzac_tool_vector(t, c) : adoc_xyzbc_tool_vector(t, c);
      worst_vector = std::max(worst_vector, dist({d.i, d.j, d.k}, K));
    }
    std::printf("[ five-axis ] %-17s %d poses against LinuxCNC's equations: joints %.3g mm, axes %.3g mm, "
                "tool vector %.3g\n",
                type, kPoses, worst_joint, worst_axis, worst_vector);
    EXPECT_LE(worst_joint, 1e-9) << type;
    EXPECT_LE(worst_axis, 1e-9) << type;
    EXPECT_LE(worst_vector, 1e-12) << type;
  }
}

// conventional_directions (LinuxCNC's conventional-directions pin): the table turns
// the other way, so the same joints with both table angles negated give the same tip.
TEST(FiveAxisLinuxCnc, ConventionalDirectionsNegateTheTableAngles) {
  for (const char* type : {"xyzac-trt", "xyzbc-trt", "xyzac-head-table"}) {
    config::MachineConfig cfg = machine(type);
    const auto plain = make_kinematics(cfg);
    cfg.kinematics.conventional_directions = true;
    const auto conventional = make_kinematics(cfg);
    const Joints j(cfg);
    const bool tilt_on_table = std::string(type).ends_with("trt");
    std::mt19937_64 rng(11);
    for (int n = 0; n < 1000; ++n) {
      const Pose joints = random_joints(rng, *plain);
      Pose mirrored = joints;
      if (tilt_on_table) mirrored[j.t] = -joints[j.t];
      mirrored[j.c] = -joints[j.c];
      Pose a{}, b{};
      conventional->forward(joints, a, Tool{25});
      plain->forward(mirrored, b, Tool{25});
      ASSERT_LE(dist(j.xyz(a), j.xyz(b)), 1e-9) << type << " pose " << n;
    }
  }
}

// ---- heads: their closed forms --------------------------------------------------------
// The tool's direction (tip towards spindle) in the workpiece frame and the tip, for
// joints J, pivot P, tool length L, written out per machine.
struct Closed {
  V3 direction;
  V3 tip;
};
Closed closed_form(const config::MachineConfig& cfg, const Pose& p, double L) {
  const Joints j(cfg);
  const double T = p[j.t] * kDeg, C = p[j.c] * kDeg, P = cfg.kinematics.pivot_mm;
  const double st = std::sin(T), ct = std::cos(T), sc = std::sin(C), cc = std::cos(C);
  const std::string& type = cfg.kinematics.type;
  const V3 J = j.xyz(p);
  auto head_tip = [&](const V3& d) { return V3{J.x - (P + L) * d.x, J.y - (P + L) * d.y, J.z + P - (P + L) * d.z}; };
  if (type == "xyzbc-head") {
    const V3 d{cc * st, sc * st, ct};  // Rz(C)·Ry(B)·Z
    return {d, head_tip(d)};
  }
  if (type == "xyzac-head") {
    const V3 d{sc * st, -cc * st, ct};  // Rz(C)·Rx(A)·Z
    return {d, head_tip(d)};
  }
  // head-table: the head tilts; the table turns by C (or -C, conventional) about (x, y rot-point).
  const V3 h = type == "xyzbc-head-table" ? V3{st, 0, ct} : V3{0, -st, ct};
  const V3 m = head_tip(h);
  const double turn = cfg.kinematics.conventional_directions ? -1.0 : 1.0;  // the table's turn per degree of C
  const double s = -turn * sc;                                             // into the table's frame: by -turn·C
  const double cx = cfg.kinematics.x_rot_point_mm, cy = cfg.kinematics.y_rot_point_mm;
  return {{cc * h.x - s * h.y, s * h.x + cc * h.y, h.z},
          {cx + cc * (m.x - cx) - s * (m.y - cy), cy + s * (m.x - cx) + cc * (m.y - cy), m.z}};
}

TEST(FiveAxis, HeadsAgreeWithTheirClosedForms) {
  for (const char* type : {"xyzac-head", "xyzbc-head", "xyzac-head-table", "xyzbc-head-table"}) {
    for (const bool conventional : {false, true}) {
      config::MachineConfig cfg = machine(type);
      if (std::string(type).ends_with("table")) cfg.kinematics.conventional_directions = conventional;
      else if (conventional) continue;
      const auto k = make_kinematics(cfg);
      const Joints j(cfg);
      std::mt19937_64 rng(5);
      for (int n = 0; n < 2000; ++n) {
        const double L = random_tool(rng);
        const Pose joints = random_joints(rng, *k);
        Pose axes{};
        k->forward(joints, axes, Tool{L});
        const Closed want = closed_form(cfg, joints, L);
        ASSERT_LE(dist(j.xyz(axes), want.tip), 1e-9) << type << " pose " << n;
        const ToolDirection d = k->tool_direction(joints);
        ASSERT_LE(dist({d.i, d.j, d.k}, want.direction), 1e-12) << type << " pose " << n;
      }
    }
  }
}

// A head turns the tool about the pivot: at fixed linear joints, whatever the angles,
// the tip stays pivot + L from the pivot point above the gauge point.
TEST(FiveAxis, AHeadsTipStaysOnItsSphereAboutThePivot) {
  for (const char* type : {"xyzac-head", "xyzbc-head"}) {
    const config::MachineConfig cfg = machine(type);
    const auto k = make_kinematics(cfg);
    const Joints j(cfg);
    const double P = cfg.kinematics.pivot_mm, L = 42;
    std::mt19937_64 rng(8);
    Pose joints = random_joints(rng, *k);
    const V3 pivot{joints[j.x], joints[j.y], joints[j.z] + P};
    for (int n = 0; n < 500; ++n) {
      joints[j.t] = in_travel(rng, k->joint_limits()[j.t]);
      joints[j.c] = in_travel(rng, k->joint_limits()[j.c]);
      Pose axes{};
      k->forward(joints, axes, Tool{L});
      EXPECT_NEAR(dist(j.xyz(axes), pivot), P + L, 1e-9);
    }
  }
}

// ---- tool directions -----------------------------------------------------------------
ToolDirection unit(double tilt_from_z_deg, double azimuth_deg) {
  return {std::sin(tilt_from_z_deg * kDeg) * std::cos(azimuth_deg * kDeg),
          std::sin(tilt_from_z_deg * kDeg) * std::sin(azimuth_deg * kDeg), std::cos(tilt_from_z_deg * kDeg)};
}
double angle_between(const ToolDirection& a, const ToolDirection& b) {
  const double na = std::hypot(a.i, a.j, a.k), nb = std::hypot(b.i, b.j, b.k);
  const double dot = (a.i * b.i + a.j * b.j + a.k * b.k) / (na * nb);
  const double cross = std::hypot(a.j * b.k - a.k * b.j, a.k * b.i - a.i * b.k, a.i * b.j - a.j * b.i) / (na * nb);
  return std::atan2(cross, dot);
}

// Both solutions of random directions (any length) point the tool along them, through
// the kinematics' own forward and, for the trunnions, LinuxCNC's tool vector; [0] has
// the tilt >= 0, [1] <= 0; each angle is the turn nearest the current joint.
TEST(FiveAxisOrient, BothSolutionsReproduceTheDirection) {
  for (const char* type : kTypes) {
    const config::MachineConfig cfg = machine(type);
    const auto k = make_kinematics(cfg);
    const Joints j(cfg);
    std::mt19937_64 rng(99);
    std::uniform_real_distribution<double> tilt(0.01, 179.0), azimuth(-180, 180), length(0.1, 10);
    double worst = 0;
    for (int n = 0; n < 4000; ++n) {
      const double scale = length(rng);
      ToolDirection dir = unit(tilt(rng), azimuth(rng));
      dir = {dir.i * scale, dir.j * scale, dir.k * scale};
      const Pose current = random_joints(rng, *k);
      Orientation o;
      k->orient(dir, current, o);
      ASSERT_EQ(o.tilt_joint, static_cast<int>(j.t));
      ASSERT_EQ(o.rotary_joint, static_cast<int>(j.c));
      ASSERT_FALSE(o.at_pole);
      for (int s = 0; s < 2; ++s) {
        const RotaryAngles& r = o.solution[static_cast<size_t>(s)];
        Pose p = current;
        p[j.t] = r.tilt_deg;
        p[j.c] = r.rotary_deg;
        worst = std::max(worst, angle_between(k->tool_direction(p), dir));
        if (cfg.kinematics.type.ends_with("trt")) {
          const V3 K = cfg.kinematics.type == "xyzac-trt" ? adoc_xyzac_tool_vector(r.tilt_deg, r.rotary_deg)
                                                          : adoc_xyzbc_tool_vector(r.tilt_deg, r.rotary_deg);
          worst = std::max(worst, angle_between({K.x, K.y, K.z}, dir));
        }
        const double principal = std::remainder(r.tilt_deg, 360.0);
        if (s == 0) {
          EXPECT_GT(principal, 0.0) << type;
        } else {
          EXPECT_LT(principal, 0.0) << type;
        }
        // C is wrapped: its turn nearest the current C
        EXPECT_LE(std::fabs(r.rotary_deg - current[j.c]), 180.0 + 1e-9) << type;
        const JointLimits& tl = k->joint_limits()[j.t];
        EXPECT_EQ(r.in_travel, r.tilt_deg >= tl.min_mm && r.tilt_deg <= tl.max_mm) << type;
      }
    }
    std::printf("[ five-axis ] %-17s 4000 directions x 2 solutions: worst %.3g rad off\n", type, worst);
    EXPECT_LE(worst, 1e-12) << type;
  }
}

// The time the rotary joints need from `current` to a solution, at their velocity limits.
double move_time_s(const Kinematics& k, const Orientation& o, int s, const Pose& current) {
  const RotaryAngles& r = o.solution[static_cast<size_t>(s)];
  const auto t = static_cast<size_t>(o.tilt_joint), c = static_cast<size_t>(o.rotary_joint);
  return std::max(std::fabs(r.tilt_deg - current[t]) / k.joint_limits()[t].max_velocity_mm_s,
                  std::fabs(r.rotary_deg - current[c]) / k.joint_limits()[c].max_velocity_mm_s);
}

TEST(FiveAxisOrient, TheRulePicksAsConfigured) {
  config::MachineConfig cfg = machine("xyzbc-head");  // B ±95: mostly both in travel
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> tilt(1, 90), azimuth(-180, 180);
  for (const char* rule : {"nearest", "positive_tilt", "negative_tilt"}) {
    cfg.kinematics.solution = rule;
    const auto k = make_kinematics(cfg);
    int both = 0, picked_negative = 0;
    for (int n = 0; n < 2000; ++n) {
      const Pose current = random_joints(rng, *k);
      Orientation o;
      const bool ok = k->orient(unit(tilt(rng), azimuth(rng)), current, o);
      ASSERT_EQ(ok, o.chosen >= 0);
      if (!o.solution[0].in_travel || !o.solution[1].in_travel) {
        EXPECT_TRUE(o.chosen < 0 || o.solution[static_cast<size_t>(o.chosen)].in_travel);
        continue;
      }
      ++both;
      picked_negative += o.chosen == 1;
      const std::string r = rule;
      if (r == "positive_tilt") {
        EXPECT_EQ(o.chosen, 0);
      }
      if (r == "negative_tilt") {
        EXPECT_EQ(o.chosen, 1);
      }
      if (r == "nearest") {
        const double t0 = move_time_s(*k, o, 0, current), t1 = move_time_s(*k, o, 1, current);
        EXPECT_EQ(o.chosen, t1 < t0 ? 1 : 0) << t0 << " " << t1;
      }
    }
    EXPECT_GT(both, 1000) << rule;
    if (std::string(rule) == "nearest") {  // both happen
      EXPECT_GT(picked_negative, both / 5);
      EXPECT_LT(picked_negative, both * 4 / 5);
    }
  }
}

// A standing at B = 40, C = 30 asked for the direction of B = -40, C = 210 (the same
// one) turns nowhere: nearest takes the solution it stands on, wherever C has wound to.
TEST(FiveAxisOrient, NearestStaysWhereTheMachineStands) {
  const config::MachineConfig cfg = machine("xyzbc-head");
  config::MachineConfig nearest = cfg;
  nearest.kinematics.solution = "nearest";
  const auto k = make_kinematics(nearest);
  const Joints j(cfg);
  for (const double turns : {0.0, 3.0, -2.0}) {
    for (const double b : {40.0, -40.0}) {
      Pose current{};
      current[j.t] = b;
      current[j.c] = 30.0 + 360.0 * turns;
      Orientation o;
      ASSERT_TRUE(k->orient(k->tool_direction(current), current, o));
      const RotaryAngles& r = o.solution[static_cast<size_t>(o.chosen)];
      EXPECT_NEAR(r.tilt_deg, b, 1e-9);
      EXPECT_NEAR(r.rotary_deg, current[j.c], 1e-9);
    }
  }
}

// xyzac-trt's A travels -30 .. 120: a direction 60° off Z has A = +60 in travel and
// A = -60 not, whatever the rule prefers; 150° off Z has neither.
TEST(FiveAxisOrient, TravelExcludesASolution) {
  config::MachineConfig cfg = machine("xyzac-trt");
  const Joints j(cfg);
  for (const char* rule : {"nearest", "positive_tilt", "negative_tilt"}) {
    cfg.kinematics.solution = rule;
    const auto k = make_kinematics(cfg);
    Pose current{};
    current[j.t] = -20;  // nearer -60 than +60
    Orientation o;
    // LinuxCNC's K at A = 60, C = 25
    const V3 K = adoc_xyzac_tool_vector(60, 25);
    ASSERT_TRUE(k->orient({K.x, K.y, K.z}, current, o)) << rule;
    EXPECT_TRUE(o.solution[0].in_travel);
    EXPECT_FALSE(o.solution[1].in_travel);
    EXPECT_NEAR(o.solution[1].tilt_deg, -60, 1e-9);
    EXPECT_EQ(o.chosen, 0) << rule;
    EXPECT_NEAR(o.solution[0].tilt_deg, 60, 1e-9);
    EXPECT_NEAR(o.solution[0].rotary_deg, 25, 1e-9);
    const V3 far = adoc_xyzac_tool_vector(150, 25);
    EXPECT_FALSE(k->orient({far.x, far.y, far.z}, current, o)) << rule;
    EXPECT_EQ(o.chosen, -1);
    EXPECT_FALSE(o.solution[0].in_travel);
    EXPECT_FALSE(o.solution[1].in_travel);
  }
  // Open the travel to -90: the rule decides again (the current A -20 is nearer -60).
  cfg.axes[j.t].min_mm = -90;
  cfg.kinematics.solution = "nearest";
  const auto k = make_kinematics(cfg);
  Pose current{};
  current[j.t] = -20;
  current[j.c] = 205;
  Orientation o;
  const V3 K = adoc_xyzac_tool_vector(60, 25);
  ASSERT_TRUE(k->orient({K.x, K.y, K.z}, current, o));
  EXPECT_EQ(o.chosen, 1);
  EXPECT_NEAR(o.solution[1].tilt_deg, -60, 1e-9);
  EXPECT_NEAR(o.solution[1].rotary_deg, 205, 1e-9);
}

TEST(FiveAxisOrient, NoDirectionFromAZeroOrNonFiniteVector) {
  const auto k = make_kinematics(machine("xyzbc-trt"));
  Orientation o;
  EXPECT_FALSE(k->orient({0, 0, 0}, Pose{}, o));
  EXPECT_FALSE(k->orient({std::nan(""), 0, 1}, Pose{}, o));
  EXPECT_FALSE(k->orient({0, std::numeric_limits<double>::infinity(), 1}, Pose{}, o));
  EXPECT_EQ(o.chosen, -1);
}

// ---- the pole -------------------------------------------------------------------------
TEST(FiveAxisPole, AlongTheCAxisCIsKeptAndTheDistanceReported) {
  for (const char* type : kTypes) {
    const config::MachineConfig cfg = machine(type);
    ASSERT_DOUBLE_EQ(cfg.kinematics.pole_tolerance_deg, 1e-6);
    const auto k = make_kinematics(cfg);
    const Joints j(cfg);
    Pose current{};
    current[j.t] = 10;
    current[j.c] = 123.25;
    Orientation o;
    ASSERT_TRUE(k->orient({0, 0, 2}, current, o)) << type;
    EXPECT_TRUE(o.at_pole);
    EXPECT_EQ(o.pole_distance_deg, 0.0);
    for (const RotaryAngles& r : o.solution) {
      EXPECT_EQ(r.tilt_deg, 0.0) << type;
      EXPECT_EQ(r.rotary_deg, 123.25) << type;
    }
    // Within the tolerance: C kept, the direction off by at most twice the distance.
    const double eps = 4e-7;
    const ToolDirection near = unit(eps, 70);
    ASSERT_TRUE(k->orient(near, current, o));
    EXPECT_TRUE(o.at_pole);
    EXPECT_NEAR(o.pole_distance_deg, eps, 1e-15);
    for (const RotaryAngles& r : o.solution) {
      EXPECT_EQ(r.rotary_deg, 123.25) << type;
      EXPECT_NEAR(std::fabs(r.tilt_deg), eps, 1e-15) << type;
      Pose p = current;
      p[j.t] = r.tilt_deg;
      p[j.c] = r.rotary_deg;
      EXPECT_LE(angle_between(k->tool_direction(p), near), 2 * eps * kDeg + 1e-15) << type;
    }
    // Outside it: C follows the direction, however close, exactly.
    const double off = 1e-3;
    const ToolDirection close = unit(off, 70);
    ASSERT_TRUE(k->orient(close, current, o));
    EXPECT_FALSE(o.at_pole);
    EXPECT_NEAR(o.pole_distance_deg, off, 1e-15);
    for (const RotaryAngles& r : o.solution) {
      Pose p = current;
      p[j.t] = r.tilt_deg;
      p[j.c] = r.rotary_deg;
      EXPECT_LE(angle_between(k->tool_direction(p), close), 1e-14) << type;
      EXPECT_EQ(k->pole_distance_deg(p), std::fabs(r.tilt_deg)) << type;
    }
  }
}

// The tool pointing straight down the C axis (a tilt of 180°) is a pole too.
TEST(FiveAxisPole, TheOtherPoleKeepsCAndIsOutOfATiltsTravel) {
  const config::MachineConfig cfg = machine("xyzac-trt");  // A -30 .. 120
  const auto k = make_kinematics(cfg);
  const Joints j(cfg);
  Pose current{};
  current[j.c] = -33;
  Orientation o;
  EXPECT_FALSE(k->orient({0, 0, -1}, current, o));
  EXPECT_TRUE(o.at_pole);
  EXPECT_EQ(o.pole_distance_deg, 0.0);
  EXPECT_EQ(o.solution[0].rotary_deg, -33.0);
  EXPECT_EQ(std::fabs(o.solution[0].tilt_deg), 180.0);
}

TEST(FiveAxisPole, DistanceOfAJointPose) {
  const config::MachineConfig cfg = machine("xyzbc-head");
  const auto k = make_kinematics(cfg);
  const Joints j(cfg);
  Pose p{};
  const std::pair<double, double> cases[] = {{0.0, 0.0},    {0.5, 0.5},    {-0.5, 0.5},   {90.0, 90.0}, {-90.0, 90.0},
                                             {179.5, 0.5},  {-180.0, 0.0}, {270.0, 90.0}, {355.0, 5.0}};
  for (const auto& [tilt, want] : cases) {
    p[j.t] = tilt;
    EXPECT_EQ(k->pole_distance_deg(p), want) << tilt;
  }
  const auto identity = make_kinematics(config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml"));
  EXPECT_EQ(identity->pole_distance_deg(p), std::numeric_limits<double>::infinity());
  Orientation o;
  EXPECT_FALSE(identity->orient({0, 0, 1}, p, o));
}

// Tolerance 0: only the exact pole keeps C.
TEST(FiveAxisPole, ToleranceZeroKeepsCOnlyOnThePole) {
  config::MachineConfig cfg = machine("xyzbc-head");
  cfg.kinematics.pole_tolerance_deg = 0;
  const auto k = make_kinematics(cfg);
  const Joints j(cfg);
  Pose current{};
  current[j.c] = 17;
  Orientation o;
  ASSERT_TRUE(k->orient({0, 0, 1}, current, o));
  EXPECT_TRUE(o.at_pole);
  EXPECT_EQ(o.solution[0].rotary_deg, 17.0);
  ASSERT_TRUE(k->orient({1e-12, 1e-12, 1}, current, o));
  EXPECT_FALSE(o.at_pole);
  EXPECT_NEAR(o.solution[0].rotary_deg, 45.0, 1e-9);
}

// ---- joint_rate ------------------------------------------------------------------------
// Along X, Y, Z alone the joints are affine in the axes: any difference is exact.
TEST(FiveAxisRate, AlongTheLinearAxesItIsTheDifference) {
  for (const char* type : kTypes) {
    const config::MachineConfig cfg = machine(type);
    const auto k = make_kinematics(cfg);
    const Joints j(cfg);
    std::mt19937_64 rng(12);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int n = 0; n < 500; ++n) {
      const Tool tool{random_tool(rng)};
      Pose axes{};
      k->forward(random_joints(rng, *k), axes, tool);
      Pose rate{};
      rate[j.x] = 100 * u(rng);
      rate[j.y] = 100 * u(rng);
      rate[j.z] = 100 * u(rng);
      Pose moved = axes, q0{}, q1{}, dq{};
      for (const size_t i : {j.x, j.y, j.z}) moved[i] += rate[i];
      k->inverse(axes, q0, tool);
      k->inverse(moved, q1, tool);
      k->joint_rate(axes, rate, tool, dq);
      for (const size_t i : {j.x, j.y, j.z}) ASSERT_NEAR(dq[i], q1[i] - q0[i], 1e-7) << type;
      EXPECT_EQ(dq[j.t], 0.0);
      EXPECT_EQ(dq[j.c], 0.0);
    }
  }
}

// Turning a head, the gauge point moves on its sphere: d/dC and d/dB of
// tip + P·Z - (P + L)·(cC sB, sC sB, cB) taken by hand.
TEST(FiveAxisRate, AHeadsTurnAgreesWithItsDerivative) {
  const config::MachineConfig cfg = machine("xyzbc-head");
  const auto k = make_kinematics(cfg);
  const Joints j(cfg);
  const double P = cfg.kinematics.pivot_mm;
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int n = 0; n < 1000; ++n) {
    const double L = random_tool(rng);
    Pose axes{};
    k->forward(random_joints(rng, *k), axes, Tool{L});
    const double vb = 30 * u(rng), vc = 90 * u(rng);
    Pose rate{};
    rate[j.t] = vb;
    rate[j.c] = vc;
    Pose dq{};
    k->joint_rate(axes, rate, Tool{L}, dq);
    const double B = axes[j.t] * kDeg, C = axes[j.c] * kDeg, r = (P + L) * kDeg;
    const V3 want{r * (std::cos(C) * std::cos(B) * vb - std::sin(C) * std::sin(B) * vc),
                  r * (std::sin(C) * std::cos(B) * vb + std::cos(C) * std::sin(B) * vc), r * (-std::sin(B) * vb)};
    ASSERT_LE(dist(j.xyz(dq), want), 1e-7 * (std::fabs(vb) + std::fabs(vc)) * r) << n;
    // passed through, off by the rounding of the positions over the step: 1e-9 of the largest rate
    const double largest = std::max(std::fabs(vb), std::fabs(vc));
    EXPECT_NEAR(dq[j.t], vb, 1e-9 * largest);
    EXPECT_NEAR(dq[j.c], vc, 1e-9 * largest);
  }
}

// Turning the trunnion's C, a workpiece point q moves: joints = tilt centre +
// Rx(A)·(C centre + Rz(C)·(q - C centre) - tilt centre) + L·Z, derived by hand.
TEST(FiveAxisRate, ATrunnionsCTurnAgreesWithItsDerivative) {
  const config::MachineConfig cfg = machine("xyzac-trt");
  const auto& kc = cfg.kinematics;
  const auto k = make_kinematics(cfg);
  const Joints j(cfg);
  std::mt19937_64 rng(14);
  std::uniform_real_distribution<double> u(-200, 200);
  for (int n = 0; n < 1000; ++n) {
    Pose axes = random_joints(rng, *k);
    axes[j.x] = u(rng);
    axes[j.y] = u(rng);
    axes[j.z] = u(rng);
    Pose rate{};
    rate[j.c] = 45;
    Pose dq{};
    k->joint_rate(axes, rate, Tool{30}, dq);
    const double A = axes[j.t] * kDeg, C = axes[j.c] * kDeg;
    const double qx = axes[j.x] - kc.x_rot_point_mm, qy = axes[j.y] - kc.y_rot_point_mm;
    // d/dC of Rz(C)·(qx, qy), per degree, times the rate
    const double dx = (-std::sin(C) * qx - std::cos(C) * qy) * kDeg * 45;
    const double dy = (std::cos(C) * qx - std::sin(C) * qy) * kDeg * 45;
    const V3 want{dx, std::cos(A) * dy, std::sin(A) * dy};  // Rx(A) of (dx, dy, 0)
    ASSERT_LE(dist(j.xyz(dq), want), 1e-7 * std::max(1.0, std::hypot(want.x, want.y, want.z))) << n;
  }
}

TEST(FiveAxisRate, IdentityIsTheRateItself) {
  const auto k = make_kinematics(config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim4_rotary.yaml"));
  Pose axes{}, rate{}, dq{};
  axes = {1, 2, 3, 4};
  rate = {0.1, -7, 1e-30, 3e5};
  k->joint_rate(axes, rate, Tool{12}, dq);
  for (size_t i = 0; i < 4; ++i) EXPECT_EQ(dq[i], rate[i]);
}

// ---- the cycle ---------------------------------------------------------------------------
TEST(FiveAxis, NothingAllocates) {
  for (const char* type : kTypes) {
    const auto k = make_kinematics(machine(type));
    std::mt19937_64 rng(1);
    for (int n = 0; n < 200; ++n) {
      const Pose joints = random_joints(rng, *k);
      Pose axes{}, back{}, rate{}, dq{};
      rate.fill(1.0);
      Orientation o;
      double sink = 0;
      test::AllocGuard g;
      k->forward(joints, axes, Tool{10});
      k->inverse(axes, back, Tool{10});
      k->joint_rate(axes, rate, Tool{10}, dq);
      k->orient(k->tool_direction(joints), joints, o);
      sink += k->pole_distance_deg(joints) + (k->in_travel(back) ? 1 : 0);
      g.pause();
      ASSERT_EQ(g.allocations() + g.frees(), 0) << type;
      ASSERT_TRUE(std::isfinite(sink));
    }
  }
}

// Inverse and forward may be given the same pose to overwrite.
TEST(FiveAxis, InPlaceTransformsAreTheSame) {
  for (const char* type : kTypes) {
    const auto k = make_kinematics(machine(type));
    std::mt19937_64 rng(2);
    const Pose joints = random_joints(rng, *k);
    Pose axes{}, in_place = joints;
    k->forward(joints, axes, Tool{7});
    k->forward(in_place, in_place, Tool{7});
    EXPECT_EQ(in_place, axes) << type;
    Pose back{};
    k->inverse(axes, back, Tool{7});
    k->inverse(in_place, in_place, Tool{7});
    EXPECT_EQ(in_place, back) << type;
  }
}

}  // namespace
}  // namespace cnc::kinematics
