// NURBS evaluation against an independent evaluation written here from Kim, Song & Kwon's
// own definitions (eq. 2: the Cox–de Boor recursion; eq. 1: the rational point),
// derivatives against finite differences of that evaluation, the exact circle, arc
// length, and validation messages. Randomised cases use a fixed seed.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/geometry/nurbs.h"

namespace cnc::geometry {
namespace {

using ::testing::HasSubstr;

// ---- independent evaluation (Kim, Song & Kwon, eqs. 1 and 2) -----------------------------

// N_{i,k}(u) of order k by the recursion, 0/0 taken as 0. The half-open spans of
// eq. 2 give zero everywhere at u = u_max; the usual convention closes the last
// non-empty span there, which is what `at_end` does.
double cox_de_boor(int i, int k, double u, const std::vector<double>& r, bool at_end) {
  if (k == 1) {
    if (r[i] <= u && u < r[i + 1]) return 1.0;
    return (at_end && r[i] < r[i + 1] && u == r[i + 1]) ? 1.0 : 0.0;
  }
  double sum = 0.0;
  const double d1 = r[i + k - 1] - r[i];
  const double d2 = r[i + k] - r[i + 1];
  if (d1 > 0.0) sum += (u - r[i]) / d1 * cox_de_boor(i, k - 1, u, r, at_end);
  if (d2 > 0.0) sum += (r[i + k] - u) / d2 * cox_de_boor(i + 1, k - 1, u, r, at_end);
  return sum;
}

Vec3 reference_point(const NurbsCurve& c, double u) {
  const auto& r = c.knots();
  const bool at_end = u == c.u_max();
  Vec3 num = Vec3::Zero();
  double den = 0.0;
  for (size_t i = 0; i < c.control_points().size(); ++i) {
    const double nw = cox_de_boor(static_cast<int>(i), c.order(), u, r, at_end) * c.weights()[i];
    num += nw * c.control_points()[i];
    den += nw;
  }
  return num / den;
}

// Central differences of the reference point, O(h²) each.
Vec3 fd_derivative(const NurbsCurve& c, double u, int k, double h) {
  auto p = [&](double x) { return reference_point(c, x); };
  switch (k) {
    case 1: return (p(u + h) - p(u - h)) / (2 * h);
    case 2: return (p(u + h) - 2 * p(u) + p(u - h)) / (h * h);
    default: return (p(u + 2 * h) - 2 * p(u + h) + 2 * p(u - h) - p(u - 2 * h)) / (2 * h * h * h);
  }
}

double max_ctrl_norm(const NurbsCurve& c) {
  double m = 0.0;
  for (const auto& v : c.control_points()) m = std::max(m, v.norm());
  return m;
}

// ---- fixtures -----------------------------------------------------------------------

// The full circle as a rational quadratic: 9 control points on a square, weights
// 1 and √2/2, double interior knots. Centre `centre`, radius r, in the plane spanned
// by the orthonormal e1, e2.
NurbsCurve circle(double r, const Vec3& centre = Vec3::Zero(), const Vec3& e1 = Vec3::UnitX(),
                  const Vec3& e2 = Vec3::UnitY()) {
  const double s = std::sqrt(0.5);
  const double xy[9][2] = {{1, 0}, {1, 1}, {0, 1}, {-1, 1}, {-1, 0}, {-1, -1}, {0, -1}, {1, -1}, {1, 0}};
  std::vector<Vec3> ctrl;
  std::vector<double> w;
  for (int i = 0; i < 9; ++i) {
    ctrl.push_back(centre + r * (xy[i][0] * e1 + xy[i][1] * e2));
    w.push_back(i % 2 == 0 ? 1.0 : s);
  }
  return NurbsCurve(3, {0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1}, ctrl, w);
}

// A cubic with an interior double knot and non-uniform weights.
NurbsCurve rational_cubic() {
  return NurbsCurve(4, {0, 0, 0, 0, 0.3, 0.3, 0.7, 1.6, 2, 2, 2, 2},
                    {{0, 0, 0}, {10, 5, 1}, {20, -3, 4}, {25, 12, -2}, {40, 8, 0}, {45, -6, 3}, {60, 0, 8}, {70, 10, 2}},
                    {1.0, 0.7, 2.0, 1.3, 0.5, 1.1, 0.9, 1.0});
}

NurbsCurve cubic_bspline() {
  return NurbsCurve(4, {0, 0, 0, 0, 1, 2, 3, 4, 4, 4, 4},
                    {{0, 0, 0}, {5, 10, 0}, {15, 12, 3}, {20, 0, 6}, {30, -5, 2}, {40, 5, 0}, {45, 20, 1}},
                    std::vector<double>(7, 1.0));
}

// Random valid curves: orders 2..6, control points in [-10, 10]³, weights in
// [0.3, 3], knot spans at least 0.1 of the mean span, some interior knots repeated
// up to the degree.
NurbsCurve random_curve(std::mt19937& rng) {
  std::uniform_int_distribution<int> order_d(2, 6);
  const int order = order_d(rng);
  std::uniform_int_distribution<int> extra_d(0, 8);
  const int n = order + extra_d(rng);
  std::uniform_real_distribution<double> coord(-10, 10);
  std::uniform_real_distribution<double> weight(0.3, 3.0);
  std::uniform_real_distribution<double> gap(0.1, 1.0);
  std::uniform_int_distribution<int> mult_d(1, order - 1);
  std::vector<double> knots(order, 0.0);
  double t = 0.0;
  while (static_cast<int>(knots.size()) < n) {
    t += gap(rng);
    const int m = std::min(mult_d(rng), n - static_cast<int>(knots.size()));
    for (int j = 0; j < m; ++j) knots.push_back(t);
  }
  t += gap(rng);
  for (int j = 0; j < order; ++j) knots.push_back(t);
  std::vector<Vec3> ctrl;
  std::vector<double> w;
  for (int i = 0; i < n; ++i) {
    ctrl.emplace_back(coord(rng), coord(rng), coord(rng));
    w.push_back(weight(rng));
  }
  return NurbsCurve(order, knots, ctrl, w);
}

// Checks C', C'', C''' at points well inside each span (finite differences must not
// straddle a knot, where the curve may be only C^(p-m)) against central differences
// D(h) of the reference point. The tolerance is scaled to the step: the truncation
// error of D(h/2) is estimated from |D(h) − D(h/2)|/3 (it is O(h²)), the rounding
// error as 3·k!·ε·|P|/(h/2)^k; the test allows 4× their sum. The steps, a fraction
// of the span, keep that near 1e-8, 1e-6, 1e-4 of the derivative for these curves,
// which the last check holds the tolerance to.
void expect_derivatives_match(const NurbsCurve& c, int samples_per_span) {
  const double p_scale = max_ctrl_norm(c);
  const auto bp = c.breakpoints();
  const double h_rel[4] = {0, 2e-4, 2e-3, 8e-3};
  const double max_rel_tol[4] = {0, 1e-6, 1e-4, 1e-2};
  const double factorial[4] = {1, 1, 2, 6};
  for (size_t s = 0; s + 1 < bp.size(); ++s) {
    const double a = bp[s];
    const double w = bp[s + 1] - a;
    for (int i = 0; i < samples_per_span; ++i) {
      const double u = a + w * (0.2 + 0.6 * (i + 0.5) / samples_per_span);
      Vec3 d[4];
      c.derivatives(u, 3, d);
      EXPECT_LE((d[0] - reference_point(c, u)).norm(), 1e-12 * p_scale) << "u=" << u;
      for (int k = 1; k <= 3; ++k) {
        const double h = h_rel[k] * w;
        const Vec3 coarse = fd_derivative(c, u, k, h);
        const Vec3 fine = fd_derivative(c, u, k, h / 2);
        const double rounding =
            3 * factorial[k] * std::numeric_limits<double>::epsilon() * p_scale / std::pow(h / 2, k);
        const double tol = 4 * ((coarse - fine).norm() / 3 + rounding);
        EXPECT_LE((d[k] - fine).norm(), tol)
            << "order " << c.order() << " k=" << k << " u=" << u << " impl " << d[k].transpose() << " fd "
            << fine.transpose();
        // The check has teeth: the tolerance is a small part of the derivative's scale.
        const double scale = std::max(d[k].norm(), p_scale * std::pow(c.degree() / w, k));
        EXPECT_LE(tol, max_rel_tol[k] * scale) << "order " << c.order() << " k=" << k << " u=" << u;
      }
    }
  }
}

// ---- evaluation ---------------------------------------------------------------------

TEST(NurbsPoint, MatchesCoxDeBoorAtManyParameters) {
  for (const NurbsCurve& c : {rational_cubic(), cubic_bspline(), circle(7.5, {1, 2, 3})}) {
    const double scale = max_ctrl_norm(c);
    for (int i = 0; i <= 2000; ++i) {
      const double u = c.u_min() + (c.u_max() - c.u_min()) * i / 2000.0;
      EXPECT_LE((c.point(u) - reference_point(c, u)).norm(), 1e-12 * scale) << "u=" << u;
    }
    // Exactly at every knot, where the span search matters.
    for (double u : c.knots()) EXPECT_LE((c.point(u) - reference_point(c, u)).norm(), 1e-12 * scale);
  }
}

TEST(NurbsPoint, ClampedEndsAreTheEndControlPoints) {
  std::mt19937 rng(1234);
  for (int n = 0; n < 50; ++n) {
    const NurbsCurve c = random_curve(rng);
    const double scale = max_ctrl_norm(c);
    EXPECT_LE((c.point(c.u_min()) - c.control_points().front()).norm(), 1e-13 * scale);
    EXPECT_LE((c.point(c.u_max()) - c.control_points().back()).norm(), 1e-13 * scale);
  }
}

TEST(NurbsPoint, OutsideTheDomainIsClamped) {
  const NurbsCurve c = rational_cubic();
  EXPECT_EQ(c.point(-5.0), c.point(c.u_min()));
  EXPECT_EQ(c.point(1e9), c.point(c.u_max()));
}

TEST(NurbsSpan, MatchesLinearSearchAndClosesTheLastSpan) {
  const NurbsCurve c = rational_cubic();  // knots 0 0 0 0 .3 .3 .7 1.6 2 2 2 2
  const auto& k = c.knots();
  for (int i = 0; i <= 400; ++i) {
    const double u = 2.0 * i / 400.0;
    int expect = -1;
    for (int s = c.degree(); s < static_cast<int>(c.control_points().size()); ++s) {
      if (k[s] <= u && u < k[s + 1]) expect = s;
    }
    if (u == c.u_max()) expect = static_cast<int>(c.control_points().size()) - 1;
    EXPECT_EQ(c.find_span(u), expect) << "u=" << u;
  }
  EXPECT_EQ(c.find_span(0.3), 5);  // a double knot: the span that starts there
  EXPECT_EQ(c.find_span(-1.0), 3);
  EXPECT_EQ(c.find_span(3.0), 7);
}

TEST(NurbsBreakpoints, AreTheDistinctKnotsOfTheDomain) {
  EXPECT_EQ(rational_cubic().breakpoints(), (std::vector<double>{0, 0.3, 0.7, 1.6, 2}));
  EXPECT_EQ(circle(1).breakpoints(), (std::vector<double>{0, 0.25, 0.5, 0.75, 1}));
  const NurbsCurve bezier(3, {0, 0, 0, 1, 1, 1}, {{0, 0, 0}, {1, 1, 0}, {2, 0, 0}}, {1, 1, 1});
  EXPECT_EQ(bezier.breakpoints(), (std::vector<double>{0, 1}));
}

// ---- derivatives --------------------------------------------------------------------

TEST(NurbsDerivatives, MatchFiniteDifferencesOnFixedCurves) {
  expect_derivatives_match(rational_cubic(), 7);
  expect_derivatives_match(cubic_bspline(), 7);
  expect_derivatives_match(circle(3.0, {1, -2, 0.5}), 7);
}

TEST(NurbsDerivatives, MatchFiniteDifferencesOnRandomCurves) {
  std::mt19937 rng(20240601);
  for (int n = 0; n < 150; ++n) {
    SCOPED_TRACE("random curve " + std::to_string(n));
    expect_derivatives_match(random_curve(rng), 3);
  }
}

TEST(NurbsDerivatives, ZeroAboveTheDegreeAndFirstEntryIsThePoint) {
  const NurbsCurve line(2, {0, 0, 1, 1}, {{1, 2, 3}, {4, 6, 3}}, {1, 1});
  Vec3 d[4];
  line.derivatives(0.4, 3, d);
  EXPECT_LE((d[0] - Vec3(2.2, 3.6, 3)).norm(), 1e-15);
  EXPECT_LE((d[1] - Vec3(3, 4, 0)).norm(), 1e-14);
  EXPECT_EQ(d[2], Vec3::Zero());
  EXPECT_EQ(d[3], Vec3::Zero());
  const NurbsCurve c = rational_cubic();
  c.derivatives(1.1, 0, d);
  EXPECT_EQ(d[0], c.point(1.1));
}

// ---- the circle ---------------------------------------------------------------------

TEST(NurbsCircle, RadiusAndCurvatureAreExact) {
  const Vec3 e1 = Vec3(1, 1, 0).normalized();
  const Vec3 e2 = Vec3(-1, 1, 2).normalized();
  for (double r : {1.0, 0.05, 25.0}) {
    const Vec3 centre(3, -4, 12);
    const NurbsCurve c = circle(r, centre, e1, e2);
    for (int i = 0; i <= 1000; ++i) {
      const double u = i / 1000.0;
      EXPECT_NEAR((c.point(u) - centre).norm(), r, 1e-12 * std::max(1.0, r)) << "u=" << u;
      EXPECT_NEAR(c.curvature(u) * r, 1.0, 1e-9) << "u=" << u;
    }
  }
}

TEST(NurbsCircle, QuarterArcLengthIsPiROverTwo) {
  for (double r : {1.0, 10.0}) {
    const NurbsCurve c = circle(r);
    EXPECT_NEAR(arc_length(c, 0.0, 0.25), std::numbers::pi * r / 2, 1e-9) << "r=" << r;
    EXPECT_NEAR(arc_length(c, 0.0, 1.0), 2 * std::numbers::pi * r, 1e-9) << "r=" << r;
  }
  // Inside a span: the angle of the point on the circle gives the exact length.
  const NurbsCurve c = circle(2.0);
  const Vec3 p0 = c.point(0.1);
  const Vec3 p1 = c.point(0.6);
  const double angle = std::atan2(p1.y(), p1.x()) - std::atan2(p0.y(), p0.x());
  EXPECT_NEAR(arc_length(c, 0.1, 0.6), 2.0 * (angle < 0 ? angle + 2 * std::numbers::pi : angle), 1e-9);
}

// ---- curvature ----------------------------------------------------------------------

TEST(NurbsCurvature, CubicBSplineMatchesFiniteDifferenceCurvature) {
  const NurbsCurve c = cubic_bspline();
  for (int i = 0; i < 200; ++i) {
    const double u = 4.0 * (i + 0.5) / 200.0;
    if (std::abs(u - std::round(u)) < 0.01) continue;  // C² at knots, but differences straddle them
    const Vec3 d1 = fd_derivative(c, u, 1, 1e-5);
    const Vec3 d2 = fd_derivative(c, u, 2, 1e-4);
    const double kappa = d1.cross(d2).norm() / std::pow(d1.norm(), 3);
    EXPECT_NEAR(c.curvature(u), kappa, 1e-6 * kappa) << "u=" << u;
  }
}

TEST(NurbsCurvature, StraightLineIsZeroAndCuspIsInfinite) {
  const NurbsCurve line(3, {0, 0, 0, 1, 1, 1}, {{0, 0, 0}, {1, 1, 1}, {3, 3, 3}}, {1, 2, 1});
  EXPECT_NEAR(line.curvature(0.3), 0.0, 1e-12);
  // A cubic Bezier whose hodograph passes through zero at u = 0.5: a cusp.
  const NurbsCurve cusp(4, {0, 0, 0, 0, 1, 1, 1, 1}, {{0, 0, 0}, {1, 1, 0}, {0, 1, 0}, {1, 0, 0}}, {1, 1, 1, 1});
  Vec3 d[2];
  cusp.derivatives(0.5, 1, d);
  EXPECT_EQ(d[1].norm(), 0.0);
  EXPECT_EQ(cusp.curvature(0.5), std::numeric_limits<double>::infinity());
}

// ---- arc length ---------------------------------------------------------------------

TEST(NurbsArcLength, LineIsExactAndIntervalsAdd) {
  const NurbsCurve line(2, {0, 0, 1, 1}, {{0, 0, 0}, {3, 4, 12}}, {1, 1});
  EXPECT_NEAR(arc_length(line, 0, 1), 13.0, 1e-12);
  EXPECT_NEAR(arc_length(line, 1, 0.5), -6.5, 1e-12);
  EXPECT_EQ(arc_length(line, 0.3, 0.3), 0.0);
  const NurbsCurve c = rational_cubic();
  const double whole = arc_length(c, 0, 2);
  EXPECT_NEAR(arc_length(c, 0, 0.45) + arc_length(c, 0.45, 1.3) + arc_length(c, 1.3, 2), whole, 3e-9);
  EXPECT_NEAR(arc_length(c, -1, 5), whole, 1e-12);  // clamped to the domain
}

TEST(NurbsArcLength, MatchesAFinePolylineOfTheReferenceCurve) {
  const NurbsCurve c = rational_cubic();
  // The chord polyline converges as O(1/n²); Richardson on n and 2n gives O(1/n⁴).
  auto polyline = [&](int n) {
    double len = 0.0;
    Vec3 prev = reference_point(c, 0.0);
    for (int i = 1; i <= n; ++i) {
      const Vec3 p = reference_point(c, 2.0 * i / n);
      len += (p - prev).norm();
      prev = p;
    }
    return len;
  };
  const double l1 = polyline(20000);
  const double l2 = polyline(40000);
  const double extrapolated = (4 * l2 - l1) / 3;
  EXPECT_NEAR(arc_length(c, 0, 2), extrapolated, 1e-7 * extrapolated);
}

// ---- validation ---------------------------------------------------------------------

std::string problem(int order, const std::vector<double>& knots, size_t n_ctrl, const std::vector<double>& w) {
  return NurbsCurve::validate(order, knots, n_ctrl, w);
}

TEST(NurbsValidate, AcceptsValidDefinitions) {
  EXPECT_EQ(problem(4, {0, 0, 0, 0, 1, 1, 1, 1}, 4, {1, 1, 1, 1}), "");
  EXPECT_EQ(problem(3, {0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1}, 9, std::vector<double>(9, 0.5)), "");
  EXPECT_EQ(problem(8, std::vector<double>{0, 0, 0, 0, 0, 0, 0, 0, 2, 2, 2, 2, 2, 2, 2, 2}, 8,
                    std::vector<double>(8, 1.0)),
            "");
}

TEST(NurbsValidate, NamesWhatIsWrong) {
  const std::vector<double> w4(4, 1.0);
  EXPECT_THAT(problem(1, {0, 0, 1, 1}, 3, {1, 1, 1}), HasSubstr("order 1 is outside 2..8"));
  EXPECT_THAT(problem(9, std::vector<double>(18, 0.0), 9, std::vector<double>(9, 1.0)),
              HasSubstr("order 9 is outside 2..8"));
  EXPECT_THAT(problem(4, {0, 0, 0, 0, 1, 1, 1}, 3, {1, 1, 1}), HasSubstr("need at least 4 control points"));
  EXPECT_THAT(problem(4, {0, 0, 0, 0, 1, 1, 1}, 4, w4), HasSubstr("knot vector has 7 values, expected 8"));
  EXPECT_THAT(problem(4, {0, 0, 0, 0, 1, 1, 1, 1}, 4, {1, 1, 1}), HasSubstr("weights has 3 values, expected 4"));
  EXPECT_THAT(problem(3, {0, 0, 0, 0.6, 0.4, 1, 1, 1}, 5, std::vector<double>(5, 1.0)),
              HasSubstr("knots decrease at index 4 (0.4 after 0.6)"));
  EXPECT_THAT(problem(3, {0, 0, 0.1, 0.5, 1, 1, 1}, 4, w4), HasSubstr("not clamped at the start"));
  EXPECT_THAT(problem(3, {0, 0, 0, 0.5, 0.9, 1, 1}, 4, w4), HasSubstr("not clamped at the end"));
  EXPECT_THAT(problem(3, {0, 0, 0, 0, 1, 1, 1}, 4, w4), HasSubstr("at the start has multiplicity above the order"));
  EXPECT_THAT(problem(3, {0, 0, 0, 1, 1, 1, 1}, 4, w4), HasSubstr("at the end has multiplicity above the order"));
  EXPECT_THAT(problem(3, std::vector<double>(7, 2.0), 4, w4), HasSubstr("knot domain is empty"));
  EXPECT_THAT(problem(3, {0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1}, 6, std::vector<double>(6, 1.0)),
              HasSubstr("interior knot 0.5 has multiplicity 3, more than the degree 2"));
  EXPECT_THAT(problem(4, {0, 0, 0, 0, 1, 1, 1, 1}, 4, {1, 0, 1, 1}), HasSubstr("weight 1 is not positive (0)"));
  EXPECT_THAT(problem(4, {0, 0, 0, 0, 1, 1, 1, 1}, 4, {1, 1, -2, 1}), HasSubstr("weight 2 is not positive (-2)"));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_THAT(problem(4, {0, 0, 0, 0, 1, 1, 1, 1}, 4, {1, 1, 1, nan}), HasSubstr("weight 3 is not finite (nan)"));
  EXPECT_THAT(problem(4, {0, 0, 0, 0, nan, 1, 1, 1, 1}, 5, {1, 1, 1, 1, 1}), HasSubstr("knot 4 is not finite (nan)"));
  EXPECT_THAT(problem(4, {0, 0, 0, 0, 1, 1, 1, inf}, 4, w4), HasSubstr("knot 7 is not finite (inf)"));
}

TEST(NurbsValidate, ConstructorThrowsTheMessage) {
  const std::vector<double> knots = {0, 0, 0, 0.5, 0.2, 1, 1, 1};
  const std::vector<double> w(5, 1.0);
  const std::vector<Vec3> ctrl(5, Vec3::Zero());
  try {
    NurbsCurve(3, knots, ctrl, w);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), NurbsCurve::validate(3, knots, 5, w));
  }
  std::vector<Vec3> bad = {{0, 0, 0}, {1, std::numeric_limits<double>::quiet_NaN(), 0}, {2, 0, 0}};
  EXPECT_THROW(NurbsCurve(3, {0, 0, 0, 1, 1, 1}, bad, {1, 1, 1}), std::invalid_argument);
  try {
    NurbsCurve(3, {0, 0, 0, 1, 1, 1}, bad, {1, 1, 1});
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("control point 1 is not finite"));
  }
}

}  // namespace
}  // namespace cnc::geometry
