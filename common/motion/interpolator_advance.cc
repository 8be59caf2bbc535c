// The step along the curve, each cycle: to the block's end and on into the next,
// or within the block by Choi et al. 2005's eq. 7 parameter update, corrected by
// Newton (and where that fails, bisection) so the step's chord has the commanded length.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

#include "common/motion/interpolator.h"

namespace cnc::interp {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();

using motion::AxisVec;
}  // namespace

// Where a step within a block starts: the point, the derivatives' products that eq. 7
// and the arc's curvature term take, and the arc-length table's spacing there.
struct Interpolator::CurveStep {
  AxisVec P{};
  double sp2 = 0, dd = 0, d2sq = 0, sp = 0;
  double du_table = 0;
};

void Interpolator::eval_on(const Planned& p, double u, AxisVec* P, AxisVec* d1, AxisVec* d2) {
  const uint64_t bits = std::bit_cast<uint64_t>(u);
  if (last_eval_.serial == p.serial && last_eval_.u_bits == bits) {
    ++work_.curve_reuses;
  } else {
    ++work_.curve_evals;
    p.path.eval(u, &last_eval_.P, &last_eval_.d1, &last_eval_.d2);
    last_eval_.serial = p.serial;
    last_eval_.u_bits = bits;
  }
  *P = last_eval_.P;
  *d1 = last_eval_.d1;
  *d2 = last_eval_.d2;
}

double Interpolator::advance(double ds, bool* reached_stop) {
  *reached_stop = false;
  double moved = 0;
  while (!blocks_.empty()) {
    Planned& p = blocks_.front();
    if (p.stop_block()) {
      *reached_stop = true;
      return moved;
    }
    const double step_left = ds - moved;
    double to_end = 0;
    if (step_reaches_end(p, step_left, &to_end)) {
      // The distance actually covered to the end point (on a line the same as the
      // count): the rest of the step goes on along the next block, so the setpoints
      // keep their spacing across the junction (the count's surplus was a dip in the
      // speed there, and a jerk spike).
      moved += std::min(to_end, std::max(0.0, step_left));
      if (cross_into_next_block(p)) {
        // A corner that is a stop: the step ends on it.
        *reached_stop = true;
        return moved;
      }
      continue;
    }
    // Else the step ends inside the block, unless it found the block's end after all.
    if (step_in_block(p, ds - moved)) return ds;
  }
  return moved;
}

bool Interpolator::step_reaches_end(const Planned& p, double step_left, double* to_end) const {
  const double left = p.length - s_;
  // The block's end by its arc-length count, or (on a curve, whose steps are chords
  // a little shorter than the arc) by distance when the count says it is near.
  double d2 = 0;
  for (int a = 0; a < naxes_; ++a) d2 += (p.path.end()[a] - pos_[a]) * (p.path.end()[a] - pos_[a]);
  *to_end = std::sqrt(d2);
  // Only into a block the path runs on into: where it stops, its jerk-limited stop
  // profile ends on the count.
  const bool runs_on = blocks_.size() > 1 && !blocks_[1].stop_at_start();
  return left <= step_left + 1e-12 || (runs_on && left <= 2 * step_left && *to_end <= step_left);
}

bool Interpolator::cross_into_next_block(const Planned& p) {
  for (int a = 0; a < naxes_; ++a) pos_[a] = p.path.end()[a];
  out_.block_index = p.block.index;
  out_.source_line = p.block.source_line;
  out_.u = p.path.u_end();
  pop_block();
  ++blocks_done_;
  ++work_.blocks_started;
  s_ = 0;
  u_ = blocks_.empty() ? 0 : blocks_.front().path.u_begin();
  return !blocks_.empty() && blocks_.front().stop_at_start();
}

bool Interpolator::step_in_block(const Planned& p, double step) {
  CurveStep c;
  double u = eq7_estimate(p, step, &c);
  if (param_update_ == ParamUpdate::kCorrected) {
    bool converged = false;  // |P(u) − P(u_k)| = Δs at the u that stands
    u = newton_on_chord(p, step, c.P, u, &converged);
    if (!bisect_on_chord(p, step, c, converged, &u)) return false;
  }
  commit_step(p, step, u, c);
  return true;
}

double Interpolator::eq7_estimate(const Planned& p, double step, CurveStep* c) {
  // Choi et al. 2005 eq. 7: u += Δs/|P'| − Δs²·(P'·P'')/(2|P'|⁴).
  AxisVec d1{}, d2{};
  eval_on(p, u_, &c->P, &d1, &d2);
  double sp2 = 0, dd = 0, d2sq = 0;
  for (int a = 0; a < naxes_; ++a) {
    sp2 += d1[a] * d1[a];
    dd += d1[a] * d2[a];
    d2sq += d2[a] * d2[a];
  }
  const double sp = std::sqrt(sp2);
  c->sp2 = sp2;
  c->dd = dd;
  c->d2sq = d2sq;
  c->sp = sp;
  double u = u_ + step / sp;
  if (param_update_ != ParamUpdate::kFirstOrder) u -= step * step * dd / (2 * sp2 * sp2);
  // Where the curve's tangent vanishes (a first or last control point doubled, a
  // cusp) eq. 7 divides by (nearly) zero and its u runs off: start from the
  // planner's arc-length table instead (the Newton step below, or the table
  // alone, then lands on it). Elsewhere eq. 7 is far closer than the table's
  // sample spacing and is kept as it is.
  double du_table = 0;
  const double u_tab = u_on_table(p, s_ + step, &du_table);
  c->du_table = du_table;
  ++work_.table_lookups;
  if (!std::isfinite(u) || !(std::fabs(u - u_tab) <= 0.5 * du_table)) u = u_tab;
  return std::clamp(u, u_, p.path.u_end());  // forward only (eq. 7 can step back where |P'| is tiny)
}

double Interpolator::newton_on_chord(const Planned& p, double step, const AxisVec& P, double u, bool* converged) {
  // Newton on |P(u) − P(u_k)| = Δs: the chord of the step has the commanded length.
  for (int it = 0; it < 4; ++it) {
    ++work_.newton_iters;
    AxisVec Q{}, q1{}, q2{};
    eval_on(p, u, &Q, &q1, &q2);
    double L = 0, dLdu = 0;
    for (int a = 0; a < naxes_; ++a) L += (Q[a] - P[a]) * (Q[a] - P[a]);
    L = std::sqrt(L);
    if (L <= 0) break;
    for (int a = 0; a < naxes_; ++a) dLdu += (Q[a] - P[a]) * q1[a];
    dLdu /= L;
    const double err = step - L;
    if (std::fabs(err) <= 1e-12 * std::max(1.0, step)) {
      *converged = true;
      break;
    }
    if (dLdu <= 0) break;
    u = std::clamp(u + err / dLdu, u_, p.path.u_end());
  }
  return u;
}

double Interpolator::chord_from(const Planned& p, const AxisVec& P, double u) {
  ++work_.bisect_evals;
  AxisVec Q{}, q1{}, q2{};
  eval_on(p, u, &Q, &q1, &q2);
  double L2 = 0;
  for (int a = 0; a < naxes_; ++a) L2 += (Q[a] - P[a]) * (Q[a] - P[a]);
  return std::sqrt(L2);
}

bool Interpolator::bisect_on_chord(const Planned& p, double step, const CurveStep& c, bool converged, double* u) {
  // Where Newton could not reach the commanded chord (near a point where the
  // tangent vanishes, at clustered knots), find it by bracketing and bisection:
  // the chord from the current point grows from 0 at u_, so the first u
  // forward where it reaches the step is bracketed by doubling and then
  // halved down to it. The arc length then never runs ahead of the curve (it
  // did by 44 um at the end of LinuxCNC's trident, closed by a jump in the
  // block's last cycle); and the path always moves on.
  const double tol = 1e-9 * std::max(1.0, step);
  // A chord of the step's length far along the curve (past a sharp turn or a
  // near-cusp, where the curve comes back near where it was) is not the step:
  // the arc length between the two, by the planner's table, must not exceed
  // the step by more than the table's resolution. Else the first u forward is
  // sought by bracketing as below.
  bool past_turn = false;
  if (converged && p.path.curved()) {
    const double arc = s_on_table(p, *u) - s_on_table(p, u_);
    past_turn = arc > 1.5 * step + 1e-9;
  }
  const bool off_chord = past_turn || (!converged && !(std::fabs(chord_from(p, c.P, *u) - step) <= tol));
  if (!off_chord) return true;
  const double u_end = p.path.u_end();
  // The first bracket holds about a quarter step (by |P'| here; at most the
  // table's spacing): doubling from there meets the first u where the chord
  // reaches the step, not one past a turn narrower than the table's spacing
  // (a bisection over both would pick either).
  double h0 = c.du_table;
  if (c.sp > 0 && std::isfinite(0.25 * step / c.sp)) h0 = std::min(h0 > 0 ? h0 : kInf, 0.25 * step / c.sp);
  double lo = u_, h = std::max(h0, 1e-12 * (u_end - p.path.u_begin()));
  double hi = std::min(u_ + h, u_end);
  for (int it = 0; it < 200 && hi < u_end && chord_from(p, c.P, hi) < step; ++it) {
    lo = hi;
    h *= 2;
    hi = std::min(u_ + h, u_end);
  }
  if (chord_from(p, c.P, hi) >= step) {
    for (int it = 0; it < 200; ++it) {
      const double mid = 0.5 * (lo + hi);
      if (mid <= lo || mid >= hi) break;
      const double L = chord_from(p, c.P, mid);
      if (std::fabs(L - step) <= tol) {
        lo = hi = mid;
        break;
      }
      (L < step ? lo : hi) = mid;
    }
    *u = hi;
  } else if (*u <= u_ && p.length - s_ < 2 * step) {
    // Newton found no forward u and the block's end is less than a step away
    // along the curve, though the arc-length count (chords fall short of the
    // arc) says a little more is left: the step ends the block here and goes
    // on into the next, rather than standing still for a cycle (a jerk spike,
    // seen at the ends of G64 P fits).
    s_ = p.length - chord_from(p, c.P, u_end);
    return false;
  }
  // Else (a curve closing on itself) Newton's u stands, as everywhere else.
  return true;
}

void Interpolator::commit_step(const Planned& p, double step, double u, const CurveStep& c) {
  u_ = u;
  // The arc the step covers: its chord plus the chord's shortfall on the local
  // curvature, L³κ²/24 (at most a tenth of the step). Counting chords alone, the
  // count fell behind the curve by ~L³κ²/24 a cycle (2 um over a 42 mm block), so
  // the brake for a near-cusp ahead landed microns past where it should, and the
  // step crossed the turn at speed.
  double arc = step;
  if (p.path.curved() && c.sp2 > 0) {
    const double k2 = std::max(0.0, c.sp2 * c.d2sq - c.dd * c.dd) / (c.sp2 * c.sp2 * c.sp2);
    arc += std::min(step * step * step * k2 / 24.0, 0.1 * step);
  }
  s_ += arc;
  {
    AxisVec q1{}, q2{};
    eval_on(p, u_, &pos_, &q1, &q2);
  }
  out_.block_index = p.block.index;
  out_.source_line = p.block.source_line;
  out_.u = u_;
}

double Interpolator::s_on_table(const Planned& p, double u) {
  // The inverse of u_on_table: arc length at u, linear between the samples around it.
  const auto& sm = p.samples;
  if (sm.empty()) return 0;
  const auto hi = std::partition_point(sm.begin(), sm.end(), [&](const Sample& x) { return x.u < u; });
  if (hi == sm.begin()) return sm.front().s;
  if (hi == sm.end()) return sm.back().s;
  const Sample& b = *hi;
  const Sample& a = *(hi - 1);
  const double f = b.u > a.u ? (u - a.u) / (b.u - a.u) : 1.0;
  return a.s + (b.s - a.s) * f;
}

double Interpolator::u_on_table(const Planned& p, double s, double* du) {
  // The planner's samples are in increasing arc length: linear between the two
  // around s. *du: the u spacing of those two samples.
  const auto& sm = p.samples;
  *du = 0;
  if (sm.empty()) return p.path.u_end();
  const auto hi = std::partition_point(sm.begin(), sm.end(), [&](const Sample& x) { return x.s < s; });
  if (hi == sm.begin()) return sm.front().u;
  if (hi == sm.end()) return sm.back().u;
  const Sample& b = *hi;
  const Sample& a = *(hi - 1);
  *du = b.u - a.u;
  const double f = b.s > a.s ? (s - a.s) / (b.s - a.s) : 1.0;
  return a.u + (b.u - a.u) * f;
}

}  // namespace cnc::interp
