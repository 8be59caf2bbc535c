// Raster passes with a fixed step, and the G-code writer: header words, modal words
// left out, coordinates within 5e-5 mm of the CL points.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <sstream>
#include <string>

#include "common/cam/gcode_writer.h"
#include "common/cam/raster.h"
#include "common/cam/terrain.h"
#include "common/geometry/polyline_fit.h"

namespace cnc::cam {
namespace {

Mesh slope_30deg() {  // z = x·tan 30° over [0, 20] × [0, 10]
  const double k = std::tan(M_PI / 6);
  Mesh m;
  m.triangles.push_back({{Vec3{0, 0, 0}, Vec3{20, 0, 20 * k}, Vec3{20, 10, 20 * k}}});
  m.triangles.push_back({{Vec3{0, 0, 0}, Vec3{20, 10, 20 * k}, Vec3{0, 10, 0}}});
  return m;
}

TEST(CamRaster, PassesCoverTheBoundsZigZagWithinPickAndStep) {
  Bounds b{{0, 0, 0}, {20, 10, 5}};
  const auto passes = raster_passes(b, RasterSpec{1.5, 0.3, 0});
  ASSERT_EQ(passes.size(), 8u);  // y = 0, 1.5, ..., 9, then 10
  EXPECT_DOUBLE_EQ(passes.front().front().y, 0);
  EXPECT_DOUBLE_EQ(passes.back().front().y, 10);
  for (std::size_t k = 0; k < passes.size(); ++k) {
    const auto& p = passes[k];
    EXPECT_DOUBLE_EQ(p.front().x, k % 2 ? 20 : 0);  // zig-zag
    EXPECT_DOUBLE_EQ(p.back().x, k % 2 ? 0 : 20);
    for (std::size_t i = 1; i < p.size(); ++i) EXPECT_LE(std::abs(p[i].x - p[i - 1].x), 0.3 + 1e-12);
    if (k > 0) {
      EXPECT_LE(std::abs(p[0].y - passes[k - 1][0].y), 1.5 + 1e-12);
    }
  }
  // At 90°, passes run along y.
  const auto turned = raster_passes(b, RasterSpec{1, 0.5, 90});
  EXPECT_NEAR(turned[0].front().x, turned[0].back().x, 1e-12);
  EXPECT_THROW(raster_passes(b, RasterSpec{0, 0.1, 0}), std::invalid_argument);
}

TEST(CamRaster, FixedStepPointsLieOnTheExactClSurface) {
  const Mesh m = slope_30deg();
  const Cutter c = parse_cutter("bull:6:1");
  const DropCutter dc(m, c);
  const RasterPath path = raster_fixed_step(dc, mesh_bounds(m), RasterSpec{2, 0.25, 0}, 2);
  ASSERT_FALSE(path.cuts.empty());
  const double th = M_PI / 6;
  std::size_t checked = 0;
  for (const auto& cut : path.cuts)
    for (const Vec3& p : cut) {
      // Where the whole torus sits over the plane: plane + r (1/cos θ − 1) + a tan θ.
      if (p.x < 4 || p.x > 16 || p.y < 4 || p.y > 6) continue;
      EXPECT_NEAR(p.z, p.x * std::tan(th) + 1 * (1 / std::cos(th) - 1) + 2 * std::tan(th), 1e-12);
      ++checked;
    }
  EXPECT_GT(checked, 40u);
}

// Hwang's step control on a smooth terrain: the measured deviation (32 CL points
// inside every segment, 3-D distance) stays within beta, with fewer points than the
// largest fixed step that does.
TEST(CamRaster, StepControlHoldsBetaWithFewerPointsThanAFixedStep) {
  TerrainSpec spec;
  spec.cols = 60;
  spec.rows = 40;
  spec.step_mm = 0.5;
  spec.bumps = 10;
  spec.height_mm = 6;
  const Mesh m = make_terrain(spec);
  for (const char* tool : {"ball:2", "bull:6:1"}) {
    const DropCutter dc(m, parse_cutter(tool));
    const double beta = 0.01;
    const RasterPath ad = raster_adaptive(dc, mesh_bounds(m), RasterSpec{4, 2, 30}, AdaptiveSpec{beta, 1e-3}, 2);
    const double dev = path_deviation(dc, ad, 32, 2);
    EXPECT_LE(dev, beta) << tool;
    std::size_t n_ad = 0;
    for (const auto& c : ad.cuts) n_ad += c.size();
    std::size_t n_fixed = 0;
    for (double step = 2; step > 1e-3; step *= 0.5) {
      const RasterPath fx = raster_fixed_step(dc, mesh_bounds(m), RasterSpec{4, step, 30}, 2);
      if (path_deviation(dc, fx, 32, 2) > beta) continue;
      for (const auto& c : fx.cuts) n_fixed += c.size();
      break;
    }
    std::printf("%s: step control %zu points (deviation %.4g mm), fixed step as accurate %zu\n", tool, n_ad, dev, n_fixed);
    EXPECT_LT(2 * n_ad, n_fixed) << tool;
  }
}

// A V-groove along y with its bottom at x = 7.3, walls rising at 35 deg (left) and
// 50 deg (right), over [0, 20] x [0, 10].
Mesh v_groove(double x0, double t1, double t2) {
  const double zl = x0 * t1, zr = (20 - x0) * t2;
  Mesh m;
  m.triangles.push_back({{Vec3{0, 0, zl}, Vec3{x0, 0, 0}, Vec3{x0, 10, 0}}});
  m.triangles.push_back({{Vec3{0, 0, zl}, Vec3{x0, 10, 0}, Vec3{0, 10, zl}}});
  m.triangles.push_back({{Vec3{x0, 0, 0}, Vec3{20, 0, zr}, Vec3{20, 10, zr}}});
  m.triangles.push_back({{Vec3{x0, 0, 0}, Vec3{20, 10, zr}, Vec3{x0, 10, 0}}});
  return m;
}

// Hwang's concave corner: a cutter in the V-groove sits where its corner arc (a
// circle of radius r whose centre is a from the axis, r above the tip; ball: a = 0,
// r = R; flat: r = 0) is r from both walls, two linear equations in the tip's x and z
// (x' = x - x0): x' sin θ1 + z cos θ1 = r (1 - cos θ1) + a sin θ1 (left wall, the arc's
// centre at x - a) and -x' sin θ2 + z cos θ2 = r (1 - cos θ2) + a sin θ2 (right wall).
// With the corner search every pass has a CL point there within 1e-6 mm in x and z
// (the search's tolerance along the pass is 1e-7 mm); with the halving alone the
// nearest CL point stays farther off, the path hangs over the crease, and it takes
// more CL points and more drops.
TEST(CamRaster, ConcaveCornerFoundByBisectionSitsTheToolInTheVGroove) {
  const double x0 = 7.3, th1 = 35 * M_PI / 180, th2 = 50 * M_PI / 180;
  const double s1 = std::sin(th1), c1 = std::cos(th1), s2 = std::sin(th2), c2 = std::cos(th2);
  const Mesh m = v_groove(x0, s1 / c1, s2 / c2);
  const double beta = 0.005;
  for (const char* tool : {"ball:4", "bull:6:1", "flat:6"}) {
    const Cutter cutter = parse_cutter(tool);
    const double r = cutter.corner_radius_mm, a = cutter.ring_radius();
    const double e1 = r * (1 - c1) + a * s1, e2 = r * (1 - c2) + a * s2;
    const double det = s1 * c2 + s2 * c1;
    const double xs = x0 + (e1 * c2 - e2 * c1) / det, zs = (s1 * e2 + s2 * e1) / det;
    const DropCutter dc(m, cutter);
    EXPECT_NEAR(dc.drop(xs, 5).z, zs, 1e-12) << tool;  // the closed form is the drop-cutter's crease
    struct Run {
      std::size_t points = 0, dropped = 0, corners = 0;
      double nearest = 0, deviation = 0, hang = 0;  // hang: the path's height over the corner
    };
    auto run = [&](bool search) {
      AdaptiveSpec ad{beta, 1e-3};
      ad.corner_search = search;
      const RasterPath p = raster_adaptive(dc, mesh_bounds(m), RasterSpec{2.5, 2, 0}, ad, 2);
      Run res;
      res.dropped = p.points_dropped;
      res.corners = p.corners;
      res.deviation = path_deviation(dc, p, 32, 2);
      std::size_t passes_checked = 0;
      for (const auto& cut : p.cuts) {
        res.points += cut.size();
        if (cut.front().y < 2 || cut.front().y > 8) continue;
        double nearest = 1e300;
        for (const Vec3& q : cut) nearest = std::min(nearest, std::max(std::abs(q.x - xs), std::abs(q.z - zs)));
        res.nearest = std::max(res.nearest, nearest);
        if (search) {
          EXPECT_LE(nearest, 1e-6) << tool << ", pass at y " << cut.front().y;
        }
        for (std::size_t i = 1; i < cut.size(); ++i) {
          const double lo = std::min(cut[i - 1].x, cut[i].x), hi = std::max(cut[i - 1].x, cut[i].x);
          if (xs < lo || xs > hi || hi == lo) continue;
          const double z = cut[i - 1].z + (cut[i].z - cut[i - 1].z) * (xs - cut[i - 1].x) / (cut[i].x - cut[i - 1].x);
          res.hang = std::max(res.hang, z - zs);
        }
        ++passes_checked;
      }
      EXPECT_EQ(passes_checked, 3u) << tool;
      EXPECT_LE(res.deviation, beta) << tool;
      return res;
    };
    const Run with = run(true), halving = run(false);
    std::printf("V-groove 35/50 deg, %s, beta 5 um, 5 passes: corner search %zu CL points (%zu drops, %zu corners, "
                "deviation %.3g mm, CL point %.2g mm from the corner, path %.2g mm over it); halving %zu CL points "
                "(%zu drops, deviation %.3g mm, nearest CL point %.3g mm from the corner, path %.3g mm over it)\n",
                tool, with.points, with.dropped, with.corners, with.deviation, with.nearest, with.hang, halving.points,
                halving.dropped, halving.deviation, halving.nearest, halving.hang);
    EXPECT_EQ(with.corners, 5u) << tool;
    EXPECT_EQ(halving.corners, 0u) << tool;
    EXPECT_GT(halving.nearest, 1e-4) << tool;
    EXPECT_LT(with.points, halving.points) << tool;
    EXPECT_LT(with.dropped, halving.dropped) << tool;
    EXPECT_LT(with.hang, 1e-6) << tool;  // the path passes through the corner
    EXPECT_GT(halving.hang, 0.1 * beta) << tool;
  }
}

TEST(CamGcode, HeaderModalWordsAndRoundTripOfCoordinates) {
  GcodeSetup s;
  s.title = "part (test)";
  s.tool_number = 3;
  s.cutter = parse_cutter("ball:2");
  s.spindle_rpm = 12000;
  s.feed_mm_per_min = 800;
  s.plunge_mm_per_min = 200;
  s.safe_z_mm = 2;
  GcodeWriter w(s);
  const std::vector<Vec3> pts = {{1, 2, -0.123456}, {1.1, 2, -0.2}, {1.2, 2, -0.2}, {1.3, 2.05, -0.19999}};
  w.cut(pts.data(), pts.size());
  const std::string g = w.finish();
  EXPECT_NE(g.find("(part  test )\n"), std::string::npos) << g;
  EXPECT_NE(g.find("G21 G17 G90 G54\nT3 M6\nS12000 M3\nG0 Z2\n"), std::string::npos) << g;
  EXPECT_NE(g.find("X1 Y2 Z2\nG1 Z-0.1235 F200\nX1.1 Z-0.2 F800\nX1.2\nX1.3 Y2.05\nG0 Z2\nM5\nM2\n%\n"),
            std::string::npos)
      << g;
  EXPECT_EQ(w.feed_moves(), 4u);  // the plunge and three cutting moves
}

// Two cuts along arcs as G6.2 NURBS: the written blocks are well formed (order 4, knots =
// control points + 4, clamped, starting on the point the tool is at, as written), and the
// curves read back from the text stay within tol + 8.7e-5 mm of every CL point.
TEST(CamGcode, NurbsCutsWithinToleranceOfTheClPoints) {
  GcodeSetup s;
  s.cutter = parse_cutter("ball:4");
  s.feed_mm_per_min = 1200;
  GcodeWriter w(s);
  const double tol = 0.002;
  std::vector<std::vector<Vec3>> cuts(2);
  for (int i = 0; i <= 400; ++i) {  // 401 and 801 points: the second is cut into several curves
    const double t = i / 400.0;
    cuts[0].push_back({40 * t, 5, -3 + 2 * std::sin(3 * t) + 0.5 * std::cos(11 * t)});
  }
  for (int i = 0; i <= 800; ++i) {
    const double t = i / 800.0;
    cuts[1].push_back({40 - 40 * t, 10 + 3 * t * t, -2 - std::cos(7 * t) + 0.3 * std::sin(150 * t)});
  }
  std::vector<Vec3> samples;
  for (const auto& c : cuts) EXPECT_LE(w.cut_nurbs(c.data(), c.size(), tol, &samples), tol);
  EXPECT_GE(w.nurbs_blocks(), 3u);
  EXPECT_LT(w.nurbs_control_points(), 1201u / 3);  // far fewer numbers than points
  const std::string g = w.finish();
  // Read the curves back from the text.
  std::istringstream in(g);
  std::string line;
  Vec3 at{};
  std::vector<std::vector<Eigen::Vector3d>> ctrl;
  std::vector<std::vector<double>> knots;
  bool in_curve = false;
  auto word = [](const std::string& l, char c, double* v) {
    const auto p = l.find(c);
    if (p == std::string::npos) return false;
    *v = std::strtod(l.c_str() + p + 1, nullptr);
    return true;
  };
  while (std::getline(in, line)) {
    if (line.rfind("G6.2 P4 ", 0) == 0) {
      in_curve = true;
      ctrl.emplace_back();
      knots.emplace_back();
      EXPECT_NE(line.find(" F1200"), std::string::npos) << line;
    } else if (in_curve && line.rfind('K', 0) != 0) {
      in_curve = false;
    }
    double x = at.x, y = at.y, z = at.z, k = 0;
    if (in_curve) {
      ASSERT_TRUE(word(line, 'K', &k)) << line;
      knots.back().push_back(k);
      if (word(line, 'X', &x) && word(line, 'Y', &y) && word(line, 'Z', &z)) {
        EXPECT_NE(line.find(" R1"), std::string::npos) << line;
        if (ctrl.back().empty()) {  // the curve starts where the tool is
          EXPECT_EQ(x, at.x);
          EXPECT_EQ(y, at.y);
          EXPECT_EQ(z, at.z);
        }
        ctrl.back().emplace_back(x, y, z);
        at = {x, y, z};
      }
      continue;
    }
    word(line, 'X', &at.x);
    word(line, 'Y', &at.y);
    word(line, 'Z', &at.z);
  }
  ASSERT_EQ(ctrl.size(), w.nurbs_blocks());
  std::vector<Eigen::Vector3d> dense;
  for (std::size_t c = 0; c < ctrl.size(); ++c) {
    ASSERT_EQ(knots[c].size(), ctrl[c].size() + 4);
    for (int k = 1; k < 4; ++k) {
      EXPECT_EQ(knots[c][k], knots[c][0]);
      EXPECT_EQ(knots[c][knots[c].size() - 1 - k], knots[c].back());
    }
    const double u0 = knots[c].front(), u1 = knots[c].back();
    for (int i = 0; i <= 20000; ++i) dense.push_back(geometry::cubic_point(knots[c], ctrl[c], u0 + (u1 - u0) * i / 20000));
  }
  // Every CL point lies within tol + 8.7e-5 mm of the curves (sampled densely enough that
  // the sampling adds under 1e-5 mm).
  double worst = 0;
  for (const auto& c : cuts)
    for (const Vec3& p : c) {
      double best = 1e9;
      for (const auto& q : dense) best = std::min(best, (q - Eigen::Vector3d(p.x, p.y, p.z)).norm());
      worst = std::max(worst, best);
    }
  std::printf("NURBS: %zu curves, %zu control points for 1202 CL points, worst CL point %.3g mm from the curves\n",
              w.nurbs_blocks(), w.nurbs_control_points(), worst);
  EXPECT_LE(worst, tol + 8.7e-5 + 1e-5);
}

}  // namespace
}  // namespace cnc::cam
