#pragma once
// Canonical calls → the interpolator's blocks: machine axes, mm, mm/min. Applies
// what LinuxCNC's canon layer applies (units, G92, XY rotation, G5x, tool length
// offset), keeps the spindle and process state that each motion block carries, and
// turns the non-motion calls the cell acts on into event blocks in program order.
// The checks of block geometry that the interpolator relies on (arc radii, NURBS
// knots and weights, axes the machine has) are made here, at the source line of the
// call, so a program that would be refused on the network is refused at its place.
#include <Eigen/Core>
#include <deque>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "common/program/block.h"
#include "common/rs274/canon.h"

namespace cnc::rs274 {

struct BuilderSetup {
  std::vector<std::string> axis_names;     // machine axes in order, e.g. X Y Z
  std::vector<double> start_position_mm;   // where the machine stands
  // Per machine axis: rotary (degrees; LinuxCNC's feed rules, rotary_feed). Empty: none.
  std::vector<bool> rotary;
  double spindle_rpm = 0;                  // speed before any S word
  program::ProcessParams process;          // what a PROCESS directive leaves out
  // G64 P (path blending within P): runs of short G1 moves are fitted to cubic
  // splines within P (fit_runs), other corners between G1 lines are rounded within
  // P by a quartic blend. A run: consecutive G1 moves of one feed, each at most
  // fit_max_segment_mm long, turning by at most fit_max_turn_deg at each vertex.
  bool fit_runs = true;
  double fit_max_segment_mm = 2.0;
  // ...or up to this many times P: a coarser CAM post's chords of a gentle curve
  // (3D_Chips' 1-2.3 mm moves at P 0.1) are one curve too.
  double fit_max_segment_per_p = 100.0;
  double fit_max_turn_deg = 30.0;
  int fit_max_spans = 100;  // knot spans per NURBS block the fit is cut into
  // No corner blend where the interpolator's corner rule passes the kink at the
  // run's feed anyway (its velocity step |Δt|·v within corner_dv_mm_s, the least of
  // one cycle's acceleration and half a cycle's jerk), nor where the blend would be
  // crossed in fewer than 1.5 cycles at the speed its curvature allows with half of
  // accel_mm_s2, or is shorter than 1.5 of the smallest steps from rest (jerk_mm_s3·T³/6):
  // the interpolation cannot resolve it, and would turn within a step (the corner stops).
  double ipo_period_s = 0.004;
  double corner_dv_mm_s = 0;
  double accel_mm_s2 = 0;  // the least of the path's and the axes' limits
  double jerk_mm_s3 = 0;
  // The machine's chord tolerance: its share of P (program::chord_tolerance_mm) is
  // not the fit's and the blends'.
  double chord_tolerance_mm = 0.001;
  // G64 without P (and the start, in G64): this P, mm; 0 keeps the lines exactly.
  double default_path_tolerance_mm = 0;
  // The spindle's position is measured (spindle.encoder_counts_per_rev): G33, G33.1,
  // M19 and G87's oriented stops make blocks; otherwise they are refused.
  bool spindle_sync = false;
};

class BlockBuilder : public Canon {
 public:
  // `file_name(i)` names file i of the interpreter's file table (for block sources).
  BlockBuilder(BuilderSetup setup, std::function<const std::string&(int32_t)> file_name);

  // Blocks made so far and not yet taken, oldest first; the caller pops them.
  std::deque<program::Block>& blocks() { return out_; }
  int64_t blocks_made() const { return next_index_; }
  void restore_spindle_and_coolant(const SourceRef&, int spindle, double s, bool mist, bool flood) override {
    spindle_dir_ = spindle;
    if (s > 0) speed_rpm_ = s;  // no S word yet: the machine's speed before any (setup.spindle_rpm)
    coolant_ = (mist ? 1 : 0) | (flood ? 2 : 0);
  }
  bool ended() const { return ended_; }

  void use_length_units(const SourceRef&, Units) override;
  void set_motion_control_mode(const SourceRef&, PathMode, double tolerance) override;
  void select_plane(const SourceRef&, Plane) override;
  void set_g5x_offset(const SourceRef&, int, const Pose&) override;
  void set_g92_offset(const SourceRef&, const Pose&) override;
  void set_xy_rotation(const SourceRef&, double) override;
  void set_feed_rate(const SourceRef&, double) override;
  void set_feed_mode(const SourceRef&, FeedMode) override;
  void use_tool_length_offset(const SourceRef&, const Pose&) override;
  void straight_traverse(const SourceRef&, const Pose& end) override;
  void straight_feed(const SourceRef&, const Pose& end) override;
  void arc_feed(const SourceRef&, double first_end, double second_end, double first_axis, double second_axis,
                int rotation, double axis_end, const Pose& end) override;
  void nurbs_feed(const SourceRef&, int order, const std::vector<NurbsPoint>& points, const std::vector<double>& knots,
                  const Pose& end) override;
  void dwell(const SourceRef&, double seconds) override;
  void straight_probe(const SourceRef&, const Pose& end, int kind) override;
  void start_speed_feed_sync(const SourceRef&, double feed_per_rev, bool velocity_mode) override;
  void stop_speed_feed_sync(const SourceRef&) override;
  void rigid_tap(const SourceRef&, const Pose& end, double retract_scale) override;
  void wait_orient_complete(const SourceRef&, double timeout_s) override;
  // Where the machine came to rest after a probing move (machine mm, one per axis):
  // the next block starts there.
  void set_position(const std::vector<double>& machine_mm) { position_ = machine_mm; }
  void change_tool(const SourceRef&, int) override;
  void orient_spindle(const SourceRef&, double, int) override;
  void set_spindle_speed(const SourceRef&, double) override;
  void start_spindle_clockwise(const SourceRef&) override;
  void start_spindle_counterclockwise(const SourceRef&) override;
  void stop_spindle_turning(const SourceRef&) override;
  void mist_on(const SourceRef&) override;
  void mist_off(const SourceRef&) override;
  void flood_on(const SourceRef&) override;
  void flood_off(const SourceRef&) override;
  void enable_feed_override(const SourceRef&, bool) override;
  void enable_speed_override(const SourceRef&, bool) override;
  void enable_adaptive_feed(const SourceRef&, bool) override;
  void enable_feed_hold(const SourceRef&, bool) override;
  void digital_output(const SourceRef&, int, bool, bool) override;
  void analog_output(const SourceRef&, int, double, bool) override;
  void wait_input(const SourceRef&, int, bool, int, double) override;
  void set_process(const SourceRef&, const ProcessSettings&) override;
  void message(const SourceRef&, const std::string&) override;
  void program_stop(const SourceRef&) override;
  void optional_program_stop(const SourceRef&) override;
  void pallet_shuttle(const SourceRef&) override;
  void program_end(const SourceRef&) override;
  void finish(const SourceRef&) override;

 private:
  program::Block& begin(const SourceRef& ref, program::BlockKind kind);
  void event(const SourceRef& ref, program::EventKind kind, int32_t number, double value, std::string text = {});
  std::vector<double> to_machine(const SourceRef& ref, const Pose& p) const;
  double feed_mm_per_min(const SourceRef& ref) const;
  // The block's feed along its path in all axes (mm and degrees, the planner's arc
  // length) for LinuxCNC's rules: F along the linear axes' length `lin_len` (0: only
  // rotary axes move, F in deg/min); `f` as feed_mm_per_min gives it.
  double rotary_feed(const SourceRef& ref, const std::vector<double>& to, double lin_len, double f) const;
  bool rotary_moves(const std::vector<double>& to) const;
  bool rotary(size_t axis) const { return axis < setup_.rotary.size() && setup_.rotary[axis]; }
  // G64 P: the G1 moves held back to be blended or fitted, and their emission.
  bool blending() const;
  // Holds a G1 move (e, machine mm; moved from) in the run; false: not blending, or
  // other axes move too (the run was ended).
  bool hold_move(const SourceRef& ref, std::vector<double>& e, double f);
  // Holds an arc in the run as chords (G64 P, fit on); false: not, it runs as an arc.
  // a1, a2: its plane's two axes, as arc_feed found them.
  bool hold_arc(const SourceRef& ref, const program::Block& arc, int a1, int a2);
  void flush_run();
  struct RunShape;
  struct Stretch;
  RunShape run_shape(double tol) const;
  std::vector<Stretch> fit_stretches(RunShape& r) const;
  void emit_run(const RunShape& r, const std::vector<Stretch>& stretches);
  // Whether a corner blend of leg d between the unit directions u_in and u_out is long
  // enough for the interpolation to resolve it (BuilderSetup: accel_mm_s2).
  bool resolvable_blend(double d, const Eigen::Vector3d& u_in, const Eigen::Vector3d& u_out, double feed_mm_s) const;
  // A block of the run being flushed: its feed, spindle and process, from `from` to `to`.
  program::Block& run_block(const SourceRef& ref, program::BlockKind kind, const std::vector<double>& from,
                            const std::vector<double>& to);

  BuilderSetup setup_;
  std::function<const std::string&(int32_t)> file_name_;
  std::vector<int> axis_of_pose_;  // pose index (X..W) → machine axis, -1: the machine has none
  std::deque<program::Block> out_;
  int64_t next_index_ = 0;
  bool ended_ = false;

  double scale_ = 1.0;  // mm per program unit
  Plane plane_ = Plane::kXY;
  Pose g5x_{}, g92_{}, tool_{};  // mm (degrees for A B C)
  double rotation_deg_ = 0;
  std::vector<double> position_;  // machine mm
  double feed_ = 0;               // program units / min (or / rev)
  double angular_feed_ = 0;       // deg / min (or / rev): the last rate set, unscaled by G20/G21
  FeedMode feed_mode_ = FeedMode::kUnitsPerMinute;
  double speed_rpm_ = 0;
  double sync_pitch_mm_ = 0;  // between START_ and STOP_SPEED_FEED_SYNCH: G33's K, G76's P (or taper pitch) in mm; 0 otherwise
  void synced_line(const SourceRef& ref, const Pose& end, int8_t sync, double retract_scale);
  int spindle_dir_ = 0;
  int coolant_ = 0;
  int overrides_ = 0xF;
  // The roughness law's parameters: none (the law off) until the program's first
  // (PROCESS, ...) says which cut its moves are; a machine's process: section only
  // fills in what the directive leaves out (an engraving or a drilling program
  // is not cut by the machine file's ball end mill).
  program::ProcessParams process_;
  bool process_declared_ = false;

  PathMode path_mode_ = PathMode::kContinuous;
  double path_tol_mm_ = 0;  // G64 P in mm (or the default); 0: no blending
  struct RunPoint {
    std::vector<double> pos;  // machine mm, every axis
    SourceRef ref;            // the move that ends here (the first: the run's first move)
    // Where an arc's chords begin or end here: the arc's own tangent (unit) as the move
    // after this point leaves it, and as the move before it arrives; else empty.
    std::optional<Eigen::Vector3d> leave, arrive;
  };
  std::vector<RunPoint> run_;  // run_[0]: where the run starts
  double run_feed_ = 0;
  double run_sagitta_mm_ = 0;  // the largest sagitta of the arcs' chords in the run
  double run_rpm_ = 0;
  program::ProcessParams run_process_;
  bool flushing_ = false;
};

}  // namespace cnc::rs274
