#pragma once
// The interpolator's inputs as they travel and are logged (lcmt_interp_input), and
// how each becomes a call on the core. One place for the live node and for replay,
// so both apply an input the same way.
#include <string>

#include "cnc/lcmt_interp_input.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "common/motion/interpolator.h"

namespace cnc::interp {

// The core command for a program command message. LOAD becomes kLoad; OVERRIDE
// carries its value. Returns false for a command that is not the core's.
bool to_core_command(const cnc::lcmt_program_command& m, Command* out);

// Applies one recorded input to the core. Returns "" when applied, else why not
// (a block the core refused, a malformed message). A BLOCK goes to the core's
// planner, a PLAN takes that many finished plans: replay runs the planner inline
// (SyncPlanLink), so the plans are ready and are taken at the recorded cycle.
std::string apply_recorded_input(Interpolator& core, const cnc::lcmt_interp_input& in, int num_axes);

}  // namespace cnc::interp
