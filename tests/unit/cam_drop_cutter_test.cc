// Drop-cutter (Hwang) against an independent reference: for each triangle, the
// concave function p.z − h(rho(p)) maximised over the triangle ∩ {rho <= R} by nested
// golden-section searches on the triangle's own parameters (u, v) — no facet, edge or
// vertex cases, no closed forms. Every contact type, every cutter shape, within 1e-9 mm.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <random>
#include <vector>

#include "common/cam/drop_cutter.h"
#include "common/cam/terrain.h"

namespace cnc::cam {
namespace {

constexpr double kTol = 1e-9;
constexpr double kNone = -std::numeric_limits<double>::infinity();

// Golden-section maximum of a concave f on [lo, hi] (endpoints included).
template <class F>
double golden_max(F&& f, double lo, double hi) {
  const double g = 0.5 * (std::sqrt(5.0) - 1);
  double a = lo, b = hi;
  double x1 = b - g * (b - a), x2 = a + g * (b - a);
  double f1 = f(x1), f2 = f(x2);
  for (int i = 0; i < 200 && b - a > 1e-15 * (1 + std::abs(a) + std::abs(b)); ++i) {
    if (f1 < f2) {
      a = x1, x1 = x2, f1 = f2, x2 = a + g * (b - a), f2 = f(x2);
    } else {
      b = x2, x2 = x1, f2 = f1, x1 = b - g * (b - a), f1 = f(x1);
    }
  }
  return std::max({f1, f2, f(lo), f(hi), f(a), f(b)});
}

// The reference drop height of one triangle (kNone if no point is within R).
double reference_triangle(const Cutter& c, double x, double y, const Triangle& t) {
  const double R = c.radius(), R2 = R * R;
  const Vec3 o = t.v[0];
  const Vec3 e1{t.v[1].x - o.x, t.v[1].y - o.y, t.v[1].z - o.z};
  const Vec3 e2{t.v[2].x - o.x, t.v[2].y - o.y, t.v[2].z - o.z};
  auto rho2 = [&](double u, double v) {
    const double px = o.x + u * e1.x + v * e2.x - x, py = o.y + u * e1.y + v * e2.y - y;
    return px * px + py * py;
  };
  auto f = [&](double u, double v) {
    const double rho = std::min(R, std::sqrt(rho2(u, v)));  // rounding just outside: the rim's height
    return o.z + u * e1.z + v * e2.z - c.height_at(rho);
  };
  // The v-interval of the slice at u: [0, 1 − u] ∩ {rho² <= R²} (a quadratic in v).
  auto slice = [&](double u, double& vlo, double& vhi) {
    const double ax = o.x + u * e1.x - x, ay = o.y + u * e1.y - y;
    const double bb = e2.x * e2.x + e2.y * e2.y, ab = ax * e2.x + ay * e2.y, aa = ax * ax + ay * ay;
    vlo = 0, vhi = 1 - u;
    if (bb == 0) {
      if (aa > R2) vlo = 1, vhi = 0;
      return aa <= R2;
    }
    const double disc = ab * ab - bb * (aa - R2);
    if (disc < 0) {
      vlo = 1, vhi = 0;  // empty, and not by rounding
      return false;
    }
    const double sq = std::sqrt(disc);
    vlo = std::max(vlo, (-ab - sq) / bb);
    vhi = std::min(vhi, (-ab + sq) / bb);
    return vlo <= vhi;
  };
  // Closest approach per slice (convex in u): find a u inside, then the interval's ends by bisection.
  auto gap = [&](double u) {
    double vlo, vhi;
    slice(u, vlo, vhi);
    const double bb = e2.x * e2.x + e2.y * e2.y;
    const double ax = o.x + u * e1.x - x, ay = o.y + u * e1.y - y;
    double v = bb > 0 ? -(ax * e2.x + ay * e2.y) / bb : 0;
    v = std::clamp(v, 0.0, 1 - u);
    return rho2(u, v);
  };
  // The u of the closest approach (golden section for the minimum of the convex gap).
  double a = 0, b = 1;
  {
    const double g = 0.5 * (std::sqrt(5.0) - 1);
    double x1 = b - g * (b - a), x2 = a + g * (b - a);
    double f1 = gap(x1), f2 = gap(x2);
    for (int i = 0; i < 200 && b - a > 1e-16; ++i) {
      if (f1 > f2) {
        a = x1, x1 = x2, f1 = f2, x2 = a + g * (b - a), f2 = gap(x2);
      } else {
        b = x2, x2 = x1, f2 = f1, x1 = b - g * (b - a), f1 = gap(x1);
      }
    }
  }
  double um = 0.5 * (a + b);
  for (double cand : {0.0, 1.0})
    if (gap(cand) < gap(um)) um = cand;
  if (gap(um) > R2) return kNone;
  auto inside = [&](double u) { return gap(u) <= R2; };
  double lo = 0, hi = um;  // lowest u inside
  if (!inside(0))
    for (int i = 0; i < 200; ++i) {
      const double mid = 0.5 * (lo + hi);
      if (mid == lo || mid == hi) break;
      (inside(mid) ? hi : lo) = mid;
    }
  else
    hi = 0;
  const double ulo = hi;
  lo = um, hi = 1;  // highest u inside
  if (!inside(1))
    for (int i = 0; i < 200; ++i) {
      const double mid = 0.5 * (lo + hi);
      if (mid == lo || mid == hi) break;
      (inside(mid) ? lo : hi) = mid;
    }
  else
    lo = 1;
  const double uhi = lo;
  auto F = [&](double u) {
    double vlo, vhi;
    if (!slice(u, vlo, vhi)) {
      if (vlo > vhi + 1e-12) return kNone;
      vhi = vlo = 0.5 * (vlo + vhi);
    }
    return golden_max([&](double v) { return f(u, v); }, vlo, vhi);
  };
  return golden_max(F, ulo, uhi);
}

double reference_drop(const Cutter& c, const Mesh& m, double x, double y) {
  double best = kNone;
  for (const Triangle& t : m.triangles) best = std::max(best, reference_triangle(c, x, y, t));
  return best;
}

// Random triangles of all orientations (steep and vertical ones too) in [0, 10]² × [0, 5],
// their sides up to about 2·size.
Mesh random_soup(std::mt19937_64& rng, int n, double size = 2.5) {
  std::uniform_real_distribution<double> pos(0, 10), hz(0, 5), off(-size, size);
  Mesh m;
  while (static_cast<int>(m.triangles.size()) < n) {
    const Vec3 a{pos(rng), pos(rng), hz(rng)};
    Triangle t{{a, Vec3{a.x + off(rng), a.y + off(rng), a.z + off(rng)}, Vec3{a.x + off(rng), a.y + off(rng), a.z + off(rng)}}};
    if (m.triangles.size() % 7 == 3) t.v[2] = {t.v[1].x, t.v[1].y, t.v[1].z + 2};  // a vertical one
    else if (m.triangles.size() % 5 == 1) t.v[1].z = t.v[2].z = a.z;             // a horizontal one
    if (!is_zero_area(t)) m.triangles.push_back(t);
  }
  return m;
}

const std::vector<Cutter>& cutters() {
  static const std::vector<Cutter> c = {parse_cutter("ball:2"), parse_cutter("flat:6"), parse_cutter("bull:6:1"),
                                        parse_cutter("ball:5"), parse_cutter("flat:1.5"), parse_cutter("bull:4:1.5"),
                                        parse_cutter("bull:3:0.2")};
  return c;
}

std::string name(const Cutter& c) {
  return "D" + std::to_string(c.diameter_mm) + " r" + std::to_string(c.corner_radius_mm);
}

TEST(CamDropCutter, EveryContactTypeOfEveryCutterMatchesTheReferenceOnRandomMeshes) {
  std::mt19937_64 rng(20261124);
  std::uniform_real_distribution<double> pt(-1, 11);
  for (const Cutter& c : cutters()) {
    std::map<Contact, int> count;
    std::map<Contact, double> worst;
    for (int mesh_no = 0; mesh_no < 4; ++mesh_no) {
      const Mesh m = random_soup(rng, 12, 1 + 2 * c.radius());
      const DropCutter dc(m, c);
      for (int i = 0; i < 60; ++i) {
        const double x = pt(rng), y = pt(rng);
        const ClPoint got = dc.drop(x, y);
        const double want = reference_drop(c, m, x, y);
        ASSERT_EQ(got.touched(), want != kNone) << name(c) << " at " << x << "," << y;
        if (!got.touched()) continue;
        ++count[got.contact];
        worst[got.contact] = std::max(worst[got.contact], std::abs(got.z - want));
        ASSERT_NEAR(got.z, want, kTol) << name(c) << " at " << x << "," << y << " contact "
                                       << contact_name(got.contact);
      }
    }
    for (Contact k : {Contact::kFacet, Contact::kVertex, Contact::kEdge})
      EXPECT_GE(count[k], 5) << name(c) << ": too few " << contact_name(k) << " contacts to say anything";
    std::printf("%s: facet %d (max |dz| %.2g), vertex %d (%.2g), edge %d (%.2g)\n", name(c).c_str(),
                count[Contact::kFacet], worst[Contact::kFacet], count[Contact::kVertex], worst[Contact::kVertex],
                count[Contact::kEdge], worst[Contact::kEdge]);
  }
}

// Each contact query alone against the reference on single triangles: the query's
// value whenever it says it is the triangle's highest contact.
TEST(CamDropCutter, EachContactQueryAloneMatchesTheReferenceWhereItWins) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> pt(-1, 11);
  for (const Cutter& c : cutters()) {
    const CutterContacts q(c);
    std::array<int, 4> wins{};
    const Mesh m = random_soup(rng, 200, 1 + 2 * c.radius());
    for (const Triangle& t : m.triangles) {
      const PreparedTriangle p = prepare(t);
      const double cx = (t.v[0].x + t.v[1].x + t.v[2].x) / 3, cy = (t.v[0].y + t.v[1].y + t.v[2].y) / 3;
      for (int i = 0; i < 6; ++i) {
        // Points near the triangle, so most touch it.
        const double x = cx + 0.2 * (1 + c.radius()) * (pt(rng) - 5);
        const double y = cy + 0.2 * (1 + c.radius()) * (pt(rng) - 5);
        const ClPoint got = q.triangle(x, y, p);
        const double want = reference_triangle(c, x, y, t);
        ASSERT_EQ(got.touched(), want != kNone);
        if (!got.touched()) continue;
        ++wins[static_cast<std::size_t>(got.contact)];
        ASSERT_NEAR(got.z, want, kTol) << name(c) << " " << contact_name(got.contact) << " at " << x << "," << y;
        // No query may claim a height above the true one.
        EXPECT_LE(q.facet(x, y, p), want + kTol);
        for (std::size_t k = 0; k < 3; ++k) {
          EXPECT_LE(q.vertex(x, y, t.v[k]), want + kTol);
          EXPECT_LE(q.edge(x, y, t.v[k], t.v[(k + 1) % 3]), want + kTol);
        }
      }
    }
    std::printf("%s alone: facet %d, vertex %d, edge %d\n", name(c).c_str(), wins[1], wins[2], wins[3]);
    EXPECT_GE(wins[1], 20) << name(c);
    EXPECT_GE(wins[2], 20) << name(c);
    EXPECT_GE(wins[3], 20) << name(c);
  }
}

TEST(CamDropCutter, IndexAgreesWithBruteForceOnTerrainAndSoup) {
  TerrainSpec spec;
  spec.cols = 40;
  spec.rows = 30;
  spec.step_mm = 0.7;
  spec.bumps = 12;
  std::mt19937_64 rng(3);
  const Mesh terrain = make_terrain(spec);
  const Mesh soup = random_soup(rng, 300);
  std::uniform_real_distribution<double> px(-4, 32), py(-4, 25);
  for (const Mesh* m : {&terrain, &soup}) {
    for (const Cutter& c : cutters()) {
      for (double cell : {0.0, 0.3, 5.0}) {
        const DropCutter dc(*m, c, DropCutter::Options{cell});
        const BruteForceDropCutter bf(*m, c);
        std::vector<XY> pts(500);
        for (XY& p : pts) p = {px(rng), py(rng)};
        std::vector<ClPoint> out(pts.size());
        dc.drop_batch(pts, out, 2);
        for (std::size_t i = 0; i < pts.size(); ++i) {
          const ClPoint want = bf.drop(pts[i].x, pts[i].y);
          ASSERT_EQ(out[i].touched(), want.touched());
          if (want.touched()) {
            ASSERT_NEAR(out[i].z, want.z, 1e-12) << name(c);
          }
        }
      }
    }
  }
}

// Closed forms on simple shapes.
TEST(CamDropCutter, KnownHeightsOnPlanesEdgesAndVertices) {
  const double th = M_PI / 6;  // a plane rising at 30° along x: z = x tan θ
  Mesh slope;
  slope.triangles.push_back({{Vec3{-50, -50, -50 * std::tan(th)}, Vec3{50, -50, 50 * std::tan(th)},
                              Vec3{50, 50, 50 * std::tan(th)}}});
  slope.triangles.push_back({{Vec3{-50, -50, -50 * std::tan(th)}, Vec3{50, 50, 50 * std::tan(th)},
                              Vec3{-50, 50, -50 * std::tan(th)}}});
  for (const Cutter& c : cutters()) {
    const DropCutter dc(slope, c);
    const double a = c.ring_radius(), r = c.corner_radius_mm;
    const ClPoint p = dc.drop(1, 2);
    EXPECT_EQ(p.contact, Contact::kFacet);
    // Torus on a plane of slope θ: z = plane + r (1/cos θ − 1) + a tan θ.
    EXPECT_NEAR(p.z, std::tan(th) + r * (1 / std::cos(th) - 1) + a * std::tan(th), 1e-12) << name(c);
  }
  // A horizontal ridge edge along y at height 3, the cutter's axis at distance d from it.
  Mesh ridge;
  // Sides falling 10:1, so that no side facet is touched before the edge for d < 0.9 R.
  ridge.triangles.push_back({{Vec3{0, -50, 3}, Vec3{0, 50, 3}, Vec3{-1, 0, -7}}});
  ridge.triangles.push_back({{Vec3{0, -50, 3}, Vec3{1, 0, -7}, Vec3{0, 50, 3}}});
  for (const Cutter& c : cutters()) {
    const DropCutter dc(ridge, c);
    for (double d : {0.1, 0.4, 0.9 * c.radius()}) {
      const ClPoint p = dc.drop(d, 5);
      EXPECT_EQ(p.contact, d <= c.ring_radius() ? p.contact : Contact::kEdge);
      EXPECT_NEAR(p.z, 3 - c.height_at(d), 1e-12) << name(c) << " d " << d;
    }
  }
  // A spike: a vertex at the top, the cutter's axis at distance d.
  Mesh spike;
  const Vec3 top{0, 0, 5};
  for (int k = 0; k < 3; ++k) {
    const double a0 = 2 * M_PI * k / 3, a1 = 2 * M_PI * (k + 1) / 3;
    spike.triangles.push_back({{top, Vec3{20 * std::cos(a0), 20 * std::sin(a0), -50}, Vec3{20 * std::cos(a1), 20 * std::sin(a1), -50}}});
  }
  for (const Cutter& c : cutters()) {
    const DropCutter dc(spike, c);
    const double d = 0.6 * c.radius();
    const ClPoint p = dc.drop(d * std::cos(1.0), d * std::sin(1.0));
    EXPECT_EQ(p.contact, Contact::kVertex) << name(c);
    EXPECT_NEAR(p.z, 5 - c.height_at(d), 1e-12) << name(c);
  }
  // Nothing within R: no contact; the empty mesh likewise.
  EXPECT_FALSE(DropCutter(spike, parse_cutter("ball:2")).drop(30, 30).touched());
  EXPECT_FALSE(DropCutter(Mesh{}, parse_cutter("ball:2")).drop(0, 0).touched());
}

TEST(CamDropCutter, CutterSpecs) {
  const Cutter b = parse_cutter("ball:2");
  EXPECT_EQ(b.radius(), 1);
  EXPECT_EQ(b.corner_radius_mm, 1);
  EXPECT_TRUE(b.is_ball());
  EXPECT_EQ(b.flute_length_mm, 8);
  const Cutter f = parse_cutter("flat:6:L=12");
  EXPECT_TRUE(f.is_flat());
  EXPECT_EQ(f.flute_length_mm, 12);
  const Cutter u = parse_cutter("bull:6:1");
  EXPECT_EQ(u.ring_radius(), 2);
  EXPECT_NEAR(u.height_at(2.5), 1 - std::sqrt(0.75), 1e-15);
  EXPECT_EQ(u.height_at(1.5), 0);
  EXPECT_EQ(u.height_at(3), 1);
  for (const char* bad : {"ball", "ball:x", "bull:6:3", "bull:6:0", "flat:-1", "cone:3", "ball:2:1", "bull:6"})
    EXPECT_THROW(parse_cutter(bad), std::invalid_argument) << bad;
}

}  // namespace
}  // namespace cnc::cam
