#include "services/monitor/monitor.h"

#include <cmath>
#include <limits>
#include <sstream>

#include "common/motion/chord_error.h"
#include "common/process/roughness.h"

namespace cnc::monitor {
namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr size_t kMaxBlocks = 512;
constexpr size_t kMaxSetpoints = 2048;
// The actual feed's window (see track_actual_feed).
constexpr int64_t kFeedWindowUs = 40'000;
constexpr size_t kMaxFeedSamples = 64;
}  // namespace

Monitor::Monitor(const config::MachineConfig& cfg)
    : cfg_(cfg), naxes_(static_cast<int>(cfg.axes.size())), cycles_(kMaxSetpoints) {
  if (cfg.cutting.enabled && naxes_ >= 3)
    force_ = std::make_unique<process::LiveForce>(process::load_cutting_setup(cfg), cfg.cutting);
}

Monitor::ForceSlot Monitor::cutting_force(const SetpointIn& sp) {
  // A new program cuts a new part: the stock is the uncut box again.
  if (sp.program_token != cut_token_) {
    if (cut_stock_dirty_) force_->reset();
    cut_stock_dirty_ = false;
    cut_prev_valid_ = false;
    cut_token_ = sp.program_token;
  }
  ForceSlot out;
  // A setpoint older than the last one (a repeat, out of order) is no step of the tool.
  if (cut_prev_valid_ && sp.cycle <= cut_prev_.cycle) return {kNaN, kNaN, kNaN, kNaN, kNaN};
  const Known* k = find(sp.program_token, sp.block_index);
  const Eigen::Vector3d tip(sp.position_mm[0], sp.position_mm[1], sp.position_mm[2]);
  // A setpoint that does not move (or the first: no step) cuts nothing (dwells, program
  // stops, the end: blocks without geometry, which the monitor does not keep); a move
  // of an unknown block is unknown.
  const bool still = !cut_prev_valid_ || tip == Eigen::Vector3d(cut_prev_.position_mm[0], cut_prev_.position_mm[1],
                                                               cut_prev_.position_mm[2]);
  const bool known = k != nullptr || sp.block_index < 0 || still;
  const bool cutting = k != nullptr && k->block.kind != program::BlockKind::kRapid && k->block.spindle_rpm > 0;
  if (!known) out = {kNaN, kNaN, kNaN, kNaN, kNaN};
  if (cutting && cut_prev_valid_ && sp.cycle > cut_prev_.cycle) {
    const Eigen::Vector3d prev(cut_prev_.position_mm[0], cut_prev_.position_mm[1], cut_prev_.position_mm[2]);
    const Eigen::Vector2d dxy = (tip - prev).head<2>();
    const double dist = dxy.norm();
    if (dist > 1e-9) cut_dir_ = dxy / dist;
    // The feed per tooth in XY from the commanded step (cycles apart when setpoints were lost).
    const double v_xy = dist / (static_cast<double>(sp.cycle - cut_prev_.cycle) * cfg_.ipo_period_s);
    const double c = v_xy * 60.0 / (force_->tool().flutes * k->block.spindle_rpm);
    force_->engage(tip, cut_dir_);
    const process::ForceEstimate e = force_->estimate(c);
    out = {e.mean_force.x(), e.mean_force.y(), e.mean_force.z(), e.peak_force_n, e.peak_deflection_mm};
    force_->remove(prev, tip);
    cut_stock_dirty_ = true;
  }
  cut_prev_ = sp;
  cut_prev_valid_ = true;
  return out;
}

Monitor::CycleSlot* Monitor::slot(int64_t cycle) {
  return &cycles_[static_cast<size_t>(cycle < 0 ? -cycle : cycle) % cycles_.size()];
}

bool Monitor::commanded_at(double cycle, int n_axes, motion::AxisVec* out) const {
  const double f0 = std::floor(cycle);
  const auto c0 = static_cast<int64_t>(f0);
  const SetpointIn* a = setpoint_at(c0);
  if (a == nullptr) return false;
  const double f = cycle - f0;
  const SetpointIn* b = f > 0 ? setpoint_at(c0 + 1) : a;
  if (b == nullptr) return false;
  for (int i = 0; i < n_axes; ++i) (*out)[i] = a->position_mm[i] + (b->position_mm[i] - a->position_mm[i]) * f;
  return true;
}

const SetpointIn* Monitor::setpoint_at(int64_t cycle) const {
  const CycleSlot& s = cycles_[static_cast<size_t>(cycle < 0 ? -cycle : cycle) % cycles_.size()];
  return s.cycle == cycle ? &s.sp : nullptr;
}

void Monitor::on_block(const program::Block& b, int64_t token) {
  if (b.kind == program::BlockKind::kDwell || b.kind == program::BlockKind::kEnd || b.kind == program::BlockKind::kEvent)
    return;
  Known k;
  k.block = b;
  try {
    k.path = std::make_unique<motion::PathSegment>(b, naxes_);
  } catch (const std::exception&) {
    return;  // the interpolator refused it too
  }
  blocks_[{token, b.index}] = std::move(k);
  while (blocks_.size() > kMaxBlocks) blocks_.erase(blocks_.begin());
}

const Monitor::Known* Monitor::find(int64_t token, int64_t index) const {
  auto it = blocks_.find({token, index});
  return it == blocks_.end() ? nullptr : &it->second;
}

double Monitor::step_chord_error(const SetpointIn& sa, const SetpointIn& sb) const {
  if (sa.program_token != sb.program_token || sb.block_index < 0) return kNaN;
  // In machine coordinates, as the blocks are.
  SetpointIn a = sa, b = sb;
  for (int i = 0; i < naxes_; ++i) {
    a.position_mm[i] -= drive_offset_[static_cast<size_t>(i)];
    b.position_mm[i] -= drive_offset_[static_cast<size_t>(i)];
  }
  if (a.block_index == b.block_index) {
    const Known* k = find(b.program_token, b.block_index);
    // A rigid tap's setpoints lie on its line by construction, past its end too.
    if (k != nullptr && k->block.sync == program::kSyncRigidTap) return 0.0;
    return k ? motion::chord_error(*k->path, a.u, b.u, a.position_mm, b.position_mm) : kNaN;
  }
  // Across block boundaries: every block part against the step's segment.
  double worst = 0;
  for (int64_t i = std::max<int64_t>(a.block_index, 0); i <= b.block_index; ++i) {
    const Known* k = find(b.program_token, i);
    if (k == nullptr) {
      // Dwell and end blocks have no geometry; anything else unknown makes it unknown.
      continue;
    }
    const double u0 = i == a.block_index ? a.u : k->path->u_begin();
    // A probing move left before its end ended where the path left it; a rigid tap
    // ends on its start (its setpoints' u is where on its line the tap is).
    const double u1 = i == b.block_index                                            ? b.u
                      : k->block.probe != 0 || k->block.sync == program::kSyncRigidTap ? u0
                                                                                        : k->path->u_end();
    worst = std::max(worst, motion::chord_error(*k->path, u0, u1, a.position_mm, b.position_mm));
  }
  return worst;
}

void Monitor::on_setpoint(const SetpointIn& sp) {
  if (sp.stream < stream_) {
    ++stale_;
    return;
  }
  if (sp.stream > stream_) {
    if (stream_ != 0) on_reset();
    stream_ = sp.stream;
  }
  double e = kNaN;
  if (last_sp_ && sp.cycle > last_sp_->cycle) {
    // Only steps between consecutive cycles are steps of the machine.
    if (sp.cycle == last_sp_->cycle + 1) {
      e = step_chord_error(*last_sp_, sp);
      if (std::isfinite(e)) largest_chord_ = std::max(largest_chord_, e);
    }
  }
  last_sp_ = sp;
  CycleSlot* s = slot(sp.cycle);
  const bool again = s->cycle == sp.cycle;
  s->cycle = sp.cycle;
  s->sp = sp;
  s->chord_mm = e;
  if (force_) {
    const ForceSlot f = cutting_force(sp);
    if (!again || !std::isnan(f.deflection)) s->force = f;  // a repeated cycle keeps its estimate
  }
}

Report Monitor::on_status(int64_t utime, int64_t cycle, const std::vector<double>& actual,
                          const std::vector<double>& fe, std::vector<Alarm>* alarms, double playback) {
  Report r;
  r.setpoint_cycle = cycle;
  r.chord_error_mm = kNaN;
  r.predicted_rmax_um = kNaN;
  r.target_rmax_um = kNaN;
  r.force_x_n = r.force_y_n = r.force_z_n = r.force_peak_n = r.deflection_mm = kNaN;
  r.deflection_tolerance_mm = force_ ? cfg_.cutting.deflection_tolerance_mm : kNaN;
  const int n_axes = static_cast<int>(std::min(actual.size(), static_cast<size_t>(program::kMaxAxes)));
  const bool have_playback = std::isfinite(playback) && playback >= 0;
  if (!have_playback) playback = -1;
  track_actual_feed(utime, cycle, actual, n_axes, have_playback, playback);
  r.actual_feed_mm_per_min = actual_feed_;
  for (double e : fe) r.max_following_error_mm = std::max(r.max_following_error_mm, std::fabs(e));
  largest_fe_ = std::max(largest_fe_, r.max_following_error_mm);

  const SetpointIn* sp_p = setpoint_at(cycle);
  if (sp_p == nullptr) return r;
  const SetpointIn& sp = *sp_p;
  r.commanded_feed_mm_per_min = sp.feed_mm_per_min;
  r.block_index = sp.block_index;
  r.source_line = sp.source_line;
  r.chord_error_mm = slot(cycle)->chord_mm;
  if (force_) {
    const ForceSlot& f = slot(cycle)->force;
    r.force_x_n = f.fx;
    r.force_y_n = f.fy;
    r.force_z_n = f.fz;
    r.force_peak_n = f.peak;
    r.deflection_mm = f.deflection;
  }
  predict_rmax(cycle, sp, have_playback, playback, &r);
  raise_alarms(cycle, r, alarms);
  return r;
}

// R_max is predicted from the commanded path (the setpoints: feed and inclination at
// the window's middle) corrected by how the axes actually followed it: the ratio of
// the actual positions' displacement to the commanded one over the same window of at
// least 40 ms (a moving average; about three tooth passes at 2000 rpm and 2 flutes,
// shorter than any feed change the law makes). Differentiating the actual positions
// over one or two 4 ms statuses on the bridge's jittering time stamps made feeds,
// and R_max predictions, several times the real ones (false alarms on every demo).
void Monitor::track_actual_feed(int64_t utime, int64_t cycle, const std::vector<double>& actual, int n_axes,
                                bool have_playback, double playback) {
  // The commanded stretch is read between the bridge's playback positions at the
  // window's ends (AXIS_STATUS playback_cycle): the path the drives were sent over
  // the same 40 ms as the actual positions moved, whatever the lead, the loss and
  // the jitter of the setpoints did to the newest cycle received, and standing
  // where the playback stood (the bridge held for a stalled link). Without it (an
  // older bridge), the newest setpoint cycle stands in, tracking_lag_cycles behind:
  // it advances in whole cycles as setpoints arrive, by two or none at a time on a
  // jittery network, so a status whose cycle has not advanced keeps the ratio.
  // A status older than the newest one (reordered on the network) is no new sample:
  // the window keeps its samples and the feed its value. A jump back of more than a
  // second (another sender, a clock set back) starts the window again.
  bool reordered = false;
  bool cycle_stood = false;  // a new sample for the actual feed, but no new tracking ratio
  if (recent_n_ > 0) {
    const Sample& last = recent(recent_n_ - 1);
    if (last.naxes != n_axes || utime < last.utime - 1'000'000) {
      recent_n_ = 0;
    } else if (utime <= last.utime) {
      reordered = true;
    } else if (!have_playback && cycle <= last.cycle) {
      cycle_stood = true;
    }
  }
  if (reordered) return;
  push_sample(utime, cycle, actual, n_axes, playback);
  if (!cycle_stood) tracking_ratio_ = 1.0;
  if (recent_n_ < 2) return;
  const Sample& a = recent(0);
  double d2 = 0;
  for (int i = 0; i < n_axes; ++i) d2 += (actual[static_cast<size_t>(i)] - a.pos[i]) * (actual[static_cast<size_t>(i)] - a.pos[i]);
  actual_feed_ = std::sqrt(d2) / (static_cast<double>(utime - a.utime) * 1e-6) * 60.0;
  // The axes follow the setpoints a few cycles late (the bridge's jitter buffer and
  // fine interpolation, the drives' lag): compare with the commanded stretch that
  // many cycles earlier, or a deceleration reads as overspeed.
  // The lag may be a fraction of a cycle: the commanded position between two
  // setpoints, linearly.
  motion::AxisVec q0{}, q1{};
  const bool by_playback = have_playback && a.playback >= 0;
  const double c0 = by_playback ? a.playback - playback_lag_cycles_ : static_cast<double>(a.cycle) - lag_cycles_;
  const double c1 = by_playback ? playback - playback_lag_cycles_ : static_cast<double>(cycle) - lag_cycles_;
  if (!cycle_stood && commanded_at(c0, n_axes, &q0) && commanded_at(c1, n_axes, &q1)) {
    double c2 = 0;
    for (int i = 0; i < n_axes; ++i) {
      const double d = q1[i] - q0[i];
      c2 += d * d;
    }
    if (c2 > 1e-12) tracking_ratio_ = std::sqrt(d2 / c2);
  }
}

void Monitor::push_sample(int64_t utime, int64_t cycle, const std::vector<double>& actual, int n_axes,
                          double playback) {
  if (recent_n_ == kRecent) {  // full: the oldest goes
    recent_head_ = (recent_head_ + 1) % kRecent;
    --recent_n_;
  }
  Sample& s = recent_[(recent_head_ + recent_n_) % kRecent];
  s.utime = utime;
  s.cycle = cycle;
  s.playback = playback;
  s.naxes = n_axes;
  for (int i = 0; i < n_axes; ++i) s.pos[i] = actual[static_cast<size_t>(i)];
  ++recent_n_;
  while (recent_n_ > 2 && (recent_n_ > kMaxFeedSamples || utime - recent(1).utime >= kFeedWindowUs)) {
    recent_head_ = (recent_head_ + 1) % kRecent;
    --recent_n_;
  }
}

void Monitor::predict_rmax(int64_t cycle, const SetpointIn& sp, bool have_playback, double playback, Report* r) const {
  // Feed and inclination where the commanded path was in the middle of the window.
  const int64_t window_cycles = recent_n_ >= 2 ? cycle - recent(0).cycle : 0;
  const int64_t mid_cycle =
      recent_n_ >= 2 && have_playback && recent(0).playback >= 0
          ? static_cast<int64_t>(std::llround(0.5 * (recent(0).playback + playback) - playback_lag_cycles_))
          : cycle - window_cycles / 2;
  // A setpoint lost on the way: the nearest one received (within two cycles).
  const SetpointIn* mid_p = nullptr;
  for (int64_t d : {0, -1, 1, -2, 2}) {
    if ((mid_p = setpoint_at(mid_cycle + d)) != nullptr) break;
  }
  const SetpointIn& mid = mid_p != nullptr ? *mid_p : sp;
  const Known* k = find(mid.program_token, mid.block_index);
  if (k == nullptr) return;
  const program::Block& b = k->block;
  r->spindle_rpm = b.spindle_rpm;
  const bool cutting = b.kind != program::BlockKind::kRapid;
  if (b.process.active() && b.spindle_rpm > 0 && cutting && naxes_ >= 3) {
    motion::AxisVec p{}, d1{}, d2{};
    k->path->eval(mid.u, &p, &d1, &d2);
    const double alpha = process::feed_inclination_angle(Eigen::Vector3d(d1[0], d1[1], d1[2]));
    const double f_t = mid.feed_mm_per_min * tracking_ratio_ / (b.process.flutes * b.spindle_rpm);
    r->target_rmax_um = b.process.target_rmax_um;
    if (f_t > 0)
      r->predicted_rmax_um = process::rmax_extended(b.process.ball_radius_mm, f_t, b.process.pick_feed_mm, alpha) * 1e3;
  }
}

void Monitor::raise_alarms(int64_t cycle, const Report& r, std::vector<Alarm>* alarms) {
  // Alarms on entering the condition (not on every report while it lasts).
  const bool rmax_bad = std::isfinite(r.predicted_rmax_um) &&
                        r.predicted_rmax_um > r.target_rmax_um * (1.0 + cfg_.monitor_rmax_margin);
  if (rmax_bad && !rmax_alarm_) {
    std::ostringstream os;
    os << "cycle " << cycle << " line " << r.source_line << ": predicted R_max " << r.predicted_rmax_um
       << " um over the target " << r.target_rmax_um << " um + " << cfg_.monitor_rmax_margin * 100 << " %";
    alarms->push_back({"rmax", os.str()});
  }
  rmax_alarm_ = rmax_bad;
  const bool chord_bad = std::isfinite(r.chord_error_mm) && r.chord_error_mm > cfg_.chord_tolerance_mm * (1 + 1e-6);
  if (chord_bad && !chord_alarm_) {
    std::ostringstream os;
    os << "cycle " << cycle << " line " << r.source_line << ": chord error " << r.chord_error_mm * 1e3
       << " um over the tolerance " << cfg_.chord_tolerance_mm * 1e3 << " um";
    alarms->push_back({"chord_error", os.str()});
  }
  chord_alarm_ = chord_bad;
  const bool deflection_bad =
      std::isfinite(r.deflection_mm) && r.deflection_mm > cfg_.cutting.deflection_tolerance_mm * (1 + 1e-6);
  if (deflection_bad && !deflection_alarm_) {
    std::ostringstream os;
    os << "cycle " << cycle << " line " << r.source_line << ": predicted tool deflection " << r.deflection_mm * 1e3
       << " um over the tolerance " << cfg_.cutting.deflection_tolerance_mm * 1e3 << " um (force " << r.force_peak_n
       << " N)";
    alarms->push_back({"deflection", os.str()});
  }
  deflection_alarm_ = deflection_bad;
  const bool force_bad = cfg_.cutting.max_force_n > 0 && std::isfinite(r.force_peak_n) &&
                         r.force_peak_n > cfg_.cutting.max_force_n * (1 + 1e-6);
  if (force_bad && !force_alarm_) {
    std::ostringstream os;
    os << "cycle " << cycle << " line " << r.source_line << ": predicted cutting force " << r.force_peak_n
       << " N over the limit " << cfg_.cutting.max_force_n << " N";
    alarms->push_back({"force", os.str()});
  }
  force_alarm_ = force_bad;
}

}  // namespace cnc::monitor
