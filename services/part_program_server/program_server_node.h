#pragma once
#include <set>

#include "cnc/lcmt_block_request.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "common/bus/bus.h"
#include "services/part_program_server/program_server.h"

namespace cnc::pps {

// LCM side: LOAD/START commands, block requests, program state.
class ProgramServerNode {
 public:
  ProgramServerNode(const config::MachineConfig& cfg, bus::Bus& bus);
  // Publishes the program state when it changed or every `period_s`.
  void publish_state(bool force);
  int8_t state() const { return state_; }

 private:
  void on_command(const cnc::lcmt_program_command& m);
  void on_request(const cnc::lcmt_block_request& m);

  config::MachineConfig cfg_;
  bus::Bus& bus_;
  ProgramServer core_;
  std::string ch_blocks_, ch_state_;
  int8_t state_;
  LoadResult last_refusal_;
  std::string refused_path_;
  int64_t blocks_sent_ = 0;
  int64_t blocks_resent_ = 0;
  std::vector<bool> sent_;
  double last_state_s_ = -1e9;
};

}  // namespace cnc::pps
