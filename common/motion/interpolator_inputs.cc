// The core's inputs: program blocks (checked, then handed to the planner) and the
// operator's commands, applied before the next step().
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <string>

#include "common/motion/feed_override.h"
#include "common/motion/interpolator.h"

namespace cnc::interp {

bool Interpolator::check_block(const program::Block& block) {
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
      const double expected = have_tail_ ? tail_[a] : pos_[a];
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
  if (block.sync != program::kSyncNone) {
    if ((block.sync != program::kSyncG33 && block.sync != program::kSyncRigidTap) ||
        block.kind != program::BlockKind::kLine || !(block.sync_pitch_mm > 0) || !(block.tap_retract_scale >= 1)) {
      refusal_ = "block " + std::to_string(block.index) + ": a malformed spindle-synchronised move";
      return false;
    }
    if (!cfg_.spindle.measured_position()) {
      refusal_ = "block " + std::to_string(block.index) +
                 ": a spindle-synchronised move (G33) on a machine without spindle.encoder_counts_per_rev";
      return false;
    }
  }
  return true;
}

bool Interpolator::submit_block(std::unique_ptr<program::Block> block) {
  if (!block || !check_block(*block)) return false;
  if (!inline_ && pending_n_ > 0 && !flush_requests()) {
    refusal_ = "the planner is busy";
    return false;
  }
  const bool had_tail = have_tail_;
  const bool was_stopping = stopping_;
  const auto tail = tail_;
  const int64_t index = block->index;
  // A rigid tap comes back to its start.
  const bool tap = block->sync == program::kSyncRigidTap;
  for (int a = 0; a < naxes_; ++a) tail_[a] = tap ? block->start[a] : block->end[a];
  have_tail_ = true;
  PlanRequest r;
  r.kind = PlanRequest::Kind::kBlock;
  r.epoch = epoch_;
  r.serial = next_serial_;
  r.block = block.get();
  if (!link_->push(r)) {  // full: not taken, nothing changed
    have_tail_ = had_tail;
    tail_ = tail;
    refusal_ = "the planner is busy";
    return false;
  }
  block.release();  // the planner's now
  ++next_serial_;
  ++next_index_;
  ++submitted_;
  if (inline_) {
    int64_t used = 0;
    apply_plans(std::numeric_limits<int64_t>::max(), &used);
    if (!failure_.empty()) {
      // Planned inline: refused as a whole, as if never submitted.
      failure_.clear();
      failed_ = false;
      stopping_ = was_stopping;
      --next_index_;
      have_tail_ = had_tail;
      tail_ = tail;
      (void)index;
      return false;
    }
  }
  return true;
}

bool Interpolator::apply_block(const program::Block& block) {
  if (!check_block(block)) return false;
  return submit_block(std::make_unique<program::Block>(block));
}

// Nothing of a program left: no block, no counts, the path at rest; the spindle and
// the coolant stopped too after a fault (RESET), left as they are by a LOAD (an MDI
// line's M3 or M8 keeps them on for the next, as LinuxCNC's MDI does).
void Interpolator::clear_program(bool stop_spindle) {
  clear_blocks();
  next_index_ = 0;
  blocks_done_ = 0;
  program_cycles_ = 0;
  starved_cycles_ = 0;
  u_ = s_ = v_ = a_ = 0;
  dwell_left_ = -1;
  rest_left_ = 0;
  probe_ = ProbeMove{};
  probe_serial_ = UINT64_MAX;
  input_ = InputWaitState{};
  input_serial_ = UINT64_MAX;
  sync_ = SyncMove{};
  sync_serial_ = UINT64_MAX;
  sync_speed_ = 0;
  if (stop_spindle) {
    spindle_off();
  } else {
    program_start_modes();
  }
}

bool Interpolator::apply_command(const Command& cmd) {
  switch (cmd.kind) {
    case Command::Kind::kLoad:
      if (state_ == RunState::kRunning || state_ == RunState::kHeld || state_ == RunState::kStarved) return true;
      clear_program(false);
      state_ = RunState::kIdle;
      // No block of the new program is under way until its first step: the
      // setpoints until then name none (they carried the last path's block and u,
      // which the monitor read on the new program's block 0: a false chord error
      // of 22 mm after a homing and a touch-off, seen in integration.hmi).
      out_.block_index = -1;
      out_.source_line = 0;
      out_.u = 0;
      break;
    case Command::Kind::kStart:
      if (state_ == RunState::kIdle || state_ == RunState::kDone) {
        state_ = RunState::kRunning;
        hold_ = false;
        stopping_ = false;
        single_block_held_ = false;
        single_block_go_ = true;  // single block: the first line runs
      }
      break;
    case Command::Kind::kHold:
      hold_ = true;
      single_block_held_ = false;
      if (cmd.value == 1) {
        door_hold_ = true;
        door_resume_ = false;
      }
      break;
    case Command::Kind::kResume:
      door_hold_ = false;
      if (door_spindle_.direction != 0) {
        // The spindle the door stopped turns again; the path, RUNNING, stands until it
        // is at speed.
        ++spindle_.seq;
        spindle_.direction = door_spindle_.direction;
        spindle_.program_rpm = door_spindle_.program_rpm;
        spindle_.rpm = overridden_rpm(door_spindle_.program_rpm);
        door_spindle_ = SpindleState{};
        spindle_wait_ = wait_for_spindle_ && !auto_resume_pauses_;
        door_resume_ = spindle_wait_;
      }
      hold_ = false;
      single_block_held_ = false;
      break;
    case Command::Kind::kSingleBlock:
      if (!std::isfinite(cmd.value)) break;
      if ((cmd.value != 0) != single_block_) {
        single_block_ = cmd.value != 0;
        single_block_go_ = false;  // switched on in a run: the next line start holds
        if (single_block_) mark_single_block_stops();
        else unmark_single_block_stops();
      }
      break;
    case Command::Kind::kOptionalStop:
      if (std::isfinite(cmd.value)) optional_stop_ = cmd.value != 0;
      break;
    case Command::Kind::kStop:
      if (state_ != RunState::kIdle && state_ != RunState::kDone) stopping_ = true;
      break;
    case Command::Kind::kReset:
      // After a fault: nothing of the program is left, the path rests where the drives are.
      clear_program(true);
      hold_ = false;
      single_block_held_ = false;
      stopping_ = false;
      state_ = RunState::kIdle;
      // The drives' positions, less the offsets of homed axes.
      for (int a = 0; a < naxes_; ++a)
        if (std::isfinite(cmd.position_mm[a])) pos_[a] = cmd.position_mm[a] - drive_offset_[a];
      output_position();
      break;
    case Command::Kind::kHomed: {
      if (cmd.axis < 0 || cmd.axis >= naxes_ || !std::isfinite(cmd.value)) break;
      if (state_ == RunState::kRunning || state_ == RunState::kHeld || state_ == RunState::kStarved) break;
      const auto a = static_cast<size_t>(cmd.axis);
      // The drive stays where it is: the machine position moves by the change of offset.
      pos_[a] += drive_offset_[a] - cmd.value;
      drive_offset_[a] = cmd.value;
      homed_[a] = true;
      any_offset_ = any_offset_ || cmd.value != 0;
      have_tail_ = false;  // the next program starts where the path now is
      output_position();
      break;
    }
    case Command::Kind::kProbeTrip:
      // Only in the probing move at the front, and with nothing after it taken yet
      // (its successor starts where the path comes to rest).
      if (blocks_.empty() || blocks_.front().block.probe == 0 || blocks_.front().serial != probe_serial_ ||
          next_index_ != blocks_.front().block.index + 1 || probe_.done)
        return false;
      probe_.tripped = true;
      probe_braking_ = true;
      break;
    case Command::Kind::kInputValue:
      if (!input_.waiting || !std::isfinite(cmd.value) || blocks_.empty() || blocks_.front().serial != input_serial_)
        return false;
      end_input_wait(cmd.value);
      break;
    case Command::Kind::kSpindleAtSpeed:
      if (spindle_wait_ && std::isfinite(cmd.value) && cmd.value >= static_cast<double>(spindle_.seq))
        spindle_wait_ = false;
      if (!spindle_wait_) door_resume_ = false;
      break;
    case Command::Kind::kSpindlePosition:
      if (!std::isfinite(cmd.position_mm[0]) || !std::isfinite(cmd.position_mm[1]) || !std::isfinite(cmd.position_mm[2]))
        return false;
      // The spindle's acceleration from the speeds of samples two cycles apart or more (a
      // reversal's: the samples are a few cycles old when a setpoint is made).
      if (sp_applied_ < 0 || cmd.position_mm[2] < sp_acc_cycle_) {
        sp_acc_ = 0;
        sp_acc_cycle_ = cmd.position_mm[2];
        sp_acc_rps_ = cmd.position_mm[1];
      } else if (cmd.position_mm[2] - sp_acc_cycle_ >= 2.0) {
        sp_acc_ = (cmd.position_mm[1] - sp_acc_rps_) / ((cmd.position_mm[2] - sp_acc_cycle_) * period_s_);
        sp_acc_cycle_ = cmd.position_mm[2];
        sp_acc_rps_ = cmd.position_mm[1];
      }
      sp_rev_ = cmd.position_mm[0];
      sp_rps_ = cmd.position_mm[1];
      sp_cycle_ = cmd.position_mm[2];
      sp_applied_ = cycle_;
      break;
    case Command::Kind::kSpindleOverride:
      if (!std::isfinite(cmd.feed_override)) return false;
      spindle_override_ = std::clamp(cmd.feed_override, cfg_.spindle.min_override, cfg_.spindle.max_override);
      spindle_reoverride();
      break;
    case Command::Kind::kSpindleSpeed: {
      if (!std::isfinite(cmd.value) || cmd.value < 0) return false;
      const double scale = law_scale_for(cmd.value);
      if (scale == law_scale_) break;
      // As an override: the cap at once, the look-ahead when the planner's pass is taken.
      PlanRequest r;
      r.kind = PlanRequest::Kind::kOverride;
      r.epoch = epoch_;
      r.feed_override = override_;
      r.rapid_override = rapid_override_;
      r.law_scale = scale;
      if (!push_request(r)) return false;
      law_scale_ = scale;
      if (inline_) {
        int64_t used = 0;
        apply_plans(std::numeric_limits<int64_t>::max(), &used);
      }
      break;
    }
    case Command::Kind::kOverride:
    case Command::Kind::kRapidOverride:
      if (std::isfinite(cmd.feed_override)) {
        // The cap follows at once; the look-ahead over the buffer is re-planned by
        // the planner and follows when that plan is taken.
        PlanRequest r;
        r.kind = PlanRequest::Kind::kOverride;
        r.epoch = epoch_;
        const bool rapid = cmd.kind == Command::Kind::kRapidOverride;
        r.feed_override = rapid ? override_ : std::clamp(cmd.feed_override, 0.0, motion::kMaxFeedOverride);
        r.rapid_override = rapid ? std::clamp(cmd.feed_override, 0.0, 1.0) : rapid_override_;
        r.law_scale = law_scale_;
        if (!push_request(r)) return false;
        override_ = r.feed_override;
        rapid_override_ = r.rapid_override;
        if (inline_) {
          int64_t used = 0;
          apply_plans(std::numeric_limits<int64_t>::max(), &used);
        }
      }
      break;
  }
  return true;
}

}  // namespace cnc::interp
