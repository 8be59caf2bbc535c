#pragma once
// A Canon that hands every call on, unchanged, to another one: the base of a filter
// between the interpreter and its consumer (cutter compensation), which then
// overrides only the calls it holds, reorders or acts on.
#include <string>
#include <vector>

#include "common/rs274/canon.h"

namespace cnc::rs274 {

class CanonForward : public Canon {
 public:
  explicit CanonForward(Canon& next) : next_(next) {}

  void use_length_units(const SourceRef& r, Units u) override { next_.use_length_units(r, u); }
  void select_plane(const SourceRef& r, Plane p) override { next_.select_plane(r, p); }
  void set_g5x_offset(const SourceRef& r, int i, const Pose& p) override { next_.set_g5x_offset(r, i, p); }
  void set_g92_offset(const SourceRef& r, const Pose& p) override { next_.set_g92_offset(r, p); }
  void set_xy_rotation(const SourceRef& r, double d) override { next_.set_xy_rotation(r, d); }
  void set_feed_reference(const SourceRef& r) override { next_.set_feed_reference(r); }
  void set_feed_rate(const SourceRef& r, double f) override { next_.set_feed_rate(r, f); }
  void set_feed_mode(const SourceRef& r, FeedMode m) override { next_.set_feed_mode(r, m); }
  void set_motion_control_mode(const SourceRef& r, PathMode m, double p) override {
    next_.set_motion_control_mode(r, m, p);
  }
  void set_naivecam_tolerance(const SourceRef& r, double q) override { next_.set_naivecam_tolerance(r, q); }
  void use_tool_length_offset(const SourceRef& r, const Pose& p) override { next_.use_tool_length_offset(r, p); }
  void on_reset(const SourceRef& r) override { next_.on_reset(r); }
  void restore_spindle_and_coolant(const SourceRef& r, int spindle, double s, bool mist, bool flood) override {
    next_.restore_spindle_and_coolant(r, spindle, s, mist, flood);
  }

  void straight_traverse(const SourceRef& r, const Pose& end) override { next_.straight_traverse(r, end); }
  void straight_feed(const SourceRef& r, const Pose& end) override { next_.straight_feed(r, end); }
  void arc_feed(const SourceRef& r, double first_end, double second_end, double first_axis, double second_axis,
                int rotation, double axis_end, const Pose& end) override {
    next_.arc_feed(r, first_end, second_end, first_axis, second_axis, rotation, axis_end, end);
  }
  void nurbs_feed(const SourceRef& r, int order, const std::vector<NurbsPoint>& points, const std::vector<double>& knots,
                  const Pose& end) override {
    next_.nurbs_feed(r, order, points, knots, end);
  }
  void dwell(const SourceRef& r, double seconds) override { next_.dwell(r, seconds); }
  void turn_probe_on(const SourceRef& r) override { next_.turn_probe_on(r); }
  void straight_probe(const SourceRef& r, const Pose& end, int kind) override { next_.straight_probe(r, end, kind); }
  void turn_probe_off(const SourceRef& r) override { next_.turn_probe_off(r); }
  void start_speed_feed_sync(const SourceRef& r, double k, bool v) override { next_.start_speed_feed_sync(r, k, v); }
  void stop_speed_feed_sync(const SourceRef& r) override { next_.stop_speed_feed_sync(r); }
  void rigid_tap(const SourceRef& r, const Pose& end, double scale) override { next_.rigid_tap(r, end, scale); }
  void wait_orient_complete(const SourceRef& r, double t) override { next_.wait_orient_complete(r, t); }

  void select_tool(const SourceRef& r, int t) override { next_.select_tool(r, t); }
  void start_change(const SourceRef& r) override { next_.start_change(r); }
  void change_tool(const SourceRef& r, int t) override { next_.change_tool(r, t); }
  void change_tool_number(const SourceRef& r, int t) override { next_.change_tool_number(r, t); }
  void set_tool_table_entry(const SourceRef& r, int index, int tool, const Pose& offset, double diameter, double front,
                            double back, int orientation) override {
    next_.set_tool_table_entry(r, index, tool, offset, diameter, front, back, orientation);
  }

  void set_spindle_speed(const SourceRef& r, double rpm) override { next_.set_spindle_speed(r, rpm); }
  void start_spindle_clockwise(const SourceRef& r) override { next_.start_spindle_clockwise(r); }
  void start_spindle_counterclockwise(const SourceRef& r) override { next_.start_spindle_counterclockwise(r); }
  void stop_spindle_turning(const SourceRef& r) override { next_.stop_spindle_turning(r); }
  void orient_spindle(const SourceRef& r, double deg, int mode) override { next_.orient_spindle(r, deg, mode); }
  void set_spindle_mode(const SourceRef& r, double max_rpm) override { next_.set_spindle_mode(r, max_rpm); }
  void mist_on(const SourceRef& r) override { next_.mist_on(r); }
  void mist_off(const SourceRef& r) override { next_.mist_off(r); }
  void flood_on(const SourceRef& r) override { next_.flood_on(r); }
  void flood_off(const SourceRef& r) override { next_.flood_off(r); }

  void enable_feed_override(const SourceRef& r, bool b) override { next_.enable_feed_override(r, b); }
  void enable_speed_override(const SourceRef& r, bool b) override { next_.enable_speed_override(r, b); }
  void enable_adaptive_feed(const SourceRef& r, bool b) override { next_.enable_adaptive_feed(r, b); }
  void enable_feed_hold(const SourceRef& r, bool b) override { next_.enable_feed_hold(r, b); }
  void digital_output(const SourceRef& r, int i, bool on, bool sync) override { next_.digital_output(r, i, on, sync); }
  void analog_output(const SourceRef& r, int i, double v, bool sync) override { next_.analog_output(r, i, v, sync); }
  void wait_input(const SourceRef& r, int i, bool analog, int mode, double t) override { next_.wait_input(r, i, analog, mode, t); }
  void set_process(const SourceRef& r, const ProcessSettings& p) override { next_.set_process(r, p); }

  void comment(const SourceRef& r, const std::string& s) override { next_.comment(r, s); }
  void message(const SourceRef& r, const std::string& s) override { next_.message(r, s); }
  void log_open(const SourceRef& r, const std::string& name, bool append) override { next_.log_open(r, name, append); }
  void log_close(const SourceRef& r) override { next_.log_close(r); }
  void log_line(const SourceRef& r, const std::string& s) override { next_.log_line(r, s); }

  void program_stop(const SourceRef& r) override { next_.program_stop(r); }
  void optional_program_stop(const SourceRef& r) override { next_.optional_program_stop(r); }
  void pallet_shuttle(const SourceRef& r) override { next_.pallet_shuttle(r); }
  void program_end(const SourceRef& r) override { next_.program_end(r); }
  void finish(const SourceRef& r) override { next_.finish(r); }

 protected:
  Canon& next_;
};

}  // namespace cnc::rs274
