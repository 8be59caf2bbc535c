#pragma once
// Prints canonical calls in the text format of LinuxCNC's standalone interpreter
// rs274 (tools/conformance/CANON_FORMAT.md): a call counter, the block's N word, the
// call with its arguments. The conformance harness compares this output with
// rs274's own, call by call.
#include <cstdio>
#include <functional>
#include <string>

#include "common/rs274/canon.h"

namespace cnc::rs274 {

class CanonPrinter : public Canon {
 public:
  // `line_text` gives the raw text of the block being executed (for the N field).
  CanonPrinter(std::FILE* out, std::function<const std::string&()> line_text);

  void use_length_units(const SourceRef&, Units) override;
  void select_plane(const SourceRef&, Plane) override;
  void set_g5x_offset(const SourceRef&, int, const Pose&) override;
  void set_g92_offset(const SourceRef&, const Pose&) override;
  void set_xy_rotation(const SourceRef&, double) override;
  void set_feed_reference(const SourceRef&) override;
  void set_feed_rate(const SourceRef&, double) override;
  void set_feed_mode(const SourceRef&, FeedMode) override;
  void set_motion_control_mode(const SourceRef&, PathMode, double) override;
  void set_naivecam_tolerance(const SourceRef&, double) override;
  void use_tool_length_offset(const SourceRef&, const Pose&) override;
  void on_reset(const SourceRef&) override;
  void straight_traverse(const SourceRef&, const Pose& end) override;
  void straight_feed(const SourceRef&, const Pose& end) override;
  void arc_feed(const SourceRef&, double first_end, double second_end, double first_axis, double second_axis,
                int rotation, double axis_end, const Pose& end) override;
  void nurbs_feed(const SourceRef&, int order, const std::vector<NurbsPoint>& points, const std::vector<double>& knots,
                  const Pose& end) override;
  void dwell(const SourceRef&, double seconds) override;
  void turn_probe_on(const SourceRef&) override;
  void straight_probe(const SourceRef&, const Pose& end, int kind) override;
  void turn_probe_off(const SourceRef&) override;
  void start_speed_feed_sync(const SourceRef&, double feed_per_rev, bool velocity_mode) override;
  void stop_speed_feed_sync(const SourceRef&) override;
  void rigid_tap(const SourceRef&, const Pose& end, double retract_scale) override;
  void wait_orient_complete(const SourceRef&, double timeout_s) override;
  void select_tool(const SourceRef&, int) override;
  void set_tool_table_entry(const SourceRef&, int, int, const Pose&, double, double, double, int) override;
  void start_change(const SourceRef&) override;
  void change_tool(const SourceRef&, int) override;
  void change_tool_number(const SourceRef&, int) override;
  void set_spindle_speed(const SourceRef&, double) override;
  void start_spindle_clockwise(const SourceRef&) override;
  void start_spindle_counterclockwise(const SourceRef&) override;
  void stop_spindle_turning(const SourceRef&) override;
  void set_spindle_mode(const SourceRef&, double) override;
  void orient_spindle(const SourceRef&, double, int) override;
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
  void comment(const SourceRef&, const std::string&) override;
  void message(const SourceRef&, const std::string&) override;
  void log_open(const SourceRef&, const std::string& name, bool append) override;
  void log_close(const SourceRef&) override;
  void log_line(const SourceRef&, const std::string& text) override;
  void program_stop(const SourceRef&) override;
  void optional_program_stop(const SourceRef&) override;
  void pallet_shuttle(const SourceRef&) override;
  void program_end(const SourceRef&) override;
  void finish(const SourceRef&) override;

  int64_t calls() const { return counter_; }

 private:
  void line(const char* fmt, ...) __attribute__((format(printf, 2, 3)));
  char* head(char* buf);
  void pose_line(const char* name, size_t name_len, const Pose& pose);
  std::FILE* out_;
  std::function<const std::string&()> line_text_;
  int64_t counter_ = 0;
};

}  // namespace cnc::rs274
