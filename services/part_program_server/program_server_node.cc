#include "services/part_program_server/program_server_node.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <iterator>

#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "common/program/block_msg.h"
#include "common/util/clock.h"

namespace cnc::pps {

namespace ch = config::channels;

ProgramServerNode::ProgramServerNode(const config::MachineConfig& cfg, bus::Bus& bus)
    : cfg_(cfg), bus_(bus), core_(cfg), ch_blocks_(cfg.channel(ch::kProgramBlocks)),
      ch_state_(cfg.channel(ch::kProgramState)), state_(cnc::lcmt_program_state::IDLE) {
  bus_.subscribe<cnc::lcmt_program_command>(cfg.channel(ch::kProgramCmd), [this](const auto& m) { on_command(m); });
  bus_.subscribe<cnc::lcmt_block_request>(cfg.channel(ch::kBlockRequest), [this](const auto& m) { on_request(m); });
  // Where the machine stands, for the start of the next program.
  bus_.subscribe<cnc::lcmt_interp_state>(cfg.channel(ch::kInterpState), [this](const cnc::lcmt_interp_state& m) {
    if (m.num_axes == static_cast<int32_t>(cfg_.axes.size())) machine_position_ = m.position_mm;
  });
}

void ProgramServerNode::on_command(const cnc::lcmt_program_command& m) {
  using C = cnc::lcmt_program_command;
  using S = cnc::lcmt_program_state;
  switch (m.command) {
    case C::LOAD: {
      // The token must differ from every earlier one, also across restarts.
      const int64_t token = std::max(util::wall_utime(), core_.token() + 1);
      const LoadResult r = core_.load(m.program_path, token, machine_position_);
      if (r.ok) {
        spdlog::info("loaded {}: {} blocks (token {})", m.program_path, core_.num_blocks(), token);
        state_ = S::LOADED;
        last_refusal_ = LoadResult{};
        sent_.clear();
        blocks_sent_ = blocks_resent_ = 0;
      } else {
        spdlog::error("program refused: {}", r.error);
        last_refusal_ = r;
        refused_path_ = m.program_path;
        state_ = S::REFUSED;
      }
      publish_state(true);
      break;
    }
    case C::START:
      if (core_.loaded()) state_ = S::RUNNING;
      publish_state(true);
      break;
    case C::STOP:
      if (core_.loaded()) state_ = S::STOPPED;
      publish_state(true);
      break;
    default: break;
  }
}

void ProgramServerNode::on_request(const cnc::lcmt_block_request& m) {
  if (!core_.loaded() || m.program_token != core_.token()) return;
  if (m.count <= 0 || m.count > 4096) {
    spdlog::warn("block request seq {} asks for {} blocks: ignored", m.seq, m.count);
    return;
  }
  const int64_t token = core_.token();
  const std::string path = core_.path();
  if (m.first_block < 0 || m.first_block >= core_.num_blocks()) return;
  const int64_t end = m.first_block + std::min<int64_t>(m.count, core_.num_blocks() - m.first_block);
  for (int64_t i = m.first_block; i < end; ++i) {
    const program::Block* b = core_.block(i);
    if (b == nullptr) {
      // The file no longer reads as validated: serve nothing more of it.
      spdlog::error("program {} withdrawn: {}", token, core_.serving_error());
      last_refusal_ = LoadResult{false, core_.serving_error(), 0, 0};
      refused_path_ = path;
      state_ = cnc::lcmt_program_state::REFUSED;
      publish_state(true);
      return;
    }
    cnc::lcmt_program_block msg = program::to_msg(*b, token);
    bus_.publish(ch_blocks_, msg);
    if (mark_sent(i)) {
      ++blocks_resent_;
    } else {
      ++blocks_sent_;
    }
  }
}

bool ProgramServerNode::mark_sent(int64_t i) {
  auto next = sent_.upper_bound(i);
  if (next != sent_.begin()) {
    auto prev = std::prev(next);
    if (i < prev->second) return true;
    if (i == prev->second) {
      prev->second = i + 1;
      if (next != sent_.end() && next->first == i + 1) {
        prev->second = next->second;
        sent_.erase(next);
      }
      return false;
    }
  }
  if (next != sent_.end() && next->first == i + 1) {
    const int64_t e = next->second;
    sent_.erase(next);
    sent_.emplace(i, e);
  } else {
    sent_.emplace(i, i + 1);
  }
  return false;
}

void ProgramServerNode::publish_state(bool force) {
  const double now = util::monotonic_s();
  if (!force && now - last_state_s_ < 0.1) return;
  last_state_s_ = now;
  cnc::lcmt_program_state s{};
  s.state = state_;
  s.program_token = core_.token();
  s.program_path = state_ == cnc::lcmt_program_state::REFUSED ? refused_path_ : core_.path();
  s.num_blocks = core_.num_blocks();
  s.blocks_sent = blocks_sent_;
  s.blocks_resent = blocks_resent_;
  s.error = last_refusal_.error;
  s.error_line = last_refusal_.line;
  s.error_column = last_refusal_.column;
  bus_.publish(ch_state_, s);
}

}  // namespace cnc::pps
