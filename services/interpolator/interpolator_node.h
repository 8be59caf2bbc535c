#pragma once
// LCM side of the interpolator: collects commands and blocks, requests blocks with
// a bounded window (re-requesting what does not arrive), applies inputs to the core
// at the start of a cycle, and publishes each applied input with its cycle index,
// the setpoint and the run state.
#include <map>
#include <vector>

#include "cnc/lcmt_program_block.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "services/interpolator/interpolator.h"

namespace cnc::interp {

class InterpolatorNode {
 public:
  InterpolatorNode(const config::MachineConfig& cfg, bus::Bus& bus);
  // One interpolation cycle. Call every T_ipo.
  void cycle();
  void publish_state(bool force);
  const Interpolator& core() const { return core_; }
  int64_t setpoints_published() const { return setpoints_published_; }

 private:
  void on_command(const cnc::lcmt_program_command& m);
  void on_program_state(const cnc::lcmt_program_state& m);
  void on_block(const cnc::lcmt_program_block& m);
  void apply_command(const Command& c, const cnc::lcmt_program_command& m);
  void request_blocks();

  config::MachineConfig cfg_;
  bus::Bus& bus_;
  Interpolator core_;
  std::string ch_setpoints_, ch_request_, ch_state_, ch_input_, ch_config_, ch_alarm_;
  int64_t config_period_cycles_;

  // Inputs that arrived since the last cycle, applied in arrival order.
  std::vector<cnc::lcmt_program_command> pending_commands_;
  int64_t token_ = 0;         // program token the blocks must carry (0: none loaded)
  int64_t num_blocks_ = 0;
  bool load_pending_ = false;
  std::string program_path_;
  std::map<int64_t, cnc::lcmt_program_block> reorder_;  // received ahead of the core
  int64_t last_request_first_ = -1;
  int64_t last_request_cycle_ = -1000000;
  int64_t resend_cycles_;
  int64_t setpoints_published_ = 0;
  RunState last_state_ = RunState::kIdle;
  int64_t last_state_cycle_ = 0;
};

}  // namespace cnc::interp
