#pragma once
// Canned cycles G73, G74, G81-G89 as LinuxCNC runs them: each repeat is a rapid to
// the hole's position at the clearance level, a rapid to R, the cycle's feeds,
// dwells and spindle calls, and the retract (G98: to the old Z or R, the higher;
// G99: to R). Pure: inputs in, canonical calls out, the interpreter keeps the state.
#include <functional>

#include "common/rs274/canon.h"

namespace cnc::rs274 {

struct CycleInput {
  int g = 0;               // 730, 740, 810 ... 890 (tenths)
  Plane plane = Plane::kXY;
  bool incremental = false;  // G91: X Y (plane) and R, Z (depth) are incremental
  bool retract_to_r = false; // G99
  Pose start{};            // current position, program coordinates
  // The words of this block (program units); has_* says which were given. Sticky
  // values (R, Q, P, Z of an earlier cycle block) are filled in by the interpreter.
  double x = 0, y = 0, z = 0;  // plane axes and depth axis in plane order: for G17 x=X, y=Y, z=Z
  bool has_x = false, has_y = false;
  double r = 0, q = 0, p = 0, k = 0;
  bool has_q = false, has_p = false;
  int repeats = 1;         // L
  double old_z = 0;        // depth-axis position when the cycle started (for G98)
                           // LinuxCNC's cycle_il: the depth-axis position at the first block of a
                           // run of cycle blocks, kept for the following cycle blocks (any
                           // non-cycle motion ends the run). G98 retracts to it; G91 R is relative to it.
  double spindle_rpm = 0;  // for G74/G84 tapping and G86/G87/G88 spindle calls
  bool spindle_cw = true;

  // ---- added for LinuxCNC's behaviour (see run_cycle in cycles.cc) ----
  // Axis mapping, LinuxCNC's (aa, bb, cc) order; the I J K fields follow the same
  // mapping (I goes with X/U, J with Y/V, K with Z/W):
  //   plane   x  y  z(depth)   i  j  k(G87 top of the back bore)
  //   G17     X  Y  Z          I  J  K
  //   G18     Z  X  Y          K  I  J
  //   G19     Y  Z  X          J  K  I
  //   G17.1   U  V  W          I  J  K     (G18.1: W U V / K I J, G19.1: V W U / J K I)
  // has_* says the word was in this block. A P-1 or Q-1 word is LinuxCNC's "absent"
  // marker: pass it as absent (has_p/has_q false, p/q the sticky value).
  bool has_z = false, has_r = false;
  double i = 0, j = 0;                 // G87 offsets (k above is the G87 level)
  bool has_i = false, has_j = false, has_k = false;
  // The motion mode before this block was this same cycle (LinuxCNC's
  // motion_mode == motion): only then may R, depth, P (G82/G86/G88/G89), Q (G73/G83)
  // and I J K (G87) be left out, the sticky values in z/r/p/q/i/j/k being used.
  bool continuing = false;
  // M3/M4 in force (even at S0); spindle_cw gives the direction. G74, G84, G86,
  // G87, G88 refuse a stopped spindle, G74 a clockwise one, G84 a counterclockwise one.
  bool spindle_turning = false;
  // G20/G21 of the program: the G73/G83 retract above the last peck is LinuxCNC
  // 2.9's fixed 0.010 in (0.254 mm).
  Units units = Units::kMm;
  double feed_rate = 0;         // F in force; LinuxCNC refuses a cycle at F0
  bool inverse_time = false;    // G93 in force: refused
  bool cutter_comp = false;     // G41/G42 in force: refused
  // G61/G61.1/G64 in force: a cycle switches to exact path (G61) for its moves and
  // restores the mode, G64 P and Q (as SET_MOTION_CONTROL_MODE, SET_NAIVECAM_TOLERANCE).
  PathMode path_mode = PathMode::kContinuous;
  double path_tolerance = 0;      // G64 P
  double naivecam_tolerance = 0;  // G64 Q
  // Overrides enabled (M48-M50/M51): G74/G84 disable both for the tap and re-enable
  // only those that were enabled.
  bool feed_override_enabled = true;
  bool speed_override_enabled = true;
  // Polar words (@ ^): each repeat's hole comes from the one before (program
  // coordinates of the plane's two axes, updated in place), as LinuxCNC recomputes
  // them at every repeat. Empty: X Y increments (G91) or the same hole (G90).
  std::function<void(double* a, double* b)> next_hole;
};

struct CycleResult {
  Pose end{};      // where the tool stands after the cycle
  double r_plane = 0;  // the R level actually used (for #<_retract_r_plane>)
};

// Emits the canonical calls of the cycle to `canon`, each with `ref`. Throws Error
// (column 0: the caller fills in the place) with LinuxCNC's messages for its
// refusals: F0, G93, cutter compensation, R or depth missing, L0, R below the
// bottom, P/Q/I/J/K missing, Q <= 0 for G73/G83, the spindle's state for G74/G84/
// G86/G87/G88. Like LinuxCNC, the calls made before a refusal found inside a repeat
// (Q <= 0, spindle) have been emitted. L > 1 in G90 repeats the hole in place.
CycleResult run_cycle(const CycleInput& in, const SourceRef& ref, Canon& canon);

}  // namespace cnc::rs274
