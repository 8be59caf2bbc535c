#pragma once
// Drive bridge core: fine interpolation of coarse setpoints (Kim, Song & Kwon's two-step
// scheme) and the safety rules the architecture asks of the bridge. Pure: no
// Modbus, no LCM, no clock, no allocation per tick; driven by servo ticks.
//
// The fine interpolation plays the coarse stream back on a clock of its own,
// τ (in coarse cycles), drive_bridge.lead_cycles (2) ± 0.5 periods behind the newest setpoint: the
// reference at τ is the straight line between the received setpoints around it, so
// a missed setpoint (a gap in the cycle index) is bridged by the line between its
// neighbours. The playback rate follows the buffer (0.90..1.05, slewed gently and
// never above an axis's velocity limit): a late setpoint that used up the buffer
// is made up again, and the clocks of two PCs may drift apart. Past the newest
// setpoint the reference goes on at the last velocity for one period; beyond that
// the axes brake; a stream back before the timeout is rejoined, one silent for
// longer than the timeout makes the brake a controlled stop and a fault.
//
// Honest tracking. The straight lines have a velocity step at every coarse point
// (a·T_ipo in one servo tick: 4·a at T_ipo = 4·T_servo). So the reference goes
// through two moving averages of one coarse period each (n ticks): velocity
// becomes a ramp over the period (acceleration = the stream's second difference)
// and acceleration a ramp too (jerk = the stream's third difference), at a delay of
// n-1 ticks. A stream within an axis's v/a/j limits then gives fine setpoints
// within them. Then every tick goes through a limiter that makes the command's
// finite differences (v = Δx/T, a = Δv/T, j = Δa/T over T_servo) keep each axis's
// velocity, acceleration and jerk limits whatever the reference does: it tracks
// the smoothed reference exactly while that keeps the limits, and otherwise (a
// late setpoint's extrapolation ending, a rejoin, a stream slightly over a limit)
// steers back onto it by nested saturated feedback (position → velocity →
// acceleration → jerk). Stops (watchdog, faults, starving) use the same limiter
// with the velocity target 0 and the deceleration min(stop_decel, the axis's).
//
// A setpoint outside an axis's travel, or implying more than its velocity or
// acceleration limit, is never followed: the bridge faults and stops. A stream
// is joined only where the axes stand (engage), and only after ENABLE.
//
// Streams. Each engagement has a token, and a setpoint carries the token the
// interpolator had seen when it made it: one made before the bridge engaged (a
// datagram queued across a fault and a reset) is dropped and counted, never joined.
// A setpoint of a stream older than the one followed is dropped and counted too; a
// newer stream (the interpolator's RESET or restart) is joined like a first one,
// where the axes stand, once the old one has come to rest; a newer stream while the
// old one's newest setpoint still moved (an interpolator restarted within the
// watchdog's timeout, or a second one) is a fault.
#include <array>
#include <cstdint>
#include <string>

#include "common/config/machine_config.h"
#include "common/kinematics/kinematics.h"
#include "common/program/block.h"

namespace cnc::bridge {

using AxisArray = std::array<double, program::kMaxAxes>;

// Where a setpoint comes from (lcmt_setpoint.stream, .engagement).
struct StreamStamp {
  int64_t stream = 0;
  int64_t engagement = 0;
};

class BridgeCore {
 public:
  enum class Mode : int8_t {
    kIdle,       // not engaged: commands hold, setpoints are ignored
    kFollowing,  // engaged: follows the stream (or waits for one that starts where the axes stand)
    kStopping,   // a fault: controlled stop at the stop deceleration
    kStopped,    // a fault, standing still: nothing moves until engaged again
  };
  enum class Verdict : int8_t { kAccepted, kIgnored, kWaiting, kStale, kFault };

  explicit BridgeCore(const config::MachineConfig& cfg);

  // Follow setpoints made after the interpolator saw `engagement` (larger than
  // every engagement before), starting where the axes stand.
  void engage(const AxisArray& hold_mm, int64_t engagement = 0);
  // Stop following (drives disabled): commands hold at `at_mm`.
  void disengage(const AxisArray& at_mm);
  Verdict on_setpoint(int64_t cycle, const AxisArray& position_mm, const StreamStamp& from = {});
  // One servo tick: the commanded positions for this tick.
  const AxisArray& tick();
  // Instead of a tick, while the drives' link is stalled (the command of the last
  // tick has not reached them): the playback stands still, so the drives receive
  // the commands one tick after another when the link moves again, instead of a
  // jump over the ticks it missed. Allowed while following a stream (braking for a
  // starved one too) while the newest setpoint leads the playback by at most 4
  // cycles over the usual lead (the lag it adds must be made up) and the setpoint
  // watchdog has not run out, and in a controlled stop for at most
  // timing.setpoint_timeout_s per stop; returns false (and does nothing)
  // otherwise: the caller ticks instead.
  bool hold();
  // Faults: a controlled stop from the current motion, then kStopped. The first reason stays.
  void fault(const std::string& why);

  Mode mode() const { return mode_; }
  bool faulted() const { return mode_ == Mode::kStopping || mode_ == Mode::kStopped; }
  // Engaged, but the stream does not start where the axes stand (yet).
  bool waiting() const { return mode_ == Mode::kFollowing && last_cycle_ < 0 && !waiting_reason_.empty(); }
  const std::string& fault_reason() const { return fault_reason_; }
  // The fault is the setpoint watchdog's (no setpoint for setpoint_timeout_s).
  bool watchdog_tripped() const { return watchdog_tripped_; }
  const std::string& waiting_reason() const { return waiting_reason_; }
  const AxisArray& commanded() const { return cmd_; }
  // Finite differences of the commanded positions over the last servo tick.
  const AxisArray& velocity() const { return vel_; }
  const AxisArray& acceleration() const { return acc_; }
  int64_t last_cycle() const { return last_cycle_; }
  // Cycle of the setpoint the current command heads for; -1 when none.
  int64_t segment_cycle() const { return seg_cycle_; }
  double playback_rate() const { return rate_; }
  // The playback's position on the stream, in coarse cycles (fractional).
  double playback_cycle() const { return tau_; }
  int64_t setpoint_gaps() const { return gaps_; }
  // Ticks past the newest setpoint, on its velocity (bridging a late one).
  int64_t bridged_ticks() const { return bridged_ticks_; }
  // Ticks braking because no setpoint came within the bridging allowance.
  int64_t starved_ticks() const { return starved_ticks_; }
  // Times the stream came back while braking and was rejoined.
  int64_t rejoins() const { return rejoins_; }
  // Ticks the playback stood still for a stalled link.
  int64_t held_ticks() const { return held_ticks_; }
  int64_t engagement() const { return engagement_; }
  int64_t stream() const { return stream_; }
  // Setpoints dropped as made before the engagement or of an older stream.
  int64_t stale_setpoints() const { return stale_; }

 private:
  struct Point {
    int64_t cycle;
    AxisArray pos;
    AxisArray vel;  // the stream's velocity over the step that ends here
  };
  static constexpr int kPoints = 64;
  // The largest playback rate above 1 the buffered stream leaves room for (see tick()).
  double catch_up_cap() const;
  const Point& point(int i) const { return points_[static_cast<size_t>((p_head_ + i) % kPoints)]; }
  void push(const Point& p);
  // Forget the stream followed so far: the next setpoint joins where the axes stand.
  void restart_stream();
  void path_at(double tau, AxisArray& out);  // the stream's position at τ (straight lines)
  void smooth(const AxisArray& p);             // the two moving averages: ref_, ref_v_, ref_a_, ref_j_
  void reset_smoothing(const AxisArray& at);   // both averages full of `at`, at rest
  // One limited step: towards the smoothed reference (follow = true) or to a
  // standstill at the stop deceleration (follow = false).
  void limit_step(bool follow);

  static constexpr int kMaxWindow = 128;  // ticks of one coarse period, at most
  static constexpr double kStillVelocity = 0.01;  // mm/s: at rest, for joining a new stream
  static constexpr double kStillAccel = 1.0;      // mm/s^2
  config::MachineConfig cfg_;
  // The joints' limits from the machine's kinematics (identity: the axes'); setpoints
  // are joint positions.
  std::array<kinematics::JointLimits, program::kMaxAxes> joints_;
  int n_;  // servo ticks per coarse period
  double servo_s_;
  double ipo_s_;
  int naxes_;
  int lead_window_;  // ticks the lead is averaged over: one coarse period (at most 128)
  int window_;       // ticks of each moving average: one coarse period (at most 128)
  double lead_cycles_;  // drive_bridge.lead_cycles: the usual lead of the newest setpoint over τ
  Mode mode_ = Mode::kIdle;
  std::array<Point, kPoints> points_{};
  int p_head_ = 0;
  int p_size_ = 0;
  double tau_ = 0;       // playback time, in coarse cycles
  double rate_ = 1.0;    // playback rate
  // Lead of the newest setpoint over τ (cycles), averaged over the last coarse
  // period: the average of a sawtooth that repeats every period is flat.
  std::array<double, 128> lead_ring_{};
  double lead_sum_ = 0;
  int lead_i_ = 0;
  bool braking_ = false; // starved past the bridging allowance
  // The two moving averages (ring buffers of the last window_ inputs per axis).
  std::array<std::array<double, kMaxWindow>, program::kMaxAxes> ma1_{};
  std::array<std::array<double, kMaxWindow>, program::kMaxAxes> ma2_{};
  int ma_i_ = 0;
  AxisArray ref_{};      // smoothed reference position
  AxisArray ref_v_{};    // and its finite differences
  AxisArray ref_a_{};
  AxisArray ref_j_{};
  bool ref_fresh_ = true;  // the reference's differences are not known yet (after a reset)
  int64_t rejoins_ = 0;
  int64_t held_ticks_ = 0;
  int64_t stop_held_ticks_ = 0;  // holds for a stalled link in the current controlled stop
  int64_t seg_cycle_ = -1;
  AxisArray cmd_{};
  AxisArray vel_{};      // commanded velocity of the last tick, mm/s
  AxisArray acc_{};      // commanded acceleration of the last tick, mm/s^2
  AxisArray last_sp_{};  // last accepted setpoint
  AxisArray sp_vel_{};   // velocity of the last accepted coarse step
  // The same between the stream's own two newest setpoints (0 until it has two: the
  // step a join takes from where the axes stand is not the stream moving).
  AxisArray stream_vel_{};
  int64_t last_cycle_ = -1;
  int64_t last_gap_ = 1;  // cycles the last accepted step spanned
  int64_t engagement_ = 0;
  int64_t stream_ = 0;    // of the setpoints followed since the engagement
  int64_t stale_ = 0;
  int64_t gaps_ = 0;
  int64_t bridged_ticks_ = 0;
  int64_t starved_ticks_ = 0;
  int64_t ticks_since_setpoint_ = 0;
  std::string fault_reason_;
  bool watchdog_tripped_ = false;
  std::string waiting_reason_;
};

}  // namespace cnc::bridge
