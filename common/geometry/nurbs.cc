#include "common/geometry/nurbs.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <stdexcept>

namespace cnc::geometry {
namespace {

constexpr int kMaxOrder = NurbsCurve::kMaxOrder;
constexpr int kMaxDerivative = NurbsCurve::kMaxDerivative;

// The shortest text that reads back as v.
std::string fmt(double v) {
  char buf[32];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

// A2.3: the non-zero basis functions N_{span-p+j,p}(u), j = 0..p, and their
// derivatives up to n (n <= p) into ders[k][j]. Fixed arrays, no allocation.
void basis_function_derivatives(int span, double u, int p, int n, const double* knot,
                                double ders[kMaxDerivative + 1][kMaxOrder]) {
  double ndu[kMaxOrder][kMaxOrder];
  double left[kMaxOrder];
  double right[kMaxOrder];
  ndu[0][0] = 1.0;
  for (int j = 1; j <= p; ++j) {
    left[j] = u - knot[span + 1 - j];
    right[j] = knot[span + j] - u;
    double saved = 0.0;
    for (int r = 0; r < j; ++r) {
      ndu[j][r] = right[r + 1] + left[j - r];  // lower triangle: knot differences
      const double temp = ndu[r][j - 1] / ndu[j][r];
      ndu[r][j] = saved + right[r + 1] * temp;  // upper triangle: basis functions
      saved = left[j - r] * temp;
    }
    ndu[j][j] = saved;
  }
  for (int j = 0; j <= p; ++j) ders[0][j] = ndu[j][p];

  double a[2][kMaxOrder];
  for (int r = 0; r <= p; ++r) {
    int s1 = 0;
    int s2 = 1;
    a[0][0] = 1.0;
    for (int k = 1; k <= n; ++k) {
      double d = 0.0;
      const int rk = r - k;
      const int pk = p - k;
      if (r >= k) {
        a[s2][0] = a[s1][0] / ndu[pk + 1][rk];
        d = a[s2][0] * ndu[rk][pk];
      }
      const int j1 = rk >= -1 ? 1 : -rk;
      const int j2 = (r - 1 <= pk) ? k - 1 : p - r;
      for (int j = j1; j <= j2; ++j) {
        a[s2][j] = (a[s1][j] - a[s1][j - 1]) / ndu[pk + 1][rk + j];
        d += a[s2][j] * ndu[rk + j][pk];
      }
      if (r <= pk) {
        a[s2][k] = -a[s1][k - 1] / ndu[pk + 1][r];
        d += a[s2][k] * ndu[r][pk];
      }
      ders[k][r] = d;
      std::swap(s1, s2);
    }
  }
  double factor = p;
  for (int k = 1; k <= n; ++k) {
    for (int j = 0; j <= p; ++j) ders[k][j] *= factor;
    factor *= p - k;
  }
}

// Binomial coefficients C(k, i) for k, i <= kMaxDerivative (A4.2).
constexpr double kBinomial[kMaxDerivative + 1][kMaxDerivative + 1] = {
    {1, 0, 0, 0}, {1, 1, 0, 0}, {1, 2, 1, 0}, {1, 3, 3, 1}};

// 8-point Gauss–Legendre on [-1, 1]: nodes ±x_i, weights w_i.
constexpr double kGaussX[4] = {0.1834346424956498049394761, 0.5255324099163289858177390,
                               0.7966664774136267395915539, 0.9602898564975362316835609};
constexpr double kGaussW[4] = {0.3626837833783619829651504, 0.3137066458778872873379622,
                               0.2223810344533744705443560, 0.1012285362903762591525314};

double speed(const NurbsCurve& c, double u) {
  Vec3 d[2];
  c.derivatives(u, 1, d);
  return d[1].norm();
}

double gauss_legendre(const NurbsCurve& c, double a, double b) {
  const double half = 0.5 * (b - a);
  const double mid = 0.5 * (a + b);
  double sum = 0.0;
  for (int i = 0; i < 4; ++i) {
    sum += kGaussW[i] * (speed(c, mid - half * kGaussX[i]) + speed(c, mid + half * kGaussX[i]));
  }
  return sum * half;
}

// Accepts the two halves when they agree with the whole to tol; otherwise splits the
// tolerance between the halves. The depth bound only matters at a cusp (|C'| = 0),
// where the integrand has a kink; there the error is already far below tol.
double adaptive(const NurbsCurve& c, double a, double b, double whole, double tol, int depth) {
  const double m = 0.5 * (a + b);
  const double left = gauss_legendre(c, a, m);
  const double right = gauss_legendre(c, m, b);
  const double both = left + right;
  const double rounding = 8.0 * std::numeric_limits<double>::epsilon() * std::abs(both);
  if (depth == 0 || std::abs(both - whole) <= std::max(tol, rounding)) return both;
  return adaptive(c, a, m, left, 0.5 * tol, depth - 1) + adaptive(c, m, b, right, 0.5 * tol, depth - 1);
}

}  // namespace

NurbsCurve::NurbsCurve(int order, std::vector<double> knots, std::vector<Vec3> ctrl, std::vector<double> weights)
    : order_(order), knots_(std::move(knots)), ctrl_(std::move(ctrl)), weights_(std::move(weights)) {
  const std::string problem = validate(order_, knots_, ctrl_.size(), weights_);
  if (!problem.empty()) throw std::invalid_argument(problem);
  for (size_t i = 0; i < ctrl_.size(); ++i) {
    if (!ctrl_[i].allFinite()) throw std::invalid_argument("control point " + std::to_string(i) + " is not finite");
  }
  weighted_.reserve(ctrl_.size());
  for (size_t i = 0; i < ctrl_.size(); ++i) {
    const double w = weights_[i];
    weighted_.emplace_back(w * ctrl_[i].x(), w * ctrl_[i].y(), w * ctrl_[i].z(), w);
  }
}

std::string NurbsCurve::validate(int order, const std::vector<double>& knots, size_t n_ctrl,
                                 const std::vector<double>& weights) {
  if (order < 2 || order > kMaxOrder) {
    return "order " + std::to_string(order) + " is outside 2.." + std::to_string(kMaxOrder);
  }
  const size_t k = static_cast<size_t>(order);
  if (n_ctrl < k) {
    return "need at least " + std::to_string(order) + " control points for order " + std::to_string(order) +
           ", got " + std::to_string(n_ctrl);
  }
  if (knots.size() != n_ctrl + k) {
    return "knot vector has " + std::to_string(knots.size()) + " values, expected " + std::to_string(n_ctrl + k) +
           " (control points " + std::to_string(n_ctrl) + " + order " + std::to_string(order) + ")";
  }
  if (weights.size() != n_ctrl) {
    return "weights has " + std::to_string(weights.size()) + " values, expected " + std::to_string(n_ctrl) +
           " (one per control point)";
  }
  for (size_t i = 0; i < knots.size(); ++i) {
    if (!std::isfinite(knots[i])) return "knot " + std::to_string(i) + " is not finite (" + fmt(knots[i]) + ")";
  }
  for (size_t i = 1; i < knots.size(); ++i) {
    if (knots[i] < knots[i - 1]) {
      return "knots decrease at index " + std::to_string(i) + " (" + fmt(knots[i]) + " after " +
             fmt(knots[i - 1]) + ")";
    }
  }
  const size_t last = knots.size() - 1;
  for (size_t i = 1; i < k; ++i) {
    if (knots[i] != knots[0]) {
      return "knot vector is not clamped at the start: the first " + std::to_string(order) +
             " knots must be equal (knot " + std::to_string(i) + " is " + fmt(knots[i]) + ", knot 0 is " +
             fmt(knots[0]) + ")";
    }
    if (knots[last - i] != knots[last]) {
      return "knot vector is not clamped at the end: the last " + std::to_string(order) +
             " knots must be equal (knot " + std::to_string(last - i) + " is " + fmt(knots[last - i]) + ", knot " +
             std::to_string(last) + " is " + fmt(knots[last]) + ")";
    }
  }
  if (knots[0] == knots[last]) return "knot domain is empty (every knot is " + fmt(knots[0]) + ")";
  if (knots[k] == knots[0]) {
    return "knot " + fmt(knots[0]) + " at the start has multiplicity above the order " + std::to_string(order);
  }
  if (knots[last - k] == knots[last]) {
    return "knot " + fmt(knots[last]) + " at the end has multiplicity above the order " + std::to_string(order);
  }
  // Interior knots (strictly inside the domain): multiplicity = order would make the
  // curve jump, which no interpolator can follow.
  for (size_t i = k; i <= last - k;) {
    size_t j = i;
    while (j + 1 <= last - k && knots[j + 1] == knots[i]) ++j;
    const size_t mult = j - i + 1;
    if (mult > k - 1) {
      return "interior knot " + fmt(knots[i]) + " has multiplicity " + std::to_string(mult) +
             ", more than the degree " + std::to_string(order - 1) + " (the curve would be discontinuous)";
    }
    i = j + 1;
  }
  for (size_t i = 0; i < weights.size(); ++i) {
    if (!std::isfinite(weights[i])) return "weight " + std::to_string(i) + " is not finite (" + fmt(weights[i]) + ")";
    if (weights[i] <= 0.0) return "weight " + std::to_string(i) + " is not positive (" + fmt(weights[i]) + ")";
  }
  return "";
}

int NurbsCurve::find_span(double u) const {
  const int n = static_cast<int>(ctrl_.size()) - 1;
  const int p = degree();
  if (u >= knots_[n + 1]) return n;
  if (u <= knots_[p]) return p;
  int low = p;
  int high = n + 1;
  int mid = (low + high) / 2;
  // knots_[low] <= u < knots_[high] holds throughout; a NaN u exits at once.
  while (u < knots_[mid] || u >= knots_[mid + 1]) {
    if (u < knots_[mid]) {
      high = mid;
    } else {
      low = mid;
    }
    mid = (low + high) / 2;
  }
  return mid;
}

Vec3 NurbsCurve::point(double u) const {
  Vec3 out[1];
  derivatives(u, 0, out);
  return out[0];
}

void NurbsCurve::derivatives(double u, int d, Vec3* out) const {
  if (d < 0 || d > kMaxDerivative) std::abort();
  const int p = degree();
  u = std::clamp(u, u_min(), u_max());
  const int span = find_span(u);
  const int n = std::min(d, p);
  double ders[kMaxDerivative + 1][kMaxOrder];
  basis_function_derivatives(span, u, p, n, knots_.data(), ders);

  // Derivatives of the homogeneous curve (w·C, w).
  Eigen::Vector4d aw[kMaxDerivative + 1];
  for (int k = 0; k <= d; ++k) aw[k].setZero();
  for (int k = 0; k <= n; ++k) {
    for (int j = 0; j <= p; ++j) aw[k] += ders[k][j] * weighted_[span - p + j];
  }
  // A4.2: C^(k) = (A^(k) − Σ_{i=1..k} C(k,i) w^(i) C^(k−i)) / w.
  for (int k = 0; k <= d; ++k) {
    Vec3 v = aw[k].head<3>();
    for (int i = 1; i <= k; ++i) v -= kBinomial[k][i] * aw[i].w() * out[k - i];
    out[k] = v / aw[0].w();
  }
}

double NurbsCurve::curvature(double u) const {
  Vec3 d[3];
  derivatives(u, 2, d);
  const double speed = d[1].norm();
  const double speed3 = speed * speed * speed;
  if (speed3 == 0.0) return std::numeric_limits<double>::infinity();
  return d[1].cross(d[2]).norm() / speed3;
}

std::vector<double> NurbsCurve::breakpoints() const {
  std::vector<double> out;
  const size_t first = static_cast<size_t>(order_ - 1);
  const size_t last = ctrl_.size();
  for (size_t i = first; i <= last; ++i) {
    if (out.empty() || knots_[i] != out.back()) out.push_back(knots_[i]);
  }
  return out;
}

double arc_length(const NurbsCurve& c, double u0, double u1, double tol) {
  u0 = std::clamp(u0, c.u_min(), c.u_max());
  u1 = std::clamp(u1, c.u_min(), c.u_max());
  if (u1 < u0) return -arc_length(c, u1, u0, tol);
  if (u1 == u0) return 0.0;
  constexpr int kMaxDepth = 40;
  const double width = u1 - u0;
  const std::vector<double>& knots = c.knots();
  double total = 0.0;
  double a = u0;
  // Each span's integrand is smooth; a share of tol in proportion to its width.
  for (size_t i = 0; i < knots.size() && a < u1; ++i) {
    if (knots[i] <= a) continue;
    const double b = std::min(knots[i], u1);
    total += adaptive(c, a, b, gauss_legendre(c, a, b), tol * (b - a) / width, kMaxDepth);
    a = b;
  }
  return total;
}

}  // namespace cnc::geometry
