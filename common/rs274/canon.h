#pragma once
// The canonical machining calls: where the language ends. Like LinuxCNC's canon
// layer, the interpreter hands every effect of a program to one of these calls, in
// program order, each with the source reference of the block that made it. Motion
// ends are in program coordinates and program units (the interpreter has already
// applied G90/G91, G90.1/G91.1 and the axis words); the offsets that turn them into
// machine coordinates come as calls of their own (SET_G5X_OFFSET, SET_G92_OFFSET,
// SET_XY_ROTATION, USE_TOOL_LENGTH_OFFSET, USE_LENGTH_UNITS), as in LinuxCNC. The
// consumers: CanonPrinter (rs274's text, for the conformance harness) and the
// block builder (machine-coordinate blocks for the interpolator).
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "common/rs274/lexer.h"

namespace cnc::rs274 {

// X Y Z A B C U V W, in that order.
constexpr int kNumAxes = 9;
using Pose = std::array<double, kNumAxes>;

enum class Plane : uint8_t { kXY, kYZ, kXZ, kUV, kVW, kUW };
enum class Units : uint8_t { kInch, kMm };
enum class FeedMode : uint8_t { kUnitsPerMinute, kInverseTime, kUnitsPerRev };
enum class PathMode : uint8_t { kExactPath /*G61*/, kExactStop /*G61.1*/, kContinuous /*G64*/ };

// A LinuxCNC-style NURBS control point (G5.2 / Fanuc G6.2): position in the plane
// or in space, and weight.
struct NurbsPoint {
  double x = 0, y = 0, z = 0, w = 1;
  bool has_z = false;  // Fanuc G6.2: x y z are X Y Z; G5.2: x y are the plane's two axes
};

// Choi et al. 2005's process parameters, changed from a program line by the comment
// directive (PROCESS, BALL_RADIUS=5, FLUTES=2, PICK_FEED=0.5, RMAX_UM=10.67); has_*
// says which keys the directive named.
struct ProcessSettings {
  double ball_radius_mm = 0, pick_feed_mm = 0, target_rmax_um = 0;
  int flutes = 0;
  bool has_ball_radius = false, has_flutes = false, has_pick_feed = false, has_target_rmax = false;
};

class Canon {
 public:
  virtual ~Canon() = default;

  // Set-up and modal state.
  virtual void use_length_units(const SourceRef&, Units) {}
  virtual void select_plane(const SourceRef&, Plane) {}
  virtual void set_g5x_offset(const SourceRef&, int /*index 1..9*/, const Pose&) {}
  virtual void set_g92_offset(const SourceRef&, const Pose&) {}
  virtual void set_xy_rotation(const SourceRef&, double /*deg*/) {}
  virtual void set_feed_reference(const SourceRef&) {}
  virtual void set_feed_rate(const SourceRef&, double /*units/min or 1/min*/) {}
  virtual void set_feed_mode(const SourceRef&, FeedMode) {}
  virtual void set_motion_control_mode(const SourceRef&, PathMode, double /*P tolerance, 0: none*/) {}
  virtual void set_naivecam_tolerance(const SourceRef&, double /*Q*/) {}
  virtual void use_tool_length_offset(const SourceRef&, const Pose&) {}
  virtual void on_reset(const SourceRef&) {}
  // An MDI line starts with the spindle and coolant the line before left: the state
  // as it is, no change to make (LinuxCNC's MDI shares one interpreter between lines).
  virtual void restore_spindle_and_coolant(const SourceRef&, int /*spindle: 1 cw, -1 ccw, 0 off*/, double /*S*/,
                                           bool /*mist*/, bool /*flood*/) {}

  // Motion. `end` in program coordinates and units.
  virtual void straight_traverse(const SourceRef&, const Pose& end) = 0;
  virtual void straight_feed(const SourceRef&, const Pose& end) = 0;
  // LinuxCNC's ARC_FEED: the two in-plane end coordinates, the centre, the turn
  // count (positive: counterclockwise, |rotation|-1 extra full turns; negative:
  // clockwise), the end of the axis normal to the plane, and the other axes' ends.
  virtual void arc_feed(const SourceRef&, double first_end, double second_end, double first_axis,
                        double second_axis, int rotation, double axis_end, const Pose& end) = 0;
  // A rational B-spline of order `order`, control points in the active plane (z used
  // for Fanuc G6.2 space curves), knots (size = points + order), ending at `end`.
  virtual void nurbs_feed(const SourceRef&, int order, const std::vector<NurbsPoint>& points,
                          const std::vector<double>& knots, const Pose& end) = 0;
  virtual void dwell(const SourceRef&, double seconds) = 0;
  // G38.2-G38.5 (LinuxCNC's TURN_PROBE_ON, STRAIGHT_PROBE, TURN_PROBE_OFF): a straight
  // move at the feed rate to `end` that stops where the probe input changes. kind:
  // 2 toward, error without contact; 3 toward; 4 away, error without loss of contact; 5 away.
  virtual void turn_probe_on(const SourceRef&) {}
  virtual void straight_probe(const SourceRef&, const Pose& /*end*/, int /*kind*/) {}
  virtual void turn_probe_off(const SourceRef&) {}
  // G33, G33.1 (LinuxCNC's START_SPEED_FEED_SYNCH ... STOP_SPEED_FEED_SYNCH): the
  // moves between them advance `feed_per_rev` program units along the path per
  // spindle revolution, following the spindle's measured position.
  virtual void start_speed_feed_sync(const SourceRef&, double /*feed_per_rev*/, bool /*velocity_mode*/) {}
  virtual void stop_speed_feed_sync(const SourceRef&) {}
  // G33.1: synchronised to `end`, the spindle reversed (turning `retract_scale` times
  // as fast), synchronised back to the start; the position after it is the start.
  virtual void rigid_tap(const SourceRef&, const Pose& /*end*/, double /*retract_scale*/) {}

  // Tool.
  virtual void select_tool(const SourceRef&, int /*pocket's tool*/) {}
  virtual void start_change(const SourceRef&) {}
  virtual void change_tool(const SourceRef&, int /*tool*/) {}
  virtual void change_tool_number(const SourceRef&, int /*tool*/) {}
  // G10 L1/L10/L11 changed the tool table's entry `index` (LinuxCNC's index: the
  // tool's line in the table from 1; 0 is the tool in the spindle). Offsets and
  // diameter in machine units (degrees for A B C), as the table holds them.
  virtual void set_tool_table_entry(const SourceRef&, int /*index*/, int /*tool*/, const Pose& /*offset*/,
                                    double /*diameter*/, double /*front angle*/, double /*back angle*/,
                                    int /*orientation*/) {}

  // Spindle and coolant.
  virtual void set_spindle_speed(const SourceRef&, double /*rpm*/) {}
  virtual void start_spindle_clockwise(const SourceRef&) {}
  virtual void start_spindle_counterclockwise(const SourceRef&) {}
  virtual void stop_spindle_turning(const SourceRef&) {}
  // LinuxCNC's ORIENT_SPINDLE(spindle, degrees, mode): G87 calls it with 0 degrees and
  // the turning direction as LinuxCNC's CANON_DIRECTION (2 clockwise, 3 counterclockwise).
  virtual void orient_spindle(const SourceRef&, double /*degrees*/, int /*mode*/) {}
  // M19 Q: the motion waits for the orientation at most `timeout_s`.
  virtual void wait_orient_complete(const SourceRef&, double /*timeout_s*/) {}
  virtual void set_spindle_mode(const SourceRef&, double /*G96 max rpm; 0: G97*/) {}
  virtual void mist_on(const SourceRef&) {}
  virtual void mist_off(const SourceRef&) {}
  virtual void flood_on(const SourceRef&) {}
  virtual void flood_off(const SourceRef&) {}

  // Overrides (M48-M53).
  virtual void enable_feed_override(const SourceRef&, bool) {}
  virtual void enable_speed_override(const SourceRef&, bool) {}
  virtual void enable_adaptive_feed(const SourceRef&, bool) {}
  virtual void enable_feed_hold(const SourceRef&, bool) {}

  // Outputs (M62-M65 digital, synchronised with motion or immediate; M67/M68 analog).
  virtual void digital_output(const SourceRef&, int /*index*/, bool /*on*/, bool /*synchronised*/) {}
  virtual void analog_output(const SourceRef&, int /*index*/, double /*value*/, bool /*synchronised*/) {}
  // M66 (LinuxCNC's WAIT): the motion ends, then the machine waits on input `index`
  // (program::InputWait's mode) for at most timeout_s; the program reads the value in #5399.
  virtual void wait_input(const SourceRef&, int /*index*/, bool /*analog*/, int /*mode*/, double /*timeout_s*/) {}

  // The PROCESS directive (after the COMMENT call of the same comment).
  virtual void set_process(const SourceRef&, const ProcessSettings&) {}

  // Text.
  virtual void comment(const SourceRef&, const std::string&) {}
  virtual void message(const SourceRef&, const std::string&) {}
  // (LOGOPEN,name) / (LOGAPPEND,name) / (LOGCLOSE) / (LOG,text): LinuxCNC writes a file;
  // the cell's logger records the run instead, so only the canon printer shows them.
  virtual void log_open(const SourceRef&, const std::string& /*name*/, bool /*append*/) {}
  virtual void log_close(const SourceRef&) {}
  virtual void log_line(const SourceRef&, const std::string&) {}

  // Program flow.
  virtual void program_stop(const SourceRef&) {}           // M0
  virtual void optional_program_stop(const SourceRef&) {}  // M1
  virtual void pallet_shuttle(const SourceRef&) {}         // M60
  virtual void program_end(const SourceRef&) {}            // M2, M30
  virtual void finish(const SourceRef&) {}                 // a program closed by '%'
};

}  // namespace cnc::rs274
