#include "services/interpolator/interpolator.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cnc::interp {

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

Interpolator::Interpolator(const config::MachineConfig& cfg)
    : cfg_(cfg), period_s_(cfg.ipo_period_s), naxes_(static_cast<int>(cfg.axes.size())) {
  for (int a = 0; a < naxes_; ++a) pos_[a] = cfg_.axes[a].home_mm;
}

bool Interpolator::apply_block(const program::Block& block) {
  if (block.index != next_index_) return false;
  if (static_cast<int>(block.end.size()) != naxes_ || static_cast<int>(block.start.size()) != naxes_) return false;
  for (int a = 0; a < naxes_; ++a)
    if (!std::isfinite(block.end[a])) return false;
  queue_.push_back(block);
  ++next_index_;
  return true;
}

void Interpolator::apply_command(const Command& cmd) {
  switch (cmd.kind) {
    case Command::Kind::kLoad:
      // A new program: only when nothing moves.
      if (state_ == RunState::kRunning || state_ == RunState::kHeld || state_ == RunState::kStarved) return;
      queue_.clear();
      have_segment_ = false;
      next_index_ = 0;
      blocks_done_ = 0;
      program_cycles_ = 0;
      starved_cycles_ = 0;
      state_ = RunState::kIdle;
      break;
    case Command::Kind::kStart:
      if (state_ == RunState::kIdle || state_ == RunState::kDone) {
        state_ = RunState::kRunning;
        hold_ = false;
        stopping_ = false;
      }
      break;
    case Command::Kind::kHold:
      hold_ = true;
      break;
    case Command::Kind::kResume:
      hold_ = false;
      break;
    case Command::Kind::kStop:
      if (state_ != RunState::kIdle && state_ != RunState::kDone) stopping_ = true;
      break;
    case Command::Kind::kOverride:
      if (std::isfinite(cmd.feed_override)) override_ = std::clamp(cmd.feed_override, 0.0, 1.5);
      break;
  }
}

void Interpolator::begin_next_segment(double entry_fraction) {
  have_segment_ = false;
  if (queue_.empty()) return;
  seg_ = Segment{};
  seg_.block = std::move(queue_.front());
  queue_.pop_front();
  s_mm_ = 0;
  v_mm_s_ = 0;
  const program::Block& b = seg_.block;
  if (b.kind == program::BlockKind::kDwell) {
    seg_.dwell_cycles_left = static_cast<int64_t>(std::ceil(b.dwell_s / period_s_ - 1e-9));
  } else if (b.kind == program::BlockKind::kRapid || b.kind == program::BlockKind::kLine) {
    double len2 = 0;
    for (int a = 0; a < naxes_; ++a) len2 += (b.end[a] - b.start[a]) * (b.end[a] - b.start[a]);
    seg_.length_mm = std::sqrt(len2);
    double v_axis = std::numeric_limits<double>::infinity();
    double accel = cfg_.path_accel_mm_s2;
    if (seg_.length_mm > 0) {
      for (int a = 0; a < naxes_; ++a) {
        const double dir = std::fabs(b.end[a] - b.start[a]) / seg_.length_mm;
        if (dir > 0) {
          v_axis = std::min(v_axis, cfg_.axes[a].max_velocity_mm_s / dir);
          accel = std::min(accel, cfg_.axes[a].max_accel_mm_s2 / dir);
        }
      }
    }
    const double v_prog = b.kind == program::BlockKind::kRapid ? std::numeric_limits<double>::infinity()
                                                               : b.feed_mm_per_min / 60.0;
    seg_.v_max_mm_s = std::min(v_prog, v_axis);
    seg_.v_axis_mm_s = v_axis;
    seg_.v_limit = v_prog <= v_axis ? Limit::kProgram : Limit::kAxisVelocity;
    seg_.accel_mm_s2 = accel;
    // Negative: the first cycle brakes the previous segment's last velocity first.
    v_mm_s_ = -entry_fraction * accel * period_s_;
  }
  have_segment_ = true;
}

void Interpolator::advance_motion() {
  out_.limit = Limit::kNone;
  out_.feed_mm_per_min = 0;
  const double entry_fraction = exit_fraction_;
  exit_fraction_ = 0;
  if (!have_segment_) begin_next_segment(entry_fraction);
  if (!have_segment_) {
    if (stopping_) {
      stopping_ = false;
      state_ = RunState::kIdle;
      return;
    }
    state_ = RunState::kStarved;
    ++starved_cycles_;
    return;
  }
  const program::Block& b = seg_.block;
  out_.block_index = b.index;
  out_.source_line = b.source_line;

  if (b.kind == program::BlockKind::kEnd) {
    have_segment_ = false;
    ++blocks_done_;
    state_ = RunState::kDone;
    out_.u = 1.0;
    return;
  }
  if (stopping_ && v_mm_s_ == 0) {
    // Controlled stop complete: the rest of the program is dropped.
    queue_.clear();
    have_segment_ = false;
    stopping_ = false;
    state_ = RunState::kIdle;
    return;
  }
  const bool pausing = hold_ || stopping_;
  if (b.kind == program::BlockKind::kDwell) {
    state_ = hold_ ? RunState::kHeld : RunState::kRunning;
    if (!pausing && seg_.dwell_cycles_left > 0) --seg_.dwell_cycles_left;
    out_.u = 0;
    if (seg_.dwell_cycles_left == 0 && !pausing) {
      ++blocks_done_;
      have_segment_ = false;
    }
    return;
  }
  if (b.kind != program::BlockKind::kRapid && b.kind != program::BlockKind::kLine) {
    // The parser does not produce other kinds yet; a broken invariant stops here.
    have_segment_ = false;
    ++blocks_done_;
    return;
  }

  const double L = seg_.length_mm;
  const double a = seg_.accel_mm_s2;
  const double T = period_s_;
  double v_next = 0;
  Limit limit = seg_.v_limit;
  if (L > 0) {
    const double ovr = b.kind == program::BlockKind::kRapid ? std::min(override_, 1.0) : override_;
    const double v_target = pausing ? 0.0 : std::min(seg_.v_max_mm_s * ovr, seg_.v_axis_mm_s);
    if (!pausing && seg_.v_max_mm_s * ovr > seg_.v_axis_mm_s) limit = Limit::kAxisVelocity;
    const double rem = L - s_mm_;
    // Largest speed from which braking at `a` in whole cycles stops within `rem`.
    // Moving at v this cycle and braking by aT per cycle covers
    //   d(v) = T·(v + (v − aT) + ... + (v − n·aT)) = T·(n+1)·(v − n·aT/2),  n = floor(v/aT),
    // after which the speed is below aT and the next cycle is at rest. d is continuous
    // and increasing, so v_brake = d⁻¹(rem): with n the largest integer such that
    // aT²·n(n+1)/2 ≤ rem, v_brake = rem/((n+1)·T) + n·aT/2. (The continuous law
    // v(v + aT)/2a ≤ rem underestimates d between multiples of aT, which let the last
    // cycle of a block brake at up to 1.125·a.)
    const double n_brake = std::floor((std::sqrt(8.0 * rem / (a * T * T) + 1.0) - 1.0) / 2.0);
    const double v_brake = rem / ((n_brake + 1.0) * T) + 0.5 * n_brake * a * T;
    v_next = std::min({std::max(v_target, v_mm_s_ - a * T), v_mm_s_ + a * T, v_brake});
    v_next = std::max(v_next, 0.0);
    if (v_brake <= std::max(v_target, v_mm_s_ - a * T) && v_brake <= v_mm_s_ + a * T) limit = Limit::kLookahead;
    if (s_mm_ + v_next * T >= L - 1e-9) {
      v_next = (L - s_mm_) / T;
      s_mm_ = L;
    } else {
      s_mm_ += v_next * T;
    }
  } else {
    s_mm_ = L;
  }
  v_mm_s_ = v_next;
  const bool finished = s_mm_ >= L;
  for (int ax = 0; ax < naxes_; ++ax)
    pos_[ax] = finished ? b.end[ax] : b.start[ax] + (b.end[ax] - b.start[ax]) * (s_mm_ / L);
  out_.u = L > 0 ? s_mm_ / L : 1.0;
  out_.feed_mm_per_min = v_next * 60.0;
  out_.limit = v_next > 0 ? limit : Limit::kNone;
  state_ = (hold_ && v_next == 0) ? RunState::kHeld : RunState::kRunning;
  if (finished) {
    exit_fraction_ = std::min(1.0, v_next / (a * T));
    v_mm_s_ = 0;
    ++blocks_done_;
    have_segment_ = false;
  }
}

const Setpoint& Interpolator::step() {
  out_.cycle = cycle_;
  out_.num_axes = naxes_;
  if (state_ == RunState::kRunning || state_ == RunState::kHeld || state_ == RunState::kStarved) {
    advance_motion();
    ++program_cycles_;
  } else {
    out_.feed_mm_per_min = 0;
    out_.limit = Limit::kNone;
  }
  out_.position_mm = pos_;
  out_.state = state_;
  ++cycle_;
  return out_;
}

}  // namespace cnc::interp
