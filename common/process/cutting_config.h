#pragma once
// Tool and material files for the cutting-force, deflection and Z-map models
// (config/tools/*.yaml, config/materials/*.yaml). Strict: unknown keys are errors
// (cnc::config::ConfigError names the key path).
#include <string>

#include "common/process/cutting_force.h"

namespace cnc::process {

Material load_material(const std::string& file);
EndMill load_tool(const std::string& file);

// "linear_edge" | "chip_thickness_law"; throws std::invalid_argument otherwise.
ForceModel force_model_from_string(const std::string& s);

}  // namespace cnc::process
