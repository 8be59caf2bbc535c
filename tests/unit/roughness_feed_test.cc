// Choi et al. 2005's roughness-controlling feed on the paper's Fig. 11 valley: the feed
// drops where the feed inclination |α| is below the critical angle α_c and holds the
// programmed feed on the slopes (Fig. 12).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "common/config/machine_config.h"
#include "common/geometry/nurbs.h"
#include "common/motion/interpolator.h"
#include "common/process/roughness.h"
#include "services/part_program_server/program_server.h"

namespace cnc::interp {
namespace {

TEST(RoughnessFeed, Fig11ValleySlowsWhereTheInclinationIsBelowTheCriticalAngle) {
  const auto cfg = config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  pps::ProgramServer server(cfg);
  const auto loaded = server.load(std::string(CNC_SOURCE_DIR) + "/config/programs/fig11_valley.ngc", 1);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  const program::Block* nb = nullptr;
  Interpolator ip(cfg);
  ip.apply_command({Command::Kind::kStart, 1.0});
  for (int64_t i = 0; i < server.num_blocks(); ++i) {
    ASSERT_TRUE(ip.apply_block(*server.block(i))) << ip.last_refusal();
    if (server.block(i)->kind == program::BlockKind::kNurbs) nb = server.block(i);
  }
  ASSERT_NE(nb, nullptr);
  std::vector<geometry::Vec3> ctrl;
  for (const auto& c : nb->nurbs.control_points) ctrl.emplace_back(c[0], c[1], c[2]);
  const geometry::NurbsCurve curve(nb->nurbs.order, nb->nurbs.knots, ctrl, nb->nurbs.weights);

  // Choi et al. 2005's numbers for this process: α_c = 4.34° at f_t = f_p, and at α = 0 the
  // feed that holds 10.67 µm is 0.653 of F = n·S·f_p = 2000 mm/min.
  const double r = 5, fp = 0.5, rmax = 10.67e-3, F = 2000;
  const double alpha_c = process::critical_angle(r, fp, fp);
  EXPECT_NEAR(alpha_c * 180 / std::numbers::pi, 4.34, 0.005);
  const process::RoughnessLaw law{r, 2, fp, rmax};
  const double f_bottom = law.feed_mm_per_min(2000, 0.0);
  EXPECT_NEAR(f_bottom / F, 0.653, 0.0005);

  double feed_at_bottom = -1, best_bottom_dx = 1e9;
  int slope_program = 0, slope_points = 0, roughness_points = 0, over_law = 0;
  for (int i = 0; i < 100000 && ip.state() != RunState::kDone; ++i) {
    const Setpoint& sp = ip.step();
    if (sp.block_index != nb->index || sp.feed_mm_per_min <= 0) continue;
    geometry::Vec3 d[2];
    curve.derivatives(sp.u, 1, d);
    const double alpha = process::feed_inclination_angle(d[1]);
    // The bottom of the valley: the tangent is horizontal at x = 35.
    if (std::fabs(sp.position_mm[0] - 35.0) < best_bottom_dx) {
      best_bottom_dx = std::fabs(sp.position_mm[0] - 35.0);
      feed_at_bottom = sp.feed_mm_per_min;
    }
    if (alpha > alpha_c + 5 * std::numbers::pi / 180) {
      ++slope_points;
      slope_program += sp.limit == Limit::kProgram && std::fabs(sp.feed_mm_per_min - F) < 1e-6 * F;
    }
    roughness_points += sp.limit == Limit::kRoughness;
    // Never faster than the law allows where this step ends (1 % for the step's extent).
    if (sp.feed_mm_per_min > law.feed_mm_per_min(2000, alpha) * 1.01 && ++over_law < 30)
      std::printf("over: x %.3f alpha %.3f deg feed %.1f law %.1f %s\n", sp.position_mm[0], alpha * 180 / std::numbers::pi,
                  sp.feed_mm_per_min, law.feed_mm_per_min(2000, alpha), to_string(sp.limit));
  }
  EXPECT_EQ(ip.state(), RunState::kDone);
  EXPECT_LT(best_bottom_dx, 0.2);
  EXPECT_LE(feed_at_bottom, f_bottom * 1.01);
  EXPECT_GE(feed_at_bottom, f_bottom * 0.95);
  EXPECT_GE(roughness_points, 3);  // mostly "lookahead": the feed tracks a limit that changes along the curve
  EXPECT_EQ(over_law, 0);
  // On the slopes the programmed feed governs at F (after the ramps).
  EXPECT_GT(slope_points, 200);
  EXPECT_GT(slope_program, slope_points * 3 / 4);
  std::printf("  fig. 11: alpha_c %.3f deg, law at the bottom %.1f mm/min (%.3f F), feed at the bottom %.1f mm/min, "
              "%d of %d slope setpoints at F\n",
              alpha_c * 180 / std::numbers::pi, f_bottom, f_bottom / F, feed_at_bottom, slope_program, slope_points);
}

}  // namespace
}  // namespace cnc::interp
