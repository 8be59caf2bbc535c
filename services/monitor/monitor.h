#pragma once
#include <cmath>
#include <array>
#include <limits>
// Monitor core: from the blocks the interpolator applied, its setpoints and the
// drive bridge's axis status, per status:
//   * commanded feed (the setpoint of that cycle) and actual feed (from the actual
//     positions of consecutive statuses),
//   * the chord error of the commanded step against the exact block geometry,
//   * the R_max that Choi et al. 2005's extended model predicts from the actual feed, the
//     feed inclination angle and the block's process parameters,
//   * the following error per axis,
//   * with the machine config's `cutting:` section, VMCS 1999's cutting force and
//     tool deflection per setpoint (common/process/live_force.h): the engagement from
//     a Z-map stock that every cutting step's envelope is removed from, the feed per
//     tooth from the commanded step in XY and the block's spindle speed,
// and alarm conditions. Pure: no LCM, no clock. A report depends only on the
// messages and their order, so a log played back gives the same reports. The actual
// feed is taken over the last two statuses (8 ms at 4 ms) to average out jitter,
// with the inclination at the window's middle.
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/motion/path_segment.h"
#include "common/process/live_force.h"
#include "common/program/block.h"

namespace cnc::monitor {

struct SetpointIn {
  int64_t stream = 0;  // lcmt_setpoint.stream
  int64_t cycle = 0;
  int64_t program_token = 0;
  int64_t block_index = -1;
  int32_t source_line = 0;
  double u = 0;
  double feed_mm_per_min = 0;
  motion::AxisVec position_mm{};
};

struct Report {
  int64_t setpoint_cycle = 0;
  double commanded_feed_mm_per_min = 0;
  double actual_feed_mm_per_min = 0;
  double chord_error_mm = 0;      // NaN when unknown
  double predicted_rmax_um = 0;   // NaN without process parameters
  double target_rmax_um = 0;      // NaN without process parameters
  double spindle_rpm = 0;
  double max_following_error_mm = 0;  // the largest |following error| of the status's axes
  int64_t block_index = -1;
  int32_t source_line = 0;
  // VMCS 1999 (NaN without `cutting:` or where the setpoint's block is unknown; 0 off the stock or not cutting).
  double force_x_n = 0, force_y_n = 0, force_z_n = 0;  // mean over a tooth period
  double force_peak_n = 0;                             // largest |F| in XY over it
  double deflection_mm = 0;                            // largest tool-tip deflection over it
  double deflection_tolerance_mm = 0;                  // NaN without `cutting:`
};

struct Alarm {
  std::string code;  // "rmax", "chord_error", "deflection", "force"
  std::string text;
};

class Monitor {
 public:
  explicit Monitor(const config::MachineConfig& cfg);
  // The axes' lag behind the setpoints in coarse cycles, a fraction allowed (the
  // bridge's jitter buffer of two periods, its fine interpolation and the drives'
  // 1.5 ms interpolation buffer): 3 on the cell; 0 where the actual positions are
  // the setpoints themselves (tests).
  void set_tracking_lag_cycles(double n) { lag_cycles_ = n; }
  // The axes' lag behind the bridge's playback position (AXIS_STATUS playback_cycle),
  // in coarse cycles: its fine interpolation's two moving averages of one period
  // ((n-1) ticks), the drives' interpolation buffer (1.5 servo periods) and the age of
  // the actual positions a status carries (about one servo period): 1.25 on the cell
  // (T_ipo = 4 T_servo); 0 where the actual positions are the setpoints (tests).
  void set_playback_lag_cycles(double n) { playback_lag_cycles_ = n; }

  // A block the interpolator applied (INTERP_INPUT), of program `token`.
  void on_block(const program::Block& b, int64_t token);
  // A setpoint of a stream older than the newest seen (one that waited in a queue
  // across a RESET) is dropped and counted; a newer stream is a reset.
  void on_setpoint(const SetpointIn& sp);
  int64_t stale_setpoints() const { return stale_; }
  // A RESET the interpolator applied: its path jumps to where the drives stand, so
  // the next setpoint is no step of the machine (no chord error across it).
  void on_reset() {
    last_sp_.reset();
    cut_prev_valid_ = false;
  }
  // A HOMED the interpolator applied (INTERP_INPUT): from then on the axis's
  // setpoints are its machine position plus `offset_mm` (the drive's coordinates),
  // while the blocks are in machine coordinates: the chord error is taken on the
  // setpoints less the offsets. (Homing happens at rest, between blocks.) A monitor
  // started after a homing does not know the offset and reads the setpoints as
  // machine positions: an error of the offset itself, a few micrometres from a switch.
  void on_homed(int axis, double offset_mm) {
    if (axis >= 0 && axis < naxes_ && std::isfinite(offset_mm)) drive_offset_[static_cast<size_t>(axis)] = offset_mm;
  }
  // An axis status (utime: when the bridge read the actual positions); returns the
  // report and appends raised alarms to *alarms. playback_cycle: the bridge's playback
  // position on the setpoint stream (fractional cycles; < 0 unknown: the newest
  // setpoint cycle stands in for it, tracking_lag_cycles behind).
  Report on_status(int64_t utime, int64_t setpoint_cycle, const std::vector<double>& actual_mm,
                   const std::vector<double>& following_error_mm, std::vector<Alarm>* alarms,
                   double playback_cycle = -1.0);

  double largest_following_error_mm() const { return largest_fe_; }
  double largest_chord_error_mm() const { return largest_chord_; }

 private:
  struct Known {
    program::Block block;
    std::unique_ptr<motion::PathSegment> path;
  };
  const Known* find(int64_t token, int64_t index) const;
  // on_status's stages.
  void track_actual_feed(int64_t utime, int64_t cycle, const std::vector<double>& actual, int n_axes,
                         bool have_playback, double playback);
  void push_sample(int64_t utime, int64_t cycle, const std::vector<double>& actual, int n_axes, double playback);
  void predict_rmax(int64_t cycle, const SetpointIn& sp, bool have_playback, double playback, Report* r) const;
  void raise_alarms(int64_t cycle, const Report& r, std::vector<Alarm>* alarms);
  double step_chord_error(const SetpointIn& prev, const SetpointIn& cur) const;

  config::MachineConfig cfg_;
  int naxes_;
  std::map<std::pair<int64_t, int64_t>, Known> blocks_;  // (token, index), bounded
  // VMCS 1999 per setpoint (NaN: unknown).
  struct ForceSlot {
    double fx = 0, fy = 0, fz = 0, peak = 0, deflection = 0;
  };
  // The last setpoints by cycle, in a ring (slot = cycle mod its size) allocated
  // once: per cycle the monitor allocates nothing.
  struct CycleSlot {
    int64_t cycle = -1;  // -1: empty
    SetpointIn sp;
    double chord_mm = std::numeric_limits<double>::quiet_NaN();  // of the step ending at this cycle
    ForceSlot force;
  };
  ForceSlot cutting_force(const SetpointIn& sp);
  std::unique_ptr<process::LiveForce> force_;  // null without `cutting:`
  int64_t cut_token_ = 0;                      // the program the stock was cut by
  bool cut_stock_dirty_ = false;
  bool cut_prev_valid_ = false;
  SetpointIn cut_prev_;
  Eigen::Vector2d cut_dir_{1.0, 0.0};
  std::vector<CycleSlot> cycles_;
  CycleSlot* slot(int64_t cycle);
  const SetpointIn* setpoint_at(int64_t cycle) const;
  bool commanded_at(double cycle, int n_axes, motion::AxisVec* out) const;
  std::optional<SetpointIn> last_sp_;
  int64_t stream_ = 0;  // the newest setpoint stream seen
  int64_t stale_ = 0;
  // The actual positions of the last statuses over a window (see on_status): a
  // fixed ring, oldest at recent_head_.
  struct Sample {
    int64_t utime = 0;
    int64_t cycle = 0;
    double playback = -1;  // the bridge's playback position, cycles (< 0: unknown)
    int naxes = 0;
    motion::AxisVec pos{};
  };
  static constexpr size_t kRecent = 64;
  std::array<Sample, kRecent> recent_{};
  size_t recent_head_ = 0, recent_n_ = 0;
  const Sample& recent(size_t i) const { return recent_[(recent_head_ + i) % kRecent]; }
  double tracking_ratio_ = 1.0;  // actual / commanded distance over the window
  double lag_cycles_ = 3.0;       // how many coarse cycles the axes follow the setpoints late
  double playback_lag_cycles_ = 1.25;  // ... and the bridge's playback position
  double actual_feed_ = 0;
  double largest_fe_ = 0;
  double largest_chord_ = 0;
  motion::AxisVec drive_offset_{};  // per axis, from HOMED inputs (drive minus machine)
  bool rmax_alarm_ = false;
  bool chord_alarm_ = false;
  bool deflection_alarm_ = false;
  bool force_alarm_ = false;
};

}  // namespace cnc::monitor
