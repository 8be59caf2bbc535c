// VMCS 1999's cutting-force model: the disc simulation against the closed-form slot
// means (digest, Al7075-T6), the projection, engagement, the chip-thickness law, the
// calibration of eqs. 7–10 on synthetic histories with noise, and the config files.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "common/config/yaml_reader.h"
#include "common/process/cutting_config.h"
#include "common/process/cutting_force.h"
#include "common/process/force_calibration.h"

namespace cnc::process {
namespace {

constexpr double kPi = std::numbers::pi;
const std::string kConfig = std::string(CNC_SOURCE_DIR) + "/config/";

EndMill four_flute() {
  EndMill t;
  t.flutes = 4;
  t.diameter_mm = 6.0;
  t.helix_deg = 30.0;
  return t;
}

double rel(double v, double ref) { return std::abs(v - ref) / std::abs(ref); }

TEST(CuttingForce, SlotMeanConvergesToTheClosedForm) {
  const Material al = load_material(kConfig + "materials/al7075_t6.yaml");
  const EndMill tool = four_flute();
  const Engagement e = Engagement::slot(3.0, 0.05);
  const Eigen::Vector3d ref = slot_mean_force_closed_form(al.linear, 4, 3.0, 0.05);
  double coarse = 0;
  for (int discs : {2, 10, 50, 200}) {
    const CuttingForceModel m(tool, al, ForceModel::kLinearEdge, discs);
    const Eigen::Vector3d mean = m.simulate_revolution(e, m.paper_steps_per_rev(e)).mean();
    const double err = std::max({rel(mean.x(), ref.x()), rel(mean.y(), ref.y()), rel(mean.z(), ref.z())});
    if (discs == 2) coarse = err;
    if (discs == 10) {
      EXPECT_LT(err, 0.2 * coarse);  // converging (the bench prints the whole series)
    }
    if (discs >= 50) {
      EXPECT_LT(err, 0.005) << "discs " << discs << " mean " << mean.transpose();
    }
  }
}

TEST(CuttingForce, ClosedFormIsTheDigestsFormula) {
  const LinearEdgeCoefficients k{796.1, 168.8, 222.0, 27.7, 30.8, 0.0};
  const Eigen::Vector3d f = slot_mean_force_closed_form(k, 4, 2.0, 0.1);
  EXPECT_NEAR(f.x(), -4 * 2.0 * 0.1 * 168.8 / 4 - 4 * 2.0 * 30.8 / kPi, 1e-12);
  EXPECT_NEAR(f.y(), 4 * 2.0 * 0.1 * 796.1 / 4 + 4 * 2.0 * 27.7 / kPi, 1e-12);
  EXPECT_NEAR(f.z(), 4 * 2.0 * 0.1 * 222.0 / kPi, 1e-12);
}

TEST(CuttingForce, ProjectionAndSigns) {
  // At φ = 90° (the element at +X, cutting towards −Y) the tangential force pushes the tool to +Y.
  const Eigen::Vector3d f = project({10.0, 3.0, 1.0}, kPi / 2);
  EXPECT_NEAR(f.x(), -3.0, 1e-12);
  EXPECT_NEAR(f.y(), 10.0, 1e-12);
  EXPECT_NEAR(f.z(), 1.0, 1e-12);
}

TEST(CuttingForce, EngagementArcs) {
  const Engagement up = Engagement::up_milling(6.0, 1.5, 2.0, 0.02);
  EXPECT_NEAR(up.phi_start, 0.0, 1e-15);
  EXPECT_NEAR(up.phi_exit, kPi / 3, 1e-12);
  const Engagement down = Engagement::down_milling(6.0, 1.5, 2.0, 0.02);
  EXPECT_NEAR(down.phi_start, 2 * kPi / 3, 1e-12);
  EXPECT_NEAR(down.phi_exit, kPi, 1e-15);
  const Engagement half = Engagement::up_milling(6.0, 3.0, 2.0, 0.02);
  EXPECT_NEAR(half.phi_exit, kPi / 2, 1e-12);
}

TEST(CuttingForce, StraightFluteSingleElementIsTheElementalForce) {
  // One disc, no helix, one flute at θ = 60° in a slot: exactly one element.
  EndMill t = four_flute();
  t.helix_deg = 0.0;
  t.flutes = 1;
  const Material al = load_material(kConfig + "materials/al7075_t6.yaml");
  const CuttingForceModel m(t, al, ForceModel::kLinearEdge, 1);
  const Engagement e = Engagement::slot(2.0, 0.1);
  const double phi = kPi / 3;
  const double h = 0.1 * std::sin(phi);
  const Eigen::Vector3d f = m.force(e, phi);
  const Eigen::Vector3d expect = project({(796.1 * h + 27.7) * 2, (168.8 * h + 30.8) * 2, 222.0 * h * 2}, phi);
  EXPECT_NEAR((f - expect).norm(), 0.0, 1e-9);
  EXPECT_EQ(m.force(e, 1.5 * kPi).norm(), 0.0);  // out of the cut
}

TEST(CuttingForce, ChipThicknessLawReadsAsPowerLaws) {
  const Material al = load_material(kConfig + "materials/al_paper004.yaml");
  ASSERT_TRUE(al.has_chip_law);
  EXPECT_EQ(al.model, ForceModel::kChipThicknessLaw);
  EXPECT_NEAR(al.chip_law.kt(0.01), 373.35 * std::pow(0.01, -0.35), 1e-9);
  EXPECT_NEAR(al.chip_law.kr(0.01), 0.3049 * std::pow(0.01, -0.126), 1e-12);
  const ElementForce f = element_force(al, ForceModel::kChipThicknessLaw, 0.01, 0.5);
  EXPECT_NEAR(f.ft, al.chip_law.kt(0.01) * 0.5 * 0.01, 1e-12);
  EXPECT_NEAR(f.fr, al.chip_law.kr(0.01) * f.ft, 1e-12);
  // Thinner chips cut at a larger specific force (size effect), but less force.
  EXPECT_GT(al.chip_law.kt(0.005), al.chip_law.kt(0.02));
  EXPECT_LT(element_force(al, ForceModel::kChipThicknessLaw, 0.005, 1).ft,
            element_force(al, ForceModel::kChipThicknessLaw, 0.02, 1).ft);
  EXPECT_EQ(element_force(al, ForceModel::kChipThicknessLaw, 0.0, 1).ft, 0.0);
}

TEST(CuttingForce, ShippedFilesLoad) {
  const EndMill t = load_tool(kConfig + "tools/hss_flat_4f_d6.yaml");
  EXPECT_EQ(t.flutes, 4);
  EXPECT_DOUBLE_EQ(t.diameter_mm, 6.0);
  EXPECT_EQ(t.type, "flat");
  const EndMill b = load_tool(kConfig + "tools/ball_r5_2f.yaml");
  EXPECT_EQ(b.type, "ball");
  EXPECT_EQ(b.flutes, 2);
  const Material s = load_material(kConfig + "materials/s41c.yaml");
  EXPECT_TRUE(s.has_chip_law);
  EXPECT_THROW(load_material(kConfig + "tools/ball_r5_2f.yaml"), cnc::config::ConfigError);
}

// ---- calibration (eqs. 7–10) ----------------------------------------------------

// Calibration cuts: up and down milling at 1 mm radial depth, three feeds; the axial
// depth a whole number of eq. 11 discs (Nθ = 180: Dz = R·2°/tan 30° = 0.1814 mm).
std::vector<CalibrationCut> cuts_for(const Material& mat, ForceModel model, double noise_fraction) {
  const EndMill tool = four_flute();
  const int steps = 180;
  const double dz = tool.radius() * (2 * kPi / steps) / std::tan(kPi / 6);
  const double a = 11 * dz;
  std::vector<CalibrationCut> cuts;
  unsigned seed = 16;
  for (double c : {0.01, 0.02, 0.03}) {
    for (bool up : {true, false}) {
      const Engagement e = up ? Engagement::up_milling(6.0, 1.0, a, c) : Engagement::down_milling(6.0, 1.0, a, c);
      const CuttingForceModel m(tool, mat, model, calibration_discs(tool, e, steps));
      double peak = 0;
      for (const Eigen::Vector3d& f : m.simulate_revolution(e, steps).force) peak = std::max(peak, f.head<2>().norm());
      cuts.push_back(synthetic_cut(tool, mat, model, e, steps, 20, noise_fraction * peak, seed++));
    }
  }
  return cuts;
}

TEST(ForceCalibration, RecoversTheChipThicknessLawFromANoisyHistory) {
  const Material al = load_material(kConfig + "materials/al_paper004.yaml");
  const CalibrationResult r = calibrate(four_flute(), cuts_for(al, ForceModel::kChipThicknessLaw, 0.01));
  ASSERT_EQ(r.error, "");
  EXPECT_LT(rel(r.chip_law.kt.c, 373.35), 0.02) << r.chip_law.kt.c;
  EXPECT_LT(rel(r.chip_law.kt.exponent, -0.35), 0.02) << r.chip_law.kt.exponent;
  EXPECT_LT(rel(r.chip_law.kr.c, 0.3049), 0.02) << r.chip_law.kr.c;
  EXPECT_LT(rel(r.chip_law.kr.exponent, -0.126), 0.02) << r.chip_law.kr.exponent;
}

TEST(ForceCalibration, RecoversTheLinearEdgeCoefficientsFromANoisyHistory) {
  const Material al = load_material(kConfig + "materials/al7075_t6.yaml");
  const CalibrationResult r = calibrate(four_flute(), cuts_for(al, ForceModel::kLinearEdge, 0.01));
  ASSERT_EQ(r.error, "");
  EXPECT_LT(rel(r.linear.ktc, 796.1), 0.02) << r.linear.ktc;
  EXPECT_LT(rel(r.linear.krc, 168.8), 0.02) << r.linear.krc;
  EXPECT_LT(rel(r.linear.kte, 27.7), 0.02) << r.linear.kte;
  EXPECT_LT(rel(r.linear.kre, 30.8), 0.02) << r.linear.kre;
}

TEST(ForceCalibration, ExactWithoutNoise) {
  const Material al = load_material(kConfig + "materials/al_paper004.yaml");
  const CalibrationResult r = calibrate(four_flute(), cuts_for(al, ForceModel::kChipThicknessLaw, 0.0));
  ASSERT_EQ(r.error, "");
  EXPECT_LT(r.residual_rms_n, 1e-9);
  for (const CoefficientSample& s : r.samples) {
    if (s.h < 1e-3) continue;
    EXPECT_NEAR(s.kt, al.chip_law.kt(s.h), 1e-6 * al.chip_law.kt(s.h));
    EXPECT_NEAR(s.kr, al.chip_law.kr(s.h), 1e-6);
  }
}

TEST(ForceCalibration, AFourFluteSlotIsNotIdentifiable) {
  const Material al = load_material(kConfig + "materials/al7075_t6.yaml");
  const EndMill tool = four_flute();
  const Engagement e = Engagement::slot(2.0, 0.02);
  const CalibrationResult r =
      calibrate(tool, {synthetic_cut(tool, al, ForceModel::kLinearEdge, e, 180, 1, 0.0, 1)});
  EXPECT_NE(r.error.find("not identifiable"), std::string::npos) << r.error;
}

}  // namespace
}  // namespace cnc::process
