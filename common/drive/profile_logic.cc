#include "common/drive/profile_logic.h"

#include <stdexcept>

#include "common/drive/cia402_profile.h"
#include "common/drive/delta_vfd_profile.h"
#include "common/drive/huanyang_profile.h"
#include "common/drive/leadshine_profile.h"
#include "common/drive/sim_profile.h"

namespace cnc::drive {

const ProfileLogic* find_profile_logic(const std::string& state_machine) {
  for (const ProfileLogic* l : {&sim_logic(), &cia402_logic(), &leadshine_logic(), &delta_vfd_logic(),
                                  &huanyang_logic(), &cia402_velocity_logic()})
    if (state_machine == l->name()) return l;
  return nullptr;
}

const ProfileLogic& profile_logic(const DriveProfile& p) {
  const ProfileLogic* l = find_profile_logic(p.state_machine);
  if (l == nullptr) throw std::logic_error("drive profile " + p.name + ": no state machine '" + p.state_machine + "'");
  return *l;
}

std::vector<std::string> profile_logic_names() {
  return {"sim", "cia402", "leadshine", "delta_vfd", "huanyang", "cia402_velocity"};
}

}  // namespace cnc::drive
