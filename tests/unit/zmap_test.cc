// Choi et al. 2005's check: the Z-map of a ball end mill's rotating edges against the
// extended roughness model (roughness.h) on the digest's cases (r = 5 mm,
// f_p = 0.5 mm, two flutes), the cusp-only limit, and threads.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "common/process/roughness.h"
#include "common/process/zmap.h"

namespace cnc::process {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kUm = 1e-3;

InclinedPlaneCase paper_case(double alpha_deg, double f_t) {
  InclinedPlaneCase c;
  c.alpha_rad = alpha_deg * kPi / 180;
  c.feed_per_tooth_mm = f_t;
  c.pitch_mm = 0.0025;
  c.window_x_mm = 1.0;
  c.window_y_mm = 1.0;
  return c;
}

double diff_um(double alpha_deg, double f_t, double* zmap_um = nullptr) {
  const InclinedPlaneResult r = simulate_inclined_plane(paper_case(alpha_deg, f_t));
  if (zmap_um) *zmap_um = r.rmax_mm / kUm;
  return (r.rmax_mm - rmax_extended(5.0, f_t, 0.5, alpha_deg * kPi / 180)) / kUm;
}

// The paper's own Z-map figures: Fig. 4 (α = 10°, f_t = f_p: 10.7 µm) and Fig. 5
// (α = 0°, f_t = f_p: 24.9 µm).
TEST(ZMap, ReproducesThePapersZMapFigures) {
  double z = 0;
  EXPECT_LT(std::abs(diff_um(10.0, 0.5, &z)), 1.8);
  EXPECT_NEAR(z, 10.7, 0.5);
  EXPECT_LT(std::abs(diff_um(0.0, 0.5, &z)), 1.8);
  EXPECT_NEAR(z, 24.9, 0.3);
}

TEST(ZMap, FeedLawCasesAgreeWithTheModel) {
  // The digest's feed-law rows at α = 0: 65.3 % of f_p holds 10.67 µm; 0.319 mm gives 10.2 µm.
  EXPECT_LT(std::abs(diff_um(0.0, 0.653 * 0.5)), 1.8);
  EXPECT_LT(std::abs(diff_um(0.0, 0.319)), 1.8);
}

// The deviation from the nominal plane at (px, py), found independently of the Z-map's
// rasteriser: along each pass of simulate_inclined_plane's set-up (same start, speed and
// spindle phase), the moments an edge's plane passes over the point are found by sign
// changes on a 0.1 µm path step (~0.04° of rotation) and the edge's height there taken.
double true_deviation_um(const InclinedPlaneCase& c, double px, double py) {
  const double r = c.radius_mm, sa = std::sin(c.alpha_rad), ca = std::cos(c.alpha_rad);
  const double margin = r + 2 * c.feed_per_tooth_mm;
  const double s0 = (-margin + r * sa) / ca;
  const double omega_per_mm = 2 * kPi / (c.flutes * c.feed_per_tooth_mm);  // rotation per mm of path
  double best = 1e9;
  for (int q = -2; q <= 4; ++q) {
    const double yq = q * c.pick_feed_mm;
    if (std::abs(py - yq) >= r) continue;
    const double sa0 = (px - r) / ca + r * sa / ca, sa1 = (px + r) / ca + r * sa / ca;
    const double ds = 1e-4;
    double prev[8] = {};
    for (int n = 0; sa0 + n * ds <= sa1; ++n) {
      const double s = sa0 + n * ds;
      const double cx = s * ca - r * sa, cz = s * sa + r * ca;
      const double dx = px - cx, dy = py - yq, rho = std::hypot(dx, dy);
      const double theta = -omega_per_mm * (s - s0);
      for (int k = 0; k < c.flutes; ++k) {
        const double g = std::remainder(std::atan2(dy, dx) - theta - 2 * kPi * k / c.flutes, 2 * kPi);
        if (n > 0 && ((prev[k] <= 0 && g > 0) || (prev[k] >= 0 && g < 0)) && std::abs(g - prev[k]) < 1.0 && rho < r) {
          const double z = cz - std::sqrt(r * r - rho * rho);  // within 0.1 µm of path: error < 1e-5 µm here
          best = std::min(best, -px * sa + z * ca);
        }
        prev[k] = g;
      }
    }
  }
  return best / kUm;
}

// Where the model is furthest below the Z-map: within about 1.3° below the critical angle
// α_c, where eq. 3 (the tip's remains, highest on the path's centre line) hands over to
// eq. 2 (cusp and feed marks). The Z-map's highest point there is a feed-mark ridge
// 0.14 mm beside the path's centre line, which neither equation describes. At α just
// below α_c (f_t = f_p) the Z-map is 2.4 µm above the model, more than the paper's
// largest 1.8 µm, and this is the true surface, not a fault of the simulation:
//  * an independent computation of the edges' passage over the highest cell agrees;
//  * a finer grid finds a higher peak, not a lower one (the ridge is sharp), and the
//    edge's rotation step does not matter (the crossing is interpolated exactly);
//  * any other spindle phase between passes gives more (up to 3.8 µm at 90°).
// The paper's figure is therefore not asserted here; the measured value is, with its
// convergence (cnc-predict-bench zmap-converge prints the full tables).
TEST(ZMap, NearTheCriticalAngleTheModelIsBelowTheTrueSurface) {
  InclinedPlaneCase c = paper_case(4.34, 0.5);  // α_c = 4.344°: region I, model 10.695 µm
  ZMap m(0, 0, 1, 1, 1, 0);
  const double model_um = rmax_extended(5.0, 0.5, 0.5, c.alpha_rad) / kUm;
  const double zmap_um = simulate_inclined_plane(c, &m).rmax_mm / kUm;
  EXPECT_NEAR(zmap_um - model_um, 2.385, 0.02);
  // The highest column, recomputed independently; the lowest column is on a path's centre line at 0.
  const double sa = std::sin(c.alpha_rad), ca = std::cos(c.alpha_rad);
  int bi = 0, bj = 0;
  double hi = -1e9, lo = 1e9;
  for (int j = 0; j < m.ny(); ++j) {
    for (int i = 0; i < m.nx(); ++i) {
      const double d = (-m.x(i) * sa + m.z(i, j) * ca) / kUm;
      lo = std::min(lo, d);
      if (d > hi) hi = d, bi = i, bj = j;
    }
  }
  EXPECT_NEAR(lo, 0.0, 0.01);
  const double dist_to_path = std::abs(std::remainder(m.y(bj), c.pick_feed_mm));
  EXPECT_GT(dist_to_path, 0.1);   // not on the centre line (eq. 3's protrusion)
  EXPECT_LT(dist_to_path, 0.2);   // nor on the cusp line between paths (eq. 2's)
  EXPECT_NEAR(true_deviation_um(c, m.x(bi), m.y(bj)), hi, 0.01);
  // Pitch 5 → 2.5 → 1.25 µm: 2.29, 2.39, 2.43 µm above the model (rising to its limit).
  InclinedPlaneCase coarse = c, fine = c;
  coarse.pitch_mm = 0.005;
  fine.pitch_mm = 0.00125;
  const double d5 = simulate_inclined_plane(coarse).rmax_mm / kUm - model_um;
  const double d125 = simulate_inclined_plane(fine).rmax_mm / kUm - model_um;
  EXPECT_LT(d5, zmap_um - model_um);
  EXPECT_LE(zmap_um - model_um, d125 + 1e-3);
  EXPECT_GT(d5, 1.8);
  // Nor is it the case's definition: the spindle phase from one pass to the next (the paper
  // gives none; here 0) only raises it (0°/45°/90°/135°: 2.39/2.76/3.81/2.86 µm).
  for (const double phase_deg : {45.0, 90.0, 135.0}) {
    InclinedPlaneCase k = c;
    k.pass_phase_rad = phase_deg * kPi / 180;
    EXPECT_GT(simulate_inclined_plane(k).rmax_mm / kUm - model_um, zmap_um - model_um) << phase_deg;
  }
  // Edge step 2° instead of 0.5°: the same surface.
  InclinedPlaneCase step = c;
  step.max_step_rad = 2.0 * kPi / 180;
  EXPECT_NEAR(simulate_inclined_plane(step).rmax_mm / kUm, zmap_um, 0.01);
}

// Away from that band the paper's 1.8 µm holds: over f_t = 0.55–1.0 f_p and α 0–8° at
// 0.25° steps (2.5 µm pitch, `cnc-predict zmap-check --grid-alpha-max 8
// --grid-alpha-step 0.25`), every point more than 1.25° below or 0.5° above α_c(f_t) is
// within 1.8 µm of the model (largest 1.77 µm; inside the band up to 2.51 µm, 22 of 330
// points above 1.8). A sample of that map on both sides of α_c:
TEST(ZMap, AwayFromTheCriticalAngleWithinThePapers1_8um) {
  for (const double ratio : {0.6, 0.8, 1.0}) {
    const double ft = ratio * 0.5;
    const double ac = critical_angle(5.0, ft, 0.5) * 180 / kPi;
    for (const double alpha : {0.0, ac - 1.5, ac + 1.5, 8.0, 15.0}) {
      if (alpha < 0) continue;
      InclinedPlaneCase c = paper_case(alpha, ft);
      c.pitch_mm = 0.004;
      const double d = (simulate_inclined_plane(c).rmax_mm - rmax_extended(5.0, ft, 0.5, c.alpha_rad)) / kUm;
      EXPECT_LT(std::abs(d), 1.8) << "alpha " << alpha << " f_t " << ft;
    }
  }
}

TEST(ZMap, WithoutFeedMarksOnlyTheCuspRemains) {
  // A tiny feed per tooth: the surface is the envelope, whose R_max is the cusp f_p²/(8r).
  InclinedPlaneCase c = paper_case(0.0, 0.02);
  c.max_step_rad = 2.0 * kPi / 180;
  const double r = simulate_inclined_plane(c).rmax_mm;
  EXPECT_NEAR(r / kUm, 0.25 / 40 / kUm, 0.2);
}

TEST(ZMap, TwoThreadsGiveTheSameMap) {
  InclinedPlaneCase c = paper_case(3.0, 0.45);
  c.pitch_mm = 0.004;
  ZMap one(0, 0, 1, 1, 1, 0), two(0, 0, 1, 1, 1, 0);
  simulate_inclined_plane(c, &one);
  c.threads = 2;
  simulate_inclined_plane(c, &two);
  ASSERT_EQ(one.data().size(), two.data().size());
  EXPECT_TRUE(one.data() == two.data());
}

TEST(ZMap, SingleEdgeCutIsTheBallBelowItsCentre) {
  // A plunge-free pass at constant z over a flat stock with many revolutions per
  // mm: along the path's centre line the columns end at the tip height.
  ZMap m(-0.5, -0.5, 0.01, 100, 100, 1.0);
  const BallCutter tool{2.0, 2};
  ZMapCutOptions opt;
  opt.spindle_rpm = 60000;  // 1000 rev/s
  const std::vector<ToolSample> path{{0.0, {-3.0, 0.0, 2.5}}, {0.6, {3.0, 0.0, 2.5}}};  // 10 mm/s: 10 µm/rev
  m.cut(tool, path, opt);
  for (int i = 0; i < m.nx(); ++i) EXPECT_NEAR(m.z(i, 50), 2.5 - std::sqrt(4.0 - 0.005 * 0.005), 2e-4);
  // 0.3 mm off the centre line the ball is higher by r − sqrt(r² − y²).
  const int j = 80;  // y = 0.305
  EXPECT_NEAR(m.z(50, j), 2.5 - std::sqrt(4.0 - m.y(j) * m.y(j)), 2e-4);
}

TEST(ZMap, RmaxMapBlocks) {
  InclinedPlaneCase c = paper_case(10.0, 0.5);
  c.pitch_mm = 0.005;
  ZMap m(0, 0, 1, 1, 1, 0);
  const double global = simulate_inclined_plane(c, &m).rmax_mm;
  const double sa = std::sin(c.alpha_rad), ca = std::cos(c.alpha_rad);
  const RmaxMap map = zmap_rmax_map(m, [&](double x, double, double z) { return -x * sa + z * ca; }, 50, 50);
  ASSERT_EQ(map.nbx, 4);
  ASSERT_EQ(map.nby, 4);
  double mx = 0;
  for (double v : map.rmax) mx = std::max(mx, v);
  EXPECT_LE(mx, global + 1e-12);
  EXPECT_GT(mx, 0.8 * global);  // 0.25 mm blocks hold most of a pass's pattern
}

}  // namespace
}  // namespace cnc::process
