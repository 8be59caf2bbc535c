#pragma once
// LCM side of the interpolator: collects commands and blocks, requests blocks with
// a bounded window (re-requesting what does not arrive), hands blocks to the planner
// thread and takes its finished plans (FeedPolicy), applies inputs to the core at the
// start of a cycle, and publishes each applied input with its cycle index (blocks,
// plans taken, commands), the setpoint and the run state.
//
// Faults: a failed publish, an exception in a cycle, or a drive that leaves the
// enabled state while a program runs stop the program (a recorded STOP: the path
// brakes jerk-limited) and put the node in FAULT (INTERP_STATE state FAULT): START,
// RESUME and new programs are refused until RESET. RESET takes the position from
// the drives (the newest AXIS_STATUS, actual positions) and is recorded with that
// position as an input, so replay reproduces it.
//
// Peers (service::PeerWatch on HEARTBEAT): the drive bridge lost (no heartbeat for
// timing.heartbeat_timeout_s), or its AXIS_STATUS silent for kStatusLost_s while a
// program runs, is a fault as above: nothing is streamed to axes nobody drives, and
// START is refused while it is lost. The program server lost is an ALARM only: the
// path runs out the blocks it has and stops at their end (the planner never plans
// past the last block it holds), and goes on when the server is back and answers
// the block requests again (the server reloads its program: --state).
#include <array>
#include <map>
#include <string>
#include <vector>

#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_joint_status.hpp"
#include "cnc/lcmt_interp_input.hpp"
#include "cnc/lcmt_logger_stats.hpp"
#include "cnc/lcmt_program_block.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "cnc/lcmt_io_command.hpp"
#include "cnc/lcmt_io_status.hpp"
#include "common/motion/input_wait.h"
#include "cnc/lcmt_spindle_command.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/motion/feed_policy.h"
#include "common/motion/interpolator.h"
#include "common/motion/planner_thread.h"
#include "common/service/bus_health.h"
#include "common/service/peer_watch.h"

namespace cnc::interp {

class InterpolatorNode {
 public:
  InterpolatorNode(const config::MachineConfig& cfg, bus::Bus& bus);
  // One interpolation cycle. Call every T_ipo. Never throws: an exception inside
  // becomes a fault (controlled stop, ALARM, FAULT until RESET).
  void cycle();
  // A fault from outside the cycle (main's last-resort catch): as above.
  void fault(const std::string& cause);
  bool faulted() const { return fault_; }
  const std::string& fault_cause() const { return fault_cause_; }
  // For the heartbeat: "" or "fault: cause" (no allocation per call).
  const std::string& detail() const { return detail_; }
  void publish_state(bool force);
  const Interpolator& core() const { return core_; }
  int64_t setpoints_published() const { return setpoints_published_; }

 private:
  void on_command(const cnc::lcmt_program_command& m);
  void on_program_state(const cnc::lcmt_program_state& m);
  void program_withdrawn(const cnc::lcmt_program_state& m);
  void program_lost(const cnc::lcmt_program_state& m);
  // The program cannot go on (a probing error, an M66 input not read, a withdrawal): an
  // ALARM (FAULT, code) naming why, and a STOP as the operator's (recorded: a replay stops too).
  void stop_program(const char* code, const std::string& text);
  void on_block(const cnc::lcmt_program_block& m);
  void apply_command(const Command& c, const cnc::lcmt_program_command& m);
  void request_blocks();
  // run_cycle and its stages.
  void run_cycle();
  void publish_config(int64_t cyc);
  void apply_pending_load();
  void apply_pending_commands();
  void apply_pending_command(const cnc::lcmt_program_command& m);
  void apply_reset(const cnc::lcmt_program_command& m);
  // Says why (log, ALARM where the operator must act) when START cannot be taken now.
  bool start_refused();
  void feed_planner(int64_t cyc);
  void stop_on_refused_block(int64_t bad_index, const std::string& bad, const std::string& failure);
  void publish_setpoint(const Setpoint& sp);
  void publish_input(const cnc::lcmt_interp_input& in);
  void flush_inputs();
  // LOGGER_STATS: the inputs the logger confirms are forgotten, the older ones it
  // does not are sent again.
  void on_logger_stats(const cnc::lcmt_logger_stats& m);
  void alarm(int8_t severity, const std::string& code, const std::string& text);
  // "" when RESET can be applied now (and fills `out` with the position), else why not.
  std::string reset_position(cnc::lcmt_program_command* out) const;
  void watch_drives();
  // The spindle (spindle: in the config): the at-speed wait ended by SPINDLE_STATUS
  // (a recorded SPINDLE_AT_SPEED input), and the core's spindle sent on SPINDLE_CMD.
  void take_spindle_at_speed();
  // The spindle's measured position (SPINDLE_STATUS) for a synchronised move: a
  // recorded SPINDLE_POSITION input each cycle a new sample came while one is queued.
  void take_spindle_position();
  // The spindle's measured speed (SPINDLE_STATUS), a recorded SPINDLE_SPEED input when
  // the process laws' scale it gives differs from the core's.
  void take_spindle_speed();
  void publish_spindle(int64_t cyc);
  // The core's coolant and digital outputs sent on IO_CMD (io: in the config).
  void publish_io(int64_t cyc);
  // Probing (probe: in the config; interpolator_node_probe.cc). The drive bridge
  // latches the probe input's edges (AXIS_STATUS); the edge a probing move (G38.x)
  // waits for stops it (a recorded PROBE_TRIP); a contact during any other move is a
  // fault. A probing move's result (tripped or not, the latched position, where the
  // path rests) goes to the program server on INTERP_STATE, which makes the next
  // blocks with it. A miss where G38.2/G38.4 needs a trip, and a probe standing
  // wrongly at the move's start, stop the program with an ALARM naming file:line.
  void probe_cycle();
  // Input waits (M66; io: in the config; interpolator_node_input.cc). While the path
  // stands at one, the input named by io.digital_inputs / io.analog_inputs is read from
  // IO_STATUS each cycle; the value that meets the wait's mode (LinuxCNC's: an
  // immediate read, a rise, a fall, high, low) ends it as a recorded INPUT_VALUE. The
  // core times it out by itself (#5399 = -1). Each ended wait goes to the program
  // server on INTERP_STATE, which makes the next blocks with its value. An input not
  // read (its module silent, IO_STATUS stale) for kInputStale_s stops the program with
  // an ALARM naming it.
  void input_cycle();
  struct InputWatch {
    int64_t start_cycle = -1;  // the wait being watched (the core's start cycle)
    InputWaitCondition condition;
    double unread_s = -1;      // monotonic time the input was first not read (-1: read)
    int64_t published = 0;     // the core's results sent on INTERP_STATE
  } input_watch_;
  cnc::lcmt_io_status io_status_{};
  double io_status_s_ = -1e9;  // monotonic time it arrived
  void probe_stop(const std::string& why);
  void probe_decide(bool tripped, const double* trip_mm);
  struct ProbeWatch {
    int32_t rises = -1, falls = -1;  // the bridge's edge counts already acted on (-1: none seen)
    int64_t block = -1;              // the probing move being decided
    int64_t start_cycle = -1;        // its first cycle at the front
    bool started = false;            // the bridge has played it from its start: the probe checked there
    bool decided = false;
    std::string file;                // its source
    int32_t line = 0;
    std::array<double, program::kMaxAxes> latch{};
    int32_t results = 0;             // of this program
    int64_t result_block = -1;
    bool tripped = false;
    std::array<double, program::kMaxAxes> trip{}, rest{};
  } probe_;

  // Operator motion (interpolator_node_manual.cc): jogs and the homing
  // sequence are moves the node makes itself, as a program of a line and an END
  // block under a token of its own (negative): its LOAD, blocks, plans and START are
  // recorded inputs like a program's, and so are the STOPs it decides (the jog's
  // keepalive lost, the home switch reached) and each axis's HOMED.
  enum class Manual : int8_t { kNone = 0, kJog = 1, kHome = 2 };
  void on_manual_command(const cnc::lcmt_program_command& m);
  // "" when an operator move may start now, else why not.
  std::string manual_refusal() const;
  // A line of `axis` from where the path stands to `target_mm` (machine) at `feed`.
  void start_move(int axis, double target_mm, double feed_mm_per_min, const std::string& label);
  void manual_cycle();
  // The guard door (safety.door, from IO_STATUS): opened, a program's path is held
  // (a recorded HOLD with value 1: the spindle stops once it stands) and an operator
  // move stopped; START, RESUME, jogs and homing are refused while it is open.
  void door_cycle();
  // A motion command the open door forbids: ALARM door_refused naming the input; true.
  bool door_refuses(const cnc::lcmt_program_command& m);
  bool door_open_ = false;    // IO_STATUS says so
  bool door_acted_ = false;   // this opening's hold (or stop) is applied
  std::string door_input_;
  void home_next_axis();
  void start_search();  // the homing search of home_.axis
  // The travel the drive bridge checks on the setpoints, in machine coordinates (the
  // drive's coordinates, which a homed axis's offset shifts): [*lo, *hi].
  void drive_travel(int axis, double* lo, double* hi) const;
  // Where a homing backs off to from the switch that closed at latch_drive_mm (the
  // drive's coordinates): the backoff distance against the search direction.
  double backoff_target(int axis, double latch_drive_mm) const;
  void manual_stop(const std::string& why);
  void manual_refuse(const char* what, const std::string& why);
  bool limits_apply(int axis) const;
  // "" when a program may move the axes (homing_required: every axis with a method homed).
  std::string unhomed() const;
  Manual manual_ = Manual::kNone;
  std::string manual_text_;
  bool jog_continuous_ = false;
  int jog_axis_ = -1;
  double jog_dir_ = 0;
  double jog_keepalive_s_ = 0;
  double jog_keepalive_mm_ = 0;     // where the path was at the last keepalive (machine)
  double jog_keepalive_v_ = 0;      // and its speed, mm/s
  int64_t local_token_ = 0;
  struct Homing {
    std::vector<int> axes;  // in order
    size_t next = 0;
    int axis = -1;
    int phase = 0;  // 0 search, 1 stopping on the switch, 2 back off, 3 latch, 4 stopping on the latch, 5 to home,
                    // 6 off the switch before the search (it was closed)
    int32_t count0 = 0;
    double seen_mm = 0;   // where the search found the switch (drive)
    double search_end_s = 0;  // monotonic time the search stood without a latch (0: not yet)
    double latch_mm = 0;  // the latch of the slow approach (drive)
    // A gantry axis: both sides search and latch together; each side's own switch. The
    // second side's latch count at the phase's start, which sides have latched in this
    // phase, and where (each in its own drive's coordinates), and the machine position
    // at the first side's latch (the other's must follow within home_max_difference_mm).
    bool gantry = false;
    int32_t count0_2 = 0;
    bool got1 = false, got2 = false;
    double at1_mm = 0, at2_mm = 0;
    double first_machine_mm = 0;
  } home_;
  // A gantry's search or latch phase: takes the sides' new latches; true once both have
  // latched (home_.at1_mm, at2_mm), false meanwhile or when the homing was stopped.
  bool gantry_latches(const char* phase);
  Manual last_manual_ = Manual::kNone;
  int64_t done_token_ = 0;
  // The loaded program runs from a line and its approach waits for CONFIRM: START is
  // refused (set with the token from PROGRAM_STATE, cleared by CONFIRM or a state saying so).
  bool approach_pending_ = false;  // the program that ran to its end (a START again is not a new run)

  config::MachineConfig cfg_;
  bus::Bus& bus_;
  // Block planning runs on the planner's thread; the cyclic thread takes its plans.
  ThreadedPlanLink planner_;
  Interpolator core_;
  FeedPolicy feed_;
  std::string ch_setpoints_, ch_request_, ch_state_, ch_input_, ch_config_, ch_alarm_;
  int64_t config_period_cycles_;
  std::string config_file_;  // the machine file's absolute path, for INTERP_CONFIG

  // Inputs that arrived since the last cycle, applied in arrival order.
  std::vector<cnc::lcmt_program_command> pending_commands_;
  int64_t token_ = 0;         // program token the blocks must carry (0: none loaded)
  int64_t num_blocks_ = 0;
  bool load_pending_ = false;
  std::string program_path_;
  std::map<int64_t, cnc::lcmt_program_block> reorder_;  // received ahead of the core
  int64_t last_request_first_ = -1;
  int64_t requested_end_ = -1;       // one past the last block asked for (in flight or here)
  int64_t waiting_for_ = -1;         // the first block missing ...
  int64_t waiting_since_ = 0;        // ... since this cycle
  int64_t last_resend_cycle_ = -1000000;
  int64_t resend_cycles_;
  int64_t setpoints_published_ = 0;
  RunState last_state_ = RunState::kIdle;
  bool last_fault_ = false;
  int64_t last_state_cycle_ = 0;

  // Fault handling.
  bool fault_ = false;
  std::string fault_cause_;
  std::string detail_;
  int64_t retired_token_ = 0;  // programs up to this token are never taken again (after a fault)
  service::BusHealth health_;
  // The inputs the logger has not confirmed yet, in index order, in one ring of
  // slots made up front (a slot's message is assigned over, its strings and arrays
  // reused). Each was sent (when: sent again after 0.5 s unconfirmed, so the log of
  // a run on a lossy network still replays) or never sent: its publish failed, or an
  // older one's did. The never-sent ones are the newest inputs_unsent_ of the ring,
  // published in order before any newer one, so the record stays complete and
  // contiguous across a bus outage. Full (no logger confirms anything, or the bus
  // fails for long), the oldest is given up: counted, and said once.
  struct PendingInput {
    cnc::lcmt_interp_input in;
    double sent_s = 0;
    bool sent = false;
  };
  PendingInput& pending(size_t i) { return inputs_[(inputs_head_ + i) % inputs_.size()]; }
  void drop_oldest_input();
  std::vector<PendingInput> inputs_;
  size_t inputs_head_ = 0, inputs_size_ = 0, inputs_unsent_ = 0;
  int64_t inputs_dropped_ = 0;  // never sent and given up: the run is no longer replayable
  int64_t next_input_index_ = 0;
  int64_t inputs_resent_ = 0;
  int64_t inputs_unconfirmed_dropped_ = 0;
  bool logger_seen_ = false;
  // The last few published setpoints (cycle, positions), newest last, for the
  // history each setpoint carries.
  static constexpr int kSetpointHistory = 3;
  struct PastSetpoint {
    int64_t cycle = -1;
    std::array<double, program::kMaxAxes> pos{};
  };
  std::array<PastSetpoint, kSetpointHistory> past_{};
  int past_head_ = 0;
  cnc::lcmt_setpoint setpoint_msg_{};  // reused every cycle
  cnc::lcmt_axis_status axis_status_{};
  // The gantries' second drives (JOINT_STATUS; machines with axes[].gantry): their home
  // latches for homing.
  cnc::lcmt_joint_status joint_status_{};
  // The entry of axis a's gantry joint in joint_status_, -1 none (or no JOINT_STATUS yet).
  int joint_of(int axis) const;
  double axis_status_s_ = -1e9;  // monotonic time it arrived
  bool drives_seen_enabled_ = false;  // every axis ENABLED in a status since the program started
  service::PeerWatch peers_;  // [0] the drive bridge, [1] the program server
  // The setpoint stream (lcmt_setpoint.stream): new at the start and at every RESET.
  int64_t stream_;
  // SPINDLE_CMD's command_seq is this plus the core's SpindleState::seq: larger than
  // any an interpolator started before this one sent (the bridge takes each once).
  int64_t spindle_seq_base_;
  int64_t spindle_at_speed_seq_ = -1;  // the newest SPINDLE_STATUS at_speed_seq
  int64_t spindle_oriented_seq_ = -1;  // ...and command_seq reported ORIENTED (M19)
  std::array<double, 3> spindle_pos_{};  // revolutions, rev/s, sample playback cycle
  bool spindle_pos_new_ = false;
  double spindle_rpm_ = 0;  // the newest measured speed, magnitude
  bool spindle_rpm_new_ = false;
  cnc::lcmt_program_command spindle_pos_cmd_{};
  int64_t spindle_sent_seq_ = -1;
  int64_t spindle_sent_cycle_ = 0;
  std::string ch_spindle_cmd_;
  cnc::lcmt_spindle_command spindle_msg_{};
  int64_t io_seq_base_;
  int64_t io_sent_seq_ = -1;
  int64_t io_sent_cycle_ = 0;
  std::string ch_io_cmd_;
  cnc::lcmt_io_command io_msg_{};
};

}  // namespace cnc::interp
