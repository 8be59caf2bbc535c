// a flat end mill's engagement from a Z-map stock — the
// engaged arc of a straight wall cut and a slot against the geometric arcs, the force
// from the profile against the engagement-arc model, and a pocket corner's growing
// engagement.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "common/process/cutting_config.h"
#include "common/process/engagement.h"

namespace cnc::process {
namespace {

constexpr double kPi = std::numbers::pi;
const std::string kConfig = std::string(CNC_SOURCE_DIR) + "/config/";

// Cuts along the polyline at tip height z in 0.05 mm steps; returns the profile at
// every step (computed before that step's removal).
std::vector<EngagementProfile> run(ZMap& stock, const std::vector<Eigen::Vector2d>& pts, double z, double c) {
  std::vector<EngagementProfile> out;
  Eigen::Vector3d prev(pts[0].x(), pts[0].y(), z);
  for (size_t s = 1; s < pts.size(); ++s) {
    const Eigen::Vector2d d = pts[s] - pts[s - 1];
    const int n = static_cast<int>(std::ceil(d.norm() / 0.05));
    for (int k = 1; k <= n; ++k) {
      const Eigen::Vector2d q = pts[s - 1] + d * (static_cast<double>(k) / n);
      const Eigen::Vector3d tip(q.x(), q.y(), z);
      out.push_back(engagement_from_stock(stock, tip, d, 3.0, 20.0, 360, c));
      remove_flat_envelope(stock, prev, tip, 3.0);
      prev = tip;
    }
  }
  return out;
}

TEST(Engagement, StraightWallCutIsTheDownMillingArc) {
  const double ae = 1.0;
  ZMap stock(-5, -8, 0.01, 3000, 1300, 0.0);
  stock.fill([&](double, double y) { return y < -(3.0 - ae) ? 0.0 : -10.0; });
  const auto prof = run(stock, {{0, 0}, {20, 0}}, -4.0, 0.02);
  const EngagementProfile& p = prof[prof.size() / 2];
  const Engagement geo = Engagement::down_milling(6.0, ae, 4.0, 0.02);
  EXPECT_NEAR(p.arc_start(), geo.phi_start, 1.5 * kPi / 180);
  EXPECT_NEAR(p.arc_exit(), kPi, 1e-9);
  EXPECT_NEAR(p.max_depth(), 4.0, 1e-6);
  // The force from the profile against the arc model at a few rotation angles.
  const CuttingForceModel m(load_tool(kConfig + "tools/hss_flat_4f_d6.yaml"),
                            load_material(kConfig + "materials/al_paper004.yaml"), ForceModel::kChipThicknessLaw, 200);
  double worst = 0, peak = 0;
  for (int j = 0; j < 90; ++j) {
    const double theta = j * kPi / 180;
    const Eigen::Vector3d a = force_from_profile(m, p, 0.02, theta);
    const Eigen::Vector3d b = m.force(geo, theta);
    worst = std::max(worst, (a - b).norm());
    peak = std::max(peak, b.norm());
  }
  EXPECT_LT(worst, 0.05 * peak) << "peak " << peak;
}

TEST(Engagement, SlotIsTheWholeFrontHalf) {
  ZMap stock(-5, -5, 0.02, 1500, 500, 0.0);
  const auto prof = run(stock, {{0, 0}, {20, 0}}, -2.0, 0.02);
  const EngagementProfile& p = prof[prof.size() / 2];
  EXPECT_NEAR(p.arc_start(), 0.0, 1e-9);
  EXPECT_NEAR(p.arc_exit(), kPi, 1e-9);
  for (double d : p.depth) EXPECT_NEAR(d, 2.0, 1e-6);
}

TEST(Engagement, PocketCornerEngagementGrowsThenFalls) {
  // A wall on the right along X (finishing allowance 0.5 mm), the next wall ahead
  // along Y; the tool runs to the corner and turns left, keeping the walls on its right.
  const double ae = 0.5;
  ZMap stock(-5, -8, 0.01, 3200, 3200, -10.0);
  stock.fill([&](double x, double y) { return (y < -(3.0 - ae) || x > 20.0 + (3.0 - ae)) ? 0.0 : -10.0; });
  const auto prof = run(stock, {{0, 0}, {20, 0}, {20, 20}}, -3.0, 0.02);
  const double straight = prof[200].arc_exit() - prof[200].arc_start();  // x = 10
  double at_corner = 0;
  for (size_t k = 380; k < 400; ++k) at_corner = std::max(at_corner, prof[k].arc_exit() - prof[k].arc_start());
  const double after = prof[400 + 200].arc_exit() - prof[400 + 200].arc_start();  // y = 10 on the second wall
  const double geo = std::acos(1.0 - ae / 3.0);
  EXPECT_NEAR(straight, geo, 1.5 * kPi / 180);
  EXPECT_GT(at_corner, 2.5 * straight);  // the second wall's allowance comes into the front of the tool
  EXPECT_NEAR(after, geo, 1.5 * kPi / 180);
}

}  // namespace
}  // namespace cnc::process
