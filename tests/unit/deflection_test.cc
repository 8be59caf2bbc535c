// VMCS 1999's tool deflection (cantilever, eq. 13, D_e = 0.8·D) and the wall's surface
// error from the rotation angle at which each height is generated (eqs. 15–16).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "common/process/cutting_config.h"
#include "common/process/deflection.h"

namespace cnc::process {
namespace {

constexpr double kPi = std::numbers::pi;
const std::string kConfig = std::string(CNC_SOURCE_DIR) + "/config/";

TEST(Deflection, InertiaUsesTheEffectiveDiameter) {
  const EndMill t = load_tool(kConfig + "tools/hss_flat_4f_d6.yaml");
  const CantileverTool beam(t);
  EXPECT_NEAR(beam.inertia_mm4(), kPi * std::pow(4.8, 4) / 64, 1e-12);
  EXPECT_NEAR(beam.ei(), 210000.0 * kPi * std::pow(4.8, 4) / 64, 1e-6);
}

TEST(Deflection, TipLoadIsPL3Over3EI) {
  const EndMill t = load_tool(kConfig + "tools/hss_flat_4f_d6.yaml");
  const CantileverTool beam(t);
  const double l = t.overhang_mm;
  const Eigen::Vector2d d = beam.deflection(0.0, {0.0}, {Eigen::Vector3d(100.0, -50.0, 7.0)});
  EXPECT_NEAR(d.x(), 100.0 * l * l * l / (3 * beam.ei()), 1e-12);
  EXPECT_NEAR(d.y(), -50.0 * l * l * l / (3 * beam.ei()), 1e-12);
  // Below the load the beam is straight: slope P·a²/(2EI) times the distance.
  const double a = l - 5.0;
  const Eigen::Vector2d d0 = beam.deflection(0.0, {5.0}, {Eigen::Vector3d(100.0, 0, 0)});
  EXPECT_NEAR(d0.x(), 100.0 * (a * a * a / 3 + a * a / 2 * 5.0) / beam.ei(), 1e-12);
  // Maxwell–Betti: the influence is symmetric.
  EXPECT_NEAR(beam.influence(7.0, 19.0), beam.influence(19.0, 7.0), 1e-18);
  EXPECT_EQ(beam.influence(0.0, 10.0), 0.0);  // the clamp does not move
}

TEST(Deflection, DownMillingLeavesMaterialUpMillingCutsIn) {
  const EndMill t = load_tool(kConfig + "tools/hss_flat_4f_d6.yaml");
  const Material al = load_material(kConfig + "materials/al_paper004.yaml");
  const CuttingForceModel m(t, al, ForceModel::kChipThicknessLaw, 60);
  const Engagement down = Engagement::down_milling(6.0, 1.0, 4.0, 0.02);
  const Engagement up = Engagement::up_milling(6.0, 1.0, 4.0, 0.02);
  for (const WallErrorPoint& w : wall_surface_error(m, down, 20, wall_angle(down))) EXPECT_GT(w.surface_error_mm, 0.0);
  double up_min = 0;
  for (const WallErrorPoint& w : wall_surface_error(m, up, 20, wall_angle(up))) up_min = std::min(up_min, w.surface_error_mm);
  EXPECT_LT(up_min, 0.0);
}

TEST(Deflection, ErrorGrowsWithLoadAndStickOut) {
  EndMill t = load_tool(kConfig + "tools/hss_flat_4f_d6.yaml");
  const Material al = load_material(kConfig + "materials/al_paper004.yaml");
  auto worst = [&](const EndMill& tool, double ae, double ap, double c) {
    const CuttingForceModel m(tool, al, ForceModel::kChipThicknessLaw, 60);
    const Engagement e = Engagement::down_milling(6.0, ae, ap, c);
    double w = 0;
    for (const WallErrorPoint& p : wall_surface_error(m, e, 30, wall_angle(e))) w = std::max(w, p.surface_error_mm);
    return w;
  };
  const double light = worst(t, 0.5, 2.0, 0.01);
  const double heavy = worst(t, 2.0, 6.0, 0.02);
  EXPECT_GT(heavy, 3 * light);
  // The paper's range (RDC 0.5–2 mm, ADC 2–6 mm, 0.01–0.02 mm/tooth, aluminium): its
  // prediction errors of 0.004–0.015 mm are "about 10 %" of the surface error, which
  // puts the heaviest straight cut's error near 0.1 mm. A plausibility band, not a
  // figure from the paper (its overhang and helix are not legible, see the tool file).
  EXPECT_GT(heavy, 0.02);
  EXPECT_LT(heavy, 0.5);
  t.overhang_mm *= 2;
  EXPECT_GT(worst(t, 2.0, 6.0, 0.02), 6 * heavy);  // ~L³
}

TEST(Deflection, GenerationAngleFollowsTheHelix) {
  const EndMill t = load_tool(kConfig + "tools/hss_flat_4f_d6.yaml");
  const Material al = load_material(kConfig + "materials/al_paper004.yaml");
  const CuttingForceModel m(t, al, ForceModel::kChipThicknessLaw, 40);
  const Engagement e = Engagement::down_milling(6.0, 1.0, 4.0, 0.02);
  const auto prof = wall_surface_error(m, e, 8, kPi);
  for (const WallErrorPoint& w : prof) {
    EXPECT_NEAR(w.theta, kPi + w.height_mm * std::tan(kPi / 6) / 3.0, 1e-12);  // eq. 15
    EXPECT_NEAR((w.force - m.force(e, w.theta)).norm(), 0.0, 1e-9);
  }
}

TEST(Deflection, MapOverChangingEngagement) {
  const EndMill t = load_tool(kConfig + "tools/hss_flat_4f_d6.yaml");
  const Material al = load_material(kConfig + "materials/al_paper004.yaml");
  const CuttingForceModel m(t, al, ForceModel::kChipThicknessLaw, 40);
  std::vector<WallSection> s;
  for (int i = 0; i <= 10; ++i) s.push_back({i * 0.5, Engagement::down_milling(6.0, 0.5 + 0.15 * i, 4.0, 0.02)});
  const WallErrorMap map = wall_error_map(m, s, 16);
  ASSERT_EQ(map.error_mm.size(), 11u);
  ASSERT_EQ(map.height_mm.size(), 16u);
  double first = 0, last = 0;
  for (double v : map.error_mm.front()) first = std::max(first, v);
  for (double v : map.error_mm.back()) last = std::max(last, v);
  EXPECT_GT(last, first);  // deeper radial engagement, larger error
  EXPECT_GE(map.max_abs_mm, last);
}

}  // namespace
}  // namespace cnc::process
