#pragma once
#include <functional>
#include <map>

#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_block_request.hpp"
#include "cnc/lcmt_command_answers.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_io_status.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "common/service/open_limit.h"
#include "common/bus/bus.h"
#include "common/service/bus_health.h"
#include "services/part_program_server/interlock.h"
#include "services/part_program_server/program_server.h"

namespace cnc::pps {

// LCM side: LOAD/START/STOP commands, block requests, program state. Blocks go out
// only on request (the interpolator asks for a bounded window and asks again after
// a silence), each stamped with the bus's per-channel sequence number, so a lost
// datagram delays a block but never loses it.
//
// Interlock (interlock.h): a command the cell's state does not allow (LOAD or START
// while a program runs, START in FAULT, ...) is refused: PROGRAM_STATE carries the
// reason and the refused command's sender and seq, the state stays as it was;
// PROGRAM_ANSWERS the last 16 decisions, so that no client's answer is lost to the
// next client's command. The
// state follows the interpolator (INTERP_STATE: running, held, done, fault) and the
// drives (AXIS_STATUS). A failed publish here puts the server in FAULT until RESET.
//
// Restarts (a killed server): with a state file, every accepted LOAD writes the
// program's path, token and start position there (atomically: a new file renamed
// over the old), and a server that starts with that file loads the same program
// again under the same token from the same start: the same blocks, served to the
// interpolator that still runs it and asks for the blocks it lacks. The cell counts
// as idle until INTERP_STATE says the interpolator runs it (then running).
class ProgramServerNode {
 public:
  ProgramServerNode(const config::MachineConfig& cfg, bus::Bus& bus);
  // The state file ("" = none). Call before the first message is handled: a program
  // recorded there is loaded again (an unreadable or malformed file is ignored with a warning).
  void use_state_file(const std::string& path);
  // Called while a load validates (ProgramServer::on_validation_progress).
  void on_validation_progress(std::function<void(int64_t)> f) { core_.on_validation_progress(std::move(f)); }
  // Publishes the program state when it changed or every `period_s`.
  void publish_state(bool force);
  // Once per loop: watches this node's publishes (FAULT on a failure, ALARM once the bus works).
  void poll(double now_s);
  int8_t state() const { return state_; }
  // The interpolator is lost (service::PeerWatch): a program it ran is not running
  // any more (STOPPED); a new one needs the cell reset (the drives stopped in FAULT).
  void interpolator_lost();
  // The interlock's view of the cell now.
  CellView view(double now_s) const;
  // What this server loads programs with (the dry run's must match: dry_run_agreement_test).
  const ProgramSetup& setup() const { return core_.setup(); }

 private:
  void on_command(const cnc::lcmt_program_command& m);
  void on_io(const cnc::lcmt_io_status& m);
  void on_interp_state(const cnc::lcmt_interp_state& m);
  void refuse(const cnc::lcmt_program_command& m, const std::string& why);
  void on_request(const cnc::lcmt_block_request& m);
  // The last block request, answered again when a probing move's result lets the
  // blocks after it be served (the interpolator need not wait for its re-request).
  cnc::lcmt_block_request last_request_{};
  // Counts block `i` as sent; returns whether it was sent before.
  bool mark_sent(int64_t i);

  config::MachineConfig cfg_;
  bus::Bus& bus_;
  ProgramServer core_;
  std::string ch_blocks_, ch_state_, ch_answers_;
  int8_t state_;
  LoadResult last_refusal_;
  std::string refused_path_;
  // A program withdrawn while it ran (its result left it invalid, its file changed):
  // its token, which PROGRAM_STATE's REFUSED carries so that the interpolator running
  // it stops; 0 after a refused LOAD (nothing ran).
  int64_t withdrawn_token_ = 0;
  int64_t blocks_sent_ = 0;
  int64_t blocks_resent_ = 0;
  // Blocks sent at least once, as disjoint ranges [first, end) keyed by first:
  // requests come in order, so this stays a handful of ranges for any program size.
  std::map<int64_t, int64_t> sent_;
  double last_state_s_ = -1e9;
  std::vector<double> machine_position_;  // from INTERP_STATE; empty until known (home)

  // Interlock state.
  bool program_ready_ = false;   // a loaded program not started yet
  double start_s_ = -1e9;        // when START was accepted (until the interpolator reports it)
  bool interp_fault_ = false;    // INTERP_STATE says FAULT
  std::string interp_fault_text_;
  bool own_fault_ = false;       // a publish of this node failed
  std::string own_fault_text_;
  // The interpolator's operator motion and homed axes, from INTERP_STATE.
  int8_t interp_mode_ = 0;
  std::string interp_mode_text_;
  bool interp_active_ = false;
  std::vector<int8_t> interp_homed_;
  // MDI and touch-off: the line is written to a one-line program (with M2, so the
  // parameters it sets are written to the var file at its end, as a program's) and
  // loaded like one; cnc-ctl starts it.
  void load_line(const cnc::lcmt_program_command& m, const std::string& line);
  int64_t mdi_count_ = 0;
  // Tool touch-off: "" when a tool is in the spindle (#5400 of the var file, then in
  // spindle_tool_) and in the tool table, else why not.
  std::string tool_touch_off_refusal();
  int spindle_tool_ = 0;
  // MDI: the modes the last accepted line left (README "MDI"); reset by LOAD and RESET.
  std::optional<rs274::ModalState> mdi_modes_;
  std::string mdi_file_;  // the line loaded last: removed once another program is loaded
  void load_program(const std::string& path, int from_line = 0);
  bool approach_pending_ = false;  // loaded from a line: START waits for CONFIRM
  cnc::lcmt_axis_status axes_{};
  bool door_open_ = false;  // INTERP_STATE: the guard door (safety.door) is open
  // IO_STATUS: the hard-limit switch that reads 0 (its axis, end -1/+1, name; -1: none).
  service::OpenLimit open_limit_;
  double axes_s_ = -1e9;
  std::string refusal_;
  int32_t refused_sender_ = 0;
  int64_t refused_seq_ = -1;
  int64_t refusals_ = 0;
  int32_t answered_sender_ = 0;
  int64_t answered_seq_ = -1;
  // The last decisions, newest first (PROGRAM_ANSWERS: each client finds its own).
  static constexpr int kAnswers = 16;
  cnc::lcmt_command_answers answers_{};
  void remember_answer(int32_t sender, int64_t seq);
  void decide(const cnc::lcmt_program_command& m);  // on_command's decision, answered around it
  service::BusHealth health_;
  std::string state_file_;
  bool restored_ = false;  // loaded again from the state file; not yet seen running (until a LOAD)
  void write_state_file() const;
};

}  // namespace cnc::pps
