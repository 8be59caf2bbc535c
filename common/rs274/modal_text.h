#pragma once
// The interpreter's modal state as an operator reads it (AXIS's "Active G-codes"):
// the codes in effect, and the offset from machine to work coordinates.
#include <string>

#include "common/rs274/interpreter.h"

namespace cnc::rs274 {

// "G1 G17 G21 G40 G49 G54 G64 G80 G90 G91.1 G94 G98 M5 M9", with G43 or G41/G42 as in
// effect, M3/M4, M7/M8, M48/M49, and the tool (T) last.
std::string active_codes(const ModalState& s);

// Machine minus work coordinates per axis: the coordinate system's offset (G54..G59.3),
// G92's when it is in effect, and the tool length offset (G43). The system's rotation
// (G10 L2 R) is not in it.
Pose work_offset(const ModalState& s);

}  // namespace cnc::rs274
