#pragma once
// The largest feed override: the planner plans every block for it (a block's top
// speed is this times its programmed feed), the core clamps to it, and the node, the
// program server's interlock, the dry run and the HMI's slider refuse or stop above it.

namespace cnc::motion {

constexpr double kMaxFeedOverride = 1.5;

}  // namespace cnc::motion
