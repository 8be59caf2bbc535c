#pragma once
// The interpolator core: a pure function of its config and of the inputs applied
// to it, cycle by cycle. It reads no clock, starts no thread, draws no random
// number; the node (interpolator_node.h) feeds it and publishes what it returns.
//
// Planning, per block on arrival: the block's curve is sampled along its arc
// length and each sample gets the geometric feed limit, the least of
//   * the chord-error limit of seed 001: step L = 2·sqrt(2ρε − ε²) per period,
//   * the roughness limit of seed 000 (eqs. 4–6) when process parameters are set,
//   * each axis's velocity limit v_i / |t_i|,
//   * the centripetal limit sqrt(a_i / (κ·|n_i|)) on half of each axis's acceleration;
// junctions between blocks get the speed at which the direction change stays
// within one cycle's acceleration and jerk of every axis (a sharp corner is a stop).
//
// Motion, per cycle: the path speed follows min(programmed feed × override, the
// limit here) with a jerk-limited acceleration. Before each cycle commits to an
// acceleration, it checks that from the resulting state a jerk-limited brake still
// meets every limit ahead (look-ahead over the buffered blocks, which end in a stop
// unless more blocks follow). The step along the curve uses seed 000's eq. 7
// parameter update, then a Newton correction so the chord length of the step
// equals the commanded step length.
#include <array>
#include <cstdint>
#include <deque>
#include <memory>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/path_segment.h"
#include "common/program/block.h"

namespace cnc::interp {

enum class RunState : int8_t { kIdle = 0, kRunning = 1, kHeld = 2, kDone = 3, kStarved = 4 };
// Which constraint set the commanded feed (values match lcmt_setpoint's LIMIT_*).
enum class Limit : int8_t {
  kNone = 0, kProgram = 1, kChord = 2, kRoughness = 3, kAxisVelocity = 4, kCurvatureAccel = 5, kLookahead = 6
};
// How the curve parameter advances each cycle (for the feed-fluctuation comparison).
enum class ParamUpdate : int8_t { kFirstOrder = 0, kTaylor2 = 1, kCorrected = 2 };

const char* to_string(Limit limit);
const char* to_string(RunState state);
ParamUpdate param_update_from_string(const std::string& s);

struct Command {
  enum class Kind : int8_t { kLoad = 1, kStart = 2, kHold = 3, kResume = 4, kStop = 5, kOverride = 6, kReset = 7 };
  Kind kind = Kind::kStart;
  double feed_override = 1.0;  // kOverride: 0.0 .. 1.5
  // kReset: the program is dropped, the path is at rest at this position (where
  // the drives stand, as the node took it from AXIS_STATUS); one finite value per axis.
  std::array<double, program::kMaxAxes> position_mm{};
};

struct Setpoint {
  int64_t cycle = 0;
  int num_axes = 0;
  std::array<double, program::kMaxAxes> position_mm{};
  double feed_mm_per_min = 0;      // commanded path speed (the step length of this cycle / T)
  double path_accel_mm_s2 = 0;     // planned tangential acceleration
  int64_t block_index = -1;
  int32_t source_line = 0;
  double u = 0;
  Limit limit = Limit::kNone;
  RunState state = RunState::kIdle;
};

class Interpolator {
 public:
  explicit Interpolator(const config::MachineConfig& cfg);
  ~Interpolator();

  // Inputs, applied before the next step(). Blocks must come in index order
  // (0, 1, 2, ... of the current program); anything else is refused (false).
  bool apply_block(const program::Block& block);
  // Program stops and tool changes (M0, M1, M6) hold the path until a RESUME; the dry
  // run resumes them at once, as an operator pressing resume without delay.
  void set_auto_resume_pauses(bool on) { auto_resume_pauses_ = on; }
  void apply_command(const Command& cmd);

  // Computes the setpoint of the current cycle and advances the cycle counter.
  const Setpoint& step();

  int64_t cycle() const { return cycle_; }
  RunState state() const { return state_; }
  int64_t next_block_index() const { return next_index_; }
  size_t queued_blocks() const { return blocks_.size(); }
  int64_t blocks_done() const { return blocks_done_; }
  int64_t starved_cycles() const { return starved_cycles_; }
  // Curve samples planned so far (all blocks): the measure of planning work by which
  // the node bounds what it applies per cycle (see motion.plan_budget_samples).
  int64_t planned_samples() const { return planned_samples_; }
  double feed_override() const { return override_; }
  double program_time_s() const { return static_cast<double>(program_cycles_) * period_s_; }
  const Setpoint& last() const { return out_; }
  void set_param_update(ParamUpdate mode) { param_update_ = mode; }
  // Why the last refused block was refused.
  const std::string& last_refusal() const { return refusal_; }

  struct Sample {
    double u;
    double s;      // arc length from the block start, mm
    double v_geo;  // geometric speed limit, mm/s
    Limit limit;
  };
  struct Planned {
    program::Block block;
    motion::PathSegment path;
    std::vector<Sample> samples;  // at least two for a moving block
    double length = 0;
    double v_prog = 0;            // programmed feed in mm/s (rapids: the axis-limited speed)
    double accel = 0, jerk = 0;   // tangential limits over the block
    double v_entry = 0;           // junction limit with the previous block
    std::vector<double> v_bw;     // backward-pass limits per sample (acceleration-limited)
    bool stop_block() const;      // dwell / end: the path stops here
    bool stop_at_start() const;   // a stop block, or a corner the path must stop at
    Planned(program::Block b, motion::PathSegment p) : block(std::move(b)), path(std::move(p)) {}
  };

 private:
  void plan_block(Planned& p);
  void plan_junction(Planned& prev, Planned& next) const;
  void backward_pass(bool full);
  // Speed limit at arc length s of block p: programmed feed × override and the
  // geometric limit (also returned alone in *v_geo when not null).
  double cap_at(const Planned& p, double s, Limit* why, double* v_geo = nullptr) const;
  // Programmed feed × override (a rapid's speed × override up to 1), mm/s.
  double programmed_speed(const Planned& p) const;
  // A rapid at override >= 1: its speed is its samples' axis-velocity limit, which
  // the geometric limit already holds (the programmed term is left out, not ∞).
  bool rapid_at_full_speed(const Planned& p) const;
  // Whether a jerk-limited brake from (v_next, a_next) at s_next still meets every
  // limit ahead; when not, *v_target (if given) is the speed limit it misses.
  bool safe(double v_next, double a_next, double s_next, double* v_target = nullptr) const;
  double advance(double ds, bool* reached_stop);
  bool creep_to_stop();

  config::MachineConfig cfg_;
  double period_s_;
  int naxes_;
  ParamUpdate param_update_ = ParamUpdate::kCorrected;

  RunState state_ = RunState::kIdle;
  bool hold_ = false;
  bool event_paused_ = false;       // the program stop / tool change at the front has paused once
  bool auto_resume_pauses_ = false;
  bool stopping_ = false;
  double override_ = 1.0;

  std::deque<Planned> blocks_;  // front: the block being executed
  int64_t next_index_ = 0;
  double u_ = 0;     // parameter in the front block
  double s_ = 0;     // arc length in the front block
  double v_ = 0;     // path speed, mm/s
  double a_ = 0;     // path acceleration, mm/s²
  int64_t dwell_left_ = -1;

  std::array<double, program::kMaxAxes> pos_{};
  int64_t cycle_ = 0;
  int64_t blocks_done_ = 0;
  int64_t starved_cycles_ = 0;
  int64_t program_cycles_ = 0;
  int64_t planned_samples_ = 0;
  Setpoint out_;
  std::string refusal_;
};

}  // namespace cnc::interp
