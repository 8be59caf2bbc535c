#include "tools/servo_sim/sim_drive.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cnc::servo_sim {

namespace {
constexpr double kRestartInterval_s = 0.001;  // the ramp of a first write after a pause
}  // namespace

SimDrive::SimDrive(std::string name, int unit, const drive::DriveProfile& profile,
                   const config::ServoSimAxisConfig& sim, double max_velocity_mm_s, double start_mm,
                   double max_accel_mm_s2)
    : name_(std::move(name)), unit_(unit), emu_(profile, start_mm), model_(sim, max_velocity_mm_s, start_mm),
      vmax_ff_(model_.max_velocity_mm_s()), amax_ff_(2.0 * max_accel_mm_s2), comm_timeout_s_(sim.comm_timeout_s),
      comm_decel_(sim.comm_stop_decel_mm_s2 > 0 ? sim.comm_stop_decel_mm_s2
                                                : (max_accel_mm_s2 > 0 ? max_accel_mm_s2 : 1000.0)) {
  pts_[0] = {0.0, start_mm};
  n_pts_ = 1;
}

void SimDrive::push_point(double t_s, double mm) {
  if (n_pts_ == kPoints) {
    std::copy(pts_ + 1, pts_ + kPoints, pts_);
    --n_pts_;
  }
  pts_[n_pts_++] = {t_s, mm};
}

int SimDrive::segment_at(double t_s) const {
  for (int i = n_pts_ - 2; i >= 0; --i)
    if (t_s >= pts_[i].t_s) return t_s < pts_[i + 1].t_s ? i : -1;
  return -1;
}

double SimDrive::extrapolation_slope() const {
  if (comm_timeout_s_ <= 0 || n_pts_ < 2) return 0.0;
  const double v = slope(n_pts_ - 2);
  return std::isfinite(v) && std::fabs(v) <= vmax_ff_ ? v : 0.0;
}

void SimDrive::quick_stop_at(double t_s, double* x, double* v, double* a) const {
  const double dir = stop_v0_ < 0 ? -1.0 : 1.0;
  const double t_end = std::fabs(stop_v0_) / comm_decel_;
  const double tau = std::clamp(t_s - stop_t0_, 0.0, t_end);
  *x = stop_x0_ + stop_v0_ * tau - 0.5 * dir * comm_decel_ * tau * tau;
  *v = stop_v0_ - dir * comm_decel_ * tau;
  *a = t_s - stop_t0_ < t_end ? -dir * comm_decel_ : 0.0;
}

double SimDrive::stream_end_s() const {
  // Only a stream whose rate is known: the first interval after a (re)start is a
  // guess (kRestartInterval_s), and a world standing on it would teach the drive a
  // master's rate without the time it stood (a serial line writes every few ms).
  if (!emu_.follows() || comm_ != Comm::kOk || last_write_s_ < 0 || n_pts_ < 2 || stream_writes_ < 1)
    return std::numeric_limits<double>::infinity();
  return pts_[n_pts_ - 1].t_s;
}

double SimDrive::demand_mm(double now_s) const {
  if (comm_ == Comm::kStopping) {
    double x, v, a;
    quick_stop_at(now_s, &x, &v, &a);
    return x;
  }
  if (now_s < pts_[0].t_s) return pts_[0].mm;
  const int i = segment_at(now_s);
  if (i < 0) {
    // Past the last target: holds it, or (watchdog on) goes on at the last slope.
    const Point& last = pts_[n_pts_ - 1];
    return now_s > last.t_s ? last.mm + extrapolation_slope() * (now_s - last.t_s) : last.mm;
  }
  const double f = (now_s - pts_[i].t_s) / (pts_[i + 1].t_s - pts_[i].t_s);
  return pts_[i].mm + (pts_[i + 1].mm - pts_[i].mm) * f;
}

void SimDrive::feed_forward(double t_s, double* v_ff, double* a_ff) const {
  *v_ff = *a_ff = 0;
  if (comm_ == Comm::kStopping) {
    double x;
    quick_stop_at(t_s, &x, v_ff, a_ff);
    return;
  }
  const int i = segment_at(t_s);
  if (i < 0) {
    if (n_pts_ > 0 && t_s > pts_[n_pts_ - 1].t_s) *v_ff = extrapolation_slope();
    return;
  }
  // The slopes belong to the segments' midpoints; between two midpoints the
  // velocity ramps from one to the other (the acceleration is that ramp's slope).
  const double mid = 0.5 * (pts_[i].t_s + pts_[i + 1].t_s);
  const int j = t_s < mid ? i - 1 : i + 1;  // the neighbouring segment on t's side
  // A segment faster than the drive can move is a jump in the stream (the master
  // stalled and its commands moved on): the position loop takes it, without
  // feed-forward, as a drive would; fed forward it would throw the axis past it.
  const bool jump = std::fabs(slope(i)) > vmax_ff_ || (j >= 0 && j <= n_pts_ - 2 && std::fabs(slope(j)) > vmax_ff_);
  if (jump) return;
  if (j < 0 || j > n_pts_ - 2) {
    *v_ff = slope(i);
    return;
  }
  const double mid_j = 0.5 * (pts_[j].t_s + pts_[j + 1].t_s);
  double acc = (slope(j) - slope(i)) / (mid_j - mid);
  if (amax_ff_ > 0) acc = std::clamp(acc, -amax_ff_, amax_ff_);
  *v_ff = slope(i) + acc * (t_s - mid);
  *a_ff = acc;
}

void SimDrive::shift_time(double dt_s) {
  for (int i = 0; i < n_pts_; ++i) pts_[i].t_s += dt_s;
  if (t_s_ >= 0) t_s_ += dt_s;
  if (last_write_s_ >= 0) last_write_s_ += dt_s;
  if (last_request_s_ >= 0) last_request_s_ += dt_s;
  stop_t0_ += dt_s;
  stream_start_s_ += dt_s;
}

void SimDrive::after_request(double now_s) {
  last_request_s_ = now_s;
  if (comm_ != Comm::kOk) {
    // Stopping or faulted by the watchdog: targets are not followed until a fault
    // reset and enable (then the stream restarts from where the axis stands).
    writes_seen_ = emu_.target_writes();
    last_write_s_ = -1;
    return;
  }
  if (emu_.target_writes() == writes_seen_) return;
  step_to(now_s);  // the dynamics up to the write, on the demand in force until now
  writes_seen_ = emu_.target_writes();
  const double since = now_s - last_write_s_;
  const double target = emu_.target_mm();
  if (last_write_s_ < 0 || since > 0.1) {
    // A write after a pause is a new start: from where the demand stands now, to
    // the target over one short interval.
    const double from = demand_mm(now_s);
    n_pts_ = 0;
    push_point(now_s, from);
    push_point(now_s + kRestartInterval_s, target);
    usual_s_ = 0;
    stream_start_s_ = now_s;
    stream_writes_ = 0;
  } else {
    // The master's rate: the mean interval since the stream (re)started, then a
    // slow running average (a rate estimate from one jittered interval would put
    // the jitter into the schedule).
    ++stream_writes_;
    usual_s_ = stream_writes_ <= 500 ? (now_s - stream_start_s_) / static_cast<double>(stream_writes_)
                                     : usual_s_ + 0.002 * (std::clamp(since, 0.5 * usual_s_, 2 * usual_s_) - usual_s_);
    const Point& last = pts_[n_pts_ - 1];
    // One usual interval after the last target, pulled gently toward the fixed
    // delay after this arrival (the phase-locked clock), never before now.
    double t = last.t_s + usual_s_;
    t += 0.03 * ((now_s + buffer_delay_s(usual_s_)) - t);
    // After an underflow (the writes stopped for longer than the buffer: the demand
    // ran out and held), the target would be due at once and the buffer would
    // refill only at the clock's slow pull: the demand would go on as a staircase
    // without feed-forward, and lag the stream by about 2*zeta*v/omega (1.8 mm at
    // 220 mm/s). Re-seat the buffer instead: the demand resumes from where it held.
    if (t < now_s + 0.5 * usual_s_) t = now_s + buffer_delay_s(usual_s_);
    t = std::max(t, last.t_s + 0.25 * usual_s_);
    push_point(t, target);
  }
  last_write_s_ = now_s;
}

void SimDrive::set_home_switch(const config::ServoSimAxisConfig& sim, int direction) {
  sw_on_ = sim.has_home_switch;
  if (!sw_on_) return;
  sw_side_ = direction < 0 ? -1.0 : 1.0;
  sw_at_ = sim.home_switch_mm;
  sw_sigma_ = sim.home_switch_sigma_mm;
  sw_hyst_ = sim.home_switch_hysteresis_mm;
  sw_rng_.seed(sim.home_switch_seed);
  sw_trip_ = sw_at_ + sw_sigma_ * sw_noise_(sw_rng_);
  sw_closed_ = sw_side_ * (model_.position_mm() - sw_trip_) >= 0;
  emu_.set_home_latch(0.0, 0);
}

void SimDrive::step_switch() {
  if (!sw_on_) return;
  const double x = model_.position_mm();
  if (!sw_closed_ && sw_side_ * (x - sw_trip_) >= 0) {
    // The closing edge: the drive latches where the axis is at this step (a touch
    // probe input's capture; at speed v it lands up to v times the step beyond the trip).
    sw_closed_ = true;
    ++sw_count_;
    sw_latch_mm_ = x;
    emu_.set_home_latch(sw_latch_mm_, sw_count_);
  } else if (sw_closed_ && sw_side_ * (x - sw_trip_) < -sw_hyst_) {
    // Open again: its next closing is at a new point (the switch's repeatability).
    sw_closed_ = false;
    sw_trip_ = sw_at_ + sw_sigma_ * sw_noise_(sw_rng_);
  }
}

void SimDrive::step_to(double now_s) {
  if (t_s_ < 0) t_s_ = now_s;
  if (now_s <= t_s_) return;
  const double dt = now_s - t_s_;
  const double mid_s = t_s_ + 0.5 * dt;
  t_s_ = now_s;
  if (comm_ == Comm::kFaulted && emu_.follows()) comm_ = Comm::kOk;  // reset and enabled again
  if (comm_ == Comm::kOk && comm_timeout_s_ > 0 && emu_.follows() && last_request_s_ >= 0 &&
      now_s - last_request_s_ > comm_timeout_s_) {
    // No request for the timeout: the drive's own quick stop, from its demand's motion.
    double v = 0, a = 0;
    feed_forward(now_s, &v, &a);
    stop_x0_ = demand_mm(now_s);
    stop_v0_ = v;
    stop_t0_ = now_s;
    comm_ = Comm::kStopping;
    ++comm_trips_;
  }
  if (comm_ == Comm::kStopping && emu_.follows()) {
    double x, v, a;
    quick_stop_at(now_s, &x, &v, &a);
    // At rest (the ramp ended and the axis settled on it, or half a second more):
    // the fault, as a drive reports its communication loss.
    if (now_s - stop_t0_ > std::fabs(stop_v0_) / comm_decel_ &&
        (std::fabs(model_.velocity_mm_s()) < 0.01 || now_s - stop_t0_ > std::fabs(stop_v0_) / comm_decel_ + 0.5)) {
      emu_.inject_fault(kCommFaultCode);
      comm_ = Comm::kFaulted;
    }
  } else if (comm_ == Comm::kStopping) {
    comm_ = Comm::kFaulted;  // disabled meanwhile
  }
  if (!emu_.follows()) {
    // Disabled: the demand restarts from wherever the axis comes to rest.
    n_pts_ = 0;
    push_point(now_s, model_.position_mm());
    last_write_s_ = -1;
    model_.step(dt, model_.position_mm(), 0.0, 0.0, false);
    emu_.set_actual(model_.position_mm(), model_.velocity_mm_s());
    emu_.set_following_error(0.0);
    step_switch();
    return;
  }
  double v_ff = 0, a_ff = 0;
  feed_forward(mid_s, &v_ff, &a_ff);
  const double target = demand_mm(now_s);
  if (jammed_)
    model_.jam(target);
  else
    model_.step(dt, target, v_ff, a_ff, true);
  emu_.set_actual(model_.position_mm(), model_.velocity_mm_s());
  emu_.set_following_error(target - model_.position_mm());
  last_fe_ = target - model_.position_mm();
  last_demand_ = target;
  step_switch();
}

void SimWorld::shift(double dt_s) {
  for (SimDrive* d : drives_) d->shift_time(dt_s);
  stood_s_ += dt_s;
}

void SimWorld::stand(double dt_s) {
  if (dt_s <= 0) return;
  shift(dt_s);
  if (t_ >= 0) t_ += dt_s;
}

void SimWorld::advance_to(double now_s) {
  if (t_ >= 0 && now_s <= t_) return;
  double end = std::numeric_limits<double>::infinity();
  for (const SimDrive* d : drives_) end = std::min(end, d->stream_end_s());
  if (now_s > end && max_pause_s_ > 0) {
    // The stream ran dry at `end`: the world stands from then (or from where it
    // already is) to now, within what is left of this stall's allowance.
    const double from = t_ >= 0 ? std::max(end, t_) : end;
    const double stand_s = std::min(now_s - from, max_pause_s_ - episode_s_);
    if (stand_s > 0) {
      if (episode_s_ == 0) ++pauses_;
      shift(stand_s);
      episode_s_ += stand_s;
      paused_s_ += stand_s;
      longest_s_ = std::max(longest_s_, episode_s_);
    }
  } else if (now_s <= end) {
    episode_s_ = 0;
  }
  for (SimDrive* d : drives_) d->step_to(now_s);
  t_ = now_s;
}

}  // namespace cnc::servo_sim
