#include "common/rs274/canon_printer.h"

#include <cmath>
#include <cstdarg>
#include <cstdint>
#include <cstring>

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

namespace {

// printf's "%.4f" of v, exactly, at p (room for 32 characters); returns the end.
// The multiple of 1e-4 nearest to v's binary value: v * 1e4 is off the exact product
// by at most 1.2e-5 below 1e11, so only a fraction within 1e-4 of one half can round
// the other way: those, and |v| >= 1e7, NaN and infinities, are left to snprintf
// (nullptr). 10 times faster than snprintf on a canon line of 6.
char* fixed4(char* p, double v) {
  const double a = std::fabs(v);
  if (!(a < 1e7)) return nullptr;
  const double s = a * 1e4;
  const double whole = std::floor(s);
  const double frac = s - whole;
  if (std::fabs(frac - 0.5) < 1e-4) return nullptr;
  const uint64_t q = static_cast<uint64_t>(whole) + (frac > 0.5 ? 1 : 0);
  if (std::signbit(v)) *p++ = '-';
  // The digits written in place (a copy loop would become a call to memcpy: 10 % of
  // the time of cnc-rs274 at this size).
  char rev[20];
  int n = 0;
  uint64_t ip = q / 10000;
  do {
    rev[n++] = static_cast<char>('0' + ip % 10);
    ip /= 10;
  } while (ip != 0);
  while (n > 0) *p++ = rev[--n];
  const auto dec = static_cast<unsigned>(q % 10000);
  p[0] = '.';
  p[1] = static_cast<char>('0' + dec / 1000);
  p[2] = static_cast<char>('0' + dec / 100 % 10);
  p[3] = static_cast<char>('0' + dec / 10 % 10);
  p[4] = static_cast<char>('0' + dec % 10);
  return p + 5;
}

// v in decimal at p, right-aligned in `width` (room for 32 characters); returns the end.
char* decimal(char* p, long v, int width) {
  char rev[24];
  int n = 0;
  const bool neg = v < 0;
  unsigned long u = neg ? 0ul - static_cast<unsigned long>(v) : static_cast<unsigned long>(v);
  do {
    rev[n++] = static_cast<char>('0' + u % 10);
    u /= 10;
  } while (u != 0);
  if (neg) rev[n++] = '-';
  for (int k = n; k < width; ++k) *p++ = ' ';
  while (n > 0) *p++ = rev[--n];
  return p;
}

}  // namespace

// "%5d " counter, then the N field of the block being executed, then the call.
// Formats the conversions the calls use (%.4f %d %s %lu) itself, into one buffer
// written at once: printf's own formatting was half of cnc-rs274's time. A call
// with any other conversion (%f), a number printf must round itself or a string
// too long for the buffer is printed by vsnprintf.
// The counter and the N field at buf (the block's text is at most 255 characters).
char* CanonPrinter::head(char* buf) {
  ++counter_;
  char* p = decimal(buf, static_cast<long>(counter_), 5);
  *p++ = ' ';
  const std::string& t = line_text_();
  size_t i = 0;
  while (i < t.size() && (t[i] == ' ' || t[i] == '\t' || t[i] == '/')) ++i;
  if (i < t.size() && (t[i] == 'N' || t[i] == 'n')) {
    ++i;
    size_t j = i;
    while (j < t.size() && t[j] >= '0' && t[j] <= '9') ++j;
    const size_t digits = j - i;
    *p++ = 'N';
    for (size_t k = i; k < j; ++k) *p++ = t[k];
    for (size_t k = digits; k < 6; ++k) *p++ = ' ';
  } else {
    std::memcpy(p, "N..... ", 7);
    p += 7;
  }
  return p;
}

// NAME(x, y, z, a, b, c): the moves, most of a program's canon, without a format
// string to read.
void CanonPrinter::pose_line(const char* name, size_t name_len, const Pose& pose) {
  char buf[1024];
  char* const start = head(buf);
  char* p = start;
  std::memcpy(p, name, name_len);
  p += name_len;
  for (size_t k = 0; k < 6; ++k) {
    if (k > 0) {
      p[0] = ',';
      p[1] = ' ';
      p += 2;
    }
    p = fixed4(p, pose[k]);
    if (p == nullptr) {  // a number printf must round itself
      std::fwrite(buf, 1, static_cast<size_t>(start - buf), out_);
      std::fprintf(out_, "%s%.4f, %.4f, %.4f, %.4f, %.4f, %.4f)\n", name, pose[0], pose[1], pose[2], pose[3], pose[4],
                   pose[5]);
      return;
    }
  }
  *p++ = ')';
  *p++ = '\n';
  fwrite_unlocked(buf, 1, static_cast<size_t>(p - buf), out_);  // one thread writes out_
}

void CanonPrinter::line(const char* fmt, ...) {
  char buf[1024];
  char* const limit = buf + sizeof buf - 40;  // room for a number and the newline
  char* p = head(buf);
  char* const call_at = p;
  va_list ap;
  va_start(ap, fmt);
  va_list again;
  va_copy(again, ap);
  bool ok = true;
  for (const char* f = fmt; ok && *f != '\0';) {
    if (*f != '%') {
      if (p >= limit) {
        ok = false;
        break;
      }
      *p++ = *f++;
      continue;
    }
    if (f[1] == '.' && f[2] == '4' && f[3] == 'f') {
      char* q = fixed4(p, va_arg(ap, double));
      if (q == nullptr) ok = false;
      else p = q;
      f += 4;
    } else if (f[1] == 'd') {
      p = decimal(p, va_arg(ap, int), 0);
      f += 2;
    } else if (f[1] == 's') {
      const char* str = va_arg(ap, const char*);
      const size_t n = std::strlen(str);
      if (n >= static_cast<size_t>(limit - p)) {
        ok = false;
      } else {
        std::memcpy(p, str, n);
        p += n;
      }
      f += 2;
    } else if (f[1] == 'l' && f[2] == 'u') {
      p = decimal(p, static_cast<long>(va_arg(ap, unsigned long)), 0);
      f += 3;
    } else {
      ok = false;
    }
    if (p >= limit) ok = false;
  }
  va_end(ap);
  if (ok) {
    *p++ = '\n';
    fwrite_unlocked(buf, 1, static_cast<size_t>(p - buf), out_);  // one thread writes out_
  } else {  // printf's, on the whole call
    std::fwrite(buf, 1, static_cast<size_t>(call_at - buf), out_);
    std::vfprintf(out_, fmt, again);
    std::fputc('\n', out_);
  }
  va_end(again);
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
  pose_line("STRAIGHT_TRAVERSE(", 18, p);
}
void CanonPrinter::straight_feed(const SourceRef&, const Pose& p) { pose_line("STRAIGHT_FEED(", 14, p); }
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
