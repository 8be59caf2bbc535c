#pragma once
// The part-program server core: loads and validates a whole program, then serves
// its blocks by index. A refused program leaves the previously accepted one as it
// was. No LCM here; program_server_node.h is the network side.
#include <optional>
#include <string>
#include <vector>

#include "common/config/machine_config.h"
#include "common/program/gcode_parser.h"

namespace cnc::pps {

struct LoadResult {
  bool ok = false;
  std::string error;  // "file:line:column: what was expected"
  int line = 0;
  int column = 0;
};

class ProgramServer {
 public:
  explicit ProgramServer(const config::MachineConfig& cfg);

  // token: the caller's unique id of this load.
  LoadResult load(const std::string& path, int64_t token);
  bool loaded() const { return program_.has_value(); }
  int64_t token() const { return token_; }
  const std::string& path() const { return path_; }
  int64_t num_blocks() const { return program_ ? static_cast<int64_t>(program_->blocks.size()) : 0; }
  // Block `index` of the loaded program, or nullptr outside it.
  const program::Block* block(int64_t index) const;

 private:
  program::GcodeParser parser_;
  std::optional<program::Program> program_;
  int64_t token_ = 0;
  std::string path_;
};

program::ParserSettings parser_settings(const config::MachineConfig& cfg);

}  // namespace cnc::pps
