#pragma once
// Chord error of an interpolation step measured against the exact block geometry:
// the largest distance between the curve on [u0, u1] and the segment a–b (the two
// setpoints). For a step inside one block a and b are P(u0) and P(u1); for a step
// across a block boundary, measure each block's part against the step's segment.
#include "common/motion/path_segment.h"

namespace cnc::motion {

// Samples [u0, u1] at 16 sub-intervals and refines each local maximum by
// golden-section search. No allocation.
double chord_error(const PathSegment& path, double u0, double u1, const AxisVec& a, const AxisVec& b);

}  // namespace cnc::motion
