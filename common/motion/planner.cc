#include "common/motion/planner.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "common/geometry/chord.h"
#include "common/motion/corner.h"
#include "common/motion/feed_override.h"
#include "common/process/roughness.h"

namespace cnc::interp {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
// Share of each axis's acceleration and jerk left to the centripetal terms on
// curved blocks; the tangential planning gets the rest.
constexpr double kCentripetalShare = 0.5;
// Share of each axis's acceleration and jerk a line leaves to the velocity step of a
// junction crossed at speed (corner_speed gives it half a cycle's jerk, and the
// tangential jerk may fall into the same cycle): with the path's limits at the axes'
// (sim3 since the G61 raster), lines at all of them ran G61 micro-segment
// corners at up to 1.58x the jerk limit. A line between two stops gets it back
// (Planned::accel_free).
constexpr double kJunctionShare = 0.5;
// The free limits of a NURBS take its centripetal terms at this margin over their
// sampled values (the curvature may peak between samples).
constexpr double kFreeMargin = 1.25;
// The share of each axis's limits the free limits may take at most: the cyclic side's
// discrete brake onto a stop point (its last step and the creep onto the point) can
// exceed the path's jerk by a little (1.3 % measured, with random holds and
// overrides), which the fixed shares of half the limits had hidden.
constexpr double kFreeShare = 0.97;
// Samples per knot span of a NURBS and per radian of an arc.
constexpr int kSamplesPerSpan = 16;
constexpr double kArcSamplesPerRad = 24.0;

using motion::AxisVec;

// What the refinement looks at in one parameter value: the local speed limit
// (chord error, roughness), the point, the unit tangent and |P'|.
struct Probe {
  double v = 0;
  double sp = 0;  // |P'|; 0 (or negligible) at a singular point, where t is unset
  AxisVec p{}, t{};
};

// Appends u0 and the points that refine (u0, u1) until
//   * the local speed limit v(u) changes by at most 0.5 % between neighbours, so
//     that interpolating it linearly between samples never overestimates it by more
//     than that (limits above v_top cannot bind and are not refined; at most 8
//     levels), and
//   * the curve is resolved: between neighbours the tangent turns by at most
//     kMaxTurn and |P'| changes by at most a factor kMaxSpeedRatio (so a sharp turn
//     or a near-cusp between two samples on straight stretches is not missed, and
//     the arc length's quadrature holds where extreme weights crowd the curve into a
//     small part of the parameter range), down to a chord of kMinChord mm or
//     kMaxGeoDepth levels.
constexpr double kMaxTurnCos = 0.984807753012208;  // cos 10°
constexpr double kCornerTurnCos = 0.939692620785908;  // cos 20°: a turn left unresolved
constexpr double kMaxSpeedRatio = 1.5;
constexpr double kMinChord = 1e-7;
constexpr int kMaxGeoDepth = 48;
constexpr int kMaxLimitDepth = 8;

template <class ProbeFn>
void refine(double u0, const Probe& a, double u1, const Probe& b, const ProbeFn& probe, double v_top, int n,
            int depth, std::vector<double>* out) {
  const double um = 0.5 * (u0 + u1);
  if (!(um > u0 && um < u1)) {
    out->push_back(u0);
    return;
  }
  const double lo = std::min(a.v, b.v);
  bool need = false;
  Probe m;
  bool have_m = false;
  if (depth < kMaxLimitDepth && lo < v_top) {
    m = probe(um);
    have_m = true;
    need = !(std::fabs(b.v - a.v) <= 0.005 * lo && m.v >= 0.995 * lo);
  }
  if (!need && depth < kMaxGeoDepth) {
    double chord2 = 0;
    for (int i = 0; i < n; ++i) chord2 += (b.p[i] - a.p[i]) * (b.p[i] - a.p[i]);
    if (chord2 > kMinChord * kMinChord) {
      if (!have_m) m = probe(um);
      have_m = true;
      auto turned = [n](const Probe& x, const Probe& y) {
        if (!(x.sp > 0) || !(y.sp > 0)) return true;
        double dot = 0;
        for (int i = 0; i < n; ++i) dot += x.t[i] * y.t[i];
        return dot < kMaxTurnCos;
      };
      const double sp_hi = std::max({a.sp, b.sp, m.sp}), sp_lo = std::min({a.sp, b.sp, m.sp});
      need = turned(a, b) || turned(a, m) || turned(m, b) || !(sp_hi <= kMaxSpeedRatio * sp_lo);
    }
  }
  if (!need) {
    out->push_back(u0);
    return;
  }
  refine(u0, a, um, m, probe, v_top, n, depth + 1, out);
  refine(um, m, u1, b, probe, v_top, n, depth + 1, out);
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

bool Planned::stop_block() const {
  return block.kind == program::BlockKind::kDwell || block.kind == program::BlockKind::kEnd ||
         block.kind == program::BlockKind::kEvent;
}

Planner::Planner(const config::MachineConfig& cfg)
    : cfg_(cfg), period_s_(cfg.ipo_period_s), naxes_(static_cast<int>(cfg.axes.size())) {
  if (cfg.cutting.enabled && cfg.cutting.feed_limit && naxes_ >= 3)
    force_ = std::make_unique<process::LiveForce>(process::load_cutting_setup(cfg), cfg.cutting);
}

void Planner::reset_stock() {
  if (force_ && force_dirty_) force_->reset();
  force_dirty_ = false;
  force_prev_valid_ = false;
}

void Planner::force_limits(const Planned& p, std::vector<double>* us, std::vector<double>* v_force) {
  const program::Block& b = p.block;
  auto tip_at = [&](double u) {
    const AxisVec q = p.path.point(u);
    return Eigen::Vector3d(q[0], q[1], q[2]);
  };
  const bool cutting = b.kind != program::BlockKind::kRapid && b.spindle_rpm > 0 && !p.path.degenerate();
  if (!cutting) {
    // Not cut out of the stock (a rapid through material would be a crash, not a cut).
    if (!p.path.degenerate()) {
      force_prev_ = tip_at(p.path.u_end());
      force_prev_valid_ = true;
    }
    return;
  }
  // Stations at most cutting.station_mm apart (by the samples' polyline length).
  const double u0 = p.path.u_begin(), u1 = p.path.u_end();
  double len = 0;
  Eigen::Vector3d q = tip_at(us->front());
  for (size_t i = 1; i < us->size(); ++i) {
    const Eigen::Vector3d r = tip_at((*us)[i]);
    len += (r - q).norm();
    q = r;
  }
  const int n = std::max(1, static_cast<int>(std::ceil(len / cfg_.cutting.station_mm)));
  std::vector<double> st(static_cast<size_t>(n) + 1);
  for (int i = 0; i <= n; ++i) st[static_cast<size_t>(i)] = u0 + (u1 - u0) * i / n;
  st.back() = u1;
  std::vector<double> merged;
  merged.reserve(us->size() + st.size());
  std::merge(us->begin(), us->end(), st.begin(), st.end(), std::back_inserter(merged));
  merged.erase(std::unique(merged.begin(), merged.end()), merged.end());
  *us = std::move(merged);

  // Per station: the engagement before the step that reaches it is cut, the feed per
  // tooth (in XY) the deflection allows, as a path speed.
  v_force->assign(us->size(), kInf);
  const double flutes = force_->tool().flutes;
  const double v_top = motion::kMaxFeedOverride * p.v_prog;  // the most an override can ask
  if (!force_prev_valid_) force_prev_ = tip_at(u0);
  for (size_t i = 0; i < us->size(); ++i) {
    AxisVec P{}, d1{}, d2{};
    p.path.eval((*us)[i], &P, &d1, &d2);
    const Eigen::Vector3d tip(P[0], P[1], P[2]);
    const double sp = norm(d1, naxes_);
    const double txy = sp > 0 ? std::hypot(d1[0], d1[1]) / sp : 0.0;
    if (txy > 1e-9) force_dir_ = Eigen::Vector2d(d1[0], d1[1]).normalized();
    if (txy > 1e-3) {
      force_->engage(tip, force_dir_);
      const double c_top = v_top * txy * 60.0 / (flutes * b.spindle_rpm);
      bool binding = false;
      const double c = force_->limit_feed_per_tooth(c_top, &binding);
      if (binding) (*v_force)[i] = c * flutes * b.spindle_rpm / 60.0 / txy;
    }
    force_->remove(force_prev_, tip);
    force_prev_ = tip;
  }
  force_prev_valid_ = true;
  force_dirty_ = true;
}

Planner::~Planner() = default;

// One block's sampling: its parameter values and what each sample's limits are built from.
struct Planner::BlockWork {
  bool curved = false;
  double share = 0;  // of each axis's limits left to the tangential planning
  double eps = 0;    // the chord tolerance the samples are held to
  bool rough = false;
  process::RoughnessLaw law;
  double sp_floor = 0;        // |P'| under which a point counts as singular
  std::vector<double> us;       // the samples' parameter values
  std::vector<double> v_force;  // cutting.feed_limit: the force limit per sample
  // Per sample (filled by sample_limits):
  std::vector<AxisVec> kvec;   // curvature vector d²P/ds²
  std::vector<AxisVec> tvec;   // unit tangent (zero at a singular point)
  std::vector<double> v_chord;
  std::vector<double> v_rough;  // the roughness law's limit (∞ where it does not apply)
  std::vector<AxisVec> kleft;  // the curvature's left-hand limit (differs at a knot where it jumps)
  AxisVec c_jump{};            // per axis: the largest v²·|Δk_a|/T at a curvature jump (jerk)
  bool inner_corner = false;   // an unresolved turn inside the block (crossed at speed)
  std::vector<std::pair<AxisVec, AxisVec>> knot_corners;  // tangents either side of each knot
};

// The chord limit at curvature kappa: the step whose chord stays within eps, and
// never below a step of arc length 2*eps, which never leaves its chord by more than
// eps (each of its points is within half its length of an end): where the circle
// formula gives 2*rho for a radius rho < eps (a near-cusp of an extreme-weight G5.2,
// rho ~1e-9 mm, crawled at 3e-7 mm/s and never finished).
double Planner::chord_speed(double kappa, double eps) const {
  return kappa > 1e-12 ? std::max(geometry::chord_step_length(1.0 / kappa, eps), 2.0 * eps) / period_s_ : kInf;
}

void Planner::plan_block(Planned& p) {
  const program::Block& b = p.block;
  // A rapid has no programmed feed: it goes as fast as its axes allow, a finite
  // speed set below from the same samples as its axis-velocity limit (so feed hold,
  // override and look-ahead do arithmetic on finite numbers only: ∞ × 0 is NaN).
  const bool rapid = b.kind == program::BlockKind::kRapid;
  p.v_prog = rapid ? rapid_speed(cfg_, b, naxes_) : b.feed_mm_per_min / 60.0;
  p.accel = cfg_.path_accel_mm_s2;
  p.jerk = cfg_.path_jerk_mm_s3;
  if (p.stop_block()) return;

  BlockWork w;
  w.curved = p.path.curved();
  w.share = w.curved ? 1.0 - kCentripetalShare : 1.0 - kJunctionShare;
  // 1 % below the tolerance: the circle formula is exact for constant curvature;
  // where the curvature changes within a step the error runs up to ~0.5 % over it.
  w.eps = 0.99 * program::chord_tolerance_mm(b.path_tolerance_mm, cfg_.chord_tolerance_mm);
  // The roughness law is for cutting moves with a ball end mill; a rapid does not cut, and a
  // thread's speed is the spindle's.
  w.rough = b.process.active() && b.spindle_rpm > 0 && b.kind != program::BlockKind::kRapid && b.sync == program::kSyncNone;
  w.law = process::RoughnessLaw{b.process.ball_radius_mm, b.process.flutes, b.process.pick_feed_mm,
                                b.process.target_rmax_um * 1e-3};
  if (w.rough) {
    const std::string why = w.law.validate();
    if (!why.empty()) throw std::invalid_argument("process parameters: " + why);
  }
  sample_grid(p, w);
  // Between two samples the cyclic side takes the limit as linear in the arc length,
  // and the look-ahead brakes for the samples' own limits only. A limit that holds at
  // one point (a curvature jump, a corner at a knot, the curvature changing fast over
  // a short stretch) set on a sample whose neighbour is far (the refinement above
  // skips stretches whose chord limit is above what the block can reach) made that
  // line a slope the look-ahead did not see, down which the step's hard cap then
  // braked without a jerk limit (a G6.2 with clustered knots: jerk 2.08x the limit).
  // Such an interval gets samples closing in on its lower end by halving, so the
  // low limit holds only at that end, and the look-ahead brakes for it.
  if (!w.curved) {
    if (force_) force_limits(p, &w.us, &w.v_force);
    sample_limits(p, w);
    return;
  }
  sample_limits(p, w);
  const bool extra = close_in_on_low_ends(p, w);
  if (force_) force_limits(p, &w.us, &w.v_force);
  if (extra || force_) sample_limits(p, w);
}

// Parameter values to sample: uniform per knot span (NURBS) or per angle (arcs),
// then refined where the chord or roughness limit changes quickly.
void Planner::sample_grid(const Planned& p, BlockWork& w) const {
  const program::Block& b = p.block;
  std::vector<double>& us = w.us;
  const double u0 = p.path.u_begin(), u1 = p.path.u_end();
  if (!w.curved) {
    us = {u0, u1};
    return;
  }
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
  // |P'| under which a point counts as singular (a vanishing tangent, where the
  // curvature's rounding error grows as 1/|P'|²): against the largest |P'| on the
  // grid, far below any real variation of the speed; its neighbours carry the
  // curvature limits.
  double sp_floor = 0;
  for (double u : grid) {
    AxisVec P{}, d1{}, d2{};
    p.path.eval(u, &P, &d1, &d2);
    sp_floor = std::max(sp_floor, norm(d1, naxes_));
  }
  sp_floor *= 1e-9;
  w.sp_floor = sp_floor;
  auto probe = [&](double u) {
    Probe r;
    AxisVec d1{}, d2{}, k{};
    p.path.eval(u, &r.p, &d1, &d2);
    r.v = kInf;
    r.sp = local_frame(d1, d2, naxes_, &r.t, &k);
    if (r.sp <= sp_floor) {
      r.sp = 0;
      return r;
    }
    const double kappa = norm(k, naxes_);
    r.v = chord_speed(kappa, w.eps);
    if (w.rough && naxes_ >= 3)
      r.v = std::min(r.v, w.law.feed_mm_per_min(b.spindle_rpm, process::feed_inclination_angle(
                                                                    Eigen::Vector3d(r.t[0], r.t[1], r.t[2]))) /
                              60.0);
    return r;
  };
  // Nothing above the fastest the block can go (kMaxFeedOverride × F) needs refining.
  const double v_top = top_speed(p.v_prog);
  Probe pa = probe(grid[0]);
  for (size_t k = 0; k + 1 < grid.size(); ++k) {
    const Probe pb = probe(grid[k + 1]);
    refine(grid[k], pa, grid[k + 1], pb, probe, v_top, naxes_, 0, &us);
    pa = pb;
  }
  us.push_back(u1);
}

// The limits at the samples us (and the force limits v_force, if any), from the
// block's limits down.
void Planner::sample_limits(Planned& p, BlockWork& w) const {
  p.accel = cfg_.path_accel_mm_s2;
  p.jerk = cfg_.path_jerk_mm_s3;
  p.accel_free = cfg_.path_accel_mm_s2;
  p.jerk_free = cfg_.path_jerk_mm_s3;
  w.inner_corner = false;
  w.knot_corners.clear();
  w.c_jump = AxisVec{};
  local_limits(p, w);
  knot_limits(p, w);
  inner_turn_limits(p, w);
  neighbour_limits(p, w);
  arc_lengths(p, w);
  curvature_jerk_limits(p, w);
  free_limits(p, w);
}

// Per sample: speed limits from the local geometry (axis velocities, centripetal
// acceleration, chord, roughness) and the block's tangential limits from its tangents.
void Planner::local_limits(Planned& p, BlockWork& w) const {
  const program::Block& b = p.block;
  const bool rapid = b.kind == program::BlockKind::kRapid;
  const std::vector<double>& us = w.us;
  const size_t n = us.size();
  p.samples.assign(n, Sample{0, 0, kInf, Limit::kNone});
  std::vector<AxisVec>& kvec = w.kvec;
  std::vector<AxisVec>& tvec = w.tvec;
  kvec.assign(n, AxisVec{});
  tvec.assign(n, AxisVec{});
  w.v_chord.assign(n, kInf);
  w.v_rough.assign(n, kInf);
  double v_rapid = p.v_prog;  // a rapid's speed: the least axis-velocity limit of its samples
  for (size_t i = 0; i < n; ++i) {
    AxisVec P{}, d1{}, d2{};
    p.path.eval(us[i], &P, &d1, &d2);
    AxisVec t{};
    Sample& smp = p.samples[i];
    smp.u = us[i];
    if (local_frame(d1, d2, naxes_, &t, &kvec[i]) <= w.sp_floor) {
      kvec[i] = AxisVec{};
      continue;
    }
    tvec[i] = t;
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
        p.accel = std::min(p.accel, w.share * cfg_.axes[a].max_accel_mm_s2 / ta);
        p.jerk = std::min(p.jerk, w.share * cfg_.axes[a].max_jerk_mm_s3 / ta);
        p.accel_free = std::min(p.accel_free, kFreeShare * cfg_.axes[a].max_accel_mm_s2 / ta);
        p.jerk_free = std::min(p.jerk_free, kFreeShare * cfg_.axes[a].max_jerk_mm_s3 / ta);
      }
      if (std::fabs(kvec[i][a]) > 0)
        take(std::sqrt(kCentripetalShare * cfg_.axes[a].max_accel_mm_s2 / std::fabs(kvec[i][a])),
             Limit::kCurvatureAccel);
    }
    w.v_chord[i] = chord_speed(kappa, w.eps);
    if (w.rough && naxes_ >= 3) {
      const double alpha = process::feed_inclination_angle(Eigen::Vector3d(t[0], t[1], t[2]));
      w.v_rough[i] = w.law.feed_mm_per_min(b.spindle_rpm, alpha) / 60.0;
      take(w.v_rough[i], Limit::kRoughness);
    }
  }
  if (rapid) p.v_prog = v_rapid;
}

// The knots of a NURBS: corners and curvature jumps the samples between them cannot see.
void Planner::knot_limits(Planned& p, BlockWork& w) const {
  const std::vector<double>& us = w.us;
  w.kleft = w.kvec;
  if (p.block.kind != program::BlockKind::kNurbs) return;
  const std::vector<double> bp = p.path.nurbs_breakpoints();
  // Corners inside a NURBS: at a knot of multiplicity >= degree the tangent may
  // jump (a sharp corner the curvature samples cannot see). The sample on that
  // knot takes the corner speed of a junction between blocks with the same
  // tangents (its velocity step within one cycle's acceleration and half a cycle's
  // jerk per axis), never zero inside a block: a crawl, where a junction would stop.
  for (size_t k = 1; k + 1 < bp.size(); ++k) {
    const double h = 1e-7 * std::min(bp[k] - bp[k - 1], bp[k + 1] - bp[k]);
    AxisVec P{}, tl{}, tr{}, d2{};
    p.path.eval(bp[k] - h, &P, &tl, &d2);
    p.path.eval(bp[k] + h, &P, &tr, &d2);
    if (!(norm(tl, naxes_) > 0 && norm(tr, naxes_) > 0)) continue;
    bool stop = false;
    const double v = std::max(corner_speed(tl, tr, p.accel, p.jerk, &stop), 1e-3);
    if (!std::isfinite(v)) continue;
    w.knot_corners.emplace_back(tl, tr);
    const auto it = std::lower_bound(us.begin(), us.end(), bp[k]);
    if (it == us.end() || *it != bp[k]) continue;  // the grid holds every knot
    Sample& smp = p.samples[static_cast<size_t>(it - us.begin())];
    if (v < smp.v_geo) {
      smp.v_geo = v;
      smp.limit = Limit::kCurvatureAccel;
    }
  }
  // A knot where the curvature jumps (every knot of a degree-2 NURBS, a repeated
  // knot of a cubic): the centripetal acceleration steps by v²·|Δk_a| within a cycle
  // there, held within the curvature's share of a cycle's jerk per axis, as at a
  // junction between blocks. The curvature's change along the interval that ends on
  // the knot is taken from its left-hand limit (smeared over that interval, the jump
  // gave a limit up to 2% too high: a G5.2 at 1.02x the jerk limit).
  for (size_t k = 1; k + 1 < bp.size(); ++k) {
    const auto it = std::lower_bound(us.begin(), us.end(), bp[k]);
    if (it == us.end() || *it != bp[k]) continue;
    const size_t i = static_cast<size_t>(it - us.begin());
    const double h = 1e-7 * std::min(bp[k] - bp[k - 1], bp[k + 1] - bp[k]);
    AxisVec P{}, d1{}, d2{}, t{}, kl{}, kr{};
    p.path.eval(bp[k] - h, &P, &d1, &d2);
    if (local_frame(d1, d2, naxes_, &t, &kl) <= w.sp_floor) continue;
    p.path.eval(bp[k] + h, &P, &d1, &d2);
    if (local_frame(d1, d2, naxes_, &t, &kr) <= w.sp_floor) continue;
    w.kleft[i] = kl;
    for (int a = 0; a < naxes_; ++a) {
      const double dk = std::fabs(kr[a] - kl[a]);
      if (!(dk > 0) || !std::isfinite(dk)) continue;
      const double v = std::sqrt(kCentripetalShare * cfg_.axes[a].max_jerk_mm_s3 * period_s_ / dk);
      if (v < p.samples[i].v_geo) {
        p.samples[i].v_geo = v;
        p.samples[i].limit = Limit::kCurvatureAccel;
      }
      const double vs = std::min(p.samples[i].v_geo, motion::kMaxFeedOverride * p.v_prog);
      if (std::isfinite(vs)) w.c_jump[a] = std::max(w.c_jump[a], vs * vs * dk / period_s_);
    }
  }
}

// A turn the refinement could not resolve (it stopped at its chord or depth floor:
// a near-cusp narrower than kMinChord) is taken like a corner between blocks.
void Planner::inner_turn_limits(Planned& p, BlockWork& w) const {
  const std::vector<AxisVec>& tvec = w.tvec;
  const size_t n = w.us.size();
  for (size_t i = 0; w.curved && i + 1 < n; ++i) {
    double dot = 0, n0 = 0, n1 = 0;
    for (int a = 0; a < naxes_; ++a) {
      dot += tvec[i][a] * tvec[i + 1][a];
      n0 += tvec[i][a] * tvec[i][a];
      n1 += tvec[i + 1][a] * tvec[i + 1][a];
    }
    if (!(n0 > 0 && n1 > 0) || dot >= kCornerTurnCos) continue;
    bool stop = false;
    const double v = std::max(corner_speed(tvec[i], tvec[i + 1], p.accel, p.jerk, &stop), 1e-3);
    w.inner_corner = true;
    for (size_t k : {i, i + 1})
      if (v < p.samples[k].v_geo) {
        p.samples[k].v_geo = v;
        p.samples[k].limit = Limit::kCurvatureAccel;
      }
  }
}

// The chord and force limits hold over a whole step, and the curvature may peak
// between samples (the force limit is interpolated linearly in between): each sample
// takes the least of its neighbours'.
void Planner::neighbour_limits(Planned& p, const BlockWork& w) const {
  auto spread = [&p](const std::vector<double>& lim, Limit why) {
    for (size_t i = 0; i < lim.size(); ++i) {
      double v = lim[i];
      if (i > 0) v = std::min(v, lim[i - 1]);
      if (i + 1 < lim.size()) v = std::min(v, lim[i + 1]);
      if (v < p.samples[i].v_geo) {
        p.samples[i].v_geo = v;
        p.samples[i].limit = why;
      }
    }
  };
  spread(w.v_chord, Limit::kChord);
  spread(w.v_force, Limit::kForce);
  // What of it the process laws set, for the cyclic side to scale with the spindle.
  p.v_law.clear();
  const size_t n = p.samples.size();
  const bool force = w.v_force.size() == n;
  bool any = false;
  for (size_t i = 0; i < n && !any; ++i) any = w.v_rough[i] < kInf || (force && w.v_force[i] < kInf);
  if (!any) return;
  p.v_law.assign(n, kInf);
  for (size_t i = 0; i < n; ++i) {
    double v = w.v_rough[i];
    if (force)
      for (size_t k = i > 0 ? i - 1 : 0; k <= i + 1 && k < n; ++k) v = std::min(v, w.v_force[k]);
    p.v_law[i] = v;
  }
}

// Arc length by 3-point Gauss–Legendre per sample interval (on top of dense samples).
void Planner::arc_lengths(Planned& p, const BlockWork& w) const {
  const std::vector<double>& us = w.us;
  const size_t n = us.size();
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
}

// The jerk the curvature makes: on an arc through the tangential acceleration, on
// any curve through the curvature changing along it.
void Planner::curvature_jerk_limits(Planned& p, const BlockWork& w) const {
  const program::Block& b = p.block;
  const std::vector<AxisVec>& kvec = w.kvec;
  const size_t n = w.us.size();
  // On an arc the curvature does not change, so the jerk share of the curvature term
  // goes to what the tangential acceleration a adds across the path: its turning with
  // the tangent, a·v·|k_a|, and the centripetal term's growth, d(v²k)/dt = 2·a·v·|k_a|
  // per axis (on an arc of 0.1 mm the path's acceleration from rest turned at 40
  // rad/s: jerk 1.08x the limit). The block's acceleration is held to it at its
  // fastest speed.
  if (b.kind == program::BlockKind::kArcCw || b.kind == program::BlockKind::kArcCcw) {
    for (size_t i = 0; i < n; ++i) {
      const double v = std::min(p.samples[i].v_geo, motion::kMaxFeedOverride * p.v_prog);
      if (!(v > 0) || !std::isfinite(v)) continue;
      for (int a = 0; a < naxes_; ++a)
        if (std::fabs(kvec[i][a]) > 0)
          p.accel = std::min(p.accel, kCentripetalShare * cfg_.axes[a].max_jerk_mm_s3 / (3 * v * std::fabs(kvec[i][a])));
    }
  }
  // Jerk from the curvature changing along the path: v³·|dk/ds| per axis.
  for (size_t i = 0; i + 1 < n && w.curved; ++i) {
    const double ds = p.samples[i + 1].s - p.samples[i].s;
    if (ds <= 0) continue;
    for (int a = 0; a < naxes_; ++a) {
      const double dk = std::fabs(w.kleft[i + 1][a] - kvec[i][a]) / ds;
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

// Free limits (between two stops, no junction crossed at speed). A line has them
// from its axes alone (local_limits). An arc keeps its shares. A NURBS without
// corners inside gets the tangential share of each axis's limits that its curvature
// leaves, not a fixed half: on a nearly straight curve (a CAM pass fitted under G64
// P) the centripetal terms use almost nothing of the axes, and holding the
// tangential limits to half of them slowed every start and stop (the raster at
// 117.5 % of its length over the feed). Per axis, over each interval between samples
// at the fastest speed the interval allows (its samples' limits, at most
// kMaxFeedOverride x F):
//   acceleration: v²·|k_a|, the centripetal part;
//   jerk: v³·|dk_a/ds| + 3·v·A·|k_a|, the curvature's change and the tangential
//   acceleration A turning with the tangent and growing the centripetal term, and
//   v²·|Δk_a|/T at a curvature jump;
// each taken kFreeMargin x, and the rest, never less than the fixed share, divided
// by the largest |t_a|, bounds the block's free limits, within the path's.
void Planner::free_limits(Planned& p, const BlockWork& w) const {
  const std::vector<AxisVec>& kvec = w.kvec;
  const std::vector<AxisVec>& tvec = w.tvec;
  const std::vector<AxisVec>& kleft = w.kleft;
  const size_t n = w.us.size();
  if (w.curved) {
    p.accel_free = p.accel;
    p.jerk_free = p.jerk;
  }
  if (p.block.kind != program::BlockKind::kNurbs || w.inner_corner || n < 2) return;
  const double v_top = top_speed(p.v_prog);
  AxisVec c_acc{}, c_dk{}, c_k{}, t_max{};
  for (size_t i = 0; i + 1 < n; ++i) {
    const double v = std::min(std::max(p.samples[i].v_geo, p.samples[i + 1].v_geo), v_top);
    const double ds = p.samples[i + 1].s - p.samples[i].s;
    for (int a = 0; a < naxes_; ++a) {
      const double k = std::max({std::fabs(kvec[i][a]), std::fabs(kleft[i + 1][a]), std::fabs(kvec[i + 1][a])});
      c_acc[a] = std::max(c_acc[a], v * v * k);
      c_k[a] = std::max(c_k[a], v * k);
      if (ds > 0) c_dk[a] = std::max(c_dk[a], v * v * v * std::fabs(kleft[i + 1][a] - kvec[i][a]) / ds);
      t_max[a] = std::max({t_max[a], std::fabs(tvec[i][a]), std::fabs(tvec[i + 1][a])});
    }
  }
  double accel = cfg_.path_accel_mm_s2;
  for (int a = 0; a < naxes_; ++a) {
    if (!(t_max[a] > 0)) continue;
    const double amax = cfg_.axes[a].max_accel_mm_s2;
    const double budget = std::max((1.0 - kCentripetalShare) * amax, kFreeShare * amax - kFreeMargin * c_acc[a]);
    accel = std::min(accel, budget / t_max[a]);
  }
  double jerk = cfg_.path_jerk_mm_s3;
  for (int a = 0; a < naxes_; ++a) {
    if (!(t_max[a] > 0)) continue;
    const double jmax = cfg_.axes[a].max_jerk_mm_s3;
    const double used = kFreeMargin * (c_dk[a] + 3.0 * accel * c_k[a]) + w.c_jump[a];
    const double budget = std::max((1.0 - kCentripetalShare) * jmax, kFreeShare * jmax - used);
    jerk = std::min(jerk, budget / t_max[a]);
  }
  // A tangent that turns at a knot (by rounding, or a real corner) is crossed at
  // speed: the raised limits hold only where that corner's speed with them stays
  // above the fastest the block can go.
  bool corners_ok = std::isfinite(accel) && std::isfinite(jerk);
  for (const auto& [tl, tr] : w.knot_corners) {
    bool stop = false;
    if (!corners_ok) break;
    corners_ok = corner_speed(tl, tr, accel, jerk, &stop) >= v_top && !stop;
  }
  if (corners_ok && accel > p.accel_free) p.accel_free = accel;
  if (corners_ok && jerk > p.jerk_free) p.jerk_free = jerk;
}

// Samples that close in on the low end of each interval whose limit falls steeply
// (see plan_block); true when any were added.
bool Planner::close_in_on_low_ends(const Planned& p, BlockWork& w) const {
  std::vector<double>& us = w.us;
  const double v_cap = top_speed(p.v_prog);
  std::vector<double> extra;
  for (size_t i = 0; i + 1 < us.size(); ++i) {
    const double va = std::min(p.samples[i].v_geo, v_cap), vb = std::min(p.samples[i + 1].v_geo, v_cap);
    const double lo = std::min(va, vb), hi = std::max(va, vb);
    if (!(hi > 1.005 * lo) || !(hi > lo + 1e-3)) continue;
    // From the far end towards the low one.
    const double u_lo = va < vb ? us[i] : us[i + 1], u_far = va < vb ? us[i + 1] : us[i];
    const AxisVec q = p.path.point(u_lo);
    const double ramp = std::max(kMinChord, 1e-3 * lo * period_s_);
    for (int k = 1; k <= kMaxGeoDepth; ++k) {
      const double u = u_lo + (u_far - u_lo) * std::ldexp(1.0, -k);
      if (!(u > us[i] && u < us[i + 1])) break;
      const AxisVec r = p.path.point(u);
      double d2 = 0;
      for (int a = 0; a < naxes_; ++a) d2 += (r[a] - q[a]) * (r[a] - q[a]);
      extra.push_back(u);
      if (d2 < ramp * ramp) break;
    }
  }
  if (extra.empty()) return false;
  std::sort(extra.begin(), extra.end());
  std::vector<double> merged;
  merged.reserve(us.size() + extra.size());
  std::merge(us.begin(), us.end(), extra.begin(), extra.end(), std::back_inserter(merged));
  merged.erase(std::unique(merged.begin(), merged.end()), merged.end());
  us = std::move(merged);
  return true;
}

void Planner::plan_junction(const Planned& prev, Planned& next) const {
  next.entry_free_ok = true;  // a stop; otherwise decided below
  // A probing move starts and ends at rest (the next block starts where it stopped);
  // so does a spindle-synchronised one (it starts at the spindle's index).
  if (prev.stop_block() || next.stop_block() || prev.path.degenerate() || next.path.degenerate() ||
      prev.block.probe != 0 || next.block.probe != 0 || prev.block.sync != 0 || next.block.sync != 0) {
    next.v_entry = 0;
    return;
  }
  AxisVec P{}, t0{}, t1{}, d2{};
  prev.path.eval(prev.path.u_end(), &P, &t0, &d2);
  next.path.eval(next.path.u_begin(), &P, &t1, &d2);
  // Where a curve's tangent vanishes at its end (a doubled first or last control
  // point, a degree-1 piece of no length), its direction there is that of the chord
  // to where the curve is first a small distance away from the end.
  auto direction = [&](const motion::PathSegment& path, bool at_start, AxisVec* t) {
    const double ua = at_start ? path.u_begin() : path.u_end();
    const double span = path.u_end() - path.u_begin();
    AxisVec q{}, e{}, f{};
    path.eval(ua, &q, &e, &f);
    const double speed = norm(e, naxes_);
    auto dist = [&](double u) {
      const AxisVec x = path.point(u);
      double sq = 0;
      for (int a = 0; a < naxes_; ++a) sq += (x[a] - q[a]) * (x[a] - q[a]);
      return std::sqrt(sq);
    };
    // A point away from the end (a curve may stand still over a part of its range).
    double far_u = ua, chord = 0;
    for (double frac : {0.5, 1.0, 0.25, 0.75}) {
      far_u = at_start ? path.u_begin() + frac * span : path.u_end() - frac * span;
      chord = dist(far_u);
      if (chord > 0) break;
    }
    if (speed * 0.5 * span > 1e-6 * chord) return;  // a proper tangent
    // The first u (from the end) at which the curve is delta away: bisection.
    const double delta = 1e-6 * chord;
    double lo = ua, hi = far_u;
    if (!(dist(hi) >= delta) || !(delta > 0)) return;
    for (int it = 0; it < 80; ++it) {
      const double mid = 0.5 * (lo + hi);
      if (mid == lo || mid == hi) break;
      (dist(mid) >= delta ? hi : lo) = mid;
    }
    const AxisVec in = path.point(hi);
    for (int a = 0; a < naxes_; ++a) (*t)[a] = at_start ? in[a] - q[a] : q[a] - in[a];
  };
  direction(prev.path, false, &t0);
  direction(next.path, true, &t1);
  bool stop = false;
  const double v = corner_speed(t0, t1, std::min(prev.accel, next.accel), std::max(prev.jerk, next.jerk), &stop);
  // No direction found (a block that does not move away from its end): a stop.
  next.v_entry = stop || !(norm(t0, naxes_) > 0 && norm(t1, naxes_) > 0) || std::isnan(v) ? 0 : v;
  // The curvature may jump at the junction (arc to arc in another plane, line to
  // arc): the centripetal acceleration steps by v²·|Δk_a| within a cycle, which must
  // stay within half a cycle's jerk per axis (arc-to-arc junctions ran at up to 2x
  // the jerk limit).
  // The curvature vectors either side of the junction (zero on a line).
  AxisVec k0{}, k1{};
  auto curvature_at = [&](const motion::PathSegment& path, double u, AxisVec* k) {
    AxisVec q{}, d1{}, dd2{}, t{};
    path.eval(u, &q, &d1, &dd2);
    if (path.curved()) local_frame(d1, dd2, naxes_, &t, k);
  };
  if (prev.path.curved()) curvature_at(prev.path, prev.path.u_end(), &k0);
  if (next.path.curved()) curvature_at(next.path, next.path.u_begin(), &k1);
  if (next.v_entry > 0 && (prev.path.curved() || next.path.curved())) {
    for (int a = 0; a < naxes_; ++a) {
      const double dk = std::fabs(k1[a] - k0[a]);
      if (dk > 0 && std::isfinite(dk))
        next.v_entry = std::min(next.v_entry, std::sqrt(0.5 * cfg_.axes[a].max_jerk_mm_s3 * period_s_ / dk));
    }
    if (next.v_entry < 1e-3) next.v_entry = 0;  // a crawl across a junction: a stop there
  }
  // Crossed at speed, the junction still allows the blocks' free limits where what
  // falls into its cycle stays within each axis's limits with them: their tangential
  // jerk and the acceleration turning (as in corner_speed), and the velocity step and
  // the step of the centripetal acceleration, taken twice (two opposite steps in a
  // row). A tangent- and curvature-continuous junction, as between a line and a G64
  // blend, does (its rounding leaves steps of ~1e-9 of the limits: 0.1 % is allowed).
  if (next.v_entry > 0) {
    const double a_free = std::max({prev.accel, prev.accel_free, next.accel, next.accel_free});
    const double j_free = std::max({prev.jerk, prev.jerk_free, next.jerk, next.jerk_free});
    // The fastest the path can cross it (the junction's own limit may be infinite).
    const double ve = std::min(next.v_entry, top_speed(std::max(prev.v_prog, next.v_prog)));
    const double n0 = norm(t0, naxes_), n1 = norm(t1, naxes_), T = period_s_;
    for (int a = 0; a < naxes_; ++a) {
      const double dt = std::fabs(t1[a] / n1 - t0[a] / n0);
      const double tmax = std::max(std::fabs(t0[a]) / n0, std::fabs(t1[a]) / n1);
      const double dk = std::fabs(k1[a] - k0[a]);
      const double step_v = dt > 0 ? ve * dt : 0.0, step_a = dk > 0 ? ve * ve * dk : 0.0;
      const double jerk = j_free * tmax + a_free * dt / T + 2.0 * (step_v / (T * T) + step_a / T);
      const double accel = a_free * tmax + step_v / T + step_a;
      if (!(jerk <= 1.001 * cfg_.axes[a].max_jerk_mm_s3) || !(accel <= 1.001 * cfg_.axes[a].max_accel_mm_s2))
        next.entry_free_ok = false;
    }
  }
}

double Planner::top_speed(double v_prog) const {
  double v = motion::kMaxFeedOverride * v_prog;
  for (int a = 0; a < naxes_; ++a) v = std::min(v, std::sqrt(3.0) * cfg_.axes[a].max_velocity_mm_s);
  return v;
}

double Planner::corner_speed(const AxisVec& t0, const AxisVec& t1, double a_path, double j_path, bool* stop) const {
  const double n0 = norm(t0, naxes_), n1 = norm(t1, naxes_);
  const double T = period_s_;
  double v = kInf;
  double dt2 = 0;
  *stop = false;
  for (int a = 0; a < naxes_; ++a) {
    const double dt = std::fabs(t1[a] / n1 - t0[a] / n0);
    dt2 += dt * dt;
    if (dt < 1e-12) continue;
    const auto& ax = cfg_.axes[a];
    const double tmax = std::max(std::fabs(t0[a]) / n0, std::fabs(t1[a]) / n1);
    // The direction change happens within one cycle, and three things may fall into
    // that cycle on this axis: the path's own jerk (j_path along the tangent), the
    // path acceleration turning by the same angle (a_path * dt within the cycle) and
    // the velocity step (v * dt, a jerk of v * dt / T² in finite differences). The
    // step gets half of what the first two leave of the axis's jerk limit: on CAM
    // micro-segments rounded to 3 decimals a corner comes every cycle, turning back
    // and forth, and two opposite steps in a row make twice the jerk of one. Where
    // nothing is left, the corner is a stop. (With the path's limits at the axes', a
    // flat half of the jerk limit per step ran G61 micro-segments at up to 1.58x it.)
    const double jerk_left = ax.max_jerk_mm_s3 - j_path * tmax - a_path * dt / T;
    const double accel_left = ax.max_accel_mm_s2 - a_path * tmax;
    if (!(jerk_left > 0) || !(accel_left > 0)) {
      *stop = true;
      continue;
    }
    v = std::min(v, motion::corner_step_mm_s(0.5 * accel_left, jerk_left, T) / dt);
  }
  if (dt2 > 0) v = std::min(v, motion::corner_step_mm_s(cfg_.path_accel_mm_s2, cfg_.path_jerk_mm_s3, T) / std::sqrt(dt2));
  return v;
}

void Planner::backward_pass(bool full, PlanUpdate* u) {
  // From the end of the buffer (a stop unless more blocks come) backwards. After a
  // block was appended only the tail changes: once a recomputed limit equals the
  // stored one, everything before it is unchanged too. What changed goes into the
  // update as patches for the cyclic side's copies.
  auto patch = [u](const Entry& e, size_t from) {
    const size_t n = e.v_bw.size();
    if (from >= n) return;
    u->patches.push_back({e.p->serial, static_cast<uint32_t>(from), static_cast<uint32_t>(n - from),
                          static_cast<uint32_t>(u->values.size())});
    u->values.insert(u->values.end(), e.v_bw.begin() + static_cast<std::ptrdiff_t>(from), e.v_bw.end());
  };
  double carry = 0;
  bool last = true;
  for (auto it = list_.rbegin(); it != list_.rend(); ++it) {
    Entry& e = *it;
    const Planned& p = *e.p;
    if (p.stop_block()) {
      carry = 0;
      last = false;
      continue;
    }
    const size_t n = p.samples.size();
    const bool fresh = e.v_bw.size() != n;
    if (fresh) e.v_bw.assign(n, -1.0);
    const double vp = programmed_speed(p);
    const bool feed_binds = !rapid_at_full_speed(p);
    for (size_t i = n; i-- > 0;) {
      const double v_lim = sample_limit(p, i, law_scale_);
      double cap = feed_binds ? std::min(v_lim, vp) : v_lim;
      if (i == 0) cap = std::min(cap, p.v_entry);
      const double ds = i + 1 < n ? p.samples[i + 1].s - p.samples[i].s : 0.0;
      const double v = std::min(cap, std::sqrt(carry * carry + 2.0 * e.accel * ds));
      if (!full && !fresh && !e.recompute && !last && v == e.v_bw[i]) {
        patch(e, i + 1);
        return;
      }
      e.v_bw[i] = v;
      carry = v;
    }
    e.recompute = false;
    patch(e, 0);
    last = false;
  }
}

bool Planner::rapid_at_full_speed(const Planned& p) const {
  return p.block.kind == program::BlockKind::kRapid && override_ >= 1.0 && rapid_override_ >= 1.0;
}

double Planner::programmed_speed(const Planned& p) const {
  // Override above 1 speeds up feed moves only; a rapid already runs at its axes' limit.
  return p.v_prog *
         (p.block.kind == program::BlockKind::kRapid ? std::min(override_, 1.0) * rapid_override_ : override_);
}

PlanUpdate* Planner::fresh_update() {
  std::unique_ptr<PlanUpdate> u;
  if (pool_.empty()) {
    u = std::make_unique<PlanUpdate>();
  } else {
    u = std::move(pool_.back());
    pool_.pop_back();
  }
  u->clear();
  u->epoch = epoch_;
  live_.push_back(std::move(u));
  return live_.back().get();
}

void Planner::recycle(PlanUpdate* u) {
  for (size_t i = 0; i < live_.size(); ++i) {
    if (live_[i].get() != u) continue;
    pool_.push_back(std::move(live_[i]));
    live_.erase(live_.begin() + static_cast<std::ptrdiff_t>(i));
    if (pool_.size() > 64) pool_.pop_back();
    return;
  }
}

void Planner::retire(uint64_t serial_below) {
  retired_below_ = std::max(retired_below_, serial_below);
  // The newest block stays: the next block's junction is planned against it.
  while (list_.size() > 1 && list_.front().p->serial < retired_below_) list_.pop_front();
}

PlanUpdate* Planner::process(const PlanRequest& r) {
  switch (r.kind) {
    case PlanRequest::Kind::kClear:
      list_.clear();
      epoch_ = r.epoch;
      reset_stock();
      return nullptr;
    case PlanRequest::Kind::kOverride: {
      override_ = r.feed_override;
      rapid_override_ = r.rapid_override;
      law_scale_ = r.law_scale;
      PlanUpdate* u = fresh_update();
      backward_pass(true, u);
      return u;
    }
    case PlanRequest::Kind::kBlock: break;
  }
  std::unique_ptr<program::Block> block(r.block);
  if (r.epoch != epoch_) {  // a block of a program already dropped (cannot happen in order; kept safe)
    list_.clear();
    epoch_ = r.epoch;
    reset_stock();
  }
  PlanUpdate* u = fresh_update();
  try {
    auto p = std::make_unique<Planned>(*block, motion::PathSegment(*block, naxes_));
    p->serial = r.serial;
    plan_block(*p);
    // The path starts from rest after a clear; otherwise the junction with the block before.
    if (!list_.empty()) {
      plan_junction(*list_.back().p, *p);
    } else {
      p->v_entry = 0;
      p->entry_free_ok = true;
    }
    p->line_start = list_.empty() || list_.back().p->block.source_line != p->block.source_line ||
                    list_.back().p->block.source_file != p->block.source_file;
    p->live_entry = p->v_entry;
    p->v_bw.assign(p->samples.size(), -1.0);
    p->v_min.assign(p->samples.size(), -1.0);
    u->samples = static_cast<int64_t>(p->samples.size());
    u->block = p.get();
    // The block before now has both of its junctions known: where each is a stop (a
    // corner too sharp to cross, a stop block) or allows the free limits at its speed
    // (Planned::entry_free_ok), it runs with them (Planned::accel_free) from the
    // cyclic side's next cycle on.
    if (!list_.empty()) {
      Entry& prev = list_.back();
      const Planned& q = *prev.p;
      if (!prev.free && !q.stop_block() && q.entry_free_ok && p->entry_free_ok &&
          (q.accel_free > q.accel || q.jerk_free > q.jerk)) {
        prev.free = true;
        prev.accel = std::max(q.accel, q.accel_free);
        prev.recompute = true;
        u->limits.push_back({q.serial, prev.accel, std::max(q.jerk, q.jerk_free)});
      }
    }
    const double accel = p->accel;
    list_.push_back(Entry{std::move(p), {}, accel, false, false});
  } catch (const std::exception& e) {
    u->error = std::string("block ") + std::to_string(block->index) + ": " + e.what();
    return u;
  }
  // Blocks the cyclic side is done with no longer need their look-ahead.
  while (list_.size() > 1 && list_.front().p->serial < retired_below_) list_.pop_front();
  backward_pass(false, u);
  return u;
}

bool SyncPlanLink::push(const PlanRequest& r) {
  if (PlanUpdate* u = planner_.process(r)) ready_.push_back(u);
  return true;
}

void SyncPlanLink::pop() {
  planner_.recycle(ready_.front());
  ready_.pop_front();
}

}  // namespace cnc::interp
