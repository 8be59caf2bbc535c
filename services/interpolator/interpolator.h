#pragma once
// The interpolator core: a pure function of its config and of the inputs applied
// to it, cycle by cycle. It reads no clock, starts no thread, draws no random
// number; the node (interpolator_node.h) feeds it and publishes what it returns.
//
// This version moves along straight lines (G0/G1) with a trapezoidal speed
// profile per block and an exact stop at each block end. The speed is planned
// online each cycle: the discrete braking law below makes the block end exact
// without overshoot, and feed hold / override act at the path acceleration limit.
#include <array>
#include <cstdint>
#include <deque>

#include "common/config/machine_config.h"
#include "common/program/block.h"

namespace cnc::interp {

enum class RunState : int8_t { kIdle = 0, kRunning = 1, kHeld = 2, kDone = 3, kStarved = 4 };
// Which constraint set the commanded feed (values match lcmt_setpoint's LIMIT_*).
enum class Limit : int8_t {
  kNone = 0, kProgram = 1, kChord = 2, kRoughness = 3, kAxisVelocity = 4, kCurvatureAccel = 5, kLookahead = 6
};

const char* to_string(Limit limit);
const char* to_string(RunState state);

struct Command {
  enum class Kind : int8_t { kLoad = 1, kStart = 2, kHold = 3, kResume = 4, kStop = 5, kOverride = 6 };
  Kind kind = Kind::kStart;
  double feed_override = 1.0;  // kOverride: 0.0 .. 1.5
};

struct Setpoint {
  int64_t cycle = 0;
  int num_axes = 0;
  std::array<double, program::kMaxAxes> position_mm{};
  double feed_mm_per_min = 0;
  int64_t block_index = -1;
  int32_t source_line = 0;
  double u = 0;
  Limit limit = Limit::kNone;
  RunState state = RunState::kIdle;
};

class Interpolator {
 public:
  explicit Interpolator(const config::MachineConfig& cfg);

  // Inputs, applied before the next step(). Blocks must come in index order
  // (0, 1, 2, ... of the current program); anything else is refused (false).
  bool apply_block(const program::Block& block);
  void apply_command(const Command& cmd);

  // Computes the setpoint of the current cycle and advances the cycle counter.
  const Setpoint& step();

  int64_t cycle() const { return cycle_; }
  RunState state() const { return state_; }
  int64_t next_block_index() const { return next_index_; }
  size_t queued_blocks() const { return queue_.size(); }
  int64_t blocks_done() const { return blocks_done_; }
  int64_t starved_cycles() const { return starved_cycles_; }
  double feed_override() const { return override_; }
  double program_time_s() const { return static_cast<double>(program_cycles_) * period_s_; }
  const Setpoint& last() const { return out_; }

 private:
  struct Segment {
    program::Block block;
    double length_mm = 0;
    double v_max_mm_s = 0;  // from the program feed and the axis velocity limits (before override)
    double v_axis_mm_s = 0;  // from the axis velocity limits alone: override never goes past it
    Limit v_limit = Limit::kProgram;
    double accel_mm_s2 = 0;
    int64_t dwell_cycles_left = 0;
  };
  void begin_next_segment(double entry_fraction);
  void advance_motion();

  config::MachineConfig cfg_;
  double period_s_;
  int naxes_;

  RunState state_ = RunState::kIdle;
  bool hold_ = false;
  bool stopping_ = false;
  double override_ = 1.0;

  std::deque<program::Block> queue_;
  int64_t next_index_ = 0;
  bool have_segment_ = false;
  Segment seg_;
  double s_mm_ = 0;      // distance along the current segment
  double v_mm_s_ = 0;    // path speed of the last cycle
  // When the last cycle ended a segment: its speed as a fraction of that segment's
  // a·T. The next segment's first cycle may only add what is left of a·T, so the
  // change of velocity across the (exact-stop) corner stays within the limits.
  double exit_fraction_ = 0;

  std::array<double, program::kMaxAxes> pos_{};
  int64_t cycle_ = 0;
  int64_t blocks_done_ = 0;
  int64_t starved_cycles_ = 0;
  int64_t program_cycles_ = 0;
  Setpoint out_;
};

}  // namespace cnc::interp
