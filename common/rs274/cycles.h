#pragma once
// Canned cycles G73, G74, G81-G89 as LinuxCNC runs them: each repeat is a rapid to
// the hole's position at the clearance level, a rapid to R, the cycle's feeds,
// dwells and spindle calls, and the retract (G98: to the old Z or R, the higher;
// G99: to R). Pure: inputs in, canonical calls out, the interpreter keeps the state.
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
  double spindle_rpm = 0;  // for G74/G84 tapping and G86/G87/G88 spindle calls
  bool spindle_cw = true;
};

struct CycleResult {
  Pose end{};      // where the tool stands after the cycle
  double r_plane = 0;  // the R level actually used (for #<_retract_r_plane>)
};

// Emits the canonical calls of the cycle to `canon`, each with `ref`. Throws Error
// (column 0: the caller fills in the place) for LinuxCNC's refusals: R below the
// bottom, Q <= 0 for G73/G83, L without G91 meaning, missing P where required ...
CycleResult run_cycle(const CycleInput& in, const SourceRef& ref, Canon& canon);

}  // namespace cnc::rs274
