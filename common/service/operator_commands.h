#pragma once
// The operator's commands to a cell, shared by every client of it (cnc-ctl, cnc-hmi):
// the same PROGRAM_CMD and DRIVE_CMD messages, signed by the bus like every other,
// and the same way of recognising the interlock's answer to one of them. A client is
// never a second way into the cell: it sends only what these functions build.
#include <cstdint>
#include <optional>
#include <string>

#include "cnc/lcmt_command_answers.hpp"
#include "cnc/lcmt_drive_command.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"

namespace cnc::service {

// The fields of an operator command (lcmt_program_command); unset ones stay 0 / "".
struct OperatorCommand {
  int8_t command = 0;           // lcmt_program_command::LOAD, START, ... MDI
  std::string program_path;     // LOAD
  double feed_override = 1.0;   // OVERRIDE
  int32_t axis = -1;            // HOME (-1: all), JOG, JOG_KEEPALIVE, TOUCH_OFF
  double value = 0;             // JOG: mm or direction; TOUCH_OFF: the reading wanted
  double feed_mm_per_min = 0;   // JOG: 0 = the axis's jog feed
  int8_t jog_continuous = 0;    // JOG: 1 continuous; TOUCH_OFF: 2 = tool length
  std::string text;             // MDI: the line
  int32_t from_line = 0;        // LOAD: run from this line (0: from the start)
};

// The command by its name as cnc-ctl's --do and the HMI's actions spell it ("hold",
// "touch-off", ...); nullopt for a name that is not a program command.
std::optional<int8_t> program_command_by_name(const std::string& name);

// Publishes the command on PROGRAM_CMD; its seq (the interlock names it when it
// refuses it), or -1 when the publish failed (bus.last_publish_error() says why).
int64_t send_program_command(bus::Bus& bus, const config::MachineConfig& cfg, const OperatorCommand& c);

// Publishes a drive command (lcmt_drive_command::ENABLE, DISABLE, FAULT_RESET) on DRIVE_CMD.
bool send_drive_command(bus::Bus& bus, const config::MachineConfig& cfg, int8_t command);

// The interlock's refusal of the command `seq` this client (`sender`) sent, from
// PROGRAM_STATE; "" while the state names another command.
std::string refusal_of(const lcmt_program_state& state, int32_t sender, int64_t seq);
// Whether the program server's last decisions (PROGRAM_ANSWERS) hold one on the command
// `seq` this client (`sender`) sent; its refusal ("" when it was taken) in *refusal.
bool answer_of(const lcmt_command_answers& answers, int32_t sender, int64_t seq, std::string* refusal);

// The file the program server writes an MDI or touch-off line to, by the command's
// sender and seq: a PROGRAM_STATE whose path ends so is that command's answer.
std::string mdi_program_suffix(int32_t sender, int64_t seq);

}  // namespace cnc::service
