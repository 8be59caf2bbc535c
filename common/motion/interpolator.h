#pragma once
// The interpolator core: a pure function of its config and of the inputs applied
// to it, cycle by cycle. It reads no clock, starts no thread, draws no random
// number; the node (interpolator_node.h) feeds it and publishes what it returns.
//
// Planning, per block on arrival: the block's curve is sampled along its arc
// length and each sample gets the geometric feed limit, the least of
//   * the chord-error limit of Kim, Song & Kwon: step L = 2·sqrt(2ρε − ε²) per period,
//   * the roughness limit of Choi et al. 2005 (eqs. 4–6) when process parameters are set,
//   * each axis's velocity limit v_i / |t_i|,
//   * the centripetal limit sqrt(a_i / (κ·|n_i|)) on half of each axis's acceleration;
// junctions between blocks get the speed at which the direction change stays
// within one cycle's acceleration and jerk of every axis (a sharp corner is a stop).
//
// Motion, per cycle: the path speed follows min(programmed feed × override, the
// limit here) with a jerk-limited acceleration. Before each cycle commits to an
// acceleration, it checks that from the resulting state a jerk-limited brake still
// meets every limit ahead (look-ahead over the buffered blocks, which end in a stop
// unless more blocks follow). The step along the curve uses Choi et al. 2005's eq. 7
// parameter update, then a Newton correction so the chord length of the step
// equals the commanded step length.
//
// Planning (planner.h) is not done here but by a Planner behind a PlanLink: a block
// is submitted (apply_block: checked, handed to the planner) and its plan is taken
// later (apply_plans), at a cycle the caller records, so replay takes it at the same
// cycle. The cyclic part (apply_plans + step) never allocates or frees memory.
// Constructed without a link, the core plans inline and takes each plan at once
// (apply_block and an override behave as one input, as the tests use it).
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/machine_outputs.h"
#include "common/motion/path_segment.h"
#include "common/motion/planner.h"
#include "common/program/block.h"

namespace cnc::interp {

enum class RunState : int8_t { kIdle = 0, kRunning = 1, kHeld = 2, kDone = 3, kStarved = 4 };
// How the curve parameter advances each cycle (for the feed-fluctuation comparison).
enum class ParamUpdate : int8_t { kFirstOrder = 0, kTaylor2 = 1, kCorrected = 2 };

const char* to_string(Limit limit);
const char* to_string(RunState state);
ParamUpdate param_update_from_string(const std::string& s);

struct Command {
  enum class Kind : int8_t {
    // kHold with value 1: the guard door's (the spindle stops once the path stands, and
    // RESUME waits for it at speed before the path moves).
    kLoad = 1, kStart = 2, kHold = 3, kResume = 4, kStop = 5, kOverride = 6, kReset = 7,
    // Homing found the axis's machine position: from now on the setpoints
    // of `axis` are its machine position plus `value` (the drive's position minus the
    // machine's), and it counts as homed. Applied only while the path stands.
    kHomed = 13,
    // Switches (value 1 on, 0 off; README "Single block, optional stop, block delete").
    // Single block: the path comes to rest at the start of each program line (the first
    // line boundary ahead it can still stop at, jerk-limited) and holds there until a
    // RESUME (or the program's START) lets it run the next line. Optional stop: an M1
    // holds the path (else the path only rests there, as at any program event).
    kSingleBlock = 14, kOptionalStop = 15,
    // The rapids' speed scale (feed_override, 0.0 .. 1.0), on top of the feed override's
    // (which a rapid takes up to 1): a G0 runs at v * min(feed, 1) * rapid.
    kRapidOverride = 18,
    // The spindle reached the speed of change `value` (a SpindleState::seq): the path,
    // at rest at that change, goes on. The node applies it when the drive bridge
    // reports the change at speed (SPINDLE_STATUS), recorded like every input.
    kSpindleAtSpeed = 19,
    // The probe input changed during the probing move (G38.x) at the front: the path
    // brakes to rest on it (jerk-limited, as at a hold) and the move ends there; the
    // next block starts where the path rests. `position_mm` (the latched position) is
    // carried for the record only. Refused (false) when the front is no probing move.
    kProbeTrip = 20,
    // The input the path waits on at an M66 (the input wait at the front) read `value`,
    // meeting the wait's condition (an immediate read: its value): the wait ends, #5399 =
    // value. The node applies it from IO_STATUS. Refused (false) when no wait is on.
    kInputValue = 21,
    // The spindle override (feed_override: a fraction, clamped to spindle.min_override
    // .. max_override, LinuxCNC's MIN/MAX_SPINDLE_OVERRIDE): the spindle turns at the
    // program's S times it (at most spindle.max_rpm) while M51 has not disabled it.
    // A change of speed it makes is a new spindle change, not waited for (LinuxCNC's
    // motion scales the spindle at once and waits for at speed only after M3/M4/S).
    kSpindleOverride = 22,
    // The spindle's measured position (the drive bridge's SPINDLE_STATUS), for the
    // synchronised move (G33) ahead: position_mm[0] revolutions (positive clockwise,
    // M3), [1] revolutions per second, [2] the bridge's playback cycle of the sample
    // (the setpoint cycle being played when it was read). The node applies one per
    // cycle while wants_spindle_position(), recorded like every input.
    kSpindlePosition = 23,
    // The spindle's measured speed (`value`, rpm, its magnitude): the process laws
    // (roughness, force) follow it, as law_scale_for(value) of their planned limits.
    // The node applies it when that scale would change, recorded like every input.
    kSpindleSpeed = 24
  };
  Kind kind = Kind::kStart;
  double feed_override = 1.0;  // kOverride: 0.0 .. kMaxFeedOverride; kRapidOverride: 0.0 .. 1.0; kSpindleOverride
  // kReset: the program is dropped, the path is at rest at this position (where
  // the drives stand, as the node took it from AXIS_STATUS); one finite value per axis.
  std::array<double, program::kMaxAxes> position_mm{};
  int axis = -1;      // kHomed
  double value = 0;   // kHomed: drive minus machine position, mm; kSingleBlock, kOptionalStop: 1 on, 0 off;
                      // kSpindleAtSpeed: the change's seq; kInputValue: the input's value
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

// What the cyclic part did, counted over the core's life (the bench diffs them
// around a cycle to tell what its slowest cycles did). Plain counters: they cost a
// few increments per cycle and change nothing the core computes.
struct WorkCounters {
  int64_t plans_taken = 0;     // updates taken from the planner
  int64_t blocks_taken = 0;    // ...of which new blocks
  int64_t patch_values = 0;    // look-ahead values copied from the updates
  int64_t blocks_started = 0;  // blocks the path ran into (a block end crossed)
  int64_t table_lookups = 0;   // arc-length table lookups (u from s)
  int64_t newton_iters = 0;    // Newton iterations on the chord length
  int64_t bisect_evals = 0;    // curve points of the bracketing/bisection fallback
  int64_t safe_calls = 0;      // look-ahead checks
  int64_t safe_samples = 0;    // look-ahead samples visited by them
  int64_t brake_evals = 0;     // brake distances computed by them
  int64_t safe_skips = 0;      // block remainders they skipped (no limit there can be missed)
  int64_t look_builds = 0;     // searches over the acceleration with the samples gathered once
  int64_t look_fallbacks = 0;  // tries outside what was gathered (full check instead)
  int64_t curve_evals = 0;     // curve points (with derivatives) computed in the step
  int64_t curve_reuses = 0;    // ...and taken from the one before instead
};

// A spindle-synchronised move (G33) at the front: it waits at rest for the spindle's
// index (a whole revolution), then speeds up to the spindle's rate times the pitch
// as fast as the limits allow, locks its phase when it gets there (LinuxCNC's way:
// every pass of a thread at the same speed locks at the same angle) and from then on
// follows the spindle's position, predicted for the cycle its setpoint is played.
// The brake at its end leaves the spindle (as LinuxCNC's).
//
// A rigid tap (G33.1) is followed the same way down to its depth, where the spindle
// is reversed (turning tap_retract_scale times as fast); the tap keeps following the
// spindle through the reversal (past the depth by the spindle's stopping distance,
// `overshoot_mm`) and back up; near its start it leaves the spindle and stops on the
// start (kExit), and the spindle turns again as before. A STOP during a tap stops the
// spindle and the tap follows it to rest.
struct SyncMove {
  enum Phase : int8_t { kNone = 0, kWaitIndex = 1, kAcquire = 2, kTrack = 3, kExit = 4 };
  int64_t block_index = -1;
  Phase phase = kNone;
  double index_rev = 0;  // the index the move starts at (revolutions along the turning direction)
  double lock_rev = 0;   // tracking: where the path's s = pitch x (rev - lock_rev)
  int64_t lock_cycle = -1;  // the cycle it locked at; the phase it took from the index is
                            // made up over the next kSettleCycles, then it counts in max_error_mm
  static constexpr int64_t kSettleCycles = 50;
  double error_mm = 0;   // tracking: the spindle's position x pitch less the path's, last cycle
  double max_error_mm = 0;  // ...its largest magnitude over the move while tracking
  // Rigid tap.
  bool index_set = false;    // index_rev taken
  bool reversed = false;     // the spindle was reversed at the depth
  bool stopping = false;     // a STOP stopped the spindle: follow it to rest
  double overshoot_mm = 0;   // how far past the depth the tap went
  int direction = 0;         // the spindle's direction and speed when the tap began
  double rpm = 0, program_rpm = 0;
  // The reversal is commanded as a ramp of the spindle's speed (rev/s, signed) whose
  // acceleration and jerk times the pitch stay within half and a quarter of the
  // tap's: a step left the tap behind a servo spindle (125 um at 400 rev/s^2).
  bool ramping = false;
  double ramp_rps = 0, ramp_acc = 0, ramp_target = 0;
};

// The spindle as the program has it where the path stands: each spindle event
// (M3, M4, M5, S) is taken when the path reaches it; program end, a finished STOP,
// LOAD and RESET turn it off. Every change gets a new seq. M19 is a change to a
// standing spindle oriented at orient_deg (orient_mode: 0 the shortest way, 1
// clockwise, 2 counterclockwise); the path waits for it (kSpindleAtSpeed of that
// change: oriented) when the M19 had a Q.
struct SpindleState {
  int64_t seq = 0;
  int direction = 0;  // 1 cw, -1 ccw, 0 off
  double rpm = 0;     // 0 when off; the program's S under the spindle override
  double program_rpm = 0;  // the program's S (0 when off)
  bool orient = false;
  double orient_deg = 0;
  int orient_mode = 0;
};

// The probing move (G38.x block) the path is in or last left, for the node that
// decides its result: from its first cycle at the front until the next one's.
struct ProbeMove {
  int64_t block_index = -1;  // -1: none yet
  int kind = 0;              // 2..5 (G38.2..G38.5)
  bool tripped = false;      // a kProbeTrip was applied during it
  bool done = false;         // the path left it (at its end, or at rest after the trip)
  int64_t end_cycle = -1;    // the cycle it was left at
};

// The input wait (M66 event) the path stands at or last left, for the node that reads
// the input: from the cycle the path reached it at rest. A wait with a timeout ends
// by itself after timeout_cycles (value -1), counted by the core so a replay times out
// at the same cycle.
struct InputWaitState {
  int64_t block_index = -1;    // -1: none yet in this program
  program::InputWait wait;
  int64_t timeout_cycles = 0;  // 0: none (an immediate read)
  int64_t start_cycle = -1;
  bool waiting = false;        // the path stands at it until its value comes or it times out
  double value = 0;            // #5399: the value read, -1 when it timed out
  int64_t results = 0;         // the program's waits ended so far
};

// The shortest distance in which a brake limited by jerk J and acceleration A brings
// the speed from v (acceleration a) to vt; 0 when the speed never exceeds vt.
double brake_distance(double v, double a, double vt, double A, double J);

class LookaheadReference;

class Interpolator {
 public:
  // Plans inline: apply_block and an override take their plans at once.
  explicit Interpolator(const config::MachineConfig& cfg);
  // Plans through `link` (which outlives the core); plans are taken by apply_plans.
  Interpolator(const config::MachineConfig& cfg, PlanLink& link);
  ~Interpolator();
  Interpolator(const Interpolator&) = delete;
  Interpolator& operator=(const Interpolator&) = delete;

  // Inputs, applied before the next step(). Blocks must come in index order
  // (0, 1, 2, ... of the current program), each starting where the one before
  // ends; anything else is refused (false, last_refusal()). With a link the block
  // goes to the planner and moves only once its plan is taken.
  bool apply_block(const program::Block& block);
  // The same without a copy: the block is handed to the planner as it is (no
  // allocation here). On refusal the block is dropped.
  bool submit_block(std::unique_ptr<program::Block> block);
  // Program stops and tool changes (M0, M1, M6) hold the path until a RESUME; the dry
  // run resumes them at once, as an operator pressing resume without delay, and takes
  // every spindle change as at speed at once.
  void set_auto_resume_pauses(bool on) { auto_resume_pauses_ = on; }
  // False for an override the planner could not be told of now (its queue is full:
  // not applied, try again).
  bool apply_command(const Command& cmd);

  // Takes finished plans in order while `*budget_used` (samples taken this cycle)
  // is below `budget`, and adds to it. Returns the number taken; each one is an
  // input to record with the cycle (replay: apply_plans_exact).
  int apply_plans(int64_t budget, int64_t* budget_used);
  // Replay: takes exactly n plans (false when fewer are ready).
  bool apply_plans_exact(int n);
  // A plan that failed (a block the planner could not plan) since the last call:
  // its reason, and the program is stopping. "" when none.
  std::string take_plan_failure();

  // Computes the setpoint of the current cycle and advances the cycle counter.
  const Setpoint& step();

  int64_t cycle() const { return cycle_; }
  RunState state() const { return state_; }
  // The index of the next block to submit.
  int64_t next_block_index() const { return next_index_; }
  // Blocks whose plans were taken and are not finished.
  size_t queued_blocks() const { return blocks_.size(); }
  // Blocks submitted whose plans were not taken yet.
  int64_t blocks_in_planning() const { return submitted_ - taken_; }
  int64_t blocks_done() const { return blocks_done_; }
  int64_t starved_cycles() const { return starved_cycles_; }
  // Curve samples of the plans taken so far: the measure of work by which the feed
  // policy bounds what it takes per cycle (see motion.plan_budget_samples).
  int64_t planned_samples() const { return planned_samples_; }
  double feed_override() const { return override_; }
  double rapid_override() const { return rapid_override_; }
  double spindle_override() const { return spindle_override_; }
  // False between M51 P0 (or M49) and M51 P1 (M48) in the program the path runs.
  bool spindle_override_enabled() const { return spindle_override_on_; }
  bool single_block() const { return single_block_; }
  bool optional_stop() const { return optional_stop_; }
  // Held by single block at the start of a line (a RESUME runs that line).
  bool single_block_held() const { return hold_ && single_block_held_; }
  double program_time_s() const { return static_cast<double>(program_cycles_) * period_s_; }
  // The setpoint (what the drives are sent): the machine position plus each homed
  // axis's drive offset (none before homing: the drive's position is taken as the machine's).
  const Setpoint& last() const { return out_; }
  // Where the path stands in machine coordinates (blocks start and end there).
  double machine_position(int axis) const { return pos_[static_cast<size_t>(axis)]; }
  bool homed(int axis) const { return homed_[static_cast<size_t>(axis)]; }
  double drive_offset(int axis) const { return drive_offset_[static_cast<size_t>(axis)]; }
  const WorkCounters& work() const { return work_; }
  const SpindleState& spindle() const { return spindle_; }
  const ProbeMove& probe_move() const { return probe_; }
  const SyncMove& sync_move() const { return sync_; }
  // The dry run's spindle (a first-order response to the command): revolutions at this cycle.
  double dry_run_spindle_rev() const { return ideal_rev_; }
  // A synchronised move is queued: the node applies the spindle's position each cycle.
  bool wants_spindle_position() const;
  // The process laws' scale (planner.h, sample_limit) for a measured spindle speed:
  // that speed over the program's S, rounded to 1/128 and at most 1 (1 with no S).
  double law_scale_for(double measured_rpm) const;
  double law_scale() const { return law_scale_; }
  const InputWaitState& input_wait() const { return input_; }
  // Coolant and digital outputs where the path stands (machine_outputs.h).
  const MachineOutputs& outputs() const { return outputs_; }
  // At rest at a spindle change until kSpindleAtSpeed (a machine with a spindle:
  // spindle.enabled; a change to a speed > 0, turning).
  bool spindle_waiting() const { return spindle_wait_; }
  // Tests: every brake check's answer (and the limit it misses) handed to a check,
  // such as the plain scan of every sample to the horizon that the look-ahead's
  // shortcuts must answer as (tests/unit/lookahead_reference.h).
  class LookaheadCheck {
   public:
    virtual ~LookaheadCheck() = default;
    virtual void check(const Interpolator& ip, bool safe, double v_n, double a_n, double s_n,
                       const double* v_target) = 0;
  };
  void set_lookahead_check(LookaheadCheck* c) { lookahead_check_ = c; }
  // Arc length into the block being executed (mm).
  double s_in_block() const { return s_; }
  void set_param_update(ParamUpdate mode) { param_update_ = mode; }
  // Why the last refused block was refused.
  const std::string& last_refusal() const { return refusal_; }

 private:
  friend class LookaheadReference;  // tests: the reference scan reads the buffer a check judged
  // The cyclic side's blocks: a ring of pointers (storage grows only if more blocks
  // are queued than it was sized for, which the feed policy's window prevents).
  class Ring {
   public:
    explicit Ring(size_t capacity) : slots_(capacity) {}
    bool empty() const { return size_ == 0; }
    size_t size() const { return size_; }
    Planned& front() const { return *slots_[head_]; }
    Planned& back() const { return *slots_[(head_ + size_ - 1) % slots_.size()]; }
    Planned& operator[](size_t i) const { return *slots_[(head_ + i) % slots_.size()]; }
    void push_back(Planned* p);
    void pop_front() {
      head_ = (head_ + 1) % slots_.size();
      --size_;
    }
    void clear() { head_ = size_ = 0; }

   private:
    std::vector<Planned*> slots_;
    size_t head_ = 0, size_ = 0;
  };

  bool push_request(const PlanRequest& r);
  bool flush_requests();
  void take(PlanUpdate& u);
  // Recomputes p.v_min after p.v_bw changed in [from, end).
  static void update_suffix_min(Planned& p, size_t from, size_t end);
  void clear_blocks();
  void clear_program(bool stop_spindle);  // LOAD (false) and RESET (true): clear_blocks() and the program's counts and motion state
  void pop_block();
  bool check_block(const program::Block& block);
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
  // safe() for the accelerations of one cycle's search, a in [a_lo, a_hi]: the
  // samples such a brake could miss are gathered once (build_look) and each try
  // visits only them, the one that failed last first; the same answers as safe(),
  // which it falls back to for a try outside the bounds it was built for.
  void build_look(double vn_lo, double a_lo, double sn_lo, double vn_hi, double a_hi, double sn_hi);
  bool safe_cached(double v_n, double a_n, double s_n, double* v_target = nullptr);
  bool safe_scan(double v_n, double a_n, double s_n, double* v_target) const;
  // Whether a brake from (v_n, a_n) misses the limit vt at distance d ahead, with the
  // least limits A, J of the blocks up to it; a block's entry sample (entry) is met
  // also by a brake with the limits of the blocks before it (A_before, J_before).
  static bool brake_misses(double v_n, double a_n, double vt, double d, double A, double J, bool entry,
                           double A_before, double J_before, double T);
  // Whether sample i's look-ahead limit is its own (its cap, the entry, a stop) rather
  // than only the backward pass's acceleration ramp up from a later one, which the
  // brake check meets by meeting that later limit.
  bool own_limit(const Planned& p, size_t i) const;
  bool safe_gathered(double v_n, double a_n, double s_n, double* v_target);
  // The least acceleration and jerk limits of the blocks up to the next stop point:
  // the brake check's horizon is what a brake with them needs (see its definition).
  void horizon_limits(double* A, double* J) const;
  // The least limits of the blocks a landing on `cap` from this cycle's state can
  // reach (its acceleration ramped down by J·T per cycle), starting from A and J.
  void landing_limits(double cap, double a_hi, double* A, double* J) const;
  double hz_A_ = 0, hz_J_ = 0;  // horizon_limits() of the cycle's buffer, for its brake checks
  // step()'s stages, by what the path does this cycle.
  void hold_at_line_start();
  void at_stop_block(bool pausing);
  void end_or_starve();
  void move_along_path(bool pausing);
  // The next cycle's acceleration: towards the cap, as far as the look-ahead lets.
  double lookahead_accel(double cap, double A, double J, double a_lo, double a_hi, bool* limited);
  // v_n lowered so the step's mean speed meets the geometric limits it passes over.
  double geometric_speed_bound(const Planned& p, double v_n, double geo_here, Limit* why) const;

  // Moves the path ds along the blocks (interpolator_advance.cc); *reached_stop when
  // it ends on a stop point. Returns the distance moved.
  double advance(double ds, bool* reached_stop);
  // advance()'s stages: a step that reaches the block's end goes on into the next
  // block; one inside the block finds its u (false: it ended the block after all).
  struct CurveStep;
  bool step_reaches_end(const Planned& p, double step_left, double* to_end) const;
  bool cross_into_next_block(const Planned& p);
  bool step_in_block(const Planned& p, double step);
  double eq7_estimate(const Planned& p, double step, CurveStep* c);
  double newton_on_chord(const Planned& p, double step, const motion::AxisVec& P, double u, bool* converged);
  bool bisect_on_chord(const Planned& p, double step, const CurveStep& c, bool converged, double* u);
  void commit_step(const Planned& p, double step, double u, const CurveStep& c);
  // |P(u) − P|, counted as a bisection evaluation.
  double chord_from(const Planned& p, const motion::AxisVec& P, double u);
  // p.path.eval(u, ...), or the result of the last call when it was for the same
  // block and the same u (bit for bit): a step starts where the last one's Newton
  // iteration ended, and the setpoint is the point it converged on.
  void eval_on(const Planned& p, double u, motion::AxisVec* P, motion::AxisVec* d1, motion::AxisVec* d2);
  // u at arc length s from the planner's samples; *du: the u spacing of the two around s.
  static double u_on_table(const Planned& p, double s, double* du);
  // Arc length at u from the planner's samples.
  static double s_on_table(const Planned& p, double u);
  bool creep_to_stop();
  // A spindle event at the front, reached: the change taken (and waited for).
  void take_spindle_event(const Planned& p);
  void spindle_off();
  // What a program starts with: M48 on, no door hold or at-speed wait carried over.
  void program_start_modes();
  // The speed the spindle turns at for the program's S: under the override, at most spindle.max_rpm.
  double overridden_rpm(double program_rpm) const;
  // After the override or its enable changed: the spindle turning takes the new speed (a change, not waited for).
  void spindle_reoverride();
  // Probing: the move at the front noted when first reached; at rest after a trip it
  // ends where the path stands.
  void track_probe_move();
  void end_probe_move();
  // An M66 at the front, reached at rest: true while the path waits there.
  bool wait_on_input(const Planned& p);
  void end_input_wait(double value);

  config::MachineConfig cfg_;
  double period_s_;
  int naxes_;
  ParamUpdate param_update_ = ParamUpdate::kCorrected;
  std::unique_ptr<SyncPlanLink> own_link_;
  PlanLink* link_;
  bool inline_ = false;  // own link: plans taken at once

  RunState state_ = RunState::kIdle;
  bool hold_ = false;
  bool event_paused_ = false;       // the program stop / tool change at the front has paused once
  bool auto_resume_pauses_ = false;
  bool stopping_ = false;
  double override_ = 1.0;
  double rapid_override_ = 1.0;
  double spindle_override_ = 1.0;
  bool spindle_override_on_ = true;
  double law_scale_ = 1.0;  // the process laws' scale (kSpindleSpeed)
  uint64_t overrides_taken_ = UINT64_MAX;  // serial of the M48-M53 event last taken
  bool single_block_ = false;
  bool optional_stop_ = true;
  bool single_block_held_ = false;           // hold_ was set by single block
  bool single_block_go_ = false;             // START: the first line runs without a hold
  uint64_t single_block_passed_ = UINT64_MAX;  // serial of the line start last held at (or let go)
  // Single block on: the line starts ahead from the first one the path can still stop
  // at become stop points (live_entry 0); off: they are given back the planner's entry.
  void mark_single_block_stops();
  void unmark_single_block_stops();
  void single_block_stop(Planned& p);

  Ring blocks_;  // front: the block being executed
  int64_t next_index_ = 0;
  uint64_t epoch_ = 0;        // a LOAD, RESET or finished STOP starts a new one
  uint64_t next_serial_ = 0;  // serial of the next block submitted
  uint64_t retired_below_ = 0;
  bool retire_pending_ = false;
  int64_t submitted_ = 0, taken_ = 0;  // block requests, over the core's life
  bool failed_ = false;                // a plan of this epoch failed: the rest of it is dropped
  std::string failure_;
  // Where the next submitted block must start (the end of the last one submitted in
  // this epoch; the path's position when none was).
  bool have_tail_ = false;
  std::array<double, program::kMaxAxes> tail_{};
  // Requests the link could not take yet, sent first next time (order is kept).
  std::array<PlanRequest, 64> pending_{};
  size_t pending_n_ = 0;

  double u_ = 0;     // parameter in the front block
  double s_ = 0;     // arc length in the front block
  double v_ = 0;     // path speed, mm/s
  double a_ = 0;     // path acceleration, mm/s²
  int64_t dwell_left_ = -1;
  // The path came to rest on a stop point with motion in that cycle: the next cycles
  // stand still, so the start from rest begins from a rest the setpoints show, and
  // long enough (kRestCycles) that the drive bridge's two moving averages of one
  // period each (2 periods together) never mix the approach with the departure: mixed,
  // they cut the corner (by up to 7.9 um at sim3's limits).
  static constexpr int kRestCycles = 2;
  int rest_left_ = 0;

  // build_look's samples, in path order: where (block offset, s), limit, brake limits.
  struct LookCand {
    double offset, s, vt, A, J, A_before, J_before;
    bool entry;
  };
  static constexpr size_t kLookCapacity = 1024;  // more: that search checks in full
  std::vector<LookCand> look_;
  size_t look_n_ = 0;
  bool look_ok_ = false;
  double look_H_ = 0, look_sn_lo_ = 0, look_sn_hi_ = 0, look_vn_hi_ = 0, look_m2_ = 0;
  bool look_term_ = false;  // a stop point within reach: where, and the brake limits up to it
  double look_term_off_ = 0, look_term_A_ = 0, look_term_J_ = 0;
  bool look_last_ = false;  // the last sample before it
  double look_last_off_ = 0, look_last_s_ = 0;
  size_t look_fail_ = 0;  // the candidate that failed last (look_n_: the stop point; more: none)

  struct LastEval {
    uint64_t serial = UINT64_MAX;  // of the block (none yet)
    uint64_t u_bits = 0;
    motion::AxisVec P{}, d1{}, d2{};
  } last_eval_;

  SpindleState spindle_;
  SyncMove sync_;
  uint64_t sync_serial_ = UINT64_MAX;  // the block sync_ belongs to
  double sync_speed_ = 0;  // the synchronised move's speed command this cycle, mm/s
  double sync_target_ = 0;  // ...and where the spindle puts the path at its end (tracking)
  // The spindle's last measured position (kSpindlePosition), and the dry run's own
  // spindle (auto_resume_pauses_: it turns exactly as commanded).
  double sp_rev_ = 0, sp_rps_ = 0, sp_cycle_ = 0;
  double sp_acc_ = 0, sp_acc_cycle_ = 0, sp_acc_rps_ = 0;  // its acceleration, rev/s², and the sample it is from
  int64_t sp_applied_ = -1;  // the cycle it was applied at (-1: none)
  double ideal_rev_ = 0, ideal_rps_ = 0;
  std::array<char, 200> sync_failure_{};  // why a synchronised move stopped (no allocation in the cycle)
  bool spindle_position(double* rev, double* rps) const;
  void update_sync();
  double acquisition_lag(double v, double A, double J, bool trapezoid) const;
  double follow_speed(double target, double v_ff) const;  // G33's and the rigid tap's tracker
  bool rigid_tap_front() const;
  void rigid_tap_step();
  // A rigid tap's last stretch up: x(t) = v0 t + a0 t^2/2 + c3 t^3 + c4 t^4 + c5 t^5 to d at rest.
  struct TapExit {
    double d = 0, v0 = 0, a0 = 0, c3 = 0, c4 = 0, c5 = 0, te = 0;
    int64_t k = 0;  // cycles into it
    double x(double t) const;
  };
  TapExit exit_;
  void plan_tap_exit(double A, double J);
  void end_rigid_tap(bool program_stops);
  ProbeMove probe_;
  uint64_t probe_serial_ = UINT64_MAX;  // the front block ProbeMove describes
  bool probe_braking_ = false;          // tripped: braking to rest in the probing move
  InputWaitState input_;
  uint64_t input_serial_ = UINT64_MAX;  // the M66 event input_ describes
  MachineOutputs outputs_;
  uint64_t outputs_taken_ = UINT64_MAX;  // serial of the coolant or output event last taken
  uint64_t spindle_taken_ = UINT64_MAX;  // serial of the spindle event last taken
  bool spindle_wait_ = false;
  bool wait_for_spindle_ = false;  // cfg.spindle.enabled
  // A guard door's hold (kHold with value 1): once the path stands the spindle stops;
  // RESUME turns it on again and the path stays held until it is at speed.
  bool door_hold_ = false;
  SpindleState door_spindle_;  // the spindle the door stopped (direction 0: none)
  bool door_resume_ = false;   // RESUMEd: the path stands (RUNNING) until the spindle is at speed
  void door_spindle_stop();

  std::array<double, program::kMaxAxes> pos_{};
  std::array<double, program::kMaxAxes> drive_offset_{};
  std::array<bool, program::kMaxAxes> homed_{};
  bool any_offset_ = false;
  // out_.position_mm from pos_ (plus the drive offsets once an axis was homed).
  void output_position();
  int64_t cycle_ = 0;
  int64_t blocks_done_ = 0;
  int64_t starved_cycles_ = 0;
  int64_t program_cycles_ = 0;
  int64_t planned_samples_ = 0;
  Setpoint out_;
  std::string refusal_;
  mutable WorkCounters work_;
  LookaheadCheck* lookahead_check_ = nullptr;
};

}  // namespace cnc::interp
