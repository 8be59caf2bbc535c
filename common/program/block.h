#pragma once
// A program block as the interpolator core sees it: plain data, no LCM.
#include <algorithm>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace cnc::program {

constexpr int kMaxAxes = 9;

enum class BlockKind : int8_t { kRapid = 0, kLine = 1, kArcCw = 2, kArcCcw = 3, kNurbs = 4, kDwell = 5, kEnd = 6, kEvent = 7 };

// What a program does besides moving, in program order between the moves (the
// interpolator comes to rest at each, as at a dwell of 0 s). Program stops (M0, M1;
// M60 is a shuttle and a stop) and tool changes (M6) hold the motion until the
// operator resumes.
enum class EventKind : int8_t {
  kNone = 0,
  kProgramStop = 1,    // M0
  kOptionalStop = 2,   // M1
  kPalletShuttle = 3,  // M60
  kToolChange = 4,     // M6: number = tool
  kSpindle = 5,        // M3/M4/M5/S: number = 1 cw, -1 ccw, 0 off; value = rpm
  kCoolant = 6,        // M7/M8/M9: number = bit 0 mist, bit 1 flood
  kMessage = 7,        // (MSG,...), (DEBUG,...): text
  kDigitalOutput = 8,  // M62-M65: number = index, value = 1 on (M64), 0 off (M65); +2 with the next motion (M62, M63)
  kAnalogOutput = 9,   // M67/M68: number = index (+1000 with the next motion, M67), value
  kOverrides = 10,     // M48-M53: number = bits feed, speed, adaptive, hold
  kWaitInput = 11,     // M66: number = InputWait::number(), value = timeout, s (0: none)
  kSpindleOrient = 12,  // M19: number = P (0 shortest way, 1 clockwise, 2 counterclockwise), value = R
                        // (degrees); Block::dwell_s = Q, the wait for it (0: not waited for)
  kLast = kSpindleOrient,
};

// M66's input and wait mode, packed in an event's number as index + 1000 x mode
// (+ 10000 for an analog input), readable in a log as it is.
struct InputWait {
  // LinuxCNC's WAIT_MODE_*: 0 read at once, 1 rise, 2 fall, 3 high, 4 low.
  enum Mode : int8_t { kImmediate = 0, kRise = 1, kFall = 2, kHigh = 3, kLow = 4 };
  int index = 0;        // P (digital) or E (analog), 0 .. 63
  bool analog = false;  // E: an analog input (kImmediate only)
  int mode = kImmediate;
  int32_t number() const { return index + 1000 * mode + (analog ? 10000 : 0); }
  static InputWait of(int32_t number) {
    InputWait w;
    w.analog = number >= 10000;
    w.index = number % 1000;
    w.mode = number % 10000 / 1000;
    return w;
  }
};

const char* to_string(EventKind kind);

struct Event {
  EventKind kind = EventKind::kNone;
  int32_t number = 0;
  double value = 0;
  std::string text;
  // Holds the motion until the operator resumes.
  bool pauses() const {
    return kind == EventKind::kProgramStop || kind == EventKind::kOptionalStop || kind == EventKind::kToolChange;
  }
};

// A kEnd block's event.number: the end of a program (M2, M30: the spindle and the
// coolant stop) or of an operator's line or move (MDI, jog, home: they stay as they
// are, as LinuxCNC's MDI leaves them).
constexpr int32_t kEndOfProgram = 0;
constexpr int32_t kEndOfOperatorLine = 1;

// Limits shared by the config, the program's PROCESS directive and the network check.
constexpr int kMaxFlutes = 64;

const char* to_string(BlockKind kind);

// Choi et al. 2005's process parameters for the roughness feed law. The law applies when
// all four are set (> 0) and the spindle turns.
struct ProcessParams {
  double ball_radius_mm = 0;
  int flutes = 0;
  double pick_feed_mm = 0;
  double target_rmax_um = 0;
  bool active() const { return ball_radius_mm > 0 && flutes > 0 && pick_feed_mm > 0 && target_rmax_um > 0; }
};

// Circular arc (G2/G3) in the plane of G17 (XY), G18 (ZX) or G19 (YZ); a move of
// the third axis makes it a helix. Angles follow the plane's right-hand rule.
struct ArcGeometry {
  std::vector<double> center;  // one entry per machine axis; only the plane's two matter
  int plane = 17;              // 17, 18, 19
  int turns = 0;               // extra full turns (RS274 P word), 0 for a plain arc
};

// Rational B-spline in machine X, Y, Z (the first three axes). order = degree + 1;
// knots.size() == control_points.size() + order; clamped (first and last knot
// repeated `order` times); weights > 0. The curve starts at `Block::start`.
struct NurbsGeometry {
  int order = 0;
  std::vector<double> knots;
  std::vector<std::array<double, 3>> control_points;
  std::vector<double> weights;
};

struct Block {
  int64_t index = 0;
  int32_t source_line = 0;
  int32_t source_column = 0;
  std::string source_file;  // the file the block's line is in (subroutine files included)
  BlockKind kind = BlockKind::kLine;
  std::vector<double> start;  // one entry per machine axis, mm
  std::vector<double> end;
  double feed_mm_per_min = 0;
  double dwell_s = 0;
  double spindle_rpm = 0;
  ProcessParams process;
  // G64 P in effect, mm (0: G61, or G64 without P): the path keeps within it of the
  // program's geometry at every point, fit, blend and chord error together.
  double path_tolerance_mm = 0;
  ArcGeometry arc;      // kArcCw, kArcCcw
  NurbsGeometry nurbs;  // kNurbs
  Event event;          // kEvent
  // kLine: a G38.x probing move (2: G38.2 ... 5: G38.5), 0 none. It starts and ends
  // at rest and stops where the probe input changes (the machine's result, not the
  // block's end, is where the next block starts). On the wire: event_kind kProbeWire.
  int8_t probe = 0;
  // kLine: spindle-synchronised motion (kSyncG33, kSyncRigidTap), kSyncNone otherwise.
  // The path advances sync_pitch_mm per spindle revolution; a rigid tap goes to `end`,
  // reverses the spindle (turning tap_retract_scale times as fast) and comes back to
  // `start` synchronised. feed_mm_per_min is the pitch times the programmed S (what the
  // dry run takes). On the wire: event_kind kSyncWire + sync, event_value the pitch,
  // dwell_s the retract scale.
  int8_t sync = 0;
  double sync_pitch_mm = 0;
  double tap_retract_scale = 1;
  // The program reads the machine's answer to this block before its next line: a
  // probing move's result (#5061-#5070) or an M66's input value (#5399).
  bool awaits_result() const { return probe != 0 || (kind == BlockKind::kEvent && event.kind == EventKind::kWaitInput); }
};

// The event_kind a LINE block carries on the wire when it is a probing move (not an EventKind).
inline constexpr int8_t kProbeWire = 100;
inline constexpr int8_t kSyncNone = 0, kSyncG33 = 1, kSyncRigidTap = 2;
// ...and when it is synchronised with the spindle: kSyncWire + Block::sync.
inline constexpr int8_t kSyncWire = 110;

// How a path tolerance P (G64 P) is shared: the interpolation's chords take at most
// a quarter of it (never more than the machine's chord tolerance), the fit and the
// corner blends the rest, so their deviations add up to P at most.
inline constexpr double kChordShareOfPathTolerance = 0.25;
inline double chord_tolerance_mm(double path_tolerance_mm, double machine_chord_mm) {
  return path_tolerance_mm > 0 ? std::min(machine_chord_mm, kChordShareOfPathTolerance * path_tolerance_mm)
                               : machine_chord_mm;
}
inline double shape_tolerance_mm(double path_tolerance_mm, double machine_chord_mm) {
  return path_tolerance_mm - chord_tolerance_mm(path_tolerance_mm, machine_chord_mm);
}

}  // namespace cnc::program
