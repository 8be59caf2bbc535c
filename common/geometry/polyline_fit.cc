#include "common/geometry/polyline_fit.h"

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <limits>

#include "common/geometry/nurbs.h"

namespace cnc::geometry {

namespace {

constexpr int kDegree = 3;
// Data points per knot span to start from: smooth through posted rounding noise;
// the refinement adds knots where the tolerance asks for them.
constexpr int kPointsPerSpan = 8;
constexpr int kMaxRounds = 30;
// Weight of the control polygon's second differences against the data's squared
// distances: regularizes spans without data and damps noise, a bias far below
// any tolerance used here (κ·h²·λ for control spacing h).
constexpr double kSmoothing = 1e-3;
constexpr double kMidWeight = 0.25;
constexpr int kMinInSpan = 1;
constexpr double kMinSpanPerTol = 8;
constexpr int kMaxSpansPerMove = 4;

// Index k of the span [U[k], U[k+1]) holding u (clamped cubic; u_max in the last span).
int span_of(const std::vector<double>& U, int n_ctrl, double u) {
  if (u >= U[static_cast<size_t>(n_ctrl)]) return n_ctrl - 1;
  if (u <= U[kDegree]) return kDegree;
  const auto it = std::upper_bound(U.begin() + kDegree, U.begin() + n_ctrl + 1, u);
  return static_cast<int>(it - U.begin()) - 1;
}

// The four non-zero cubic basis functions at u in span k (The NURBS Book, A2.2).
void basis(const std::vector<double>& U, int k, double u, double N[4]) {
  double left[4], right[4];
  N[0] = 1.0;
  for (int j = 1; j <= kDegree; ++j) {
    left[j] = u - U[static_cast<size_t>(k + 1 - j)];
    right[j] = U[static_cast<size_t>(k + j)] - u;
    double saved = 0.0;
    for (int r = 0; r < j; ++r) {
      const double den = right[r + 1] + left[j - r];
      const double t = den != 0 ? N[r] / den : 0.0;
      N[r] = saved + right[r + 1] * t;
      saved = left[j - r] * t;
    }
    N[j] = saved;
  }
}

std::vector<double> clamped_knots(const std::vector<double>& breaks) {
  std::vector<double> U;
  U.reserve(breaks.size() + 6);
  for (int i = 0; i < kDegree; ++i) U.push_back(breaks.front());
  U.insert(U.end(), breaks.begin(), breaks.end());
  for (int i = 0; i < kDegree; ++i) U.push_back(breaks.back());
  return U;
}

// Projects q onto the curve near parameter t (Newton on (C - q)·C' = 0, kept in [lo, hi]).
double project(const NurbsCurve& c, const Eigen::Vector3d& q, double t, double lo, double hi, double* dist) {
  Vec3 d[3];
  for (int it = 0; it < 4; ++it) {
    c.derivatives(t, 2, d);
    const Vec3 r = d[0] - q;
    const double f = r.dot(d[1]);
    const double fp = d[1].squaredNorm() + r.dot(d[2]);
    if (!(fp > 0)) break;
    const double next = std::clamp(t - f / fp, lo, hi);
    if (std::fabs(next - t) < 1e-13 * (1.0 + std::fabs(t))) {
      t = next;
      break;
    }
    t = next;
  }
  *dist = (c.point(t) - q).norm();
  return t;
}

// The polyline's segments, for the distance bound below.
struct Seg {
  Eigen::Vector3d a, ab;
  double ab2;
};

double seg_dist(const Eigen::Vector3d& p, const Seg& s) {
  const double t = std::clamp((p - s.a).dot(s.ab) / s.ab2, 0.0, 1.0);
  return (p - s.a - t * s.ab).norm();
}

// Subdivisions of a Bézier piece before it counts as outside: a piece within the
// tolerance by a margin δ is proven once its control polygon lies within δ of the
// curve, which halving reaches quadratically.
constexpr int kMaxBezierDepth = 14;

// An upper bound on the largest distance of the cubic Bézier piece b from the
// segments [lo, hi): d(., S) is convex for a segment S and the piece is a convex
// combination of its control points, so along the piece d(., S) stays below its
// largest value at them; the least of that over S bounds the distance to the union.
// Where the bound exceeds tol and the piece's ends (points of the curve) are within
// it, the piece is halved (de Casteljau) and each half bounded on its own.
double piece_bound(const Eigen::Vector3d b[4], const std::vector<Seg>& segs, size_t lo, size_t hi, double tol,
                   int depth) {
  double upper = std::numeric_limits<double>::infinity(), f0 = upper, f3 = upper;
  for (size_t i = lo; i < hi; ++i) {
    const double d0 = seg_dist(b[0], segs[i]), d3 = seg_dist(b[3], segs[i]);
    f0 = std::min(f0, d0);
    f3 = std::min(f3, d3);
    upper = std::min(upper, std::max({d0, d3, seg_dist(b[1], segs[i]), seg_dist(b[2], segs[i])}));
  }
  if (upper <= tol || depth == 0 || std::max(f0, f3) > tol) return upper;
  const Eigen::Vector3d b01 = 0.5 * (b[0] + b[1]), b12 = 0.5 * (b[1] + b[2]), b23 = 0.5 * (b[2] + b[3]);
  const Eigen::Vector3d b012 = 0.5 * (b01 + b12), b123 = 0.5 * (b12 + b23), mid = 0.5 * (b012 + b123);
  const Eigen::Vector3d left[4] = {b[0], b01, b012, mid}, right[4] = {mid, b123, b23, b[3]};
  const double l = piece_bound(left, segs, lo, hi, tol, depth - 1);
  if (l > tol) return l;
  return std::max(l, piece_bound(right, segs, lo, hi, tol, depth - 1));
}

// The span [u0, u1] of the cubic as a Bézier piece: a polynomial span is fixed by its
// ends' points and first derivatives (the fit's interior knots are simple: C2 there).
void span_bezier(const NurbsCurve& c, double u0, double u1, Eigen::Vector3d b[4]) {
  Vec3 d0[2], d1[2];
  c.derivatives(u0, 1, d0);
  c.derivatives(u1, 1, d1);
  const double h = (u1 - u0) / 3.0;
  b[0] = d0[0];
  b[1] = d0[0] + h * d0[1];
  b[2] = d1[0] - h * d1[1];
  b[3] = d1[0];
}

// The run as the fit sees it: vertices with their chord-length parameters, the
// segments' midpoints (checked, not fitted), and the segments for the distance bound.
struct FitData {
  const std::vector<Eigen::Vector3d>& pts;
  int np;
  std::vector<double> t, tm;
  std::vector<Eigen::Vector3d> mids;
  std::vector<Seg> segs;
};

// False where two consecutive points coincide.
bool make_fit_data(FitData& d) {
  const auto& pts = d.pts;
  const int np = d.np;
  d.t.assign(static_cast<size_t>(np), 0.0);
  for (int i = 1; i < np; ++i) {
    const double l = (pts[static_cast<size_t>(i)] - pts[static_cast<size_t>(i - 1)]).norm();
    if (!(l > 0)) return false;
    d.t[static_cast<size_t>(i)] = d.t[static_cast<size_t>(i - 1)] + l;
  }
  d.mids.resize(static_cast<size_t>(np - 1));
  d.tm.resize(static_cast<size_t>(np - 1));
  for (int i = 0; i + 1 < np; ++i) {
    d.mids[static_cast<size_t>(i)] = 0.5 * (pts[static_cast<size_t>(i)] + pts[static_cast<size_t>(i + 1)]);
    d.tm[static_cast<size_t>(i)] = 0.5 * (d.t[static_cast<size_t>(i)] + d.t[static_cast<size_t>(i + 1)]);
  }
  d.segs.resize(static_cast<size_t>(np - 1));
  for (size_t i = 0; i + 1 < pts.size(); ++i)
    d.segs[i] = {pts[i], pts[i + 1] - pts[i], (pts[i + 1] - pts[i]).squaredNorm()};
  return true;
}

// Evenly spread over the vertices, kPointsPerSpan a span; a fixed end takes a span of its own.
std::vector<double> first_breaks(const FitData& d, int fixed0, int fixed1) {
  const int np = d.np;
  std::vector<double> breaks;
  const int spans0 = std::max({1, (np - 1) / kPointsPerSpan, fixed0 + fixed1 - 3});
  for (int j = 0; j <= spans0; ++j) {
    const int i = static_cast<int>(std::lround(static_cast<double>(j) * (np - 1) / spans0));
    breaks.push_back(j == spans0 ? d.t.back() : d.t[static_cast<size_t>(i)]);
  }
  breaks.erase(std::unique(breaks.begin(), breaks.end()), breaks.end());
  return breaks;
}

// The control points on knots U: the ends (and the given tangents' points) fixed, the
// rest by least squares on the data with a smoothing term. False where it cannot solve.
bool solve_ctrl(const FitData& d, const std::vector<double>& U, const FitEnds& ends, int fixed0, int fixed1,
                std::vector<Eigen::Vector3d>& P) {
  const auto& pts = d.pts;
  const auto& t = d.t;
  const int np = d.np;
  const int nc = static_cast<int>(U.size()) - kDegree - 1;  // control points
  const int nu = nc - fixed0 - fixed1;                       // unknowns: all but the fixed ends
  P.assign(static_cast<size_t>(nc), Eigen::Vector3d::Zero());
  P.front() = pts.front();
  P.back() = pts.back();
  // Unit speed along the given tangent and no second derivative at the end: the
  // control points of the line u·t there (Greville abscissae), as C'(0) = 3(P1-P0)/u4
  // and C''(0) = 0 ask.
  if (ends.start) {
    P[1] = P[0] + (U[4] - U[3]) / 3.0 * *ends.start;
    P[2] = P[1] + (U[5] - U[3]) / 3.0 * *ends.start;
  }
  if (ends.end) {
    const size_t m = static_cast<size_t>(nc - 1);
    P[m - 1] = P[m] - (U[m + 1] - U[m]) / 3.0 * *ends.end;
    P[m - 2] = P[m - 1] - (U[m + 1] - U[m - 1]) / 3.0 * *ends.end;
  }
  if (nu <= 0) return true;
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(static_cast<size_t>(np) * 64 + static_cast<size_t>(nc) * 9);
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(nu, 3);
  auto add_row = [&](const int* idx, const double* w, int cnt, const Eigen::Vector3d& target, double weight) {
    // One squared residual weight·|Σ w_j P_idx_j - target|²: known ends move to the right-hand side.
    Eigen::Vector3d known = target;
    for (int a = 0; a < cnt; ++a)
      if (idx[a] < fixed0 || idx[a] >= nc - fixed1) known -= w[a] * P[static_cast<size_t>(idx[a])];
    for (int a = 0; a < cnt; ++a) {
      const int ia = idx[a] - fixed0;
      if (ia < 0 || ia >= nu) continue;
      rhs.row(ia) += weight * w[a] * known.transpose();
      for (int b = 0; b < cnt; ++b) {
        const int ib = idx[b] - fixed0;
        if (ib < 0 || ib >= nu) continue;
        trip.emplace_back(ia, ib, weight * w[a] * w[b]);
      }
    }
  };
  // The vertices, and the segments' midpoints with a lower weight: the run is a
  // polyline, and the curve must not swing away from it between its vertices.
  auto add_data = [&](double u, const Eigen::Vector3d& q, double weight) {
    const int k = span_of(U, nc, u);
    double N[4];
    basis(U, k, u, N);
    int idx[4];
    for (int j = 0; j < 4; ++j) idx[j] = k - kDegree + j;
    add_row(idx, N, 4, q, weight);
  };
  for (int i = 0; i < np; ++i) add_data(t[static_cast<size_t>(i)], pts[static_cast<size_t>(i)], 1.0);
  for (int i = 0; i + 1 < np; ++i) add_data(d.tm[static_cast<size_t>(i)], d.mids[static_cast<size_t>(i)], kMidWeight);
  // Quarter points too: between its data the curve must stay on the polyline.
  for (int i = 0; i + 1 < np; ++i)
    for (double f : {0.25, 0.75}) {
      const size_t k = static_cast<size_t>(i);
      add_data((1 - f) * t[k] + f * t[k + 1], (1 - f) * pts[k] + f * pts[k + 1], kMidWeight);
    }
  const double lambda = kSmoothing * static_cast<double>(np) / static_cast<double>(nc);
  for (int j = 1; j + 1 < nc; ++j) {
    const int idx[3] = {j - 1, j, j + 1};
    const double w[3] = {1.0, -2.0, 1.0};
    add_row(idx, w, 3, Eigen::Vector3d::Zero(), lambda);
  }
  Eigen::SparseMatrix<double> A(nu, nu);
  A.setFromTriplets(trip.begin(), trip.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(A);
  if (solver.info() != Eigen::Success) return false;
  const Eigen::MatrixXd X = solver.solve(rhs);
  if (solver.info() != Eigen::Success) return false;
  for (int j = 0; j < nu; ++j) P[static_cast<size_t>(j + fixed0)] = X.row(j).transpose();
  return true;
}

// The span of breaks holding u (the last span for u at the end).
size_t break_span(const std::vector<double>& breaks, double u) {
  const auto it = std::upper_bound(breaks.begin(), breaks.end(), u);
  return std::min(static_cast<size_t>(std::max<std::ptrdiff_t>(0, (it - breaks.begin()) - 1)), breaks.size() - 2);
}

// The fit's largest distance from the polyline: projections of the vertices and
// midpoints, then every point of every span by the spans' bound. Spans out of
// tolerance are marked in bad.
double fit_error(const NurbsCurve& curve, const FitData& d, const std::vector<double>& breaks, double tol,
                 std::vector<char>& bad) {
  const auto& t = d.t;
  const int np = d.np;
  double worst = 0;
  bad.assign(breaks.size(), 0);
  for (int i = 1; i + 1 < np; ++i) {
    double dist = 0;
    const double lo = t[static_cast<size_t>(i - 1)], hi = t[static_cast<size_t>(i + 1)];
    const double u = project(curve, d.pts[static_cast<size_t>(i)], t[static_cast<size_t>(i)], lo, hi, &dist);
    worst = std::max(worst, dist);
    if (dist > tol) bad[break_span(breaks, u)] = 1;
  }
  for (int i = 0; i + 1 < np; ++i) {
    double dist = 0;
    const double u = project(curve, d.mids[static_cast<size_t>(i)], d.tm[static_cast<size_t>(i)],
                             t[static_cast<size_t>(i)], t[static_cast<size_t>(i + 1)], &dist);
    worst = std::max(worst, dist);
    if (dist > tol) bad[break_span(breaks, u)] = 1;
  }
  for (size_t sp = 0; sp + 1 < breaks.size(); ++sp) {
    const double u0 = breaks[sp], u1 = breaks[sp + 1], reach = u1 - u0;
    const size_t lo = static_cast<size_t>(
        std::max<std::ptrdiff_t>(0, (std::lower_bound(t.begin(), t.end(), u0 - reach) - t.begin()) - 1));
    const size_t hi = std::min(d.segs.size(), static_cast<size_t>(std::upper_bound(t.begin(), t.end(), u1 + reach) -
                                                                    t.begin()));
    Eigen::Vector3d b[4];
    span_bezier(curve, u0, u1, b);
    const double bound = piece_bound(b, d.segs, lo, hi, tol, kMaxBezierDepth);
    worst = std::max(worst, bound);
    if (bound > tol) bad[sp] = 1;
  }
  return worst;
}

// Halves the bad spans. A span is halved while it holds a fitted point (a vertex or a
// midpoint), or while it is long against the tolerance: rounding a vertex within tol
// takes spans shorter than the moves (the smoothing term keeps an empty span tame, and
// the bound above catches it if not). False where nothing can be halved, or where the
// spans would far outnumber the moves: the run is no smooth curve at this tolerance.
bool refine_breaks(const FitData& d, const std::vector<char>& bad, double tol, std::vector<double>& breaks) {
  const auto& t = d.t;
  const int np = d.np;
  std::vector<int> inside(breaks.size(), 0);
  auto count = [&](double u) {
    const size_t sp = break_span(breaks, u);
    if (u > breaks[sp] && u < breaks[sp + 1]) ++inside[sp];
  };
  for (int i = 1; i + 1 < np; ++i) count(t[static_cast<size_t>(i)]);
  for (int i = 0; i + 1 < np; ++i) count(d.tm[static_cast<size_t>(i)]);
  std::vector<double> next;
  next.reserve(breaks.size() * 2);
  bool added = false;
  for (size_t s = 0; s + 1 < breaks.size(); ++s) {
    next.push_back(breaks[s]);
    if (bad[s] && (inside[s] >= kMinInSpan || breaks[s + 1] - breaks[s] > kMinSpanPerTol * tol)) {
      next.push_back(0.5 * (breaks[s] + breaks[s + 1]));
      added = true;
    }
  }
  next.push_back(breaks.back());
  if (!added || next.size() > static_cast<size_t>(kMaxSpansPerMove * np)) return false;
  breaks = std::move(next);
  return true;
}

}  // namespace

Eigen::Vector3d cubic_point(const std::vector<double>& knots, const std::vector<Eigen::Vector3d>& ctrl, double u) {
  const int n = static_cast<int>(ctrl.size());
  const int k = span_of(knots, n, u);
  double N[4];
  basis(knots, k, u, N);
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int j = 0; j < 4; ++j) p += N[j] * ctrl[static_cast<size_t>(k - kDegree + j)];
  return p;
}

CubicFit fit_cubic(const std::vector<Eigen::Vector3d>& pts, double tol, const FitEnds& ends) {
  CubicFit out;
  const int np = static_cast<int>(pts.size());
  if (np < 2 || !(tol > 0)) return out;
  FitData d{pts, np, {}, {}, {}, {}};
  if (!make_fit_data(d)) return out;
  // An end whose tangent is given leaves the curve along it with zero curvature: its
  // next two control points are fixed, so a straight end needs a span of its own.
  const int fixed0 = ends.start ? 3 : 1, fixed1 = ends.end ? 3 : 1;
  std::vector<double> breaks = first_breaks(d, fixed0, fixed1);
  std::vector<Eigen::Vector3d> P;
  std::vector<char> bad;
  for (int round = 1; round <= kMaxRounds; ++round) {
    out.rounds = round;
    const std::vector<double> U = clamped_knots(breaks);
    if (!solve_ctrl(d, U, ends, fixed0, fixed1, P)) return out;
    for (const auto& p : P)
      if (!p.allFinite()) return out;
    const NurbsCurve curve(kDegree + 1, U, P, std::vector<double>(P.size(), 1.0));
    out.max_error = fit_error(curve, d, breaks, tol, bad);
    if (out.max_error <= tol) {
      out.ok = true;
      out.knots = U;
      out.ctrl = std::move(P);
      out.params = std::move(d.t);
      return out;
    }
    if (!refine_breaks(d, bad, tol, breaks)) return out;
  }
  return out;
}

std::vector<CubicPiece> split_cubic(const std::vector<double>& knots, const std::vector<Eigen::Vector3d>& ctrl,
                                    int max_spans) {
  std::vector<double> U = knots;
  std::vector<Eigen::Vector3d> P = ctrl;
  // Distinct interior knot values; every max_spans-th is a cut.
  std::vector<double> cuts;
  {
    int spans = 0;
    for (size_t i = kDegree + 1; i + kDegree + 1 < U.size(); ++i) {
      if (U[i] == U[i - 1]) continue;
      if (++spans % std::max(1, max_spans) == 0) cuts.push_back(U[i]);
    }
  }
  for (double u : cuts) {
    int s = static_cast<int>(std::count(U.begin(), U.end(), u));
    while (s < kDegree) {
      const int n = static_cast<int>(P.size());
      const int k = static_cast<int>(std::upper_bound(U.begin(), U.end(), u) - U.begin()) - 1;
      std::vector<Eigen::Vector3d> Q(static_cast<size_t>(n + 1));
      for (int i = 0; i <= n; ++i) {
        if (i <= k - kDegree) {
          Q[static_cast<size_t>(i)] = P[static_cast<size_t>(i)];
        } else if (i >= k - s + 1) {
          Q[static_cast<size_t>(i)] = P[static_cast<size_t>(i - 1)];
        } else {
          const double a = (u - U[static_cast<size_t>(i)]) / (U[static_cast<size_t>(i + kDegree)] - U[static_cast<size_t>(i)]);
          Q[static_cast<size_t>(i)] = a * P[static_cast<size_t>(i)] + (1.0 - a) * P[static_cast<size_t>(i - 1)];
        }
      }
      U.insert(U.begin() + k + 1, u);
      P = std::move(Q);
      ++s;
    }
  }
  std::vector<CubicPiece> out;
  size_t first_ctrl = 0;
  size_t a_prev = 1;  // first index of the piece's start knot among the triple (clamped start: 1..3)
  auto emit = [&](size_t a_end, double u_end) {
    CubicPiece piece;
    const double u_start = U[a_prev];
    for (int i = 0; i < kDegree + 1; ++i) piece.knots.push_back(u_start);
    for (size_t i = a_prev + kDegree; i < a_end; ++i) piece.knots.push_back(U[i]);
    for (int i = 0; i < kDegree + 1; ++i) piece.knots.push_back(u_end);
    piece.ctrl.assign(P.begin() + static_cast<std::ptrdiff_t>(first_ctrl), P.begin() + static_cast<std::ptrdiff_t>(a_end));
    out.push_back(std::move(piece));
  };
  for (double u : cuts) {
    const size_t a = static_cast<size_t>(std::lower_bound(U.begin(), U.end(), u) - U.begin());
    emit(a, u);  // control points first_ctrl .. a-1 (P[a-1] is on the curve at u)
    first_ctrl = a - 1;
    a_prev = a;
  }
  emit(P.size(), U.back());
  return out;
}

double corner_blend_leg(const Eigen::Vector3d& u_in, const Eigen::Vector3d& u_out, double tol, double max_leg) {
  const double gap = (u_out - u_in).norm();
  if (!(gap > 1e-9) || !(tol > 0) || !(max_leg > 0)) return 0;
  if (u_in.dot(u_out) < std::cos(150.0 * M_PI / 180.0)) return 0;
  return std::min(tol / (0.375 * gap), 0.5 * max_leg);
}

}  // namespace cnc::geometry
