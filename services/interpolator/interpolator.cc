#include "services/interpolator/interpolator.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

#include "common/geometry/chord.h"
#include "common/process/roughness.h"

namespace cnc::interp {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
// Share of each axis's acceleration and jerk left to the centripetal terms on
// curved blocks; the tangential planning gets the rest.
constexpr double kCentripetalShare = 0.5;
// Samples per knot span of a NURBS and per radian of an arc.
constexpr int kSamplesPerSpan = 16;
constexpr double kArcSamplesPerRad = 24.0;

using motion::AxisVec;

// One phase of constant jerk j for time t applied to (s, v, a).
void integrate(double j, double t, double* s, double* v, double* a) {
  *s += *v * t + 0.5 * *a * t * t + j * t * t * t / 6.0;
  *v += *a * t + 0.5 * j * t * t;
  *a += j * t;
}

// Shortest distance in which a jerk-limited (J) and acceleration-limited (A) brake
// brings the speed from v (acceleration a) to vt; 0 when the speed never exceeds vt.
double brake_distance(double v, double a, double vt, double A, double J) {
  if (a >= 0 ? v + a * a / (2 * J) <= vt : v <= vt) return 0.0;
  const double ap2 = J * (v - vt) + 0.5 * a * a;
  double s = 0, vv = v, aa = a;
  if (a < 0 && ap2 < a * a) {
    // Already braking harder than needed: releasing the brake reaches vt.
    const double disc = std::max(0.0, a * a - 2 * J * (v - vt));
    integrate(J, (-a - std::sqrt(disc)) / J, &s, &vv, &aa);
    return s;
  }
  double ap = std::sqrt(ap2), t2 = 0;
  if (ap > A) {
    ap = A;
    t2 = std::max(0.0, (v - vt + a * a / (2 * J) - A * A / J) / A);
  }
  integrate(-J, (a + ap) / J, &s, &vv, &aa);
  integrate(0.0, t2, &s, &vv, &aa);
  integrate(J, ap / J, &s, &vv, &aa);
  return s;
}

// The acceleration with which a path at speed v approaches the speed v + gap in
// cycles of T: the largest a (at most A) from which lowering the acceleration by
// J·T per cycle down to zero gains no more than the gap, this cycle included. Taken
// afresh every cycle, it never overshoots and lands on the speed with the
// acceleration at zero, each step of the acceleration within J·T (the continuous
// ramp sqrt(2·J·gap), rounded to whole cycles, overshot and had to be clipped,
// a jerk step of up to ~2 J·T at the landing). A negative gap mirrors it.
double landing_accel(double gap, double A, double J, double T) {
  const double g = std::fabs(gap) / T;  // the speed gain, in units of acceleration × cycle
  const double q = J * T;               // the largest step of the acceleration per cycle
  if (!(g >= 0)) return 0.0;
  // From a in [m·q, (m+1)·q) the steps a, a − q, ..., a − m·q gain
  // G(a) = (m+1)·a − q·m(m+1)/2; G(m·q) = q·m(m+1)/2. A gap at least G(A) (an
  // unlimited cap included) takes the full acceleration.
  const double m_a = std::floor(A / q);
  if (g >= (m_a + 1) * A - 0.5 * q * m_a * (m_a + 1)) return gap >= 0 ? A : -A;
  double m = std::floor(0.5 * (std::sqrt(1.0 + 8.0 * g / q) - 1.0));
  while (m > 0 && 0.5 * q * m * (m + 1) > g) m -= 1;
  while (0.5 * q * (m + 1) * (m + 2) <= g) m += 1;
  const double a = std::min(A, (g + 0.5 * q * m * (m + 1)) / (m + 1));
  return gap >= 0 ? a : -a;
}

// Appends u0 and the points that refine (u0, u1) until the local speed limit v(u)
// (chord error, roughness) changes by at most 0.5 % between neighbours, so that
// interpolating it linearly between samples never overestimates it by more than
// that. Limits above v_top cannot bind and are not refined. At most 8 levels.
template <class Limit>
void refine(double u0, double v0, double u1, double v1, const Limit& vlim, double v_top, int depth,
            std::vector<double>* out) {
  const double lo = std::min(v0, v1);
  if (depth >= 8 || lo >= v_top) {
    out->push_back(u0);
    return;
  }
  const double um = 0.5 * (u0 + u1);
  const double vm = vlim(um);
  if (std::fabs(v1 - v0) <= 0.005 * lo && vm >= 0.995 * lo) {
    out->push_back(u0);
    return;
  }
  refine(u0, v0, um, vm, vlim, v_top, depth + 1, out);
  refine(um, vm, u1, v1, vlim, v_top, depth + 1, out);
}

double norm(const AxisVec& v, int n) {
  double s = 0;
  for (int i = 0; i < n; ++i) s += v[i] * v[i];
  return std::sqrt(s);
}

// The local frame of a curve from its first two derivatives in u: the unit tangent
// t and the curvature vector k = d²P/ds² (|k| = κ, along the normal). Returns |P'|;
// 0 at a singular point, where t and k are left untouched.
double local_frame(const AxisVec& d1, const AxisVec& d2, int n, AxisVec* t, AxisVec* k) {
  const double sp = norm(d1, n);
  if (sp <= 0) return 0;
  double d2t = 0;
  for (int a = 0; a < n; ++a) {
    (*t)[a] = d1[a] / sp;
    d2t += d2[a] * (*t)[a];
  }
  for (int a = 0; a < n; ++a) (*k)[a] = (d2[a] - d2t * (*t)[a]) / (sp * sp);
  return sp;
}

// The speed of a rapid: the fastest its straight line allows within every axis's
// velocity limit (for a move of no length, the slowest axis's limit).
double rapid_speed(const config::MachineConfig& cfg, const program::Block& b, int n) {
  double len2 = 0;
  for (int a = 0; a < n; ++a) len2 += (b.end[a] - b.start[a]) * (b.end[a] - b.start[a]);
  const double len = std::sqrt(len2);
  double v = cfg.axes[0].max_velocity_mm_s;
  for (int a = 0; a < n; ++a) v = std::min(v, cfg.axes[a].max_velocity_mm_s);
  if (!(len > 0)) return v;
  v = std::numeric_limits<double>::max();
  for (int a = 0; a < n; ++a) {
    const double d = std::fabs(b.end[a] - b.start[a]);
    if (d > 0) v = std::min(v, cfg.axes[a].max_velocity_mm_s * len / d);
  }
  return v;
}

}  // namespace

const char* to_string(Limit limit) {
  switch (limit) {
    case Limit::kNone: return "none";
    case Limit::kProgram: return "program";
    case Limit::kChord: return "chord";
    case Limit::kRoughness: return "roughness";
    case Limit::kAxisVelocity: return "axis_velocity";
    case Limit::kCurvatureAccel: return "curvature_accel";
    case Limit::kLookahead: return "lookahead";
  }
  return "?";
}

const char* to_string(RunState state) {
  switch (state) {
    case RunState::kIdle: return "idle";
    case RunState::kRunning: return "running";
    case RunState::kHeld: return "held";
    case RunState::kDone: return "done";
    case RunState::kStarved: return "starved";
  }
  return "?";
}

ParamUpdate param_update_from_string(const std::string& s) {
  if (s == "first_order") return ParamUpdate::kFirstOrder;
  if (s == "taylor2") return ParamUpdate::kTaylor2;
  if (s == "corrected") return ParamUpdate::kCorrected;
  throw std::invalid_argument("parameter update '" + s + "' is not one of first_order, taylor2, corrected");
}

bool Interpolator::Planned::stop_block() const {
  return block.kind == program::BlockKind::kDwell || block.kind == program::BlockKind::kEnd ||
         block.kind == program::BlockKind::kEvent;
}

bool Interpolator::Planned::stop_at_start() const { return stop_block() || v_entry == 0; }

Interpolator::Interpolator(const config::MachineConfig& cfg)
    : cfg_(cfg), period_s_(cfg.ipo_period_s), naxes_(static_cast<int>(cfg.axes.size())),
      param_update_(param_update_from_string(cfg.param_update)) {
  for (int a = 0; a < naxes_; ++a) pos_[a] = cfg_.axes[a].home_mm;
}

Interpolator::~Interpolator() = default;

// ---- planning ------------------------------------------------------------------

void Interpolator::plan_block(Planned& p) {
  const program::Block& b = p.block;
  // A rapid has no programmed feed: it goes as fast as its axes allow, a finite
  // speed set below from the same samples as its axis-velocity limit (so feed hold,
  // override and look-ahead do arithmetic on finite numbers only: ∞ × 0 is NaN).
  const bool rapid = b.kind == program::BlockKind::kRapid;
  p.v_prog = rapid ? rapid_speed(cfg_, b, naxes_) : b.feed_mm_per_min / 60.0;
  p.accel = cfg_.path_accel_mm_s2;
  p.jerk = cfg_.path_jerk_mm_s3;
  if (p.stop_block()) return;

  const bool curved = p.path.curved();
  const double share = curved ? 1.0 - kCentripetalShare : 1.0;
  // 1 % below the tolerance: the circle formula is exact for constant curvature;
  // where the curvature changes within a step the error runs up to ~0.5 % over it.
  const double eps = 0.99 * cfg_.chord_tolerance_mm;
  // The roughness law is for cutting moves; a rapid does not cut.
  const bool rough = b.process.active() && b.spindle_rpm > 0 && b.kind != program::BlockKind::kRapid;
  const process::RoughnessLaw law{b.process.ball_radius_mm, b.process.flutes, b.process.pick_feed_mm,
                                  b.process.target_rmax_um * 1e-3};
  if (rough) {
    const std::string why = law.validate();
    if (!why.empty()) throw std::invalid_argument("process parameters: " + why);
  }

  // Parameter values to sample: uniform per knot span (NURBS) or per angle (arcs),
  // then refined where the chord or roughness limit changes quickly.
  std::vector<double> us;
  const double u0 = p.path.u_begin(), u1 = p.path.u_end();
  if (!curved) {
    us = {u0, u1};
  } else {
    std::vector<double> grid;
    if (b.kind == program::BlockKind::kNurbs) {
      const std::vector<double> bp = p.path.nurbs_breakpoints();
      for (size_t k = 0; k + 1 < bp.size(); ++k)
        for (int i = 0; i < kSamplesPerSpan; ++i) grid.push_back(bp[k] + (bp[k + 1] - bp[k]) * i / kSamplesPerSpan);
    } else {
      const int n = std::max(2, static_cast<int>(std::ceil(p.path.arc_sweep_rad() * kArcSamplesPerRad)));
      for (int i = 0; i < n; ++i) grid.push_back(u0 + (u1 - u0) * i / n);
    }
    grid.push_back(u1);
    auto vlim = [&](double u) {
      AxisVec P{}, d1{}, d2{}, t{}, k{};
      p.path.eval(u, &P, &d1, &d2);
      if (local_frame(d1, d2, naxes_, &t, &k) <= 0) return kInf;
      const double kappa = norm(k, naxes_);
      double v = kappa > 1e-12 ? geometry::chord_step_length(1.0 / kappa, eps) / period_s_ : kInf;
      if (rough && naxes_ >= 3)
        v = std::min(v, law.feed_mm_per_min(b.spindle_rpm,
                                            process::feed_inclination_angle(Eigen::Vector3d(t[0], t[1], t[2]))) /
                            60.0);
      return v;
    };
    // Nothing above the fastest the block can go (1.5 × override) needs refining.
    double v_top = 1.5 * p.v_prog;
    for (int a = 0; a < naxes_; ++a) v_top = std::min(v_top, std::sqrt(3.0) * cfg_.axes[a].max_velocity_mm_s);
    double va = vlim(grid[0]);
    for (size_t k = 0; k + 1 < grid.size(); ++k) {
      const double vb = vlim(grid[k + 1]);
      refine(grid[k], va, grid[k + 1], vb, vlim, v_top, 0, &us);
      va = vb;
    }
    us.push_back(u1);
  }

  // Per sample: speed limits from the local geometry.
  const size_t n = us.size();
  p.samples.assign(n, Sample{0, 0, kInf, Limit::kNone});
  planned_samples_ += static_cast<int64_t>(n);
  std::vector<AxisVec> kvec(n);  // curvature vector d²P/ds²
  std::vector<double> v_chord(n, kInf);
  double v_rapid = p.v_prog;  // a rapid's speed: the least axis-velocity limit of its samples
  for (size_t i = 0; i < n; ++i) {
    AxisVec P{}, d1{}, d2{};
    p.path.eval(us[i], &P, &d1, &d2);
    AxisVec t{};
    Sample& smp = p.samples[i];
    smp.u = us[i];
    if (local_frame(d1, d2, naxes_, &t, &kvec[i]) <= 0) continue;
    const double kappa = norm(kvec[i], naxes_);
    auto take = [&smp](double v, Limit why) {
      if (v < smp.v_geo) {
        smp.v_geo = v;
        smp.limit = why;
      }
    };
    for (int a = 0; a < naxes_; ++a) {
      const double ta = std::fabs(t[a]);
      if (ta > 0) {
        const double v_axis = cfg_.axes[a].max_velocity_mm_s / ta;
        take(v_axis, Limit::kAxisVelocity);
        v_rapid = std::min(v_rapid, v_axis);
        p.accel = std::min(p.accel, share * cfg_.axes[a].max_accel_mm_s2 / ta);
        p.jerk = std::min(p.jerk, share * cfg_.axes[a].max_jerk_mm_s3 / ta);
      }
      if (std::fabs(kvec[i][a]) > 0)
        take(std::sqrt(kCentripetalShare * cfg_.axes[a].max_accel_mm_s2 / std::fabs(kvec[i][a])),
             Limit::kCurvatureAccel);
    }
    if (kappa > 1e-12) v_chord[i] = geometry::chord_step_length(1.0 / kappa, eps) / period_s_;
    if (rough && naxes_ >= 3) {
      const double alpha = process::feed_inclination_angle(Eigen::Vector3d(t[0], t[1], t[2]));
      take(law.feed_mm_per_min(b.spindle_rpm, alpha) / 60.0, Limit::kRoughness);
    }
  }
  if (rapid) p.v_prog = v_rapid;
  // The chord limit holds over a whole step, and the curvature may peak between
  // samples: each sample takes the least of its neighbours' chord limits.
  for (size_t i = 0; i < n; ++i) {
    double v = v_chord[i];
    if (i > 0) v = std::min(v, v_chord[i - 1]);
    if (i + 1 < n) v = std::min(v, v_chord[i + 1]);
    if (v < p.samples[i].v_geo) {
      p.samples[i].v_geo = v;
      p.samples[i].limit = Limit::kChord;
    }
  }
  // Arc length by 3-point Gauss–Legendre per sample interval (on top of dense samples).
  double s = 0;
  for (size_t i = 0; i + 1 < n; ++i) {
    const double a = us[i], c = us[i + 1], h = 0.5 * (c - a), m = 0.5 * (a + c);
    static constexpr double kX = 0.7745966692414834, kW0 = 8.0 / 9.0, kW1 = 5.0 / 9.0;
    auto spd = [&](double u) {
      AxisVec P{}, d1{}, d2{};
      p.path.eval(u, &P, &d1, &d2);
      return norm(d1, naxes_);
    };
    s += h * (kW0 * spd(m) + kW1 * (spd(m - h * kX) + spd(m + h * kX)));
    p.samples[i + 1].s = s;
  }
  p.length = s;
  // Jerk from the curvature changing along the path: v³·|dk/ds| per axis.
  for (size_t i = 0; i + 1 < n && curved; ++i) {
    const double ds = p.samples[i + 1].s - p.samples[i].s;
    if (ds <= 0) continue;
    for (int a = 0; a < naxes_; ++a) {
      const double dk = std::fabs(kvec[i + 1][a] - kvec[i][a]) / ds;
      if (dk <= 0) continue;
      const double v = std::cbrt(kCentripetalShare * cfg_.axes[a].max_jerk_mm_s3 / dk);
      for (size_t k : {i, i + 1}) {
        if (v < p.samples[k].v_geo) {
          p.samples[k].v_geo = v;
          p.samples[k].limit = Limit::kCurvatureAccel;
        }
      }
    }
  }
}

void Interpolator::plan_junction(Planned& prev, Planned& next) const {
  if (prev.stop_block() || next.stop_block() || prev.path.degenerate() || next.path.degenerate()) {
    next.v_entry = 0;
    return;
  }
  AxisVec P{}, t0{}, t1{}, d2{};
  prev.path.eval(prev.path.u_end(), &P, &t0, &d2);
  next.path.eval(next.path.u_begin(), &P, &t1, &d2);
  const double n0 = norm(t0, naxes_), n1 = norm(t1, naxes_);
  const double T = period_s_;
  const double a_path = std::min(prev.accel, next.accel);
  double v = kInf;
  double dt2 = 0;
  for (int a = 0; a < naxes_; ++a) {
    const double dt = std::fabs(t1[a] / n1 - t0[a] / n0);
    dt2 += dt * dt;
    if (dt < 1e-12) continue;
    const auto& ax = cfg_.axes[a];
    // The direction change happens within one cycle. It turns the path
    // acceleration by the same angle: where that alone would step the axis's
    // acceleration by more than half its jerk budget, the corner is a stop.
    if (a_path * dt > 0.5 * ax.max_jerk_mm_s3 * T) {
      next.v_entry = 0;
      return;
    }
    // Otherwise its velocity step must stay within one cycle's acceleration and
    // half a cycle's jerk (the tangential acceleration changes across it too).
    v = std::min(v, std::min(ax.max_accel_mm_s2 * T, 0.5 * ax.max_jerk_mm_s3 * T * T) / dt);
  }
  if (dt2 > 0) v = std::min(v, std::min(cfg_.path_accel_mm_s2 * T, 0.5 * cfg_.path_jerk_mm_s3 * T * T) / std::sqrt(dt2));
  next.v_entry = v;
}

void Interpolator::backward_pass(bool full) {
  // From the end of the buffer (a stop unless more blocks come) backwards. After a
  // block was appended only the tail changes: once a recomputed limit equals the
  // stored one, everything before it is unchanged too.
  double carry = 0;
  bool last = true;
  for (auto it = blocks_.rbegin(); it != blocks_.rend(); ++it) {
    Planned& p = *it;
    if (p.stop_block()) {
      carry = 0;
      last = false;
      continue;
    }
    const size_t n = p.samples.size();
    const bool fresh = p.v_bw.size() != n;
    if (fresh) p.v_bw.assign(n, -1.0);
    const double vp = programmed_speed(p);
    const bool feed_binds = !rapid_at_full_speed(p);
    for (size_t i = n; i-- > 0;) {
      double cap = feed_binds ? std::min(p.samples[i].v_geo, vp) : p.samples[i].v_geo;
      if (i == 0) cap = std::min(cap, p.v_entry);
      const double ds = i + 1 < n ? p.samples[i + 1].s - p.samples[i].s : 0.0;
      const double v = std::min(cap, std::sqrt(carry * carry + 2.0 * p.accel * ds));
      if (!full && !fresh && !last && v == p.v_bw[i]) return;
      p.v_bw[i] = v;
      carry = v;
    }
    last = false;
  }
}

// ---- inputs ----------------------------------------------------------------------

bool Interpolator::apply_block(const program::Block& block) {
  refusal_.clear();
  if (block.index != next_index_) {
    refusal_ = "block " + std::to_string(block.index) + " out of order (expected " + std::to_string(next_index_) + ")";
    return false;
  }
  if (static_cast<int>(block.end.size()) != naxes_ || static_cast<int>(block.start.size()) != naxes_) {
    refusal_ = "block has the wrong number of axes";
    return false;
  }
  for (int a = 0; a < naxes_; ++a) {
    if (!std::isfinite(block.start[a]) || !std::isfinite(block.end[a])) {
      refusal_ = "block " + std::to_string(block.index) + ": coordinate is not finite";
      return false;
    }
  }
  // The path is continuous: a block starts where the one before ended, the first
  // where the machine stands. Anything else would be a jump in one cycle.
  {
    double gap = 0;
    for (int a = 0; a < naxes_; ++a) {
      const double expected = blocks_.empty() ? pos_[a] : blocks_.back().block.end[a];
      gap = std::max(gap, std::fabs(block.start[a] - expected));
    }
    if (gap > 1e-6) {
      refusal_ = "block " + std::to_string(block.index) + " (line " + std::to_string(block.source_line) +
                 ") starts " + std::to_string(gap) + " mm away from where the path is: reload the program here";
      return false;
    }
  }
  if (!(block.feed_mm_per_min >= 0) || !std::isfinite(block.feed_mm_per_min) ||
      (block.kind == program::BlockKind::kLine && block.feed_mm_per_min <= 0) ||
      (block.kind == program::BlockKind::kDwell && !(block.dwell_s >= 0 && std::isfinite(block.dwell_s)))) {
    refusal_ = "block " + std::to_string(block.index) + ": feed or dwell time out of range";
    return false;
  }
  try {
    Planned p(block, motion::PathSegment(block, naxes_));
    plan_block(p);
    if (!blocks_.empty()) plan_junction(blocks_.back(), p);
    else p.v_entry = v_;  // the path starts from the current speed (0 when at rest)
    blocks_.push_back(std::move(p));
  } catch (const std::exception& e) {
    refusal_ = std::string("block ") + std::to_string(block.index) + ": " + e.what();
    return false;
  }
  ++next_index_;
  backward_pass(false);
  return true;
}

void Interpolator::apply_command(const Command& cmd) {
  switch (cmd.kind) {
    case Command::Kind::kLoad:
      if (state_ == RunState::kRunning || state_ == RunState::kHeld || state_ == RunState::kStarved) return;
      blocks_.clear();
      next_index_ = 0;
      blocks_done_ = 0;
      program_cycles_ = 0;
      starved_cycles_ = 0;
      u_ = s_ = v_ = a_ = 0;
      dwell_left_ = -1;
      state_ = RunState::kIdle;
      break;
    case Command::Kind::kStart:
      if (state_ == RunState::kIdle || state_ == RunState::kDone) {
        state_ = RunState::kRunning;
        hold_ = false;
        stopping_ = false;
      }
      break;
    case Command::Kind::kHold: hold_ = true; break;
    case Command::Kind::kResume: hold_ = false; break;
    case Command::Kind::kStop:
      if (state_ != RunState::kIdle && state_ != RunState::kDone) stopping_ = true;
      break;
    case Command::Kind::kReset:
      // After a fault: nothing of the program is left, the path rests where the drives are.
      blocks_.clear();
      next_index_ = 0;
      blocks_done_ = 0;
      program_cycles_ = 0;
      starved_cycles_ = 0;
      u_ = s_ = v_ = a_ = 0;
      dwell_left_ = -1;
      hold_ = false;
      stopping_ = false;
      state_ = RunState::kIdle;
      for (int a = 0; a < naxes_; ++a)
        if (std::isfinite(cmd.position_mm[a])) pos_[a] = cmd.position_mm[a];
      out_.position_mm = pos_;
      break;
    case Command::Kind::kOverride:
      if (std::isfinite(cmd.feed_override)) {
        override_ = std::clamp(cmd.feed_override, 0.0, 1.5);
        backward_pass(true);
      }
      break;
  }
}

// ---- motion ----------------------------------------------------------------------

bool Interpolator::rapid_at_full_speed(const Planned& p) const {
  return p.block.kind == program::BlockKind::kRapid && override_ >= 1.0;
}

double Interpolator::programmed_speed(const Planned& p) const {
  // Override above 1 speeds up feed moves only; a rapid already runs at its axes' limit.
  return p.v_prog * (p.block.kind == program::BlockKind::kRapid ? std::min(override_, 1.0) : override_);
}

double Interpolator::cap_at(const Planned& p, double s, Limit* why, double* v_geo) const {
  const auto& sm = p.samples;
  size_t i = 0;
  if (sm.size() > 2) {
    auto it = std::upper_bound(sm.begin(), sm.end(), s, [](double x, const Sample& q) { return x < q.s; });
    i = it == sm.begin() ? 0 : static_cast<size_t>(it - sm.begin()) - 1;
    i = std::min(i, sm.size() - 2);
  }
  const double span = sm[i + 1].s - sm[i].s;
  const double f = span > 0 ? std::clamp((s - sm[i].s) / span, 0.0, 1.0) : 0.0;
  double v = sm[i].v_geo + (sm[i + 1].v_geo - sm[i].v_geo) * f;
  if (!std::isfinite(v)) v = std::min(sm[i].v_geo, sm[i + 1].v_geo);
  *why = f < 0.5 ? sm[i].limit : sm[i + 1].limit;
  if (v_geo != nullptr) *v_geo = v;
  // A rapid at full override runs at its axes' limit, which v already is.
  if (rapid_at_full_speed(p)) return std::isfinite(v) ? v : p.v_prog;
  const double vp = programmed_speed(p);
  if (vp <= v) {
    *why = Limit::kProgram;
    return vp;
  }
  return v;
}

bool Interpolator::safe(double v_n, double a_n, double s_n, double* v_target) const {
  double A = kInf, J = kInf;
  // The brake is continuous-time; executed in whole cycles it needs about half a
  // cycle's travel at the speed it sheds more room.
  const double T = period_s_;
  double offset = 0;  // arc length of the front block's start relative to its start
  double horizon = -1;
  for (const Planned& p : blocks_) {
    A = std::min(A, p.accel);
    J = std::min(J, p.jerk);
    if (horizon < 0) horizon = brake_distance(v_n, a_n, 0.0, A, J) + v_n * period_s_ + 1e-9;
    if (p.stop_block() || (p.v_entry == 0 && offset > 0)) {
      if (v_target != nullptr) *v_target = 0;
      return brake_distance(v_n, a_n, 0.0, A, J) + 0.5 * v_n * T <= offset - s_n + 1e-9;
    }
    const size_t n = p.samples.size();
    for (size_t i = 0; i < n; ++i) {
      const double d = offset + p.samples[i].s - s_n;
      if (d < 0) continue;
      if (d > horizon) return true;
      const double vt = p.v_bw[i];
      if (vt < v_n + a_n * a_n / (2 * J) &&
          brake_distance(v_n, a_n, vt, A, J) + 0.5 * std::max(0.0, v_n - vt) * T > d + 1e-9) {
        if (v_target != nullptr) *v_target = vt;
        return false;
      }
    }
    offset += p.length;
  }
  return true;
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
    const double left = p.length - s_;
    if (left <= ds - moved + 1e-12) {
      moved += std::max(0.0, left);
      for (int a = 0; a < naxes_; ++a) pos_[a] = p.path.end()[a];
      out_.block_index = p.block.index;
      out_.source_line = p.block.source_line;
      out_.u = p.path.u_end();
      blocks_.pop_front();
      ++blocks_done_;
      s_ = 0;
      u_ = blocks_.empty() ? 0 : blocks_.front().path.u_begin();
      if (!blocks_.empty() && blocks_.front().stop_at_start()) {
        // A corner that is a stop: the step ends on it.
        *reached_stop = true;
        return moved;
      }
      continue;
    }
    const double step = ds - moved;
    // Seed 000 eq. 7: u += Δs/|P'| − Δs²·(P'·P'')/(2|P'|⁴).
    AxisVec P{}, d1{}, d2{};
    p.path.eval(u_, &P, &d1, &d2);
    double sp2 = 0, dd = 0;
    for (int a = 0; a < naxes_; ++a) {
      sp2 += d1[a] * d1[a];
      dd += d1[a] * d2[a];
    }
    const double sp = std::sqrt(sp2);
    double u = u_ + step / sp;
    if (param_update_ != ParamUpdate::kFirstOrder) u -= step * step * dd / (2 * sp2 * sp2);
    u = std::min(u, p.path.u_end());
    if (param_update_ == ParamUpdate::kCorrected) {
      // Newton on |P(u) − P(u_k)| = Δs: the chord of the step has the commanded length.
      for (int it = 0; it < 4; ++it) {
        AxisVec Q{}, q1{}, q2{};
        p.path.eval(u, &Q, &q1, &q2);
        double L = 0, dLdu = 0;
        for (int a = 0; a < naxes_; ++a) L += (Q[a] - P[a]) * (Q[a] - P[a]);
        L = std::sqrt(L);
        if (L <= 0) break;
        for (int a = 0; a < naxes_; ++a) dLdu += (Q[a] - P[a]) * q1[a];
        dLdu /= L;
        const double err = step - L;
        if (std::fabs(err) <= 1e-12 * std::max(1.0, step) || dLdu <= 0) break;
        u = std::clamp(u + err / dLdu, u_, p.path.u_end());
      }
    }
    u_ = u;
    s_ += step;
    pos_ = p.path.point(u_);
    out_.block_index = p.block.index;
    out_.source_line = p.block.source_line;
    out_.u = u_;
    return ds;
  }
  return moved;
}

bool Interpolator::creep_to_stop() {
  // Within half a cycle's jerk-limited travel (J·T³/2) of the next stop point.
  double d = -s_;
  double J = kInf;
  bool first = true;
  for (const Planned& p : blocks_) {
    if (p.stop_block() || (!first && p.v_entry == 0)) break;
    first = false;
    J = std::min(J, p.jerk);
    d += p.length;
  }
  const double T = period_s_;
  // Slow enough that stopping within this cycle stays within the jerk limit.
  if (v_ > 0.5 * J * T * T || std::fabs(a_) > J * T) return false;
  if (!(d > 0) || d > 0.5 * J * T * T * T) return false;
  bool at_stop = false;
  const double moved = advance(d, &at_stop);
  out_.feed_mm_per_min = moved / T * 60.0;
  v_ = a_ = 0;
  return true;
}

const Setpoint& Interpolator::step() {
  out_.cycle = cycle_;
  out_.num_axes = naxes_;
  out_.feed_mm_per_min = 0;
  out_.path_accel_mm_s2 = 0;
  out_.limit = Limit::kNone;
  const bool active = state_ == RunState::kRunning || state_ == RunState::kHeld || state_ == RunState::kStarved;
  if (active) {
    ++program_cycles_;
    const double T = period_s_;
    const bool pausing = hold_ || stopping_;
    // Arrived at a stop block: dwell, end, or wait.
    if (!blocks_.empty() && blocks_.front().stop_block() && v_ == 0) {
      Planned& p = blocks_.front();
      out_.block_index = p.block.index;
      out_.source_line = p.block.source_line;
      if (p.block.kind == program::BlockKind::kEnd) {
        blocks_.pop_front();
        ++blocks_done_;
        state_ = RunState::kDone;
      } else if (!pausing && p.block.kind == program::BlockKind::kEvent && p.block.event.pauses() &&
                 !event_paused_ && !auto_resume_pauses_) {
        // M0, M1, M6: at rest here until the operator resumes (a RESUME input).
        event_paused_ = true;
        hold_ = true;
        state_ = RunState::kHeld;
      } else if (!pausing) {
        if (dwell_left_ < 0) dwell_left_ = static_cast<int64_t>(std::ceil(p.block.dwell_s / T - 1e-9));
        if (dwell_left_ > 0) --dwell_left_;
        state_ = RunState::kRunning;
        if (dwell_left_ == 0) {
          blocks_.pop_front();
          ++blocks_done_;
          dwell_left_ = -1;
          event_paused_ = false;
          if (!blocks_.empty()) u_ = blocks_.front().path.u_begin();
        }
      }
    } else if (blocks_.empty() || (stopping_ && v_ == 0 && a_ == 0)) {
      if (stopping_) {
        blocks_.clear();
        stopping_ = false;
        state_ = RunState::kIdle;
        v_ = a_ = 0;
      } else {
        state_ = RunState::kStarved;
        ++starved_cycles_;
      }
    } else if (!pausing && creep_to_stop()) {
      // A discrete brake ended a hair short of a stop point: step onto it.
      out_.limit = Limit::kLookahead;
    } else {
      Planned& p = blocks_.front();
      Limit why = Limit::kNone;
      double geo_here = kInf;
      const double cap = pausing ? 0.0 : cap_at(p, s_, &why, &geo_here);
      const double A = p.accel, J = p.jerk;
      const double a_lo = std::max(-A, a_ - J * T), a_hi = std::min(A, a_ + J * T);
      // Acceleration that approaches the cap and lands on it within the jerk limit.
      double a_n = std::clamp(landing_accel(cap - v_, A, J, T), a_lo, a_hi);
      auto next_v = [&](double a) { return std::max(0.0, v_ + a * T); };
      auto ok = [&](double a, double* v_target = nullptr) {
        const double vn = next_v(a);
        return safe(vn, a, s_ + 0.5 * (v_ + vn) * T, v_target);
      };
      bool limited = false;
      if (!ok(a_n)) {
        limited = true;
        double v_target = 0;
        if (!ok(a_lo, &v_target)) {
          // Even the hardest brake misses a limit ahead (an override dropped it under
          // the current speed): brake towards it as hard as the jerk limit lets the
          // brake still land on it, rather than braking flat out and hitting zero
          // speed with the brake still on.
          a_n = std::clamp(landing_accel(std::min(cap, v_target) - v_, A, J, T), a_lo, a_hi);
        } else {
          double lo = a_lo, hi = a_n;
          for (int i = 0; i < 14; ++i) {
            const double mid = 0.5 * (lo + hi);
            (ok(mid) ? lo : hi) = mid;
          }
          a_n = lo;
        }
      }
      double v_n = next_v(a_n);
      // Approaching the cap from below, the discrete ramp must not overshoot it by
      // its rounding. (A cap that dropped under a running ramp, by an override,
      // is overshot and returned to within the jerk limit instead.)
      if (v_ <= cap && v_n > cap && v_n - cap <= J * T * T) v_n = cap;
      // Hard geometric caps over the step (chord error, axis velocity) bound its
      // mean speed; the programmed feed and override are followed jerk-limited.
      const double v_avg = 0.5 * (v_ + v_n);
      Limit w2;
      double geo_end = kInf;
      cap_at(p, std::min(p.length, s_ + v_avg * T), &w2, &geo_end);
      const double hard = std::min(geo_here, geo_end);
      if (v_avg > hard) {
        v_n = std::max(0.0, 2.0 * hard - v_);
        if (geo_end < geo_here) why = w2;
      }
      a_n = (v_n - v_) / T;
      // Creep onto a stop point that a discrete brake ended just short of.
      double ds = 0.5 * (v_ + v_n) * T;
      bool at_stop = false;
      const double moved = advance(ds, &at_stop);
      if (at_stop) {
        v_n = 0;
        a_n = 0;
      }
      out_.feed_mm_per_min = moved / T * 60.0;
      out_.path_accel_mm_s2 = a_n;
      if (moved <= 0) out_.limit = Limit::kNone;
      else out_.limit = (limited || v_n < cap * (1 - 1e-6)) ? Limit::kLookahead : why;
      v_ = v_n;
      a_ = a_n;  // the realised acceleration, also on the cycle that comes to rest
      state_ = (hold_ && v_ == 0) ? RunState::kHeld : RunState::kRunning;
      if (blocks_.empty() && v_ > 0) v_ = a_ = 0;
    }
  }
  out_.position_mm = pos_;
  out_.state = state_;
  ++cycle_;
  return out_;
}

}  // namespace cnc::interp
