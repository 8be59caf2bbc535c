#pragma once
// cnc-predict program: VMCS 1999's force and deflection and Choi et al. 2005's surface along a
// program's dry-run setpoints (cnc-plan's CSV), through a Z-map stock (a start).
#include <string>

namespace cnc::predict {
class Args;
int cmd_program(const Args& a);
}  // namespace cnc::predict
