// Polylines to curves for G64 P (common/geometry/polyline_fit.h): the cubic fit
// stays within the tolerance of the polyline at every point, and every vertex and
// midpoint within it of the curve (measured here independently of the fit's own bookkeeping), passes through the run's
// ends, needs far fewer control points than there are points; cutting it into
// pieces leaves the curve unchanged; the corner blend deviates from the corner by
// exactly the tolerance.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "common/geometry/polyline_fit.h"

namespace cnc::geometry {
namespace {

using V = Eigen::Vector3d;

double round3(double v) { return std::round(v * 1000.0) / 1000.0; }

// Distance from q to the curve: a dense scan of every knot span, then golden-section
// refinement around the best sample.
double distance_to_curve(const CubicFit& f, const V& q) {
  const double u0 = f.knots.front(), u1 = f.knots.back();
  const int n = 4000;
  double best_u = u0, best = 1e300;
  for (int i = 0; i <= n; ++i) {
    const double u = u0 + (u1 - u0) * i / n;
    const double d = (cubic_point(f.knots, f.ctrl, u) - q).norm();
    if (d < best) best = d, best_u = u;
  }
  double a = std::max(u0, best_u - (u1 - u0) / n), b = std::min(u1, best_u + (u1 - u0) / n);
  for (int it = 0; it < 100; ++it) {
    const double m1 = a + (b - a) * 0.381966, m2 = a + (b - a) * 0.618034;
    if ((cubic_point(f.knots, f.ctrl, m1) - q).norm() < (cubic_point(f.knots, f.ctrl, m2) - q).norm())
      b = m2;
    else
      a = m1;
  }
  return std::min(best, (cubic_point(f.knots, f.ctrl, 0.5 * (a + b)) - q).norm());
}

std::vector<V> surface_row(int n, double step, bool rounded = true) {
  std::vector<V> p;
  for (int i = 0; i <= n; ++i) {
    const double x = 10 + step * i, z = -10 + 3 * std::sin(x / 15.0);
    p.emplace_back(rounded ? round3(x) : x, 12.0, rounded ? round3(z) : z);
  }
  return p;
}

// Distance from q to the polyline.
double distance_to_polyline(const std::vector<V>& pts, const V& q) {
  double best = 1e300;
  for (size_t i = 0; i + 1 < pts.size(); ++i) {
    const V ab = pts[i + 1] - pts[i];
    const double t = std::clamp((q - pts[i]).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
    best = std::min(best, (q - pts[i] - t * ab).norm());
  }
  return best;
}

// The largest distance of the curve from the polyline, sampled span by span every
// kStep mm or closer: the distance is 1-Lipschitz along the curve, so the truth is
// below the result + *slack (half the largest step). On span [u_k, u_k+1] |C'| is at
// most the largest 3|P_i - P_i-1| / (u_i+3 - u_i) of its control points.
double curve_from_polyline(const CubicFit& f, const std::vector<V>& pts, double* slack) {
  constexpr double kStep = 2e-4;
  const std::vector<double>& U = f.knots;
  double worst = 0;
  *slack = 0;
  for (size_t k = 3; k + 4 < U.size(); ++k) {
    if (!(U[k + 1] > U[k])) continue;
    double speed = 0;
    for (size_t i = k - 2; i <= k; ++i)
      speed = std::max(speed, 3 * (f.ctrl[i] - f.ctrl[i - 1]).norm() / (U[i + 3] - U[i]));
    const int n = std::max(1, static_cast<int>(std::ceil((U[k + 1] - U[k]) * speed / kStep)));
    for (int j = 0; j <= n; ++j)
      worst = std::max(worst, distance_to_polyline(pts, cubic_point(f.knots, f.ctrl, U[k] + (U[k + 1] - U[k]) * j / n)));
    *slack = std::max(*slack, 0.5 * (U[k + 1] - U[k]) * speed / n);
  }
  return worst;
}

// Within tol both ways: every point of the curve from the polyline (sampled, with
// the sampling's slack), every vertex and midpoint from the curve.
void expect_within(const CubicFit& f, const std::vector<V>& pts, double tol) {
  ASSERT_TRUE(f.ok);
  EXPECT_EQ(f.ctrl.front(), pts.front());
  EXPECT_EQ(f.ctrl.back(), pts.back());
  double back = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    back = std::max(back, distance_to_curve(f, pts[i]));
    if (i + 1 < pts.size()) back = std::max(back, distance_to_curve(f, 0.5 * (pts[i] + pts[i + 1])));
  }
  EXPECT_LE(back, tol * (1 + 1e-6));
  double slack = 0;
  const double out = curve_from_polyline(f, pts, &slack);
  EXPECT_LE(out, tol * (1 + 1e-6));
  // The fit's own figure is an upper bound of both.
  EXPECT_LE(std::max(back, out - slack), f.max_error + 1e-9);
  EXPECT_LE(f.max_error, tol);
}

TEST(PolylineFit, ANoisyRowOfShortMovesFitsWithinTheTolerance) {
  // 200 moves of 0.3 mm over a gently curved surface, coordinates to 3 decimals.
  const std::vector<V> pts = surface_row(200, 0.3);
  const CubicFit f = fit_cubic(pts, 0.01);
  expect_within(f, pts, 0.01);
  EXPECT_LT(f.ctrl.size(), pts.size() / 4) << "the fit should compress the run";
}

TEST(PolylineFit, ATighterToleranceRefinesTheKnots) {
  const std::vector<V> pts = surface_row(200, 0.3, false);
  const CubicFit loose = fit_cubic(pts, 0.01);
  const CubicFit tight = fit_cubic(pts, 5e-5);
  expect_within(loose, pts, 0.01);
  expect_within(tight, pts, 5e-5);
  EXPECT_GT(tight.ctrl.size(), loose.ctrl.size());
}

TEST(PolylineFit, AKinkIsRoundedWithinALooseToleranceAndRefusedWithinATightOne) {
  // A 25-degree kink in the middle of a run: a C2 cubic rounds it within 10 um, but
  // cannot come within 1 um of both the corner and its segments' midpoints; the fit
  // says so (the block builder then cuts the run at its sharpest turn).
  std::vector<V> pts;
  for (int i = 0; i <= 40; ++i) pts.emplace_back(0.25 * i, 0, 0);
  const double c = std::cos(25 * M_PI / 180), s = std::sin(25 * M_PI / 180);
  for (int i = 1; i <= 40; ++i) pts.emplace_back(10 + 0.25 * i * c, 0.25 * i * s, 0.01 * i);
  expect_within(fit_cubic(pts, 0.01), pts, 0.01);
  const CubicFit tight = fit_cubic(pts, 1e-5);
  EXPECT_FALSE(tight.ok);
  EXPECT_GT(tight.max_error, 1e-5);
}

TEST(PolylineFit, RandomRunsStayWithinTolerance) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> turn(-0.15, 0.15), len(0.05, 0.5);
  int fitted = 0;
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<V> pts{V(0, 0, 0)};
    double h = 0, climb = 0;
    for (int i = 0; i < 120; ++i) {
      h += turn(rng);
      climb += 0.3 * turn(rng);
      const double l = len(rng);
      pts.push_back(pts.back() + l * V(std::cos(h), std::sin(h), 0.2 * std::sin(climb)));
      pts.back() = V(round3(pts.back()[0]), round3(pts.back()[1]), round3(pts.back()[2]));
    }
    const CubicFit f = fit_cubic(pts, 0.005);
    if (f.ok) {
      ++fitted;
      expect_within(f, pts, 0.005);
    } else {
      EXPECT_GT(f.max_error, 0.005);
    }
  }
  // Turns of up to 8.6 degrees every 0.05-0.5 mm: most are a curve within 5 um, some
  // are not (the block builder then cuts the run at its sharpest turn).
  EXPECT_GE(fitted, 16);
}

TEST(PolylineFit, CuttingIntoPiecesKeepsTheCurve) {
  const std::vector<V> pts = surface_row(600, 0.3);
  const CubicFit f = fit_cubic(pts, 0.002);
  ASSERT_TRUE(f.ok);
  const std::vector<CubicPiece> pieces = split_cubic(f.knots, f.ctrl, 7);
  ASSERT_GT(pieces.size(), 2u);
  for (size_t k = 0; k < pieces.size(); ++k) {
    const CubicPiece& p = pieces[k];
    ASSERT_EQ(p.knots.size(), p.ctrl.size() + 4);
    // Clamped, and the same curve as the whole over the piece's domain.
    for (size_t i = 0; i < 4; ++i) {
      EXPECT_EQ(p.knots[i], p.knots.front());
      EXPECT_EQ(p.knots[p.knots.size() - 1 - i], p.knots.back());
    }
    for (int i = 0; i <= 50; ++i) {
      const double u = p.knots.front() + (p.knots.back() - p.knots.front()) * i / 50;
      EXPECT_LT((cubic_point(p.knots, p.ctrl, u) - cubic_point(f.knots, f.ctrl, u)).norm(), 1e-9);
    }
    if (k > 0) {
      EXPECT_LT((p.ctrl.front() - pieces[k - 1].ctrl.back()).norm(), 1e-9);
    }
  }
  EXPECT_EQ(pieces.front().ctrl.front(), pts.front());
  EXPECT_LT((pieces.back().ctrl.back() - pts.back()).norm(), 1e-12);
}

TEST(PolylineFit, TheCornerBlendDeviatesByTheTolerance) {
  for (double deg : {2.0, 30.0, 90.0, 140.0}) {
    const V in(1, 0, 0);
    const V out(std::cos(deg * M_PI / 180), std::sin(deg * M_PI / 180), 0);
    const double d = corner_blend_leg(in, out, 0.01, 100.0);
    ASSERT_GT(d, 0);
    const V v(5, 5, 0);
    const V q[5] = {v - 2 * d * in, v - d * in, v, v + d * out, v + 2 * d * out};
    // Closest to the corner at the middle, by the tolerance.
    auto at = [&](double t) {
      const double s = 1 - t;
      return V(s * s * s * s * q[0] + 4 * s * s * s * t * q[1] + 6 * s * s * t * t * q[2] + 4 * s * t * t * t * q[3] +
               t * t * t * t * q[4]);
    };
    double nearest = 1e300;
    for (int i = 0; i <= 1000; ++i) nearest = std::min(nearest, (at(i / 1000.0) - v).norm());
    EXPECT_NEAR(nearest, 0.01, 1e-12) << deg << " degrees";
  }
  // Legs limited by the lines; no blend on a straight line or a reversal.
  EXPECT_DOUBLE_EQ(corner_blend_leg(V(1, 0, 0), V(0, 1, 0), 1.0, 0.2), 0.1);
  EXPECT_EQ(corner_blend_leg(V(1, 0, 0), V(1, 0, 0), 0.01, 1.0), 0.0);
  EXPECT_EQ(corner_blend_leg(V(1, 0, 0), V(-1, 0.01, 0).normalized(), 0.01, 1.0), 0.0);
}

}  // namespace
}  // namespace cnc::geometry
