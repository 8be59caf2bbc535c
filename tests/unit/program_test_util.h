#pragma once
// Helpers of the program tests: temporary folders and files, the machine set-up of a
// plain XYZ mill in mm, and a whole program run through the interpreter and the block
// builder (the path the server takes, without its chunks and hashes).
#include <stdlib.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "common/program/block.h"
#include "common/rs274/block_builder.h"
#include "common/rs274/interpreter.h"
#include "services/part_program_server/program_server.h"
#include "tests/unit/temp_dir.h"

namespace cnc::test {

// X Y Z, mm, at the origin, no tool table, no var file, spindle at 0 rpm and the
// roughness law off until the program says otherwise.
inline pps::ProgramSetup xyz_setup() {
  pps::ProgramSetup s;
  s.machine.axes = "XYZ";
  s.builder.axis_names = {"X", "Y", "Z"};
  s.builder.start_position_mm = {0, 0, 0};
  return s;
}

// Every block of the program at `path`, in order, ending with the end block. Throws
// rs274::Error as the interpreter or the block builder does.
inline std::vector<program::Block> run_program(const std::string& path, const pps::ProgramSetup& s = xyz_setup(),
                                               int64_t max_lines = 10'000'000) {
  std::unique_ptr<rs274::Interpreter> interp;
  rs274::BlockBuilder builder(
      s.builder, [&interp](int32_t f) -> const std::string& { return interp->file_names()[static_cast<size_t>(f)]; });
  rs274::MachineSetup m = s.machine;
  for (size_t i = 0; i < s.builder.axis_names.size() && i < s.builder.start_position_mm.size(); ++i) {
    static const std::string kAxes = "XYZABCUVW";
    const size_t at = kAxes.find(s.builder.axis_names[i]);
    if (at != std::string::npos) m.start_position[at] = s.builder.start_position_mm[i];
  }
  interp = std::make_unique<rs274::Interpreter>(std::move(m), builder);
  std::vector<program::Block> out;
  interp->open(path);
  for (;;) {
    const bool more = interp->execute_next();
    for (auto& b : builder.blocks()) out.push_back(std::move(b));
    builder.blocks().clear();
    if (!more) break;
    if (interp->lines_executed() > max_lines) throw std::runtime_error(path + ": too many lines");
  }
  return out;
}

}  // namespace cnc::test
