#pragma once
// Block planning of the interpolator, apart from its cyclic step: per block the
// curve samples along the arc length with their geometric feed limits (chord error,
// roughness, axis velocity, curvature), the junction with the block before, and the
// look-ahead (the backward pass of acceleration-limited speed limits over the
// buffered blocks, which end in a stop). A Planner is a pure function of the
// ordered requests it processed: the same requests give the same updates, bit for
// bit, whichever thread runs it and whenever. The cyclic core (interpolator.h)
// applies the updates at cycles it records as inputs; see README.md "Timing".
#include <array>
#include <cstdint>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/path_segment.h"
#include "common/process/live_force.h"
#include "common/program/block.h"

namespace cnc::interp {

// Which constraint set the commanded feed (values match lcmt_setpoint's LIMIT_*).
enum class Limit : int8_t {
  kNone = 0, kProgram = 1, kChord = 2, kRoughness = 3, kAxisVelocity = 4, kCurvatureAccel = 5, kLookahead = 6,
  kForce = 7
};

struct Sample {
  double u;
  double s;      // arc length from the block start, mm
  double v_geo;  // geometric speed limit, mm/s
  Limit limit;
};

// One planned block. Everything but the "cyclic side" fields is written by the
// planner before the block is handed over and only read afterwards.
struct Planned {
  program::Block block;
  motion::PathSegment path;
  std::vector<Sample> samples;  // at least two for a moving block
  double length = 0;
  double v_prog = 0;            // programmed feed in mm/s (rapids: the axis-limited speed)
  double accel = 0, jerk = 0;   // tangential limits over the block
  // The tangential limits the block may use where no junction of it is crossed at
  // speed with a velocity step (both are stops, or tangent-continuous): the share of
  // each axis's limits kept for that step goes to the tangential planning too (lines:
  // all of it; NURBS without corners inside: what their curvature leaves).
  // The planner hands them over in a limits patch once the block's exit junction is
  // known to allow them; until then the block runs with accel and jerk.
  double accel_free = 0, jerk_free = 0;
  // Its entry junction allows free limits on both sides: a stop, or crossed at a speed
  // the corner rule would allow with them (tangent- and curvature-continuous).
  bool entry_free_ok = false;
  double v_entry = 0;           // junction limit with the previous block (planner's)
  uint64_t serial = 0;          // submission number (monotonic over the core's life)
  // The first block of a program line (its source file or line differs from the block
  // before, or none came before in this epoch): where single block holds.
  bool line_start = false;
  bool stop_block() const;      // dwell / end / event: the path stops here

  // Cyclic side, written only by the thread that steps the core after the handover.
  std::vector<double> v_bw;     // look-ahead limits per sample (sized by the planner)
  std::vector<double> v_min;    // v_min[i]: the least of v_bw[i..] (sized by the planner)
  double live_entry = 0;        // the entry limit the cyclic side uses
  bool single_block_stop = false;  // live_entry made 0 by the single-block switch
  double planned_v0 = 0;        // the planner's v_bw[0] before the cyclic side lowered it to live_entry
  double live_accel = 0, live_jerk = 0;  // the tangential limits the cyclic side uses
  bool stop_at_start() const { return stop_block() || live_entry == 0; }
  // The process laws' own limit per sample (the roughness law, the force limit), at
  // the programmed S; empty where neither applies. Both are feeds per tooth, so they
  // scale with the spindle's speed (sample_limit).
  std::vector<double> v_law;

  Planned(program::Block b, motion::PathSegment p) : block(std::move(b)), path(std::move(p)) {}
};

// Sample i's speed limit with the process laws scaled by law_scale: the spindle's
// measured speed over the programmed S, at most 1 (a faster spindle leaves the plan's
// limits as they are). At 1 it is the planned limit, bit for bit.
inline double sample_limit(const Planned& p, size_t i, double law_scale) {
  const double v = p.samples[i].v_geo;
  if (!(law_scale < 1.0) || p.v_law.empty()) return v;
  return std::min(v, law_scale * p.v_law[i]);
}

// From the cyclic side to the planner, in the order the core emitted them.
struct PlanRequest {
  enum class Kind : uint8_t { kBlock = 1, kOverride = 2, kClear = 3 };
  Kind kind = Kind::kBlock;
  uint64_t epoch = 0;               // the core's program epoch (a LOAD, RESET or finished STOP starts one)
  uint64_t serial = 0;              // kBlock: the block's submission number
  program::Block* block = nullptr;  // kBlock: owned by the planner from the push on
  double feed_override = 1.0;       // kOverride
  double rapid_override = 1.0;      // kOverride: the rapids' scale (0 .. 1)
  double law_scale = 1.0;           // kOverride: the process laws' scale (sample_limit)
};

// From the planner to the cyclic side: one per block or override request, in order.
struct PlanUpdate {
  uint64_t epoch = 0;
  Planned* block = nullptr;  // kBlock: the new block, owned by the planner (freed after it is retired)
  int64_t samples = 0;       // samples planned for it (the per-cycle budget counts these)
  // New look-ahead values for blocks the cyclic side may hold: values[offset, offset+count)
  // go to the block with `serial`, starting at sample `from`.
  struct Patch {
    uint64_t serial;
    uint32_t from, count, offset;
  };
  std::vector<Patch> patches;
  std::vector<double> values;
  // Raised tangential limits for a block the cyclic side may hold (its accel_free and
  // jerk_free: neither of its junctions turned out to be crossed with a velocity step).
  struct Limits {
    uint64_t serial;
    double accel, jerk;
  };
  std::vector<Limits> limits;
  std::string error;  // kBlock: the block could not be planned (block is null)
  void clear() {
    epoch = 0;
    block = nullptr;
    samples = 0;
    patches.clear();
    values.clear();
    limits.clear();
    error.clear();
  }
};

class Planner {
 public:
  explicit Planner(const config::MachineConfig& cfg);
  ~Planner();
  Planner(const Planner&) = delete;
  Planner& operator=(const Planner&) = delete;

  // Processes one request; returns its update (kBlock, kOverride) or nullptr (kClear).
  // The update stays the planner's; give it back with recycle() once applied.
  PlanUpdate* process(const PlanRequest& r);
  void recycle(PlanUpdate* u);
  // The cyclic side holds no block with a serial below this any more.
  void retire(uint64_t serial_below);
  size_t held_blocks() const { return list_.size(); }

 private:
  struct Entry {
    std::unique_ptr<Planned> p;
    std::vector<double> v_bw;  // the planner's own look-ahead values
    double accel = 0;          // the acceleration its look-ahead values use (raised once free)
    bool free = false;         // runs with accel_free and jerk_free (Planned::entry_free_ok at both ends)
    bool recompute = false;    // its look-ahead values changed without its end's
  };
  // One block's limits, in stages (planner.cc): the samples, the limits at each, and
  // samples added where a limit falls steeply.
  struct BlockWork;
  void plan_block(Planned& p);
  double chord_speed(double kappa, double eps) const;
  void sample_grid(const Planned& p, BlockWork& w) const;
  void sample_limits(Planned& p, BlockWork& w) const;
  void local_limits(Planned& p, BlockWork& w) const;
  void knot_limits(Planned& p, BlockWork& w) const;
  void inner_turn_limits(Planned& p, BlockWork& w) const;
  void neighbour_limits(Planned& p, const BlockWork& w) const;
  void arc_lengths(Planned& p, const BlockWork& w) const;
  void curvature_jerk_limits(Planned& p, const BlockWork& w) const;
  void free_limits(Planned& p, const BlockWork& w) const;
  bool close_in_on_low_ends(const Planned& p, BlockWork& w) const;
  // The force feed limit (cutting.feed_limit): adds stations to *us and returns the
  // speed limit per station (∞ where none binds), cutting the block out of the stock.
  void force_limits(const Planned& p, std::vector<double>* us, std::vector<double>* v_force);
  void reset_stock();
  void plan_junction(const Planned& prev, Planned& next) const;
  // The fastest a block programmed at v_prog can go: kMaxFeedOverride x F (the override's most) and
  // no faster than every axis at its velocity limit together.
  double top_speed(double v_prog) const;
  // The speed at which the path may turn from tangent t0 to t1 within one cycle, with
  // the path's tangential limits a_path and j_path on either side; *stop when these
  // alone would use up an axis's jerk or acceleration limit in that cycle.
  double corner_speed(const motion::AxisVec& t0, const motion::AxisVec& t1, double a_path, double j_path,
                      bool* stop) const;
  void backward_pass(bool full, PlanUpdate* u);
  double programmed_speed(const Planned& p) const;
  bool rapid_at_full_speed(const Planned& p) const;
  PlanUpdate* fresh_update();

  config::MachineConfig cfg_;
  double period_s_;
  int naxes_;
  double override_ = 1.0;
  double rapid_override_ = 1.0;  // the rapids' scale (0 .. 1)
  double law_scale_ = 1.0;       // the process laws' (sample_limit)
  uint64_t epoch_ = 0;
  uint64_t retired_below_ = 0;
  std::deque<Entry> list_;  // this epoch's blocks not yet retired, and always the newest
  std::vector<std::unique_ptr<PlanUpdate>> pool_;  // recycled updates
  std::vector<std::unique_ptr<PlanUpdate>> live_;  // handed out (owned here until recycled)
  // cutting.feed_limit: VMCS 1999's deflection along the path, from a stock the planned
  // blocks are cut out of in planning order (reset with each epoch: a new program run).
  std::unique_ptr<process::LiveForce> force_;
  bool force_dirty_ = false;
  bool force_prev_valid_ = false;
  Eigen::Vector3d force_prev_ = Eigen::Vector3d::Zero();
  Eigen::Vector2d force_dir_{1.0, 0.0};
};

// How the cyclic core reaches its planner: inline (SyncPlanLink: dry run, replay,
// tests) or on a thread of its own (ThreadedPlanLink, planner_thread.h).
class PlanLink {
 public:
  virtual ~PlanLink() = default;
  // Cyclic side. push: false when the link is full (try again later; nothing is taken).
  virtual bool push(const PlanRequest& r) = 0;
  // The next finished update or nullptr; pop() hands it back after it was applied.
  virtual PlanUpdate* front() = 0;
  virtual void pop() = 0;
  virtual void retire(uint64_t serial_below) = 0;
};

// The planner called inline: every request's update is ready at once.
class SyncPlanLink final : public PlanLink {
 public:
  explicit SyncPlanLink(const config::MachineConfig& cfg) : planner_(cfg) {}
  bool push(const PlanRequest& r) override;
  PlanUpdate* front() override { return ready_.empty() ? nullptr : ready_.front(); }
  void pop() override;
  void retire(uint64_t serial_below) override { planner_.retire(serial_below); }
  size_t ready() const { return ready_.size(); }

 private:
  Planner planner_;
  std::deque<PlanUpdate*> ready_;
};

}  // namespace cnc::interp
