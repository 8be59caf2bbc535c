#pragma once
// The corner rule's velocity step. A junction turns the direction within one cycle T,
// so the velocity step dv it makes is an acceleration dv/T and, in finite
// differences, a jerk dv/T². The planner (Planner::corner_speed) bounds each axis's
// and the path's step with it; the program server bounds the corners it leaves
// unblended (BuilderSetup::corner_dv_mm_s) with it.
#include <algorithm>

namespace cnc::motion {

// The largest velocity step within one cycle of period_s: one cycle's acceleration
// accel_mm_s2, half a cycle's jerk jerk_mm_s3.
inline double corner_step_mm_s(double accel_mm_s2, double jerk_mm_s3, double period_s) {
  return std::min(accel_mm_s2 * period_s, 0.5 * jerk_mm_s3 * period_s * period_s);
}

}  // namespace cnc::motion
