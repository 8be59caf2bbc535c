#pragma once
// Conversion between program::Block and its LCM message.
#include <string>

#include "cnc/lcmt_program_block.hpp"
#include "cnc/lcmt_program_block_v2.hpp"
#include "common/program/block.h"

namespace cnc::program {

cnc::lcmt_program_block to_msg(const Block& b, int64_t program_token);
// Validates what arrives from the network; returns an empty string when the
// message is a usable block for a machine of `num_axes` axes, else why not.
std::string from_msg(const cnc::lcmt_program_block& m, int num_axes, Block* out);

// A block as logs of formats 1 and 2 hold it, into today's message (no path tolerance).
cnc::lcmt_program_block from_v2(const cnc::lcmt_program_block_v2& v);

}  // namespace cnc::program
