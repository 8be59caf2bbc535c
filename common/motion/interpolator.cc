#include "common/motion/interpolator.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <stdexcept>

#include "common/geometry/chord.h"
#include "common/process/roughness.h"

namespace cnc::interp {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();

// One phase of constant jerk j for time t applied to (s, v, a).
void integrate(double j, double t, double* s, double* v, double* a) {
  *s += *v * t + 0.5 * *a * t * t + j * t * t * t / 6.0;
  *v += *a * t + 0.5 * j * t * t;
  *a += j * t;
}

}  // namespace

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

namespace {

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
    case Limit::kForce: return "force";
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


Interpolator::Interpolator(const config::MachineConfig& cfg)
    : cfg_(cfg), period_s_(cfg.ipo_period_s), naxes_(static_cast<int>(cfg.axes.size())),
      param_update_(param_update_from_string(cfg.param_update)), own_link_(std::make_unique<SyncPlanLink>(cfg)),
      link_(own_link_.get()), inline_(true),
      blocks_(static_cast<size_t>(std::max(64, 2 * cfg.block_window + 4))), look_(kLookCapacity) {
  for (int a = 0; a < naxes_; ++a) pos_[a] = cfg_.axes[a].home_mm;
  optional_stop_ = cfg_.program.optional_stop;
  wait_for_spindle_ = cfg_.spindle.enabled;
}

Interpolator::Interpolator(const config::MachineConfig& cfg, PlanLink& link)
    : cfg_(cfg), period_s_(cfg.ipo_period_s), naxes_(static_cast<int>(cfg.axes.size())),
      param_update_(param_update_from_string(cfg.param_update)), link_(&link),
      blocks_(static_cast<size_t>(std::max(64, 2 * cfg.block_window + 4))), look_(kLookCapacity) {
  for (int a = 0; a < naxes_; ++a) pos_[a] = cfg_.axes[a].home_mm;
  optional_stop_ = cfg_.program.optional_stop;
  wait_for_spindle_ = cfg_.spindle.enabled;
}

Interpolator::~Interpolator() = default;

void Interpolator::Ring::push_back(Planned* p) {
  if (size_ == slots_.size()) {
    // More blocks queued than the ring was sized for (a caller without the feed
    // policy's window): grow, keeping the order.
    std::vector<Planned*> bigger(2 * slots_.size());
    for (size_t i = 0; i < size_; ++i) bigger[i] = slots_[(head_ + i) % slots_.size()];
    slots_.swap(bigger);
    head_ = 0;
  }
  slots_[(head_ + size_) % slots_.size()] = p;
  ++size_;
}

// ---- planner hand-over -------------------------------------------------------------

bool Interpolator::flush_requests() {
  size_t sent = 0;
  while (sent < pending_n_ && link_->push(pending_[sent])) ++sent;
  if (sent > 0) {
    for (size_t i = sent; i < pending_n_; ++i) pending_[i - sent] = pending_[i];
    pending_n_ -= sent;
  }
  return pending_n_ == 0;
}

bool Interpolator::push_request(const PlanRequest& r) {
  // Requests reach the planner in the order they were made, whenever the link has
  // room: the planner's output depends on that order only.
  if (flush_requests() && link_->push(r)) return true;
  if (pending_n_ == pending_.size()) return false;
  pending_[pending_n_++] = r;
  return true;
}

void Interpolator::clear_blocks() {
  // The cyclic side lets go of every block; the planner frees them on the clear.
  blocks_.clear();
  ++epoch_;
  failed_ = false;
  probe_braking_ = false;
  input_.waiting = false;  // a STOP at the wait: the program ends there
  have_tail_ = false;
  PlanRequest r;
  r.kind = PlanRequest::Kind::kClear;
  r.epoch = epoch_;
  if (!push_request(r)) throw std::runtime_error("planner request queue full: the planner thread is stuck");
}

void Interpolator::pop_block() {
  retired_below_ = blocks_.front().serial + 1;
  retire_pending_ = true;
  blocks_.pop_front();
}

void Interpolator::take(PlanUpdate& u) {
  if (u.epoch != epoch_ || failed_) return;  // of a program dropped since
  if (!u.error.empty()) {
    // The block could not be planned: the program stops here, as after a STOP.
    failed_ = true;
    failure_ = u.error;
    refusal_ = u.error;
    if (state_ != RunState::kIdle && state_ != RunState::kDone) stopping_ = true;
    return;
  }
  if (u.block != nullptr) {
    Planned* p = u.block;
    // On an empty buffer the path starts from its current speed (at rest: a block
    // arriving after the buffer ran out starts from a stop).
    if (blocks_.empty()) p->live_entry = v_;
    p->planned_v0 = 0;
    p->live_accel = p->accel;
    p->live_jerk = p->jerk;
    // Single block: a new line's start is a stop. The path can always stop there: the
    // buffer's end, where the block is appended, is a stop in the look-ahead.
    const bool sb = single_block_ && p->line_start && !blocks_.empty() && !p->stop_block() && p->live_entry > 0;
    blocks_.push_back(p);
    if (sb) single_block_stop(*p);
    planned_samples_ += u.samples;
    ++work_.blocks_taken;
  }
  if (blocks_.empty()) return;
  const uint64_t first = blocks_.front().serial;
  for (const PlanUpdate::Patch& pt : u.patches) {
    if (pt.serial < first || pt.serial - first >= blocks_.size()) continue;  // done, or not yet taken
    Planned& p = blocks_[static_cast<size_t>(pt.serial - first)];
    work_.patch_values += pt.count;
    std::copy(u.values.begin() + pt.offset, u.values.begin() + pt.offset + pt.count,
              p.v_bw.begin() + pt.from);
    if (pt.from == 0 && !p.v_bw.empty()) p.planned_v0 = p.v_bw[0];
    if (pt.from == 0 && p.live_entry < p.v_entry && !p.v_bw.empty()) p.v_bw[0] = std::min(p.v_bw[0], p.live_entry);
    update_suffix_min(p, pt.from, pt.from + pt.count);
  }
  // Free limits: only for a block the cyclic side enters no faster than the planner
  // planned (a block taken on an empty buffer starts from the speed the path has).
  for (const PlanUpdate::Limits& l : u.limits) {
    if (l.serial < first || l.serial - first >= blocks_.size()) continue;
    Planned& p = blocks_[static_cast<size_t>(l.serial - first)];
    if (p.live_entry > p.v_entry) continue;
    p.live_accel = std::max(p.live_accel, l.accel);
    p.live_jerk = std::max(p.live_jerk, l.jerk);
  }
}

void Interpolator::update_suffix_min(Planned& p, size_t from, size_t end) {
  // v_min[i] = min(v_bw[i..n)), a NaN counted as -inf (it never lets safe() skip).
  // v_bw changed in [from, end): v_min is recomputed from end - 1 down to from, and
  // below from until a minimum comes out as it was (the rest below is unchanged then).
  const size_t n = p.v_bw.size();
  if (p.v_min.size() != n) return;
  for (size_t i = std::min(end, n); i-- > 0;) {
    const double x = p.v_bw[i] >= -kInf ? p.v_bw[i] : -kInf;
    const double m = i + 1 < n ? std::min(x, p.v_min[i + 1]) : x;
    if (i < from && m == p.v_min[i]) break;
    p.v_min[i] = m;
  }
}

int Interpolator::apply_plans(int64_t budget, int64_t* budget_used) {
  flush_requests();
  int n = 0;
  while (*budget_used < budget) {
    PlanUpdate* u = link_->front();
    if (u == nullptr) break;
    *budget_used += u->epoch == epoch_ && !failed_ ? u->samples : 0;
    if (u->block != nullptr || !u->error.empty()) ++taken_;
    take(*u);
    link_->pop();
    ++work_.plans_taken;
    ++n;
  }
  return n;
}

bool Interpolator::apply_plans_exact(int n) {
  for (int i = 0; i < n; ++i) {
    PlanUpdate* u = link_->front();
    if (u == nullptr) return false;
    if (u->block != nullptr || !u->error.empty()) ++taken_;
    take(*u);
    link_->pop();
  }
  return true;
}

std::string Interpolator::take_plan_failure() {
  std::string f;
  f.swap(failure_);
  if (f.empty() && sync_failure_[0] != 0) f = sync_failure_.data();
  sync_failure_[0] = 0;
  return f;
}

// ---- motion ----------------------------------------------------------------------

bool Interpolator::rapid_at_full_speed(const Planned& p) const {
  return p.block.kind == program::BlockKind::kRapid && override_ >= 1.0 && rapid_override_ >= 1.0;
}

double Interpolator::programmed_speed(const Planned& p) const {
  // A synchronised move runs at the spindle's rate, no override (LinuxCNC's G33).
  if (p.block.sync != program::kSyncNone) return p.serial == sync_serial_ ? sync_speed_ : 0.0;
  // Override above 1 speeds up feed moves only; a rapid already runs at its axes' limit.
  return p.v_prog *
         (p.block.kind == program::BlockKind::kRapid ? std::min(override_, 1.0) * rapid_override_ : override_);
}

bool Interpolator::own_limit(const Planned& p, size_t i) const {
  // The planner's backward pass: v_bw[i] = min(cap, sqrt(v_bw[i+1]² + 2·A·ds)). Where
  // the ramp is below the cap, the limit comes from the next sample's, and so on to
  // a sample whose limit is its own (or zero: the end of the buffered path). The
  // brake check (a jerk-limited brake that lands on a limit with no acceleration
  // left) needs only those: landing on each ramp sample on the way braked early and
  // in two steps (a raster's stop at a pass end: 26 cycles where 21 do).
  const double v = p.v_bw[i];
  if (!(v > 0)) return true;
  const double v_lim = sample_limit(p, i, law_scale_);
  double cap = rapid_at_full_speed(p) ? v_lim : std::min(v_lim, programmed_speed(p));
  if (i == 0) cap = std::min(cap, p.live_entry);
  return !(v < cap);
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
  if (law_scale_ < 1.0 && !p.v_law.empty()) {
    // A slower spindle lowers the process laws' cap (taken jerk-limited, as an
    // override's), not the hard geometric caps (*v_geo).
    const double v0 = sample_limit(p, i, law_scale_), v1 = sample_limit(p, i + 1, law_scale_);
    double vl = v0 + (v1 - v0) * f;
    if (!std::isfinite(vl)) vl = std::min(v0, v1);
    if (vl < v) {
      v = vl;
      *why = Limit::kRoughness;
    }
  }
  // A rapid at full override runs at its axes' limit, which v already is.
  if (rapid_at_full_speed(p)) return std::isfinite(v) ? v : p.v_prog;
  const double vp = programmed_speed(p);
  if (vp <= v) {
    *why = Limit::kProgram;
    return vp;
  }
  return v;
}

void Interpolator::landing_limits(double cap, double a_hi, double* A, double* J) const {
  if (!std::isfinite(cap)) return;  // no landing: the full acceleration
  const double T = period_s_;
  // A landing takes at most a/(J·T) + 2 cycles at speeds up to max(v, cap); a lower J
  // further on lengthens it, so the reach is taken again with each block's.
  double offset = 0;  // the block's start, relative to s_
  for (size_t b = 0; b < blocks_.size(); ++b) {
    const Planned& p = blocks_[b];
    const double reach = std::max(v_, cap) * T * (std::fabs(a_hi) / (*J * T) + 2.0);
    if (b > 0 && offset - s_ >= reach) return;
    *A = std::min(*A, p.live_accel);
    *J = std::min(*J, p.live_jerk);
    if (p.stop_block()) return;
    offset += p.length;
  }
}

void Interpolator::horizon_limits(double* A, double* J) const {
  // A brake to a sample uses the least limits of the blocks up to it; the horizon,
  // beyond which no sample is checked, must be what a brake with the least limits of
  // every block it could reach needs. Taken from the front block alone, a block of low
  // limits further on (a 0.1 mm G19 arc: 97 mm/s² after a G0's 1500) came into the
  // check only within the front block's brake distance, too late for its own: the
  // junction planned at 0.165 mm/s was crossed at 0.59 mm/s, jerk 1.19x the limit.
  *A = kInf;
  *J = kInf;
  double offset = 0;
  for (size_t b = 0; b < blocks_.size(); ++b) {
    const Planned& p = blocks_[b];
    *A = std::min(*A, p.live_accel);
    *J = std::min(*J, p.live_jerk);
    if (p.stop_block() || (p.live_entry == 0 && offset > 0)) return;
    offset += p.length;
  }
}

bool Interpolator::safe(double v_n, double a_n, double s_n, double* v_target) const {
  const bool r = safe_scan(v_n, a_n, s_n, v_target);
  if (lookahead_check_ != nullptr) lookahead_check_->check(*this, r, v_n, a_n, s_n, v_target);
  return r;
}

bool Interpolator::safe_cached(double v_n, double a_n, double s_n, double* v_target) {
  const bool r = safe_gathered(v_n, a_n, s_n, v_target);
  if (lookahead_check_ != nullptr) lookahead_check_->check(*this, r, v_n, a_n, s_n, v_target);
  return r;
}

bool Interpolator::brake_misses(double v_n, double a_n, double vt, double d, double A, double J, bool entry,
                                double A_before, double J_before, double T) {
  const double margin = 0.5 * std::max(0.0, v_n - vt) * T;
  if (brake_distance(v_n, a_n, vt, A, J) + margin <= d + 1e-9) return false;
  if (!entry) return true;
  // A block's entry is met by a brake with the limits of the blocks before it, if
  // the acceleration is also down to zero there: within this block's lower limits
  // a ramp-down still under way would carry the speed over the entry's.
  double s = brake_distance(v_n, a_n, vt, A_before, J_before);
  if (s == 0 && a_n > 0) {
    const double t = a_n / J_before;
    s = v_n * t + 0.5 * a_n * t * t - J_before * t * t * t / 6.0;
  }
  return s + margin > d + 1e-9;
}

bool Interpolator::safe_scan(double v_n, double a_n, double s_n, double* v_target) const {
  double A = kInf, J = kInf;
  // The brake is continuous-time; executed in whole cycles it needs about half a
  // cycle's travel at the speed it sheds more room.
  const double T = period_s_;
  double offset = 0;  // arc length of the front block's start relative to its start
  // (hz_A_, hz_J_: horizon_limits() of this cycle's buffer, taken once before its checks.)
  const double horizon = brake_distance(v_n, a_n, 0.0, hz_A_, hz_J_) + v_n * period_s_ + 1e-9;
  ++work_.safe_calls;
  for (size_t b = 0; b < blocks_.size(); ++b) {
    const Planned& p = blocks_[b];
    // A brake that ends where block b begins runs in the blocks before it only.
    const double A_before = b > 0 ? A : p.live_accel, J_before = b > 0 ? J : p.live_jerk;
    A = std::min(A, p.live_accel);
    J = std::min(J, p.live_jerk);
    if (p.stop_block() || (p.live_entry == 0 && offset > 0)) {
      if (v_target != nullptr) *v_target = 0;
      return brake_distance(v_n, a_n, 0.0, A_before, J_before) + 0.5 * v_n * T <= offset - s_n + 1e-9;
    }
    // The samples behind s_n do not count: skip them by bisection (the same test as
    // the scan's, so the result is the same bit for bit), not one by one (the scan
    // from the block's start made every cycle linear in how far into the block it was).
    const size_t n = p.samples.size();
    const auto first = std::partition_point(p.samples.begin(), p.samples.end(),
                                            [&](const Sample& x) { return offset + x.s - s_n < 0; });
    const bool entry = b > 0 && first == p.samples.begin() && n > 0 && own_limit(p, 0);
    // No sample from i on with a limit under v_n + a_n²/(2J) (v_min: the least limit
    // from i to the block's end): none of them can be missed, so the scan would only
    // return at the first of them beyond the horizon; the last one tells whether there is one.
    const double v_reach = v_n + a_n * a_n / (2 * J);
    for (size_t i = static_cast<size_t>(first - p.samples.begin()); i < n; ++i) {
      if (p.v_min[i] >= v_reach) {
        ++work_.safe_skips;
        if (offset + p.samples[n - 1].s - s_n > horizon) return true;
        break;
      }
      const double d = offset + p.samples[i].s - s_n;
      ++work_.safe_samples;
      if (d > horizon) return true;
      const double vt = p.v_bw[i];
      if (entry && i > 0 && vt >= p.v_bw[0]) continue;  // met by meeting the entry's
      if (vt < v_reach && own_limit(p, i) && ++work_.brake_evals > 0 &&
          brake_misses(v_n, a_n, vt, d, A, J, entry && i == 0, A_before, J_before, T)) {
        if (v_target != nullptr) *v_target = vt;
        return false;
      }
    }
    offset += p.length;
  }
  return true;
}

void Interpolator::build_look(double vn_lo, double a_lo, double sn_lo, double vn_hi, double a_hi, double sn_hi) {
  // For every a in [a_lo, a_hi] (v_n and s_n grow with a): safe() skips the samples
  // behind s_n >= sn_lo, returns true at the first sample beyond its horizon (at
  // most look_H_, checked per try), fails only at a sample whose limit is under
  // v_n + a²/(2J) <= vn_hi + max(a_lo², a_hi²)/(2J) or at the stop point. Gathered
  // here: those samples, the stop point, the last sample before it.
  look_ok_ = false;
  look_n_ = 0;
  look_term_ = false;
  look_last_ = false;
  look_fail_ = SIZE_MAX;
  if (blocks_.empty()) return;
  ++work_.look_builds;
  {
    const double h_lo = brake_distance(vn_lo, a_lo, 0.0, hz_A_, hz_J_) + vn_lo * period_s_ + 1e-9;
    const double h_hi = brake_distance(vn_hi, a_hi, 0.0, hz_A_, hz_J_) + vn_hi * period_s_ + 1e-9;
    look_H_ = std::max(h_lo, h_hi);
  }
  look_sn_lo_ = sn_lo;
  look_sn_hi_ = sn_hi;
  look_vn_hi_ = vn_hi;
  look_m2_ = std::max(a_lo * a_lo, a_hi * a_hi);
  if (!std::isfinite(look_H_) || !std::isfinite(sn_lo) || !std::isfinite(sn_hi) || !std::isfinite(vn_hi) ||
      !std::isfinite(look_m2_))
    return;
  double A = kInf, J = kInf;
  double offset = 0;
  for (size_t b = 0; b < blocks_.size(); ++b) {
    const Planned& p = blocks_[b];
    const double A_before = b > 0 ? A : p.live_accel, J_before = b > 0 ? J : p.live_jerk;
    A = std::min(A, p.live_accel);
    J = std::min(J, p.live_jerk);
    if (p.stop_block() || (p.live_entry == 0 && offset > 0)) {
      look_term_ = true;
      look_term_off_ = offset;
      look_term_A_ = A_before;
      look_term_J_ = J_before;
      break;
    }
    const double theta = look_vn_hi_ + look_m2_ / (2 * J);
    const size_t n = p.samples.size();
    const auto first = std::partition_point(p.samples.begin(), p.samples.end(),
                                            [&](const Sample& x) { return offset + x.s - sn_lo < 0; });
    // The entry sample ahead of some tries and behind others: safe_scan answers those.
    bool entry = false;
    if (b > 0 && first == p.samples.begin() && n > 0 && own_limit(p, 0)) {
      if (offset + p.samples[0].s - sn_hi < 0) return;
      entry = true;
    }
    for (size_t i = static_cast<size_t>(first - p.samples.begin()); i < n; ++i) {
      if (offset + p.samples[i].s - sn_hi > look_H_) {
        // Beyond every try's horizon: each returns true by here.
        look_ok_ = true;
        return;
      }
      if (p.v_min[i] >= theta) break;  // nothing under it to the block's end
      if (entry && i > 0 && p.v_bw[i] >= p.v_bw[0]) continue;  // met by meeting the entry's
      if (p.v_bw[i] < theta && own_limit(p, i)) {
        if (look_n_ == look_.size()) return;  // too many: full checks
        look_[look_n_++] = LookCand{offset, p.samples[i].s, p.v_bw[i], A, J, A_before, J_before, entry && i == 0};
      }
    }
    if (n > 0) {
      look_last_ = true;
      look_last_off_ = offset;
      look_last_s_ = p.samples[n - 1].s;
    }
    offset += p.length;
  }
  look_ok_ = true;
}

bool Interpolator::safe_gathered(double v_n, double a_n, double s_n, double* v_target) {
  const double horizon = look_ok_ ? brake_distance(v_n, a_n, 0.0, hz_A_, hz_J_) + v_n * period_s_ + 1e-9 : 0.0;
  if (!look_ok_ || !(horizon <= look_H_) || !(s_n >= look_sn_lo_ && s_n <= look_sn_hi_) || !(v_n <= look_vn_hi_) ||
      !(a_n * a_n <= look_m2_)) {
    ++work_.look_fallbacks;
    return safe_scan(v_n, a_n, s_n, v_target);
  }
  ++work_.safe_calls;
  const double T = period_s_;
  auto fails = [&](const LookCand& c, double d) {
    ++work_.safe_samples;
    const double vt = c.vt;
    return vt < v_n + a_n * a_n / (2 * c.J) && ++work_.brake_evals > 0 &&
           brake_misses(v_n, a_n, vt, d, c.A, c.J, c.entry, c.A_before, c.J_before, T);
  };
  // Reached only when no sample before it is beyond the horizon.
  auto term_reached = [&] { return !(look_last_ && look_last_off_ + look_last_s_ - s_n > horizon); };
  auto term_ok = [&] {
    ++work_.brake_evals;
    return brake_distance(v_n, a_n, 0.0, look_term_A_, look_term_J_) + 0.5 * v_n * T <= look_term_off_ - s_n + 1e-9;
  };
  if (v_target == nullptr) {
    // Any miss within reach answers false, whichever is found first: the last one first.
    if (look_fail_ < look_n_) {
      const LookCand& c = look_[look_fail_];
      const double d = c.offset + c.s - s_n;
      if (d >= 0 && d <= horizon && fails(c, d)) return false;
    } else if (look_fail_ == look_n_ && look_term_ && term_reached() && !term_ok()) {
      return false;
    }
  }
  for (size_t k = 0; k < look_n_; ++k) {
    const LookCand& c = look_[k];
    const double d = c.offset + c.s - s_n;
    if (d < 0) continue;
    if (d > horizon) return true;
    if (fails(c, d)) {
      look_fail_ = k;
      if (v_target != nullptr) *v_target = c.vt;
      return false;
    }
  }
  if (!look_term_ || !term_reached()) return true;
  if (v_target != nullptr) *v_target = 0;
  if (term_ok()) return true;
  look_fail_ = look_n_;
  return false;
}

bool Interpolator::creep_to_stop() {
  // Within half a cycle's jerk-limited travel (J·T³/2) of the next stop point.
  const double T = period_s_;
  // J below is at most the front block's: a path faster than that allows cannot
  // creep, and is told so without walking the buffer (the walk gives the same false).
  if (!blocks_.empty() && !blocks_.front().stop_block()) {
    const double J0 = blocks_.front().live_jerk;
    if (v_ > 0.5 * J0 * T * T || std::fabs(a_) > J0 * T) return false;
  }
  double d = -s_;
  double J = kInf;
  bool first = true;
  for (size_t b = 0; b < blocks_.size(); ++b) {
    const Planned& p = blocks_[b];
    if (p.stop_block() || (!first && p.live_entry == 0)) break;
    first = false;
    J = std::min(J, p.live_jerk);
    d += p.length;
    if (d > 0.5 * J * T * T * T) return false;  // only grows while the bound only falls
  }
  // Slow enough that stopping within this cycle stays within the jerk limit.
  if (v_ > 0.5 * J * T * T || std::fabs(a_) > J * T) return false;
  if (!(d > 0) || d > 0.5 * J * T * T * T) return false;
  bool at_stop = false;
  const double moved = advance(d, &at_stop);
  out_.feed_mm_per_min = moved / T * 60.0;
  v_ = a_ = 0;
  rest_left_ = moved > 0 && !blocks_.empty() && !blocks_.front().stop_block() ? kRestCycles : 0;  // a dwell or event rests anyway
  return true;
}

void Interpolator::single_block_stop(Planned& p) {
  p.single_block_stop = true;
  p.live_entry = 0;
  if (!p.v_bw.empty() && p.v_bw[0] > 0) {
    p.v_bw[0] = 0;
    update_suffix_min(p, 0, 1);
  }
}

void Interpolator::mark_single_block_stops() {
  // The first line start ahead that a jerk-limited brake from where the path is now
  // reaches at rest (with the margin of a cycle and a half of travel: the look-ahead
  // check runs on the next cycle's state), and every one after it.
  const double T = period_s_;
  double A = kInf, J = kInf;
  double offset = 0;
  bool reachable = false;
  for (size_t b = 0; b < blocks_.size(); ++b) {
    Planned& p = blocks_[b];
    if (b > 0) {
      if (!reachable) reachable = p.stop_at_start() || brake_distance(v_, a_, 0.0, A, J) + 1.5 * v_ * T + 1e-9 <= offset - s_;
      if (reachable && p.line_start && !p.stop_at_start()) single_block_stop(p);
    }
    A = std::min(A, p.live_accel);
    J = std::min(J, p.live_jerk);
    offset += p.length;
  }
}

void Interpolator::unmark_single_block_stops() {
  // Back to the planner's junction speeds (lifting a stop never makes a brake miss:
  // every limit beyond it was planned for the path running through it).
  for (size_t b = 0; b < blocks_.size(); ++b) {
    Planned& p = blocks_[b];
    if (!p.single_block_stop) continue;
    p.single_block_stop = false;
    if (b == 0 && s_ == 0 && v_ == 0) continue;  // the path stands on it: it starts from rest
    p.live_entry = p.v_entry;
    if (!p.v_bw.empty()) {
      p.v_bw[0] = std::min(p.planned_v0, p.v_entry);
      update_suffix_min(p, 0, 1);
    }
  }
}

void Interpolator::output_position() {
  out_.position_mm = pos_;
  if (!any_offset_) return;
  for (int a = 0; a < naxes_; ++a) out_.position_mm[a] += drive_offset_[a];
}

const Setpoint& Interpolator::step() {
  if (pending_n_ > 0) flush_requests();
  out_.cycle = cycle_;
  out_.num_axes = naxes_;
  out_.feed_mm_per_min = 0;
  out_.path_accel_mm_s2 = 0;
  out_.limit = Limit::kNone;
  const bool active = state_ == RunState::kRunning || state_ == RunState::kHeld || state_ == RunState::kStarved;
  if (active) {
    ++program_cycles_;
    hold_at_line_start();
    track_probe_move();
    if (probe_braking_ && v_ == 0) end_probe_move();
    update_sync();
    // A feed hold waits for the end of a synchronised move that has started (the
    // tool is in the thread); a STOP does not.
    const bool in_sync = sync_.phase == SyncMove::kAcquire || sync_.phase == SyncMove::kTrack;
    const bool pausing = (hold_ && !in_sync) || stopping_ || door_resume_ || probe_braking_;
    if (rigid_tap_front() && (sync_serial_ == blocks_.front().serial || (rest_left_ == 0 && !pausing))) {
      rigid_tap_step();
    } else if (!blocks_.empty() && blocks_.front().stop_block() && v_ == 0) {
      at_stop_block(pausing);
    } else if (blocks_.empty() || (stopping_ && v_ == 0 && a_ == 0)) {
      end_or_starve();
    } else if (rest_left_ > 0) {
      // At rest on the stop point the last cycle ended on (the start from rest assumes
      // a cycle of it: without it the axes' jerk ran up to 1.07x the limit there).
      --rest_left_;
      out_.limit = Limit::kLookahead;
    } else if (!pausing && creep_to_stop()) {
      // A discrete brake ended a hair short of a stop point: step onto it.
      out_.limit = Limit::kLookahead;
    } else {
      move_along_path(pausing);
    }
  }
  if (door_hold_ && state_ == RunState::kHeld) door_spindle_stop();
  if (sync_.phase == SyncMove::kTrack && !blocks_.empty() && blocks_.front().serial == sync_serial_) {
    // The step's error against the spindle, counted until the end's brake may begin (it
    // leaves the spindle).
    const Planned& f = blocks_.front();
    sync_.error_mm = sync_target_ - s_;
    const double A = f.live_accel, J = f.live_jerk;
    if (f.length - s_ > 2 * (v_ * v_ / (2 * A) + v_ * A / J) + v_ * period_s_ &&
        cycle_ - sync_.lock_cycle >= SyncMove::kSettleCycles)
      sync_.max_error_mm = std::max(sync_.max_error_mm, std::fabs(sync_.error_mm));
  }
  if (probe_.block_index >= 0 && !probe_.done && (blocks_.empty() || blocks_.front().serial != probe_serial_)) {
    probe_.done = true;  // ran to its end (or the program was dropped)
    probe_.end_cycle = cycle_;
  }
  output_position();
  if (out_.feed_mm_per_min > 0) outputs_.motion();
  out_.state = state_;
  if (auto_resume_pauses_) {
    // The dry run's spindle: the VFD's first-order response (spindle.sim), turning as commanded.
    const double cmd = spindle_.direction * spindle_.rpm / 60.0;
    const double tau = cfg_.spindle.enabled ? cfg_.spindle.sim.time_constant_s : 0.0;
    ideal_rps_ = tau > 0 ? cmd + (ideal_rps_ - cmd) * std::exp(-period_s_ / tau) : cmd;
    ideal_rev_ += ideal_rps_ * period_s_;
  }
  ++cycle_;
  if (retire_pending_) {
    // The planner may free what the path has left behind.
    retire_pending_ = false;
    link_->retire(retired_below_);
  }
  return out_;
}

bool Interpolator::wants_spindle_position() const {
  for (size_t b = 0; b < blocks_.size(); ++b)
    if (blocks_[b].block.sync != program::kSyncNone) return true;
  return false;
}

double Interpolator::law_scale_for(double measured_rpm) const {
  if (!(spindle_.program_rpm > 0) || !std::isfinite(measured_rpm)) return 1.0;
  // Steps of 1/128: a drive's speed reading wanders in its last digit; each step re-plans the look-ahead.
  return std::clamp(std::round(std::fabs(measured_rpm) / spindle_.program_rpm * 128.0) / 128.0, 0.0, 1.0);
}

bool Interpolator::spindle_position(double* rev, double* rps) const {
  if (auto_resume_pauses_) {
    *rev = ideal_rev_;
    *rps = ideal_rps_;
    return true;
  }
  // Samples come every cycle while a synchronised move is queued; 25 cycles (0.1 s
  // at 4 ms) without one is a lost spindle feedback, not a late datagram.
  constexpr int64_t kStaleCycles = 25;
  if (sp_applied_ < 0 || cycle_ - sp_applied_ > kStaleCycles) return false;
  // Where the spindle will be when the axes reach this cycle's setpoint (played at
  // this cycle, reached spindle.sync_lead_s later), at its speed and acceleration
  // (the samples are a few cycles old).
  const double dt = (static_cast<double>(cycle_) - sp_cycle_) * period_s_ + cfg_.spindle.sync_lead_s;
  *rps = sp_rps_ + sp_acc_ * dt;
  *rev = sp_rev_ + (sp_rps_ + 0.5 * sp_acc_ * dt) * dt;
  return true;
}

double Interpolator::acquisition_lag(double v, double A, double J, bool trapezoid) const {
  // How far a speed-up from rest to v (the landing the cycle makes, within A and J)
  // falls behind a path that ran at v from the start; bounded (a few hundred cycles).
  const double T = period_s_;
  double vc = 0, a = 0, lag = 0;
  for (int k = 0; k < 10000 && vc < v * (1 - 1e-3); ++k) {
    const double an = std::clamp(landing_accel(v - vc, A, J, T), std::max(-A, a - J * T), std::min(A, a + J * T));
    const double vn = vc + an * T;
    lag += v * T - (trapezoid ? 0.5 * (vc + vn) : vn) * T;
    vc = vn;
    a = an;
  }
  return lag;
}

double Interpolator::follow_speed(double target, double v_ff) const {
  // The spindle's rate times the pitch, and a correction that closes the gap to where
  // the spindle puts the path at the end of this cycle in about 8 cycles.
  return v_ff + (target - (s_ + v_ff * period_s_)) / (8 * period_s_);
}

void Interpolator::update_sync() {
  if (rigid_tap_front()) return;  // rigid_tap_step's
  if (blocks_.empty() || blocks_.front().block.sync != program::kSyncG33) {
    sync_.phase = SyncMove::kNone;
    sync_speed_ = 0;
    return;
  }
  const Planned& f = blocks_.front();
  const double pitch = f.block.sync_pitch_mm;
  const double dir = spindle_.direction < 0 ? -1.0 : 1.0;
  double rev = 0, rps = 0;
  const bool have = spindle_position(&rev, &rps);
  if (f.serial != sync_serial_) {
    if (s_ != 0 || v_ != 0) return;  // not yet at rest on its start
    sync_serial_ = f.serial;
    sync_ = SyncMove{f.block.index, SyncMove::kWaitIndex, 0, 0, 0, 0};
    sync_speed_ = 0;
    if (!have) {
      std::snprintf(sync_failure_.data(), sync_failure_.size(),
                    "spindle-synchronised move at block %lld: no measured spindle position (is the spindle's "
                    "encoder configured and answering?)", static_cast<long long>(f.block.index));
      stopping_ = true;
      return;
    }
    sync_.index_rev = std::floor(dir * rev) + 1.0;  // the next index ahead
  }
  if (!have) {
    if (sync_.phase != SyncMove::kNone && !stopping_) {
      std::snprintf(sync_failure_.data(), sync_failure_.size(),
                    "spindle-synchronised move at block %lld: the spindle's measured position stopped arriving",
                    static_cast<long long>(f.block.index));
      stopping_ = true;
    }
    sync_speed_ = 0;
    return;
  }
  const double u = dir * rev, w = dir * rps;  // along the turning direction
  const double v_sync = std::max(0.0, pitch * w);
  switch (sync_.phase) {
    case SyncMove::kWaitIndex:
      if (u < sync_.index_rev) {
        sync_speed_ = 0;
        break;
      }
      sync_.phase = SyncMove::kAcquire;
      // The phase: the index, less the distance a speed-up from rest to the commanded
      // rate leaves the path behind (the same on every pass at one S, whatever the
      // spindle's speed does meanwhile and however late in its cycle the index came).
      sync_.lock_rev = sync_.index_rev +
                       acquisition_lag(pitch * spindle_.rpm / 60.0, f.live_accel, f.live_jerk, true) / pitch;
      [[fallthrough]];
    case SyncMove::kAcquire:
      sync_speed_ = v_sync;
      if (v_ < v_sync * (1 - 1e-3)) break;
      sync_.lock_cycle = cycle_;
      sync_.phase = SyncMove::kTrack;
      [[fallthrough]];
    case SyncMove::kTrack: {
      sync_target_ = pitch * (u - sync_.lock_rev);
      sync_speed_ = std::clamp(follow_speed(sync_target_, v_sync), 0.0, 1.5 * v_sync);
      break;
    }
    case SyncMove::kExit:  // a rigid tap's
    case SyncMove::kNone: break;
  }
}

bool Interpolator::rigid_tap_front() const {
  return !blocks_.empty() && blocks_.front().block.sync == program::kSyncRigidTap;
}

void Interpolator::rigid_tap_step() {
  Planned& f = blocks_.front();
  const double T = period_s_;
  const double pitch = f.block.sync_pitch_mm;
  const double A = f.live_accel, J = f.live_jerk;
  state_ = RunState::kRunning;
  out_.block_index = f.block.index;
  out_.source_line = f.block.source_line;
  if (f.serial != sync_serial_) {
    sync_serial_ = f.serial;
    sync_ = SyncMove{};
    sync_.block_index = f.block.index;
    sync_.phase = SyncMove::kWaitIndex;
    sync_.direction = spindle_.direction;
    sync_.rpm = spindle_.rpm;
    sync_.program_rpm = spindle_.program_rpm;
    s_ = v_ = a_ = 0;
  }
  const double dir = sync_.direction < 0 ? -1.0 : 1.0;
  double rev = 0, rps = 0;
  const bool have = spindle_position(&rev, &rps) && sync_.direction != 0;
  double a_n = 0;
  auto toward = [&](double v_target) {
    return std::clamp(landing_accel(v_target - v_, A, J, T), std::max(-A, a_ - J * T), std::min(A, a_ + J * T));
  };
  if (!have) {
    // No spindle to follow: stop where the tap is (the tool may be in the hole).
    if (sync_failure_[0] == 0 && !stopping_)
      std::snprintf(sync_failure_.data(), sync_failure_.size(),
                    "rigid tap at block %lld: no measured spindle position (is the spindle's encoder configured and "
                    "answering?)", static_cast<long long>(f.block.index));
    stopping_ = true;
    a_n = toward(0.0);
  } else {
    if (stopping_ && !sync_.stopping && sync_.phase >= SyncMove::kAcquire) {
      // A STOP in the hole: the spindle stops and the tap follows it to rest.
      sync_.stopping = true;
      ++spindle_.seq;
      spindle_.direction = 0;
      spindle_.rpm = 0;
      spindle_.program_rpm = 0;
    }
    const double u = dir * rev, w = dir * rps;
    switch (sync_.phase) {
      case SyncMove::kWaitIndex:
        if (!sync_.index_set) {
          sync_.index_rev = std::floor(u) + 1.0;  // the next index ahead
          sync_.index_set = true;
        }
        if (stopping_ || u < sync_.index_rev) break;
        sync_.phase = SyncMove::kAcquire;
        sync_.lock_rev = sync_.index_rev + acquisition_lag(pitch * sync_.rpm / 60.0, A, J, false) / pitch;  // as G33's
        [[fallthrough]];
      case SyncMove::kAcquire: {
        const double v_sync = std::max(0.0, pitch * w);
        a_n = toward(v_sync);
        if (v_ + a_n * T < v_sync * (1 - 1e-3)) break;
        sync_.lock_cycle = cycle_;
        sync_.phase = SyncMove::kTrack;
        [[fallthrough]];
      }
      case SyncMove::kTrack: {
        const double target = pitch * (u - sync_.lock_rev);
        sync_target_ = target;
        const double As = 0.5 * A / pitch, Js = 0.25 * J / pitch;
        if (!sync_.reversed && !sync_.stopping &&
            target + pitch * brake_distance(sync_.rpm / 60.0, 0.0, 0.0, As, Js) >= f.length) {
          // The depth: the spindle reverses (LinuxCNC's rigid tap), its command's ramp
          // begun where it stands at the depth; the tap follows the spindle (past the
          // depth by what the spindle lags behind its command).
          sync_.reversed = true;
          sync_.ramping = true;
          sync_.ramp_rps = sync_.direction * sync_.rpm / 60.0;
          sync_.ramp_acc = 0;
          sync_.ramp_target = -sync_.direction * std::min(sync_.rpm * f.block.tap_retract_scale, cfg_.spindle.max_rpm) / 60.0;
        }
        if (sync_.ramping && !sync_.stopping) {
          const double acc = std::clamp(landing_accel(sync_.ramp_target - sync_.ramp_rps, As, Js, T),
                                        std::max(-As, sync_.ramp_acc - Js * T), std::min(As, sync_.ramp_acc + Js * T));
          sync_.ramp_rps += acc * T;
          sync_.ramp_acc = acc;
          if (std::fabs(sync_.ramp_rps - sync_.ramp_target) <= 1e-9 * std::fabs(sync_.ramp_target) && acc == 0) {
            sync_.ramp_rps = sync_.ramp_target;
            sync_.ramping = false;
          }
          ++spindle_.seq;
          spindle_.direction = sync_.ramp_rps > 0 ? 1 : sync_.ramp_rps < 0 ? -1 : 0;
          spindle_.rpm = std::fabs(sync_.ramp_rps) * 60.0;
        }
        // On the way up, leave the spindle where a jerk-limited brake still stops on the start.
        if (!(sync_.reversed && w < 0 && v_ < 0 &&
              s_ <= 1.5 * brake_distance(-v_, -a_, 0.0, 0.5 * A, 0.25 * J) + 4 * (-v_) * T)) {
          // Follow as G33 does, within the jerk limit (a step straight onto each
          // predicted position rang: the samples' stamps scatter).
          const double v_ff = pitch * w;
          // Stopped by a STOP: once the spindle all but stands, the tap lands at rest.
          a_n = sync_.stopping && std::fabs(v_ff) < 1e-3 ? toward(0.0)
                                                          : toward(follow_speed(target, v_ff));
          break;
        }
        // The rest of the way up is a quintic stop on the start (zero speed and
        // acceleration there), as short as keeps its jerk within half the limit, its
        // acceleration within 0.8 of it and its speed from reversing.
        sync_.phase = SyncMove::kExit;
        plan_tap_exit(A, J);
        [[fallthrough]];
      }
      case SyncMove::kExit: {
        ++exit_.k;
        const double t = std::min(static_cast<double>(exit_.k) * T, exit_.te);
        const double x = exit_.x(t);
        a_n = ((exit_.d - x - s_) / T - v_) / T;  // the step onto the quintic's point
        break;
      }
      case SyncMove::kNone: break;
    }
    if (sync_.stopping && sync_.phase != SyncMove::kTrack) a_n = toward(0.0);
  }
  double v_n = v_ + a_n * T;
  double s_n = s_ + v_n * T;
  if (sync_.phase == SyncMove::kExit && static_cast<double>(exit_.k) * T >= exit_.te - 1e-12) {
    s_n = 0;  // the quintic's end: on the start at rest
    v_n = 0;
  }
  if (sync_.phase == SyncMove::kTrack) {
    sync_.error_mm = sync_target_ - s_n;
    if (cycle_ - sync_.lock_cycle >= SyncMove::kSettleCycles)
      sync_.max_error_mm = std::max(sync_.max_error_mm, std::fabs(sync_.error_mm));
  }
  if (sync_.reversed) sync_.overshoot_mm = std::max(sync_.overshoot_mm, s_n - f.length);
  const double moved = s_n - s_;
  out_.feed_mm_per_min = std::fabs(moved) / T * 60.0;
  out_.path_accel_mm_s2 = (v_n - v_) / T;
  out_.limit = Limit::kProgram;
  a_ = (v_n - v_) / T;
  v_ = v_n;
  s_ = s_n;
  const double L = f.length;
  for (int a = 0; a < naxes_; ++a) pos_[a] = f.block.start[a] + (f.block.end[a] - f.block.start[a]) * (s_ / L);
  // The line's parameter where the tap is (held at the ends past them: the monitor
  // measures the step against the line between two parameters).
  out_.u = f.path.u_begin() + (f.path.u_end() - f.path.u_begin()) * std::clamp(s_ / L, 0.0, 1.0);
  const bool at_rest = v_ == 0;
  if (sync_.phase == SyncMove::kExit && s_ == 0 && at_rest) {
    end_rigid_tap(false);
  } else if (stopping_ && at_rest && (sync_.phase < SyncMove::kAcquire || sync_.stopping || !have) &&
             (!have || std::fabs(rps) * pitch < 1e-3)) {
    end_rigid_tap(true);
  }
}

double Interpolator::TapExit::x(double t) const {
  return ((((c5 * t + c4) * t + c3) * t + 0.5 * a0) * t + v0) * t;
}

void Interpolator::plan_tap_exit(double A, double J) {
  // Along the motion (upwards): x from 0 to d = s_, from speed -v_ and acceleration -a_.
  const double T = period_s_;
  TapExit& e = exit_;
  e.k = 0;
  e.d = s_;
  e.v0 = -v_;
  e.a0 = -a_;
  // The shortest that keeps the limits; failing that (a start too near), the one of least
  // jerk among those that never turn back past the start.
  double best_j = std::numeric_limits<double>::infinity();
  int best_n = 0;
  for (int pass = 0; pass < 2; ++pass)
  for (int n = 2; n <= 1000; ++n) {
    if (pass == 1 && n != best_n) continue;
    const double te = n * T;
    const double h = e.d - e.v0 * te - 0.5 * e.a0 * te * te, hv = -e.v0 - e.a0 * te, ha = -e.a0;
    e.te = te;
    e.c3 = (10 * h - 4 * hv * te + 0.5 * ha * te * te) / (te * te * te);
    e.c4 = (-15 * h + 7 * hv * te - ha * te * te) / (te * te * te * te);
    e.c5 = (6 * h - 3 * hv * te + 0.5 * ha * te * te) / (te * te * te * te * te);
    if (pass == 1) return;
    bool monotone = true;
    double jmax = 0, amax = 0;
    for (int i = 0; i <= 64 && monotone; ++i) {
      const double t = te * i / 64.0;
      const double v = (((5 * e.c5 * t + 4 * e.c4) * t + 3 * e.c3) * t + e.a0) * t + e.v0;
      const double a = ((20 * e.c5 * t + 12 * e.c4) * t + 6 * e.c3) * t + e.a0;
      const double j = (60 * e.c5 * t + 24 * e.c4) * t + 6 * e.c3;
      monotone = v >= -1e-9;
      jmax = std::max(jmax, std::fabs(j));
      amax = std::max(amax, std::fabs(a));
    }
    if (!monotone) continue;
    if (amax <= 0.8 * A && jmax <= 0.5 * J) return;
    if (jmax < best_j) {
      best_j = jmax;
      best_n = n;
    }
  }
}

void Interpolator::end_rigid_tap(bool program_stops) {
  if (program_stops) {
    // Where the STOP left it: the program ends there.
    clear_blocks();
    spindle_off();
    stopping_ = false;
    hold_ = false;
    state_ = RunState::kIdle;
    v_ = a_ = s_ = 0;
    sync_.phase = SyncMove::kNone;
    return;
  }
  // Back on its start: the spindle turns as it did before the tap.
  ++spindle_.seq;
  spindle_.direction = sync_.direction;
  spindle_.rpm = sync_.rpm;
  spindle_.program_rpm = sync_.program_rpm;
  for (int a = 0; a < naxes_; ++a) pos_[a] = blocks_.front().block.start[a];
  pop_block();
  ++blocks_done_;
  s_ = v_ = a_ = 0;
  u_ = blocks_.empty() ? 0 : blocks_.front().path.u_begin();
  sync_.phase = SyncMove::kNone;
  rest_left_ = kRestCycles;
}

void Interpolator::track_probe_move() {
  if (blocks_.empty() || blocks_.front().block.probe == 0 || blocks_.front().serial == probe_serial_) return;
  const Planned& f = blocks_.front();
  probe_serial_ = f.serial;
  probe_ = ProbeMove{f.block.index, f.block.probe, false, false, -1};
  probe_braking_ = false;
}

void Interpolator::end_probe_move() {
  // At rest in the probing move after its trip: it ends here, and the next block
  // (made with this result) starts here.
  probe_braking_ = false;
  pop_block();
  ++blocks_done_;
  a_ = 0;
  s_ = 0;
  for (int a = 0; a < naxes_; ++a) tail_[a] = pos_[a];
  have_tail_ = true;
  u_ = blocks_.empty() ? 0 : blocks_.front().path.u_begin();  // as advance() leaves an empty buffer
  probe_.done = true;
  probe_.end_cycle = cycle_;
}

void Interpolator::hold_at_line_start() {
  // Single block: at rest at a line's start, hold until RESUME (the line START
  // began with runs; an event that holds by itself, M0 M1 M6, holds there instead).
  if (single_block_ && !auto_resume_pauses_ && !hold_ && !stopping_ && v_ == 0 && s_ == 0 && !blocks_.empty()) {
    const Planned& f = blocks_.front();
    const bool own_pause = f.block.kind == program::BlockKind::kEvent && f.block.event.pauses() &&
                           (f.block.event.kind != program::EventKind::kOptionalStop || optional_stop_);
    if (f.line_start && f.serial != single_block_passed_ && f.block.kind != program::BlockKind::kEnd && !own_pause) {
      single_block_passed_ = f.serial;
      if (single_block_go_) {
        single_block_go_ = false;
      } else {
        hold_ = true;
        single_block_held_ = true;
      }
    }
  }
}

void Interpolator::at_stop_block(bool pausing) {
  // Arrived at a stop block: dwell, end, or wait.
  Planned& p = blocks_.front();
  out_.block_index = p.block.index;
  out_.source_line = p.block.source_line;
  if (p.block.kind == program::BlockKind::kEnd) {
    const bool program_end = p.block.event.number != program::kEndOfOperatorLine;
    pop_block();
    ++blocks_done_;
    state_ = RunState::kDone;
    if (program_end) spindle_off();
  } else if (stopping_) {
    // STOP at rest before a dwell or an event: the program ends here.
    clear_blocks();
    spindle_off();
    stopping_ = false;
    hold_ = false;
    state_ = RunState::kIdle;
    v_ = a_ = 0;
  } else if (!pausing && p.block.kind == program::BlockKind::kEvent && p.block.event.pauses() &&
             (p.block.event.kind != program::EventKind::kOptionalStop || optional_stop_) && !event_paused_ &&
             !auto_resume_pauses_) {
    // M0, M1, M6: at rest here until the operator resumes (a RESUME input).
    event_paused_ = true;
    hold_ = true;
    state_ = RunState::kHeld;
  } else if (!pausing) {
    if (wait_on_input(p)) {
      state_ = RunState::kRunning;  // at rest until the input's value or the timeout
      return;
    }
    if (p.block.kind == program::BlockKind::kEvent &&
        (p.block.event.kind == program::EventKind::kSpindle || p.block.event.kind == program::EventKind::kSpindleOrient) &&
        spindle_taken_ != p.serial)
      take_spindle_event(p);
    if (p.block.kind == program::BlockKind::kEvent && p.block.event.kind == program::EventKind::kOverrides &&
        overrides_taken_ != p.serial) {
      // M48-M53 (bits: feed, speed, adaptive, hold): the speed bit enables the spindle override.
      overrides_taken_ = p.serial;
      const bool on = (p.block.event.number & 2) != 0;
      if (on != spindle_override_on_) {
        spindle_override_on_ = on;
        spindle_reoverride();
      }
    }
    if (p.block.kind == program::BlockKind::kEvent && outputs_taken_ != p.serial) {
      outputs_taken_ = p.serial;
      outputs_.take(p.block.event);
    }
    if (spindle_wait_) {
      state_ = RunState::kRunning;  // at rest until the spindle is at speed
      return;
    }
    // (An M19 event's dwell_s is its Q, the wait for the orientation: no dwell.)
    if (dwell_left_ < 0)
      dwell_left_ = p.block.kind == program::BlockKind::kEvent ? 0
                                                                : static_cast<int64_t>(std::ceil(p.block.dwell_s / period_s_ - 1e-9));
    if (dwell_left_ > 0) --dwell_left_;
    state_ = RunState::kRunning;
    if (dwell_left_ == 0) {
      pop_block();
      ++blocks_done_;
      dwell_left_ = -1;
      event_paused_ = false;
      if (!blocks_.empty()) u_ = blocks_.front().path.u_begin();
    }
  } else if (hold_) {
    state_ = RunState::kHeld;  // held at rest before a dwell or an event
  }
}

bool Interpolator::wait_on_input(const Planned& p) {
  if (p.block.kind != program::BlockKind::kEvent || p.block.event.kind != program::EventKind::kWaitInput) return false;
  // The dry run passes it at once (the program server took the value rs274 takes).
  if (auto_resume_pauses_) return false;
  if (input_serial_ != p.serial) {
    input_serial_ = p.serial;
    input_.block_index = p.block.index;
    input_.wait = program::InputWait::of(p.block.event.number);
    input_.timeout_cycles = input_.wait.mode == program::InputWait::kImmediate || !(p.block.event.value > 0)
                                ? 0
                                : std::max<int64_t>(1, static_cast<int64_t>(std::ceil(p.block.event.value / period_s_ - 1e-9)));
    input_.start_cycle = cycle_;
    input_.waiting = true;
    input_.value = 0;
  }
  if (input_.waiting && input_.timeout_cycles > 0 && cycle_ - input_.start_cycle >= input_.timeout_cycles)
    end_input_wait(-1.0);  // LinuxCNC: a timeout is no error, #5399 = -1
  return input_.waiting;
}

void Interpolator::end_input_wait(double value) {
  input_.waiting = false;
  input_.value = value;
  ++input_.results;
}

void Interpolator::take_spindle_event(const Planned& p) {
  spindle_taken_ = p.serial;
  if (p.block.event.kind == program::EventKind::kSpindleOrient) {
    // M19: the spindle stops at the angle; the path waits for it only with a Q.
    ++spindle_.seq;
    spindle_.direction = 0;
    spindle_.rpm = spindle_.program_rpm = 0;
    spindle_.orient = true;
    spindle_.orient_deg = p.block.event.value;
    spindle_.orient_mode = p.block.event.number;
    spindle_wait_ = wait_for_spindle_ && !auto_resume_pauses_ && p.block.dwell_s > 0;
    return;
  }
  const int dir = p.block.event.number > 0 ? 1 : p.block.event.number < 0 ? -1 : 0;
  const double rpm = dir == 0 || !(p.block.event.value > 0) ? 0.0 : p.block.event.value;
  if (dir == spindle_.direction && rpm == spindle_.program_rpm && !spindle_.orient) return;  // no change: nothing to wait for
  ++spindle_.seq;
  spindle_.orient = false;
  spindle_.direction = dir;
  spindle_.program_rpm = rpm;
  spindle_.rpm = overridden_rpm(rpm);
  spindle_wait_ = wait_for_spindle_ && !auto_resume_pauses_ && dir != 0 && spindle_.rpm > 0;
}

double Interpolator::overridden_rpm(double program_rpm) const {
  if (!spindle_override_on_ || spindle_override_ == 1.0) return program_rpm;  // as before any override: S as programmed
  return std::min(program_rpm * spindle_override_, cfg_.spindle.max_rpm);
}

void Interpolator::spindle_reoverride() {
  if (spindle_.direction == 0) return;  // a stopped spindle takes it at its next M3/M4
  const double rpm = overridden_rpm(spindle_.program_rpm);
  if (rpm == spindle_.rpm) return;
  ++spindle_.seq;
  spindle_.rpm = rpm;
}

void Interpolator::door_spindle_stop() {
  if (spindle_.direction == 0) return;
  door_spindle_ = spindle_;
  spindle_wait_ = false;
  ++spindle_.seq;
  spindle_.direction = 0;
  spindle_.rpm = 0;
  spindle_.program_rpm = 0;
}

void Interpolator::program_start_modes() {
  spindle_wait_ = false;
  door_hold_ = false;
  door_resume_ = false;
  door_spindle_ = SpindleState{};
  spindle_override_on_ = true;  // M48 is in effect at a program's start (LinuxCNC's)
}

void Interpolator::spindle_off() {
  outputs_.end();  // the coolant stops with the spindle
  program_start_modes();
  if (spindle_.direction == 0 && spindle_.rpm == 0 && !spindle_.orient) return;
  ++spindle_.seq;
  spindle_.orient = false;
  spindle_.direction = 0;
  spindle_.rpm = 0;
  spindle_.program_rpm = 0;
}

void Interpolator::end_or_starve() {
  // No block left to run (or a STOP came to rest): the program ends, or waits for blocks.
  if (stopping_) {
    clear_blocks();
    spindle_off();
    stopping_ = false;
    state_ = RunState::kIdle;
    v_ = a_ = 0;
  } else {
    state_ = RunState::kStarved;
    ++starved_cycles_;
  }
}

void Interpolator::move_along_path(bool pausing) {
  const double T = period_s_;
  Planned& p = blocks_.front();
  Limit why = Limit::kNone;
  double geo_here = kInf;
  const double cap = pausing ? 0.0 : cap_at(p, s_, &why, &geo_here);
  const double A = p.live_accel, J = p.live_jerk;
  const double a_lo = std::max(-A, a_ - J * T), a_hi = std::min(A, a_ + J * T);
  bool limited = false;
  double a_n = lookahead_accel(cap, A, J, a_lo, a_hi, &limited);
  double v_n = std::max(0.0, v_ + a_n * T);
  // Approaching the cap from below, the discrete ramp must not overshoot it by
  // its rounding, as far as the jerk limit lets the acceleration drop this cycle.
  // (A cap that dropped under a running ramp, by an override, is overshot and
  // returned to within the jerk limit instead: clipped onto it, the acceleration
  // fell by up to 2·J·T in one cycle, 1.2x an axis's jerk limit once the path's
  // jerk was the axis's.)
  if (v_ <= cap && v_n > cap && v_n - cap <= J * T * T) v_n = std::max(cap, v_ + a_lo * T);
  v_n = geometric_speed_bound(p, v_n, geo_here, &why);
  a_n = (v_n - v_) / T;
  // Creep onto a stop point that a discrete brake ended just short of.
  double ds = 0.5 * (v_ + v_n) * T;
  bool at_stop = false;
  const double moved = advance(ds, &at_stop);
  if (at_stop) {
    v_n = 0;
    a_n = 0;
    rest_left_ = moved > 0 && !blocks_.empty() && !blocks_.front().stop_block() ? kRestCycles : 0;
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

double Interpolator::lookahead_accel(double cap, double A, double J, double a_lo, double a_hi, bool* limited) {
  const double T = period_s_;
  // Acceleration that approaches the cap and lands on it within the jerk limit, of
  // every block the landing runs into: with the front block's alone, a landing begun
  // in a 0.133 mm block (J 58,200) went on in one of J 30,000 under the same cap,
  // overshot it and was clipped onto it (Y's jerk 2.25x its limit).
  double A_land = A, J_land = J;
  landing_limits(cap, a_hi, &A_land, &J_land);
  double a_n = std::clamp(landing_accel(cap - v_, A_land, J_land, T), a_lo, a_hi);
  horizon_limits(&hz_A_, &hz_J_);  // the brake checks' horizon, for this cycle's buffer
  auto next_v = [&](double a) { return std::max(0.0, v_ + a * T); };
  auto ok = [&](double a) {
    const double vn = next_v(a);
    return safe(vn, a, s_ + 0.5 * (v_ + vn) * T);
  };
  if (ok(a_n)) return a_n;
  *limited = true;
  // The search below tries accelerations in [a_lo, a_n] only: gather what they check once.
  const double vn_lo = next_v(a_lo), vn_hi = next_v(a_n);
  build_look(vn_lo, a_lo, s_ + 0.5 * (v_ + vn_lo) * T, vn_hi, a_n, s_ + 0.5 * (v_ + vn_hi) * T);
  auto ok_in = [&](double a, double* v_target = nullptr) {
    const double vn = next_v(a);
    return safe_cached(vn, a, s_ + 0.5 * (v_ + vn) * T, v_target);
  };
  double v_target = 0;
  if (!ok_in(a_lo, &v_target)) {
    // Even the hardest brake misses a limit ahead (an override dropped it under
    // the current speed): brake towards it as hard as the jerk limit lets the
    // brake still land on it, rather than braking flat out and hitting zero
    // speed with the brake still on.
    return std::clamp(landing_accel(std::min(cap, v_target) - v_, A, J, T), a_lo, a_hi);
  }
  double lo = a_lo, hi = a_n;
  for (int i = 0; i < 14; ++i) {
    const double mid = 0.5 * (lo + hi);
    (ok_in(mid) ? lo : hi) = mid;
  }
  return lo;
}

double Interpolator::geometric_speed_bound(const Planned& p, double v_n, double geo_here, Limit* why) const {
  // Hard geometric caps over the step (chord error, axis velocity) bound its
  // mean speed; the programmed feed and override are followed jerk-limited.
  const double T = period_s_;
  const double v_avg = 0.5 * (v_ + v_n);
  Limit w2;
  double geo_end = kInf;
  cap_at(p, std::min(p.length, s_ + v_avg * T), &w2, &geo_end);
  double hard = std::min(geo_here, geo_end);
  // And the samples the step passes over: a narrow dip between them (a turn the
  // planner resolved only at its chord floor) bounds the step too.
  if (p.path.curved()) {
    const double s_hi = std::min(p.length, s_ + v_avg * T);
    auto it = std::partition_point(p.samples.begin(), p.samples.end(),
                                   [&](const Sample& x) { return x.s <= s_; });
    // (Never below 1 um/s: a sample's limit of zero, a singular point, would hold
    // the step short of it for good; the look-ahead brakes for it as before.)
    for (; it != p.samples.end() && it->s < s_hi; ++it) hard = std::min(hard, std::max(it->v_geo, 1e-3));
  }
  if (v_avg > hard) {
    v_n = std::max(0.0, 2.0 * hard - v_);
    if (geo_end < geo_here) *why = w2;
  }
  return v_n;
}

}  // namespace cnc::interp
