#pragma once
// Conversion between program::Block and its LCM message.
#include <string>

#include "cnc/lcmt_program_block.hpp"
#include "common/program/block.h"

namespace cnc::program {

cnc::lcmt_program_block to_msg(const Block& b, int64_t program_token);
// Validates what arrives from the network; returns an empty string when the
// message is a usable block for a machine of `num_axes` axes, else why not.
std::string from_msg(const cnc::lcmt_program_block& m, int num_axes, Block* out);

}  // namespace cnc::program
