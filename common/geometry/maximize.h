#pragma once
// The largest value of a function on an interval, for measuring chord errors:
// sampled at kSamples sub-intervals, each sampled local maximum refined by
// golden-section search until its bracket is below rel_tol of the interval. Near a
// maximum the error in the value is quadratic in the error in u, so the result is
// far more accurate than rel_tol. Assumes every bump of f is wider than one
// sub-interval (true for interpolation steps). No allocation.
#include <algorithm>
#include <cmath>

namespace cnc::geometry {

template <class F>
double maximize_on_interval(const F& f, double u0, double u1, double rel_tol = 1e-9) {
  constexpr int kSamples = 16;
  double u[kSamples + 1];
  double v[kSamples + 1];
  for (int i = 0; i <= kSamples; ++i) {
    u[i] = i == kSamples ? u1 : u0 + (u1 - u0) * i / kSamples;
    v[i] = f(u[i]);
  }
  double best = std::max(v[0], v[kSamples]);
  const double invphi = (std::sqrt(5.0) - 1.0) / 2.0;
  const double stop = rel_tol * std::fabs(u1 - u0);
  for (int i = 1; i < kSamples; ++i) {
    best = std::max(best, v[i]);
    if (v[i] < v[i - 1] || v[i] < v[i + 1]) continue;
    double lo = u[i - 1], hi = u[i + 1];
    double x1 = hi - invphi * (hi - lo), x2 = lo + invphi * (hi - lo);
    double f1 = f(x1), f2 = f(x2);
    // The iteration cap ends brackets that rounding keeps wider than `stop`.
    for (int it = 0; it < 80 && std::fabs(hi - lo) > stop; ++it) {
      if (f1 < f2) {
        lo = x1;
        x1 = x2;
        f1 = f2;
        x2 = lo + invphi * (hi - lo);
        f2 = f(x2);
      } else {
        hi = x2;
        x2 = x1;
        f2 = f1;
        x1 = hi - invphi * (hi - lo);
        f1 = f(x1);
      }
    }
    best = std::max({best, f1, f2});
  }
  return best;
}

}  // namespace cnc::geometry
