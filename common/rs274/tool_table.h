#pragma once
// LinuxCNC's tool table: one tool per line, "T<n> P<pocket> [X..W<offset>] [D<dia>]
// [I<front>] [J<back>] [Q<orientation>] [;comment]", values in machine units.
#include <string>
#include <vector>

#include "common/rs274/canon.h"

namespace cnc::rs274 {

struct Tool {
  int number = 0;
  int pocket = 0;
  Pose offset{};
  double diameter = 0;
  double front_angle = 0;
  double back_angle = 0;
  int orientation = 0;
  std::string comment;
};

class ToolTable {
 public:
  // Throws Error naming "file:line:column" for a malformed line.
  void read(const std::string& path);
  const Tool* find(int number) const;
  Tool* find(int number);
  // Adds or replaces a tool (G10 L1/L10/L11).
  void put(const Tool& t);
  const std::vector<Tool>& tools() const { return tools_; }

 private:
  std::vector<Tool> tools_;
};

// Writes `tools` in the table's format (machine units, as given), in their order,
// atomically (a temporary file in the same folder, synced, renamed over the old one).
// Throws std::runtime_error with the path and errno text on failure.
void write_tool_table(const std::string& path, const std::vector<Tool>& tools);

}  // namespace cnc::rs274
