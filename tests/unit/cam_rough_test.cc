// Shin et al.'s z-level roughing: the cusp-limited z-step's closed forms against bisection,
// against a sampled envelope of the two cutter profiles and against values worked by
// hand; slices of known meshes; the tool-offset contour against the drop-cutter; level
// counts on a frustum; rings inside the stock and outside the keep-out.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "common/cam/cusp.h"
#include "common/cam/drop_cutter.h"
#include "common/cam/rough.h"
#include "common/cam/shapes.h"
#include "common/cam/slice.h"
#include "common/cam/terrain.h"

namespace cnc::cam {
namespace {

constexpr double kDeg = M_PI / 180;

// Independent reference: the cusp as the largest normal distance between the surface
// line and the envelope of the two profiles, sampled on 200,001 heights.
double cusp_sampled(const Cutter& c, double theta, double dz) {
  const double R = c.radius(), r = c.corner_radius_mm, a = R - r;
  const double st = std::sin(theta), ct = std::cos(theta), d = dz * ct / st;
  auto profile = [&](double z) {  // outer x of the lower cutter's swept region at height z >= 0
    if (z >= r) return R;
    return a + std::sqrt(std::max(0.0, 2 * r * z - z * z));
  };
  // The line is tangent to the lower cutter: r below its corner centre (a, r) along n.
  auto line_x = [&](double z) { return a + ((z - r) * ct + r) / st; };
  // Between the two tangent points (each r(1 − cos θ) above its tip): above the upper
  // one, the cusp is the next pair's.
  double h = 0;
  const int n = 200000;
  const double t0 = r * (1 - ct);
  for (int i = 0; i <= n; ++i) {
    const double z = t0 + dz * i / n;
    double env = profile(z);
    if (z >= dz) env = std::max(env, d + profile(z - dz));  // the upper cutter from its tip up
    h = std::max(h, (line_x(z) - env) * st);
  }
  // Just under the upper tip the upper cutter is not there yet.
  if (dz >= t0) h = std::max(h, (line_x(dz) - profile(dz)) * st);
  return h;
}

TEST(CamCusp, ClosedFormsAgreeWithASampledEnvelope) {
  const Cutter cutters[] = {make_cutter(10, 0, 40), make_cutter(10, 2, 40), make_cutter(10, 4, 40),
                            make_cutter(10, 5, 40)};
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> th(2 * kDeg, 89 * kDeg), dz(0.01, 12);
  int cases[5] = {};
  for (const Cutter& c : cutters)
    for (int k = 0; k < 150; ++k) {
      const double t = th(rng), z = dz(rng);
      const Cusp cu = cusp_height(c, t, z);
      ++cases[static_cast<int>(cu.kind)];
      // The sampling's own error: the profile's slope near the tip times the height step.
      EXPECT_NEAR(cu.h, cusp_sampled(c, t, z), 2e-3) << "D10 r" << c.corner_radius_mm << " theta " << t / kDeg
                                                     << " dz " << z << " " << cusp_case_name(cu.kind);
    }
  for (int k = 0; k < 4; ++k) EXPECT_GT(cases[k], 0) << cusp_case_name(static_cast<CuspCase>(k));
}

TEST(CamCusp, ZStepClosedFormsMatchBisection) {
  const Cutter cutters[] = {make_cutter(10, 0, 40), make_cutter(10, 2, 40), make_cutter(10, 4, 40),
                            make_cutter(10, 5, 40), make_cutter(6, 1, 24)};
  int closed = 0, bisected = 0;
  for (const Cutter& c : cutters)
    for (double deg = 1; deg <= 90; deg += 1)
      for (double h : {0.005, 0.05, 0.2, 0.5, 1.0, 2.0, 5.0}) {
        bool cf = false;
        const double dz = zstep_for_cusp(c, deg * kDeg, h, 40, &cf);
        const double ref = zstep_bisect(c, deg * kDeg, h, 40);
        EXPECT_NEAR(dz, ref, 1e-9 * std::max(1.0, ref)) << "r " << c.corner_radius_mm << " deg " << deg << " h " << h;
        EXPECT_LE(cusp_height(c, deg * kDeg, dz).h, h + 1e-9);
        (cf ? closed : bisected) += 1;
      }
  EXPECT_GT(closed, 1000);  // the closed forms do most of the work
  EXPECT_GT(bisected, 10);  // the side-meets-arc case has none
}

TEST(CamCusp, CuspGrowsWithTheStep) {
  for (double r : {0.0, 1.0, 2.0, 5.0}) {
    const Cutter c = make_cutter(10, r, 40);
    for (double deg = 1; deg <= 89; deg += 4) {
      double last = 0;
      for (double dz = 0.001; dz < 20; dz += 0.01) {
        const double h = cusp_height(c, deg * kDeg, dz).h;
        EXPECT_GE(h, last - 1e-12) << "r " << r << " deg " << deg << " dz " << dz;
        last = h;
      }
    }
  }
}

TEST(CamCusp, HandCheckedValues) {
  bool cf = false;
  // Flat D10 on 60°: h = Δz cos θ, Δz = 5 / 0.5 = 10.
  EXPECT_NEAR(zstep_for_cusp(make_cutter(10, 0, 40), 60 * kDeg, 5, 40, &cf), 10, 1e-12);
  EXPECT_TRUE(cf);
  // Ball D10 on 30°, h 0.5: arc meets arc, Δz = 2 sin θ sqrt(2Rh − h²) = sqrt(4.75).
  const Cutter ball = make_cutter(10, 5, 40);
  EXPECT_NEAR(zstep_for_cusp(ball, 30 * kDeg, 0.5, 40, &cf), std::sqrt(4.75), 1e-12);
  EXPECT_TRUE(cf);
  EXPECT_EQ(cusp_height(ball, 30 * kDeg, std::sqrt(4.75)).kind, CuspCase::kArcArc);
  // Bull D10 r2 on 60°, h 5: the side meets the next floor, Δz = r + (h − r(1 − sin θ)) / cos θ
  // = 2 + (5 − 2 + √3) / 0.5 = 11.4641.
  const Cutter bull = make_cutter(10, 2, 40);
  EXPECT_NEAR(zstep_for_cusp(bull, 60 * kDeg, 5, 40, &cf), 2 + 2 * (3 + std::sqrt(3.0)), 1e-9);
  EXPECT_EQ(cusp_height(bull, 60 * kDeg, 11.4641).kind, CuspCase::kFloorSide);
  // Bull D10 r2 on 10°, h 0.5: the corner arc meets the next floor; with u = Δz − r,
  // u = −(r − h) cos θ + sin θ sqrt(r² − (r − h)²) = −1.477212 + 0.229715, Δz = 0.752503.
  const double u = -1.5 * std::cos(10 * kDeg) + std::sin(10 * kDeg) * std::sqrt(4 - 2.25);
  EXPECT_NEAR(u + 2, 0.752503, 1e-6);
  EXPECT_NEAR(zstep_for_cusp(bull, 10 * kDeg, 0.5, 40, &cf), u + 2, 1e-9);
  EXPECT_EQ(cusp_height(bull, 10 * kDeg, u + 2).kind, CuspCase::kFloorArc);
  // A vertical wall leaves no cusp once the step reaches r: the step is the cap.
  EXPECT_NEAR(cusp_height(bull, 90 * kDeg, 3).h, 0, 1e-12);
  EXPECT_EQ(zstep_for_cusp(bull, 90 * kDeg, 0.1, 40), 40);
  // Bull D10 r4 on 80°, h 0.2: the lower side meets the upper arc (no closed form).
  const Cutter bull4 = make_cutter(10, 4, 40);
  const double dz = zstep_for_cusp(bull4, 80 * kDeg, 0.2, 40, &cf);
  EXPECT_FALSE(cf);
  EXPECT_EQ(cusp_height(bull4, 80 * kDeg, dz).kind, CuspCase::kSideArc);
  EXPECT_NEAR(cusp_height(bull4, 80 * kDeg, dz).h, 0.2, 1e-9);
}

TEST(CamSlice, BoxGivesItsRectangle) {
  const Mesh box = make_box(1, 2, 0, 11, 22, 10);
  const Slice s = slice_mesh(box, 4.25);
  ASSERT_EQ(s.loops.size(), 1u);
  EXPECT_EQ(s.open_chains, 0u);
  EXPECT_NEAR(std::fabs(loop_area(s.loops[0])), 200, 1e-9);
  EXPECT_NEAR(loop_length(s.loops[0]), 60, 1e-9);
  for (const XY& p : s.loops[0]) {
    const bool on_x = std::fabs(p.x - 1) < 1e-12 || std::fabs(p.x - 11) < 1e-12;
    const bool on_y = std::fabs(p.y - 2) < 1e-12 || std::fabs(p.y - 22) < 1e-12;
    EXPECT_TRUE(on_x || on_y) << p.x << " " << p.y;
  }
  EXPECT_TRUE(slice_mesh(box, 10).loops.empty());  // the top face at 10 counts as below
}

TEST(CamSlice, FrustumGivesItsSquare) {
  const Mesh m = make_frustum(50, 10, 30);
  for (double z : {0.5, 7.3, 29.9}) {
    const Slice s = slice_mesh(m, z);
    ASSERT_EQ(s.loops.size(), 1u);
    const double side = 50 - 40 * z / 30;
    EXPECT_NEAR(std::fabs(loop_area(s.loops[0])), side * side, 1e-9 * side * side) << z;
    for (const XY& p : s.loops[0]) EXPECT_NEAR(std::max(std::fabs(p.x), std::fabs(p.y)), side / 2, 1e-12);
  }
}

TEST(CamSlice, HemisphereVerticesLieOnMeshEdgesNearTheCircle) {
  const double R = 20;
  const Mesh m = make_hemisphere(R, 16, 64);
  for (double z : {0.7, 7.3, 15.0, 19.5}) {
    const Slice s = slice_mesh(m, z);
    ASSERT_EQ(s.loops.size(), 1u) << z;
    EXPECT_EQ(s.open_chains, 0u);
    const double rho = std::sqrt(R * R - z * z);
    for (const XY& p : s.loops[0]) {
      // On an edge of the mesh: some edge whose line passes through (p, z) between its ends.
      bool on_edge = false;
      for (const Triangle& t : m.triangles)
        for (int k = 0; k < 3 && !on_edge; ++k) {
          const Vec3 &a = t.v[k], &b = t.v[(k + 1) % 3];
          if ((a.z > z) == (b.z > z)) continue;
          const double u = (z - a.z) / (b.z - a.z);
          on_edge = std::fabs(a.x + u * (b.x - a.x) - p.x) < 1e-12 && std::fabs(a.y + u * (b.y - a.y) - p.y) < 1e-12;
        }
      EXPECT_TRUE(on_edge) << p.x << " " << p.y;
      // Inside the sphere, and no deeper than the tessellation's sagitta (cells of 5.6°).
      const double r3 = std::sqrt(p.x * p.x + p.y * p.y + z * z);
      EXPECT_LE(r3, R + 1e-12);
      EXPECT_GE(r3, R * std::cos(0.07));
    }
    EXPECT_LE(std::fabs(loop_area(s.loops[0])), M_PI * rho * rho);
  }
}

TEST(CamRough, KeepOutKeepsTheToolOffTheHemisphere) {
  const Mesh m = make_hemisphere(15, 12, 48);
  for (const char* spec : {"flat:10", "bull:10:2", "ball:10", "bull:6:1"}) {
    const Cutter c = parse_cutter(spec);
    const DropCutter dc(m, c);
    const int n = 16;
    const double arc_tol = 0.002, slack = c.corner_radius_mm / n + arc_tol + 0.02;
    for (double z : {1.0, 6.5, 12.0, 14.5}) {
      const Polygons ko = keep_out(m, c, z, n, arc_tol);
      ASSERT_FALSE(ko.empty()) << spec << " z " << z;
      std::size_t checked = 0;
      for (const Loop& l : ko)
        for (std::size_t i = 0; i < l.size(); ++i) {
          const XY& p = l[i];
          const XY& q = l[(i + 1) % l.size()];
          for (const XY s : {p, XY{(p.x + q.x) / 2, (p.y + q.y) / 2}}) {
            // The tool at level z on the contour does not reach into the part (1e-4 mm: the
            // polygons' integer grid of 1e-5 mm on a slope).
            EXPECT_LE(dc.drop(s.x, s.y).z, z + 1e-4) << spec << " z " << z << " at " << s.x << "," << s.y;
            // ...and stands no farther than r/n + arc_tol from touching it: moved that much
            // (plus 0.02) towards the axis, it would cut into the part.
            const double rr = std::hypot(s.x, s.y);
            EXPECT_GT(dc.drop(s.x * (rr - slack) / rr, s.y * (rr - slack) / rr).z, z) << spec << " z " << z;
            ++checked;
          }
        }
      EXPECT_GT(checked, 50u);
    }
  }
}

TEST(CamRough, LevelsOnAFrustumCountAsTheClosedFormsSay) {
  // Faces at θ = atan(30 / 20); flat top at 30.
  const Mesh m = make_frustum(50, 10, 30);
  const double th = std::atan2(30.0, 20.0);
  const Bounds b = mesh_bounds(m);
  const SlopeProfile prof = slope_profile(m, 0.01, 0.5 * kDeg);
  // Flat D10, cusp 1: Δz = 1 / cos θ = 1.8028; 16 levels below 30, then the top.
  {
    const auto lv = choose_levels(prof, make_cutter(10, 0, 40), 1, 40, b.min.z, b.max.z, b.max.z);
    const double dz = 1 / std::cos(th);
    ASSERT_EQ(lv.size(), 17u);
    for (int k = 0; k < 16; ++k) EXPECT_NEAR(lv[k].z, (k + 1) * dz, 1e-9);
    EXPECT_EQ(lv.back().kind, LevelKind::kFlat);
    EXPECT_NEAR(lv.back().z, 30, 1e-12);
  }
  // Bull D10 r2, cusp 1: Δz = r + (h − r(1 − sin θ)) / cos θ = 3.1972; 9 levels, then the top.
  {
    const auto lv = choose_levels(prof, make_cutter(10, 2, 40), 1, 40, b.min.z, b.max.z, b.max.z);
    const double dz = 2 + (1 - 2 * (1 - std::sin(th))) / std::cos(th);
    EXPECT_NEAR(dz, 3.1972, 1e-4);
    ASSERT_EQ(lv.size(), 10u);
    for (int k = 0; k < 9; ++k) EXPECT_NEAR(lv[k].z, (k + 1) * dz, 1e-9);
    // With the stock's side at the base (no floor level), the first step is a flat
    // cutter's, 1.8028; then 8 bull steps up to 27.38, and the top.
    const auto lw = choose_levels(prof, make_cutter(10, 2, 40), 1, 40, b.min.z, b.max.z, b.max.z, true);
    ASSERT_EQ(lw.size(), 10u);
    EXPECT_NEAR(lw[0].z, 1 / std::cos(th), 1e-9);
    for (int k = 1; k < 9; ++k) EXPECT_NEAR(lw[k].z, 1 / std::cos(th) + k * dz, 1e-9);
  }
  // A pyramid has no flat top: no level at its apex.
  {
    const Mesh p = make_frustum(50, 0, 30);
    const auto lv = choose_levels(slope_profile(p, 0.01, 0.5 * kDeg), make_cutter(10, 0, 40), 1, 40, 0, 30, 30);
    const double dz = 1 / std::cos(std::atan2(30.0, 25.0));  // 1.5621
    EXPECT_EQ(lv.size(), 19u);  // ceil(30 / 1.5621) − 1
    EXPECT_NEAR(lv.back().z, 19 * dz, 1e-9);
  }
  // The largest step-down caps the step: flat D10, cusp 1 on a wall-steep part.
  {
    const Mesh box = make_box(0, 0, 0, 10, 10, 25);
    const auto lv = choose_levels(slope_profile(box, 0.01, 0.5 * kDeg), make_cutter(10, 0, 40), 1, 10, 0, 25, 25);
    ASSERT_EQ(lv.size(), 3u);  // 10, 20, and the top face at 25
    EXPECT_NEAR(lv[0].z, 10, 1e-9);
    EXPECT_NEAR(lv[1].z, 20, 1e-9);
  }
}

TEST(CamRough, PlanStaysInsideTheStockAndOffThePart) {
  const Mesh m = make_frustum(40, 10, 20);
  const Stock st = parse_stock("margin:5", mesh_bounds(m));
  RoughSpec spec;
  spec.cutter = parse_cutter("bull:8:1");
  spec.cusp_mm = 0.5;
  const RoughPlan plan = plan_roughing(m, st, spec);
  ASSERT_FALSE(plan.paths.empty());
  EXPECT_EQ(plan.levels.front().kind, LevelKind::kFloor);  // the margin leaves a floor around the base
  // The flat top at 20 is the highest level, and it faces the 5 mm of stock above the part.
  EXPECT_EQ(plan.levels.back().kind, LevelKind::kFlat);
  EXPECT_NEAR(plan.paths.front().z, 20, 1e-12);
  EXPECT_NEAR(plan.paths.front().approach_z, 26, 1e-12);
  const DropCutter dc(m, spec.cutter);
  const double R = spec.cutter.radius();
  for (std::size_t k = 1; k < plan.paths.size(); ++k) EXPECT_LT(plan.paths[k].z, plan.paths[k - 1].z);  // top-down
  for (const LevelPath& lp : plan.paths)
    for (const auto& ch : lp.chains)
      for (std::size_t i = 0; i < ch.size(); ++i) {
        const XY& p = ch[i];
        EXPECT_LE(dc.drop(p.x, p.y).z, lp.z + 1e-4) << "level " << lp.z;
        // The tool centre stays where the tool touches the stock.
        EXPECT_GE(p.x, st.xmin - R);
        EXPECT_LE(p.x, st.xmax + R);
        EXPECT_GE(p.y, st.ymin - R);
        EXPECT_LE(p.y, st.ymax + R);
        if (i > 0) {  // links within the level are short and also off the part
          const XY mid{(p.x + ch[i - 1].x) / 2, (p.y + ch[i - 1].y) / 2};
          EXPECT_LE(dc.drop(mid.x, mid.y).z, lp.z + 1e-4);
        }
      }
  // Ramps down the first ring of each chain at 3°: off the part, ending on the chain's
  // start at the level, as steep as asked.
  std::size_t ramps = 0;
  for (const LevelPath& lp : plan.paths)
    for (std::size_t c = 0; c < lp.chains.size(); ++c) {
      const std::vector<Vec3> r = ramp_into(lp.chains[c], lp.ring_end[c], lp.approach_z, lp.z, 3 * kDeg);
      if (r.empty()) continue;
      ++ramps;
      EXPECT_NEAR(r.front().z, lp.approach_z, 1e-9);
      EXPECT_EQ(r.back().z, lp.z);
      EXPECT_EQ(r.back().x, lp.chains[c].front().x);
      EXPECT_EQ(r.back().y, lp.chains[c].front().y);
      double len = 0;
      for (std::size_t i = 1; i < r.size(); ++i) {
        len += std::hypot(r[i].x - r[i - 1].x, r[i].y - r[i - 1].y);
        EXPECT_LE(dc.drop(r[i].x, r[i].y).z, r[i].z + 1e-4);
        EXPECT_LE(r[i].z, r[i - 1].z);
      }
      EXPECT_NEAR((lp.approach_z - lp.z) / len, std::tan(3 * kDeg), 1e-9);
    }
  EXPECT_GT(ramps, 3u);
  EXPECT_THROW(parse_stock("margin:x", mesh_bounds(m)), std::invalid_argument);
  EXPECT_THROW(parse_stock("cube", mesh_bounds(m)), std::invalid_argument);
}

// The whole chain on the real paths: a Z-map (0.25 mm grid) of what the rings of every
// level leave of a box stock around a frustum (faces at θ = atan 1.5, cusp 1), against the
// frustum's analytic surface. No grid point is cut below the part; on the faces, away from
// the ridges and edges, the cusp normal to the face stays under the limit and comes close
// to it (the levels are as far apart as the limit lets them be). On the convex ridges
// the keep-out rounds the corner and leaves more: measured, and bounded at 15 %.
TEST(CamRough, ZMapOfThePathsLeavesTheCuspOnTheFaces) {
  const Mesh m = make_frustum(50, 10, 30);
  const Stock st = parse_stock("box", mesh_bounds(m));
  const double tan_t = 1.5, cos_t = 1 / std::sqrt(1 + tan_t * tan_t);
  auto part_z = [&](double x, double y) { return std::min(30.0, (25 - std::max(std::fabs(x), std::fabs(y))) * tan_t); };
  for (const char* tool : {"flat:10", "bull:10:2", "ball:10"}) {
    RoughSpec spec;
    spec.cutter = parse_cutter(tool);
    spec.cusp_mm = 1;
    const RoughPlan plan = plan_roughing(m, st, spec);
    const double g = 0.25, R = spec.cutter.radius();
    const int n = static_cast<int>(std::lround(50 / g)) + 1;
    std::vector<double> top(static_cast<std::size_t>(n * n), st.zmax);
    for (const LevelPath& lp : plan.paths)
      for (const auto& ch : lp.chains)
        for (std::size_t i = 1; i < ch.size(); ++i) {
          const XY a = ch[i - 1], b = ch[i];
          const double dx = b.x - a.x, dy = b.y - a.y, l2 = dx * dx + dy * dy;
          const int i0 = std::max(0, static_cast<int>(std::floor((std::min(a.x, b.x) - R + 25) / g)));
          const int i1 = std::min(n - 1, static_cast<int>(std::ceil((std::max(a.x, b.x) + R + 25) / g)));
          const int j0 = std::max(0, static_cast<int>(std::floor((std::min(a.y, b.y) - R + 25) / g)));
          const int j1 = std::min(n - 1, static_cast<int>(std::ceil((std::max(a.y, b.y) + R + 25) / g)));
          for (int j = j0; j <= j1; ++j)
            for (int k = i0; k <= i1; ++k) {
              const double x = -25 + k * g, y = -25 + j * g;
              const double t = l2 > 0 ? std::clamp(((x - a.x) * dx + (y - a.y) * dy) / l2, 0.0, 1.0) : 0;
              const double d = std::hypot(x - a.x - t * dx, y - a.y - t * dy);
              if (d < R) {
                double& z = top[static_cast<std::size_t>(j * n + k)];
                z = std::min(z, lp.z + spec.cutter.height_at(d));
              }
            }
        }
    double gouge = 0, face = 0, ridge = 0;
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k) {
        const double x = -25 + k * g, y = -25 + j * g, zp = part_z(x, y);
        const double left = top[static_cast<std::size_t>(j * n + k)] - zp;
        gouge = std::min(gouge, left);
        if (zp >= 30 || zp <= 0) continue;
        const double normal = left * cos_t;
        const double u = std::max(std::fabs(x), std::fabs(y)), v = std::min(std::fabs(x), std::fabs(y));
        if (u - v > R && zp > 1 && zp < 29) face = std::max(face, normal);
        else ridge = std::max(ridge, normal);
      }
    std::printf("%s: %zu levels; cusp normal to the faces %.3f (faces), %.3f (ridges, edges); deepest cut below the part %.2g\n",
                tool, plan.levels.size(), face, ridge, -gouge);
    EXPECT_GE(gouge, -1e-3) << tool;
    EXPECT_LE(face, 1 + 1e-3) << tool;
    EXPECT_GE(face, 0.9) << tool;
    EXPECT_LE(ridge, 1.15) << tool;
  }
}

// An open height field with hills and dips (a terrain, 4,800 triangles): the slices are
// oriented by the facets' normals and closed by the skirt, so a dip is a hole in the
// part's section, not the section itself (read even-odd, a level just above the deepest
// dip took the dip for the part and ran the tool through the hills: 12.4 mm deep on this
// terrain, 33 mm on a larger one). Every path point and the quarter points of every move
// stay off the part (drop-cutter).
TEST(CamRough, TerrainWithDipsIsNotGouged) {
  TerrainSpec ts;
  ts.cols = 60, ts.rows = 40, ts.step_mm = 0.5, ts.bumps = 12, ts.height_mm = 8, ts.seed = 3;
  const Mesh m = make_terrain(ts);
  const Bounds b = mesh_bounds(m);
  ASSERT_LT(b.min.z, -0.5);  // the deepest point is a dip's bottom, inside the part's border
  for (const char* tool : {"flat:6", "bull:6:1"}) {
    RoughSpec spec;
    spec.cutter = parse_cutter(tool);
    spec.cusp_mm = 0.5;
    spec.threads = 2;
    const RoughPlan plan = plan_roughing(m, parse_stock("box", b), spec);
    const DropCutter dc(m, spec.cutter);
    std::size_t checked = 0;
    double worst = -1e9;
    for (const LevelPath& lp : plan.paths)
      for (const auto& ch : lp.chains)
        for (std::size_t i = 0; i < ch.size(); ++i)
          for (int f = 0; f < 4; ++f) {
            if (i == 0 && f > 0) continue;
            const XY p = f == 0 ? ch[i]
                                : XY{ch[i - 1].x + (ch[i].x - ch[i - 1].x) * f / 4, ch[i - 1].y + (ch[i].y - ch[i - 1].y) * f / 4};
            worst = std::max(worst, dc.drop(p.x, p.y).z - lp.z);
            ++checked;
          }
    std::printf("%s: %zu levels, %zu points checked, highest drop-cutter z above the level %.2g mm\n", tool,
                plan.levels.size(), checked, worst);
    EXPECT_GT(checked, 10000u);
    EXPECT_LE(worst, 1e-4) << tool;
  }
}

}  // namespace
}  // namespace cnc::cam
