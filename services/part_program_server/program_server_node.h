#pragma once
#include <map>

#include "cnc/lcmt_block_request.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "common/bus/bus.h"
#include "services/part_program_server/program_server.h"

namespace cnc::pps {

// LCM side: LOAD/START/STOP commands, block requests, program state. Blocks go out
// only on request (the interpolator asks for a bounded window and asks again after
// a silence), each stamped with the bus's per-channel sequence number, so a lost
// datagram delays a block but never loses it.
class ProgramServerNode {
 public:
  ProgramServerNode(const config::MachineConfig& cfg, bus::Bus& bus);
  // Publishes the program state when it changed or every `period_s`.
  void publish_state(bool force);
  int8_t state() const { return state_; }

 private:
  void on_command(const cnc::lcmt_program_command& m);
  void on_request(const cnc::lcmt_block_request& m);
  // Counts block `i` as sent; returns whether it was sent before.
  bool mark_sent(int64_t i);

  config::MachineConfig cfg_;
  bus::Bus& bus_;
  ProgramServer core_;
  std::string ch_blocks_, ch_state_;
  int8_t state_;
  LoadResult last_refusal_;
  std::string refused_path_;
  int64_t blocks_sent_ = 0;
  int64_t blocks_resent_ = 0;
  // Blocks sent at least once, as disjoint ranges [first, end) keyed by first:
  // requests come in order, so this stays a handful of ranges for any program size.
  std::map<int64_t, int64_t> sent_;
  double last_state_s_ = -1e9;
  std::vector<double> machine_position_;  // from INTERP_STATE; empty until known (home)
};

}  // namespace cnc::pps
