#pragma once
// The machine's devices as the operator reads them (`cnc-ctl --do status`; the HMI's
// machine panel shows the same): the spindle, the coolant, every named I/O point, the
// safety chain, the probe and an M66 wait. Pure functions of the config and the last
// messages heard, so a unit test checks the text.
#include <string>
#include <vector>

#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_io_status.hpp"
#include "cnc/lcmt_joint_status.hpp"
#include "cnc/lcmt_spindle_status.hpp"
#include "common/config/machine_config.h"

namespace cnc::service {

// The last message of each channel, nullptr when none was heard.
struct MachineView {
  const cnc::lcmt_spindle_status* spindle = nullptr;
  const cnc::lcmt_io_status* io = nullptr;
  const cnc::lcmt_axis_status* axes = nullptr;
  const cnc::lcmt_interp_state* interp = nullptr;
  const cnc::lcmt_joint_status* joints = nullptr;  // a machine with a gantry
};

// Lines for what the config has (a spindle:, io:, safety:, probe: section, a gantry), each
// ending in '\n'; a device whose status was not heard says so. "" for a cell without any.
std::string machine_status(const cnc::config::MachineConfig& cfg, const MachineView& v);

// What the config makes of each io.points[] entry: the codes that switch or read it
// ("M8 flood", "M66 P0") or its place in the safety chain ("E-stop", "X max limit",
// "door", "probe"), comma-separated; "" for a point with no role.
std::vector<std::string> point_roles(const cnc::config::MachineConfig& cfg);

}  // namespace cnc::service
