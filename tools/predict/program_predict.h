#pragma once
// cnc-predict program: seed 004's force and deflection and seed 000's surface along a
// program's dry-run setpoints (cnc-plan's CSV), through a Z-map stock (issue 16 item 5,
// a start).
#include <string>

namespace cnc::predict {
class Args;
int cmd_program(const Args& a);
}  // namespace cnc::predict
