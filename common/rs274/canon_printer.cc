#include "common/rs274/canon_printer.h"

#include <cstdarg>

namespace cnc::rs274 {

namespace {

const char* plane_name(Plane p) {
  switch (p) {
    case Plane::kXY: return "CANON_PLANE_XY";
    case Plane::kYZ: return "CANON_PLANE_YZ";
    case Plane::kXZ: return "CANON_PLANE_XZ";
    case Plane::kUV: return "CANON_PLANE_UV";
    case Plane::kVW: return "CANON_PLANE_VW";
    case Plane::kUW: return "CANON_PLANE_UW";
  }
  return "?";
}

}  // namespace

CanonPrinter::CanonPrinter(std::FILE* out, std::function<const std::string&()> line_text)
    : out_(out), line_text_(std::move(line_text)) {}

// "%5d " counter, then the N field of the block being executed, then the call.
void CanonPrinter::line(const char* fmt, ...) {
  ++counter_;
  std::fprintf(out_, "%5ld ", static_cast<long>(counter_));
  const std::string& t = line_text_();
  size_t i = 0;
  while (i < t.size() && (t[i] == ' ' || t[i] == '\t' || t[i] == '/')) ++i;
  if (i < t.size() && (t[i] == 'N' || t[i] == 'n')) {
    ++i;
    size_t j = i;
    while (j < t.size() && t[j] >= '0' && t[j] <= '9') ++j;
    const int digits = static_cast<int>(j - i);
    std::fprintf(out_, "N%.*s%*s", digits, t.c_str() + i, digits < 6 ? 6 - digits : 0, "");
  } else {
    std::fputs("N..... ", out_);
  }
  va_list ap;
  va_start(ap, fmt);
  std::vfprintf(out_, fmt, ap);
  va_end(ap);
  std::fputc('\n', out_);
}

void CanonPrinter::use_length_units(const SourceRef&, Units u) {
  line("USE_LENGTH_UNITS(%s)", u == Units::kMm ? "CANON_UNITS_MM" : "CANON_UNITS_INCHES");
}
void CanonPrinter::select_plane(const SourceRef&, Plane p) { line("SELECT_PLANE(%s)", plane_name(p)); }
void CanonPrinter::set_g5x_offset(const SourceRef&, int index, const Pose& p) {
  line("SET_G5X_OFFSET(%d, %.4f, %.4f, %.4f, %.4f, %.4f, %.4f)", index, p[0], p[1], p[2], p[3], p[4], p[5]);
}
void CanonPrinter::set_g92_offset(const SourceRef&, const Pose& p) {
  line("SET_G92_OFFSET(%.4f, %.4f, %.4f, %.4f, %.4f, %.4f)", p[0], p[1], p[2], p[3], p[4], p[5]);
}
void CanonPrinter::set_xy_rotation(const SourceRef&, double deg) { line("SET_XY_ROTATION(%.4f)", deg); }
void CanonPrinter::set_feed_reference(const SourceRef&) { line("SET_FEED_REFERENCE(CANON_XYZ)"); }
void CanonPrinter::set_feed_rate(const SourceRef&, double rate) { line("SET_FEED_RATE(%.4f)", rate); }
void CanonPrinter::set_feed_mode(const SourceRef&, FeedMode m) {
  line("SET_FEED_MODE(0, %d)", m == FeedMode::kUnitsPerRev ? 1 : 0);
}
void CanonPrinter::set_motion_control_mode(const SourceRef&, PathMode m, double tolerance) {
  if (m == PathMode::kContinuous)
    line("SET_MOTION_CONTROL_MODE(CANON_CONTINUOUS, %f)", tolerance);
  else
    line("SET_MOTION_CONTROL_MODE(%s)", m == PathMode::kExactStop ? "CANON_EXACT_STOP" : "CANON_EXACT_PATH");
}
void CanonPrinter::set_naivecam_tolerance(const SourceRef&, double q) { line("SET_NAIVECAM_TOLERANCE(%.4f)", q); }
void CanonPrinter::use_tool_length_offset(const SourceRef&, const Pose& p) {
  line("USE_TOOL_LENGTH_OFFSET(%.4f %.4f %.4f, %.4f %.4f %.4f, %.4f %.4f %.4f)", p[0], p[1], p[2], p[3], p[4], p[5], p[6],
       p[7], p[8]);
}
void CanonPrinter::on_reset(const SourceRef&) { line("ON_RESET()"); }
void CanonPrinter::straight_traverse(const SourceRef&, const Pose& p) {
  line("STRAIGHT_TRAVERSE(%.4f, %.4f, %.4f, %.4f, %.4f, %.4f)", p[0], p[1], p[2], p[3], p[4], p[5]);
}
void CanonPrinter::straight_feed(const SourceRef&, const Pose& p) {
  line("STRAIGHT_FEED(%.4f, %.4f, %.4f, %.4f, %.4f, %.4f)", p[0], p[1], p[2], p[3], p[4], p[5]);
}
void CanonPrinter::arc_feed(const SourceRef&, double first_end, double second_end, double first_axis,
                            double second_axis, int rotation, double axis_end, const Pose& p) {
  line("ARC_FEED(%.4f, %.4f, %.4f, %.4f, %d, %.4f, %.4f, %.4f, %.4f)", first_end, second_end, first_axis, second_axis,
       rotation, axis_end, p[3], p[4], p[5]);
}
void CanonPrinter::nurbs_feed(const SourceRef&, int, const std::vector<NurbsPoint>& points, const std::vector<double>&,
                              const Pose&) {
  line("NURBS_FEED(%lu, ...)", static_cast<unsigned long>(points.size()));
}
void CanonPrinter::dwell(const SourceRef&, double s) { line("DWELL(%.4f)", s); }
void CanonPrinter::turn_probe_on(const SourceRef&) { line("TURN_PROBE_ON()"); }
void CanonPrinter::straight_probe(const SourceRef&, const Pose& p, int) {
  line("STRAIGHT_PROBE(%.4f, %.4f, %.4f, %.4f, %.4f, %.4f)", p[0], p[1], p[2], p[3], p[4], p[5]);
}
void CanonPrinter::turn_probe_off(const SourceRef&) { line("TURN_PROBE_OFF()"); }
// saicanon's spellings, the missing H of the first included.
void CanonPrinter::start_speed_feed_sync(const SourceRef&, double k, bool v) {
  line("START_SPEED_FEED_SYNC(%f,%d)", k, v ? 1 : 0);
}
void CanonPrinter::stop_speed_feed_sync(const SourceRef&) { line("STOP_SPEED_FEED_SYNCH()"); }
void CanonPrinter::rigid_tap(const SourceRef&, const Pose& p, double) { line("RIGID_TAP(%.4f, %.4f, %.4f)", p[0], p[1], p[2]); }
void CanonPrinter::wait_orient_complete(const SourceRef&, double t) { line("SPINDLE.0.WAIT_ORIENT_COMPLETE(%.4f)", t); }
void CanonPrinter::select_tool(const SourceRef&, int t) { line("SELECT_TOOL(%d)", t); }
// saicanon prints no diameter.
void CanonPrinter::set_tool_table_entry(const SourceRef&, int index, int tool, const Pose& o, double, double front,
                                        double back, int orientation) {
  line("SET_TOOL_TABLE_ENTRY(%d, %d, %.4f %.4f %.4f %.4f %.4f %.4f %.4f %.4f %.4f, %.4f, %.4f, %d)", index, tool, o[0],
       o[1], o[2], o[3], o[4], o[5], o[6], o[7], o[8], front, back, orientation);
}
void CanonPrinter::start_change(const SourceRef&) { line("START_CHANGE()"); }
void CanonPrinter::change_tool(const SourceRef&, int t) { line("CHANGE_TOOL(%d)", t); }
void CanonPrinter::change_tool_number(const SourceRef&, int t) { line("CHANGE_TOOL_NUMBER(%d)", t); }
void CanonPrinter::set_spindle_speed(const SourceRef&, double rpm) { line("SET_SPINDLE_SPEED(0, %.4f)", rpm); }
void CanonPrinter::start_spindle_clockwise(const SourceRef&) { line("START_SPINDLE_CLOCKWISE(0)"); }
void CanonPrinter::start_spindle_counterclockwise(const SourceRef&) { line("START_SPINDLE_COUNTERCLOCKWISE(0)"); }
void CanonPrinter::stop_spindle_turning(const SourceRef&) { line("STOP_SPINDLE_TURNING(0)"); }
void CanonPrinter::set_spindle_mode(const SourceRef&, double max_rpm) { line("SET_SPINDLE_MODE(0 %.4f)", max_rpm); }
void CanonPrinter::orient_spindle(const SourceRef&, double deg, int mode) {
  line("ORIENT_SPINDLE(0, %.4f, %d)", deg, mode);
}
void CanonPrinter::mist_on(const SourceRef&) { line("MIST_ON()"); }
void CanonPrinter::mist_off(const SourceRef&) { line("MIST_OFF()"); }
void CanonPrinter::flood_on(const SourceRef&) { line("FLOOD_ON()"); }
void CanonPrinter::flood_off(const SourceRef&) { line("FLOOD_OFF()"); }
void CanonPrinter::enable_feed_override(const SourceRef&, bool on) {
  line(on ? "ENABLE_FEED_OVERRIDE()" : "DISABLE_FEED_OVERRIDE()");
}
void CanonPrinter::enable_speed_override(const SourceRef&, bool on) {
  line(on ? "ENABLE_SPEED_OVERRIDE(0)" : "DISABLE_SPEED_OVERRIDE(0)");
}
void CanonPrinter::enable_adaptive_feed(const SourceRef&, bool on) {
  line(on ? "ENABLE_ADAPTIVE_FEED()" : "DISABLE_ADAPTIVE_FEED()");
}
void CanonPrinter::enable_feed_hold(const SourceRef&, bool on) { line(on ? "ENABLE_FEED_HOLD()" : "DISABLE_FEED_HOLD()"); }
void CanonPrinter::digital_output(const SourceRef&, int index, bool on, bool synchronised) {
  if (synchronised)
    line(on ? "SET_MOTION_OUTPUT_BIT(%d)" : "CLEAR_MOTION_OUTPUT_BIT(%d)", index);
  else
    line(on ? "SET_AUX_OUTPUT_BIT(%d)" : "CLEAR_AUX_OUTPUT_BIT(%d)", index);
}
void CanonPrinter::analog_output(const SourceRef&, int index, double value, bool synchronised) {
  line(synchronised ? "SET_MOTION_OUTPUT_VALUE(%d,%f)" : "SET_AUX_OUTPUT_VALUE(%d,%f)", index, value);
}
void CanonPrinter::comment(const SourceRef&, const std::string& text) { line("COMMENT(\"%s\")", text.c_str()); }
void CanonPrinter::message(const SourceRef&, const std::string& text) { line("MESSAGE(\"%s\")", text.c_str()); }
void CanonPrinter::log_open(const SourceRef&, const std::string& name, bool append) {
  line(append ? "LOGAPPEND(\"%s\")" : "LOGOPEN(\"%s\")", name.c_str());
}
void CanonPrinter::log_close(const SourceRef&) { line("LOGCLOSE()"); }
void CanonPrinter::log_line(const SourceRef&, const std::string& text) { line("LOG(\"%s\")", text.c_str()); }
void CanonPrinter::program_stop(const SourceRef&) { line("PROGRAM_STOP()"); }
void CanonPrinter::optional_program_stop(const SourceRef&) { line("OPTIONAL_PROGRAM_STOP()"); }
void CanonPrinter::pallet_shuttle(const SourceRef&) { line("PALLET_SHUTTLE()"); }
void CanonPrinter::program_end(const SourceRef&) { line("PROGRAM_END()"); }
void CanonPrinter::finish(const SourceRef&) { line("FINISH()"); }

}  // namespace cnc::rs274
