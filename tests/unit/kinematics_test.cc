// Kinematics: identity's transforms both ways are exact (bit for bit) and allocate
// nothing, its joint limits are the config's axes, and the factory makes identity.
#include "common/kinematics/kinematics.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>

#include "common/config/machine_config.h"
#include "tests/unit/alloc_guard.h"

namespace cnc::kinematics {
namespace {

config::MachineConfig sim3() {
  return config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
}

// Nine axes with limits that differ per axis.
config::MachineConfig nine_axes() {
  config::MachineConfig c = sim3();
  c.axes.resize(program::kMaxAxes, c.axes.front());
  for (int i = 0; i < program::kMaxAxes; ++i) {
    auto& ax = c.axes[static_cast<size_t>(i)];
    ax.name = std::string(1, "XYZABCUVW"[i]);
    ax.min_mm = -100.0 - i;
    ax.max_mm = 200.0 + 0.5 * i;
    ax.max_velocity_mm_s = 100.0 + i;
    ax.max_accel_mm_s2 = 1000.0 + 3 * i;
    ax.max_jerk_mm_s3 = 1e5 + 7 * i;
  }
  return c;
}

// A finite double from random bits: every exponent and sign, not only a range.
double random_finite(std::mt19937_64& rng) {
  for (;;) {
    const double d = std::bit_cast<double>(rng());
    if (std::isfinite(d)) return d;
  }
}

bool same_bits(double a, double b) { return std::bit_cast<uint64_t>(a) == std::bit_cast<uint64_t>(b); }

TEST(Kinematics, FactoryMakesIdentityWithTheConfigsAxesAsJoints) {
  const config::MachineConfig c = nine_axes();
  const auto k = make_kinematics(c);
  EXPECT_EQ(k->name(), "identity");
  EXPECT_EQ(k->joints(), program::kMaxAxes);
  EXPECT_EQ(k->axes(), program::kMaxAxes);
  for (int j = 0; j < k->joints(); ++j) {
    const auto& ax = c.axes[static_cast<size_t>(j)];
    const JointLimits& l = k->joint_limits()[static_cast<size_t>(j)];
    EXPECT_EQ(l.name, ax.name);
    EXPECT_TRUE(same_bits(l.min_mm, ax.min_mm));
    EXPECT_TRUE(same_bits(l.max_mm, ax.max_mm));
    EXPECT_TRUE(same_bits(l.max_velocity_mm_s, ax.max_velocity_mm_s));
    EXPECT_TRUE(same_bits(l.max_accel_mm_s2, ax.max_accel_mm_s2));
    EXPECT_TRUE(same_bits(l.max_jerk_mm_s3, ax.max_jerk_mm_s3));
  }
}

// Every name the config reader accepts is made, under that name: identity on sim3, a
// five-axis type on its example machine (tests/unit/kinematics_machines).
TEST(Kinematics, FactoryMakesEveryTypeTheConfigAccepts) {
  for (const char* type : config::kKinematicsTypes) {
    const config::MachineConfig c =
        std::string(type) == "identity"
            ? sim3()
            : config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/tests/unit/kinematics_machines/" + type + ".yaml");
    EXPECT_EQ(c.kinematics.type, type);
    EXPECT_EQ(make_kinematics(c)->name(), type);
  }
  config::MachineConfig c = sim3();
  c.kinematics.type = "bogus";
  EXPECT_THROW(make_kinematics(c), std::invalid_argument);
  // A five-axis type on a machine without its axes: refused here too, not only by the reader.
  c.kinematics.type = "xyzbc-trt";
  EXPECT_THROW(make_kinematics(c), std::invalid_argument);
}

// A tool length moves joint Z above the tip; without one identity is what it was.
TEST(Kinematics, IdentityPutsTheToolLengthBetweenJointAndAxisZ) {
  const auto k = make_kinematics(nine_axes());
  Pose axes{}, joints{}, back{};
  for (size_t i = 0; i < axes.size(); ++i) axes[i] = 10.0 * static_cast<double>(i);
  axes[2] = -0.0;
  ASSERT_TRUE(k->inverse(axes, joints, Tool{35.5}));
  for (size_t i = 0; i < axes.size(); ++i) EXPECT_EQ(joints[i], i == 2 ? 35.5 : axes[i]) << i;
  k->forward(joints, back, Tool{35.5});
  EXPECT_EQ(back, axes);
  ASSERT_TRUE(k->inverse(axes, joints, Tool{}));
  EXPECT_TRUE(std::signbit(joints[2]));  // -0 stays -0: no tool, nothing added
  EXPECT_TRUE(k->in_travel(joints));
  joints[4] = 1e6;
  EXPECT_FALSE(k->in_travel(joints));
}

TEST(Kinematics, ShippedMachineIsIdentityWithItsLimits) {
  const config::MachineConfig c = sim3();
  const auto k = make_kinematics(c);
  ASSERT_EQ(k->joints(), static_cast<int>(c.axes.size()));
  for (size_t j = 0; j < c.axes.size(); ++j) {
    EXPECT_EQ(k->joint_limits()[j].name, c.axes[j].name);
    EXPECT_EQ(k->joint_limits()[j].min_mm, c.axes[j].min_mm);
    EXPECT_EQ(k->joint_limits()[j].max_mm, c.axes[j].max_mm);
    EXPECT_EQ(k->joint_limits()[j].max_velocity_mm_s, c.axes[j].max_velocity_mm_s);
    EXPECT_EQ(k->joint_limits()[j].max_accel_mm_s2, c.axes[j].max_accel_mm_s2);
    EXPECT_EQ(k->joint_limits()[j].max_jerk_mm_s3, c.axes[j].max_jerk_mm_s3);
  }
}

TEST(Kinematics, IdentityRoundTripsBitForBitWithoutAllocating) {
  const auto k = make_kinematics(nine_axes());
  std::mt19937_64 rng(28);
  for (int n = 0; n < 100000; ++n) {
    Pose p{}, joints{}, back{};
    for (double& x : p) x = random_finite(rng);
    bool ok = false;
    {
      test::AllocGuard g;
      ok = k->inverse(p, joints);
      k->forward(joints, back);
      g.pause();
      ASSERT_EQ(g.allocations() + g.frees(), 0);
    }
    ASSERT_TRUE(ok);
    for (size_t i = 0; i < p.size(); ++i) {
      ASSERT_TRUE(same_bits(back[i], p[i])) << "pose " << n << " axis " << i;
      ASSERT_TRUE(same_bits(joints[i], p[i])) << "pose " << n << " joint " << i;
    }
  }
}

TEST(Kinematics, IdentityLeavesEntriesPastTheMachinesAxesAlone) {
  const config::MachineConfig c = sim3();
  const auto k = make_kinematics(c);
  Pose p{}, out{};
  p.fill(1.0);
  out.fill(-7.0);
  ASSERT_TRUE(k->inverse(p, out));
  for (size_t i = 0; i < out.size(); ++i) EXPECT_EQ(out[i], i < c.axes.size() ? 1.0 : -7.0);
}

}  // namespace
}  // namespace cnc::kinematics
