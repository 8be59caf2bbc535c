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


// The law's feed is a feed per tooth (f_t = F / (n·S)): with the spindle measured slower
// than the program's S, the law's limit falls in proportion (a spindle override, a slow
// VFD). Here f_t = f_p at F and S, so on the 45° slopes the law is F itself at S (2000.2
// mm/min) and 0.7 F at 0.7 S.
struct ValleyRun {
  std::vector<Setpoint> sps;
  double feed_at_bottom = -1;
  int slope_points = 0, slope_at_f = 0;
  double max_jerk_ratio = 0;  // per axis, finite differences of the setpoints, against the limit
};

ValleyRun run_valley(double measured_rpm, double apply_at_x, double slope_feed) {
  const auto cfg = config::load_machine_config(std::string(CNC_SOURCE_DIR) + "/config/machines/sim3.yaml");
  pps::ProgramServer server(cfg);
  const auto loaded = server.load(std::string(CNC_SOURCE_DIR) + "/config/programs/fig11_valley.ngc", 1);
  EXPECT_TRUE(loaded.ok) << loaded.error;
  Interpolator ip(cfg);
  ip.apply_command({Command::Kind::kStart, 1.0});
  int64_t nurbs = -1;
  for (int64_t i = 0; i < server.num_blocks(); ++i) {
    EXPECT_TRUE(ip.apply_block(*server.block(i))) << ip.last_refusal();
    if (server.block(i)->kind == program::BlockKind::kNurbs) nurbs = server.block(i)->index;
  }
  ValleyRun r;
  bool applied = measured_rpm < 0;
  double best_dx = 1e9;
  const double T = cfg.ipo_period_s;
  for (int i = 0; i < 100000 && ip.state() != RunState::kDone; ++i) {
    const Setpoint& sp = ip.step();
    r.sps.push_back(sp);
    if (!applied && sp.block_index == nurbs && sp.position_mm[0] >= apply_at_x) {
      Command c;
      c.kind = Command::Kind::kSpindleSpeed;
      c.value = measured_rpm;
      EXPECT_TRUE(ip.apply_command(c));
      applied = true;
    }
    if (sp.block_index != nurbs || sp.feed_mm_per_min <= 0) continue;
    if (std::fabs(sp.position_mm[0] - 35.0) < best_dx) {
      best_dx = std::fabs(sp.position_mm[0] - 35.0);
      r.feed_at_bottom = sp.feed_mm_per_min;
    }
    // The slopes beyond the bottom, |alpha| well above alpha_c, after the ramp up.
    if (sp.position_mm[0] > 47 && sp.position_mm[0] < 53) {
      ++r.slope_points;
      r.slope_at_f += std::fabs(sp.feed_mm_per_min - slope_feed) < 0.01 * slope_feed;
    }
  }
  EXPECT_EQ(ip.state(), RunState::kDone);
  EXPECT_TRUE(applied);
  for (size_t k = 3; k < r.sps.size(); ++k)
    for (int a = 0; a < 3; ++a) {
      const auto x = [&](size_t j) { return r.sps[j].position_mm[static_cast<size_t>(a)]; };
      const double jerk = std::fabs(x(k) - 3 * x(k - 1) + 3 * x(k - 2) - x(k - 3)) / (T * T * T);
      r.max_jerk_ratio = std::max(r.max_jerk_ratio, jerk / cfg.axes[static_cast<size_t>(a)].max_jerk_mm_s3);
    }
  return r;
}

TEST(RoughnessFeed, FollowsTheSpindlesMeasuredSpeed) {
  const process::RoughnessLaw law{5, 2, 0.5, 10.67e-3};
  const double f_bottom = law.feed_mm_per_min(2000, 0.0);
  const ValleyRun plain = run_valley(-1, 0, 2000);
  // The spindle at its S: nothing changes, bit for bit.
  const ValleyRun at_s = run_valley(2000, 5.0, 2000);
  ASSERT_EQ(at_s.sps.size(), plain.sps.size());
  for (size_t k = 0; k < plain.sps.size(); ++k)
    for (int a = 0; a < 3; ++a)
      ASSERT_EQ(at_s.sps[k].position_mm[static_cast<size_t>(a)], plain.sps[k].position_mm[static_cast<size_t>(a)]) << k;
  // At 70 % (an override of 0.7 once the VFD has followed), measured on the way down to
  // the valley: the law's feed at the bottom and on the slopes is 70 % of S's.
  const ValleyRun slow = run_valley(1400, 15.0, 1400);
  const double want = law.feed_mm_per_min(1400, 0.0);
  EXPECT_NEAR(want / f_bottom, 0.7, 1e-9);
  EXPECT_LE(slow.feed_at_bottom, want * 1.01);
  EXPECT_GE(slow.feed_at_bottom, want * 0.97);
  EXPECT_NEAR(law.feed_mm_per_min(1400, std::numbers::pi / 4), 1400, 1.0);
  EXPECT_GT(slow.slope_points, 50);
  EXPECT_GT(slow.slope_at_f, slow.slope_points * 3 / 4);
  EXPECT_GT(slow.sps.size(), plain.sps.size());  // the valley takes longer
  // Speeds rounded to 1/128: 1996 rpm is 2000's scale.
  const ValleyRun near_s = run_valley(1996, 15.0, 2000);
  EXPECT_EQ(near_s.sps.size(), plain.sps.size());
  // A faster spindle leaves the plan as it is (the scale is at most 1).
  const ValleyRun fast = run_valley(2400, 15.0, 2000);
  EXPECT_EQ(fast.sps.size(), plain.sps.size());
  // The drop (taken like an override's: the cap at once, the look-ahead after) within the jerk limits.
  EXPECT_LE(slow.max_jerk_ratio, 1.0);
  EXPECT_LE(plain.max_jerk_ratio, 1.0);
  std::printf("  measured 1400 of S2000: feed at the bottom %.1f mm/min (law %.1f; at S %.1f / %.1f), %d of %d slope "
              "setpoints at the law's 1400; %zu against %zu cycles; jerk %.3f / %.3f of the limit\n",
              slow.feed_at_bottom, want, plain.feed_at_bottom, f_bottom, slow.slope_at_f, slow.slope_points,
              slow.sps.size(), plain.sps.size(), slow.max_jerk_ratio, plain.max_jerk_ratio);
}

}  // namespace
}  // namespace cnc::interp
