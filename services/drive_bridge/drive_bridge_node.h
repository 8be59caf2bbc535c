#pragma once
// LCM side of the drive bridge and its servo loop. Every T_servo: take the
// setpoints and commands that arrived, read what the link workers last got from
// the drives, apply the safety rules (lost link, drive fault, following error),
// advance the fine interpolation, hand the commands to the workers; every T_ipo
// publish AXIS_STATUS. Nothing here blocks on Modbus: the workers do the I/O.
//
// States: starting (links not answered yet) -> disabled -> enabling (the profiles'
// state machines run) -> enabled (following setpoints) -> stopping -> fault.
// After any fault nothing moves until an ENABLE on DRIVE_CMD (or cnc-ctl --do enable).
//
// The E-stop (safety.estop.input, a normally closed discrete input of an I/O module):
// when it reads 0 or its module stops answering, a category 1 stop (IEC 60204-1): the
// axes brake as at any fault, at timing.stop_decel_mm_s2 within their jerk limits,
// the spindle and the coolant stop at once, and once the axes stand the drives are
// disabled. The E-stop stays latched: ENABLE is refused until the input reads 1 again
// and the operator's FAULT_RESET has cleared it (refused while it reads 0).
// A hard limit (safety.hard_limits, a normally closed switch per axis end): falling to 0
// while the drives follow setpoints, the same category 1 stop (a fault naming the axis,
// the end and the input), latched until the operator's FAULT_RESET (allowed with the
// switch still at 0) and ENABLE. While a switch reads 0, a setpoint that takes its axis
// further towards it than where the axis stood (or got to, moving off) is refused: a
// stop and a fault. Moving off it is followed, as a machinist jogs off a limit.
// A gantry (axes[].gantry): the axis's second drive (a joint) follows the axis's command
// plus the squaring offset (the second drive's position minus the first's): the
// difference of their positions at each engagement, moving from there at the axis's
// home.search_velocity_mm_s to the difference of the two sides' HOMED offsets (the
// interpolator's HOMED on INTERP_INPUT carries the second side's). While enabled, the
// sides' actual positions less that offset differing by more than gantry.skew_limit_mm
// is a category 1 stop as a hard limit's (a fault naming the axis, both drives and the
// skew; the drives disabled once the axes stand; FAULT_RESET and ENABLE to move again).
// The guard door (safety.door): its state on IO_STATUS with the stamp of its opening;
// the feed hold and the refusals are the interpolator's and the program server's.
//
// servo_tick and publish_status never throw: an exception inside, and a failed
// publish (the bus counts them; service::BusHealth), are faults like any other: the
// axes brake to a controlled stop at timing.stop_decel_mm_s2 and the bridge stays in
// FAULT until ENABLE; the ALARM naming the cause goes out when the bus works again.
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_drive_command.hpp"
#include "cnc/lcmt_interp_input.hpp"
#include "cnc/lcmt_joint_status.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "cnc/lcmt_io_command.hpp"
#include "cnc/lcmt_io_status.hpp"
#include "cnc/lcmt_spindle_command.hpp"
#include "cnc/lcmt_spindle_status.hpp"
#include "common/bus/bus.h"
#include "common/drive/drive_profile.h"
#include "common/drive/link.h"
#include "common/service/bus_health.h"
#include "services/drive_bridge/drive_bridge.h"
#include "services/drive_bridge/io_control.h"
#include "services/drive_bridge/link_worker.h"
#include "services/drive_bridge/spindle_control.h"

namespace cnc::bridge {

class DriveBridgeNode {
 public:
  enum class State : int8_t { kStarting, kDisabled, kEnabling, kEnabled, kStopping, kFault };
  struct Options {
    bool threaded = true;  // false: each servo tick runs one I/O round inline (deterministic tests)
  };

  // Loads the drive profiles (a bad one throws config::ConfigError) and opens nothing yet.
  DriveBridgeNode(const config::MachineConfig& cfg, bus::Bus& bus, Options opt);
  DriveBridgeNode(const config::MachineConfig& cfg, bus::Bus& bus) : DriveBridgeNode(cfg, bus, Options{}) {}
  ~DriveBridgeNode();
  DriveBridgeNode(const DriveBridgeNode&) = delete;
  DriveBridgeNode& operator=(const DriveBridgeNode&) = delete;

  void set_write_probe(LinkWorker::WriteProbe p);
  void start();
  void servo_tick(double now_s);
  void publish_status(int64_t overruns);
  // Disables the drives that answer and closes the links.
  void shut_down();
  void command(int8_t drive_command);

  State state() const { return state_; }
  // For the heartbeat: past start-up (enabled once when enable_on_start, else disabled or faulted).
  bool ready() const { return ready_; }
  // "enabled", "fault: why", ... (kept up to date by servo_tick; no allocation per call).
  const std::string& detail() const { return detail_; }
  const BridgeCore& core() const { return core_; }
  drive::Link& link_of(size_t axis);
  const AxisReport& report(size_t axis) const { return axes_[axis].rep; }
  const drive::DriveProfile& profile_of(size_t axis) const { return *axes_[axis].profile; }
  int64_t tick_count() const { return tick_; }
  // The spindle (spindle: in the config), else nullptr.
  const SpindleControl* spindle() const { return spindle_ ? &spindle_->ctl : nullptr; }
  // The I/O logic (io: in the config), else nullptr.
  const IoControl* io() const { return io_ ? &io_->ctl : nullptr; }
  // Setpoints lost on the way and taken from a later one's history.
  int64_t recovered_setpoints() const { return recovered_setpoints_; }
  // The gantries' second drives (axes[].gantry), in axes[] order.
  size_t joints() const { return joints_.size(); }
  size_t joint_axis(size_t j) const { return joints_[j].axis; }
  const AxisReport& joint_report(size_t j) const { return joints_[j].drv.rep; }
  double joint_command(size_t j) const { return joints_[j].drv.cmd.cmd_mm; }
  double joint_squaring(size_t j) const { return joints_[j].squaring_mm; }
  double joint_skew(size_t j) const { return joints_[j].skew_mm; }
  // The last skew fault: how long before the read that showed it the skew crossed the
  // limit (interpolated between the two reads around it; the read itself is up to one
  // I/O round old), the stop beginning in that tick; -1 none.
  double skew_reaction_ms() const { return skew_.reaction_ms; }

 private:
  struct Axis {
    const drive::DriveProfile* profile = nullptr;
    LinkWorker* worker = nullptr;
    size_t slot = 0;
    AxisCommand cmd;
    AxisReport rep;
    int64_t lost_seen = 0;
    int64_t fe_seen = 0;
    int64_t reconnects_seen = 0;
    bool link_down = false;  // lost since the last ENABLE: stays disabled
  };
  // servo_tick_inner and its stages.
  void servo_tick_inner(double now_s);
  void take_operator_command(double now_s);
  void advance_state(double now_s);
  void advance_enabling(double now_s);
  void report_reconnects();
  // The bridge's state, ALARMs and detail text after the core's tick (a fault, a setpoint mismatch).
  void follow_core_state();
  void set_axis_commands(const AxisArray& cmd);
  void trace_tick(double now_s, bool hold, const AxisArray& cmd);
  void post_rounds(double now_s);
  void publish_status_inner(int64_t overruns);
  void on_exception(const char* where, const char* what);
  void on_setpoint(const cnc::lcmt_setpoint& m);
  // After a setpoint watchdog trip: the stream's next setpoint tells whose stall it
  // was (its publish stamp against its arrival), as an ALARM `watchdog_cause`.
  void explain_trip(const cnc::lcmt_setpoint& m);
  // The spindle's share of a servo tick and of a status publish.
  LinkWorker* worker_for(const config::DriveConfig& d, std::map<std::string, LinkWorker*>& by_link);
  void make_spindle(std::map<std::string, LinkWorker*>& by_link);
  void make_io(std::map<std::string, LinkWorker*>& by_link);
  void spindle_tick(double now_s);
  // Its command to the drive, stamped with this tick's playback (after the core's tick).
  void post_spindle_command(double now_s);
  void publish_spindle_status();
  // The I/O modules' share (io: in the config).
  void io_tick();
  // The E-stop's share: its input, read first in every tick (safety: in the config).
  void safety_tick(double now_s);
  // An ENABLE the E-stop or a hard limit's latch forbids: ALARM enable_refused naming the input; true.
  bool safety_refuses_enable();
  void publish_io_status();
  // The probe's share (probe.input): its input sampled every tick, each edge latched
  // with the drives' actual positions of the same I/O round.
  void probe_tick();
  void fault(size_t axis, const std::string& why, bool disable_axis);
  // One drive's link, fault and following-error checks (check_drives); `axis` the one
  // whose fault it is (a gantry's joint: its axis).
  void check_drive(Axis& a, size_t axis, const std::string& name, bool expect_enabled);
  // The gantries: the skew check (before the core's tick: a fault brakes in it), the
  // squaring's motion (after it, with the commands), JOINT_STATUS.
  void gantry_tick(double now_s);
  void advance_squaring();
  void publish_joint_status();
  void on_interp_input(const cnc::lcmt_interp_input& m);
  void begin_enable(double now_s);
  void check_drives();
  void alarm(int8_t severity, const std::string& code, const std::string& text);
  AxisArray actuals() const;

  config::MachineConfig cfg_;
  bus::Bus& bus_;
  Options opt_;
  BridgeCore core_;
  std::vector<std::unique_ptr<drive::DriveProfile>> profiles_;
  std::vector<std::unique_ptr<drive::Link>> links_;
  std::vector<std::unique_ptr<LinkWorker>> workers_;
  // Per worker: is its link keeping up with the ticks? (see link_stalled())
  struct LinkPace {
    int64_t rounds_seen = -1;
    bool outstanding = false;  // posted, and no round finished since
    int ticks_waiting = 0;     // ticks since the first post no round has answered yet
    double usual_ticks = 1.0;  // its usual ticks from a post to the round's end (serial lines: several)
  };
  std::vector<LinkPace> pace_;
  int64_t recovered_setpoints_ = 0;  // lost, and taken from a later setpoint's history
  // The last engagement's token (util::next_token), kept here: the core's goes to 0 on
  // disengage, and the next token must exceed every earlier one even if the wall clock steps back.
  int64_t engagement_ = 0;
  double stale_report_s_ = -1e9;
  bool link_stalled();
  std::vector<Axis> axes_;
  // A gantry's second drive and its squaring (axes[axis].gantry).
  struct Joint {
    size_t axis = 0;
    Axis drv;
    double squaring_mm = 0;  // commanded: second drive minus first
    double target_mm = 0;    // where squaring_mm moves to
    bool homed = false;      // target_mm is the HOMED offsets' difference (else the engagement's)
    double v_mm_s = 0;       // squaring_mm's rate
    double skew_mm = 0;      // (second actual - first actual) - squaring_mm
    double max_skew_mm = 0;  // |skew_mm| since the engagement
    double prev_abs_skew_mm = 0;  // at the tick before, for the crossing's time
    double prev_s = -1;
  };
  std::vector<Joint> joints_;
  struct SkewLatch {
    bool latched = false;  // tripped; until a FAULT_RESET once the axes stand
    bool stood = false;
    double at_s = 0;
    double reaction_ms = -1;
    double stop_ms = -1;
    double command_stood_s = -1;
  };
  SkewLatch skew_;
  std::string ch_joint_status_;
  cnc::lcmt_joint_status joint_msg_{};  // reused by every status publish
  // The spindle's VFD (cfg.spindle.enabled): on a link worker like the axes' drives.
  struct Spindle {
    explicit Spindle(const config::SpindleConfig& c) : ctl(c) {}
    SpindleControl ctl;
    LinkWorker* worker = nullptr;
    const drive::DriveProfile* profile = nullptr;
    SpindleCommand cmd;
    SpindleReport rep;
    SpindleFeedback fb;
    bool pending = false;  // a SPINDLE_CMD arrived since the last tick (the newest kept)
    int64_t pending_seq = 0;
    int8_t pending_direction = 0;
    double pending_rpm = 0;
    bool pending_orient = false;
    double pending_orient_deg = 0;
    int8_t pending_orient_mode = 0;
    bool reset_pending = false;  // ENABLE or FAULT_RESET asked for the drive's fault reset
    double reset_deadline_s = 0;  // and it must have taken effect by then
  };
  std::unique_ptr<Spindle> spindle_;
  std::string ch_spindle_status_;
  cnc::lcmt_spindle_status spindle_msg_{};  // reused by every status publish
  // The I/O modules (cfg.io.enabled), each on a link worker like a drive.
  struct IoModule {
    LinkWorker* worker = nullptr;
    size_t slot = 0;
    std::vector<int> points[4];  // its points by kind (config::IoKind), as its device orders them
    IoReport rep;
    uint64_t logged_coils = 0;   // the read-back coils last logged
    bool logged_valid = false;
  };
  struct Io {
    Io(const config::IoConfig& c, const std::vector<std::vector<int>>& coils, const std::vector<std::vector<int>>& holding)
        : ctl(c, coils, holding) {}
    IoControl ctl;
    std::vector<IoModule> modules;
    bool pending = false;  // an IO_CMD arrived since the last tick (the newest kept)
    int64_t pending_seq = 0;
    int8_t pending_coolant = 0;
    uint64_t pending_outputs = 0;
    std::vector<double> pending_analog;  // io.analog_outputs' values, sized once
    bool analog_known = false;           // an IO_CMD has carried them
  };
  std::unique_ptr<Io> io_;
  struct Estop {
    int module = -1;      // index into io_->modules; -1: no E-stop configured
    size_t bit = 0;       // its bit among the module's discrete inputs
    bool ok = false;      // the input reads 1 and its module answers
    bool latched = false; // tripped; until a FAULT_RESET with the input at 1
    bool stood = false;   // the axes stood after the trip: drives disabled
    int64_t utime = 0;    // the trip, wall clock
    double at_s = 0;      // and on the servo clock
    double stop_ms = -1;  // from the trip until the axes stood
    double command_stood_s = -1;  // when the stop's command came to rest
  };
  Estop estop_;
  // The hard limits (safety.hard_limits): each switch, normally closed.
  struct LimitInput {
    int module = 0;       // index into io_->modules
    size_t bit = 0;       // among the module's discrete inputs
    size_t axis = 0;
    int end = 1;          // -1 the min end, +1 the max end
    int point = 0;        // index into io.points
    bool ok = true;       // as read last tick
    double bound_mm = 0;  // while it reads 0: setpoints may take the axis no further towards it
  };
  std::vector<LimitInput> limits_;
  struct LimitLatch {
    bool latched = false;  // tripped; until a FAULT_RESET once the axes stand
    bool stood = false;    // the axes stood after the trip: drives disabled
    int tripped = -1;      // index into limits_ of the last trip
    int64_t utime = 0;     // the trip, wall clock
    double at_s = 0;       // and on the servo clock
    double stop_ms = -1;   // from the trip until the axes stood
    double command_stood_s = -1;
    int64_t held_off = 0;  // the engagement whose stream towards a switch was reported
  };
  LimitLatch limit_;
  void limits_tick(double now_s);
  // A setpoint (cycle) the core took that takes an axis further towards a switch reading
  // 0 than it stood: refused, a stop and a fault; true. Else the bounds follow a move off it.
  bool limits_refuse(const AxisArray& p, int64_t cycle);
  // A stream the core would join standing towards a switch reading 0: dropped
  // (ALARM hard_limit_not_joined, once per engagement); true.
  bool limits_hold_off(const AxisArray& p, const StreamStamp& from);
  // The first switch reading 0 that `p` goes towards beyond where its axis stood, else -1.
  int limit_towards(const AxisArray& p) const;
  std::string limit_name(const LimitInput& l) const;
  // The drives have settled on a command at rest (following error within 1 um), or
  // kStandstillWaitS have passed since `since_s` (set at the first call).
  bool settled(double& since_s, double now_s) const;
  // The guard door (safety.door): its switch, normally closed (1: shut).
  struct Door {
    int module = -1;     // index into io_->modules; -1: none configured
    size_t bit = 0;
    bool ok = true;      // shut, as read last tick
    int64_t utime = 0;   // its last opening, wall clock
  };
  Door door_;
  struct ProbeLatch {
    int module = -1;  // index into io_->modules; -1: no probe configured
    size_t bit = 0;   // its bit among the module's discrete inputs
    int8_t value = -1;  // 1 touching, 0 not, -1 not read
    int32_t rises = 0, falls = 0;
    std::vector<double> rise_mm, fall_mm;
    double rise_cycle = -1, fall_cycle = -1;
    // probe.latch: drives. The input's edge (its tick, sampled positions and cycle) waits
    // for every drive's latch of it: a drive counter that changed within kLatchTicks of
    // the edge, before or after, and not taken for an earlier edge. [0] falling, [1] rising.
    static constexpr int64_t kLatchTicks = 5;
    int64_t tick = 0;
    struct Edge {
      bool pending = false;
      int64_t tick = 0;
      double cycle = -1;
      std::vector<double> sampled_mm;
    };
    Edge edge[2];
    struct DriveCounter {
      bool known = false;  // read since the drive last (re)started answering
      int64_t count = 0;
      int64_t changed = -1000000;  // tick of its last change
      int64_t taken = -1000000;    // tick of the change an edge took
      double mm = 0;
    };
    std::vector<DriveCounter> counter[2];  // [direction][axis]
    int64_t fallbacks = 0;                 // edges no drive latched in time: sampled positions
  };
  ProbeLatch probe_;
  void probe_drive_counters();
  void probe_settle(int rising, bool force);
  std::string ch_io_status_;
  cnc::lcmt_io_status io_msg_{};  // reused by every status publish
  std::string ch_status_;
  cnc::lcmt_axis_status status_msg_{};  // reused by every status publish
  std::string ch_alarm_;
  int ticks_per_ipo_;
  int64_t tick_ = 0;
  State state_ = State::kStarting;
  bool ready_ = false;
  bool started_ = false;
  int8_t pending_command_ = 0;
  double enable_deadline_s_ = 0;
  std::string fault_text_;
  bool waiting_reported_ = false;
  double last_setpoint_s_ = 0;
  int64_t last_setpoint_utime_ = 0;
  double tick_s_ = 0;  // the servo tick's time: setpoints are taken inside it
  struct Trip {         // the setpoint watchdog's last trip, until explained
    bool open = false;
    int64_t cycle = -1;    // the newest setpoint before it
    int64_t utime = 0;     // that setpoint's publish stamp
    double arrived_s = 0;  // and its arrival
  };
  Trip trip_;
  std::string detail_ = "starting";
  State detail_state_ = State::kStarting;
  service::BusHealth health_;
  // Diagnostics (CNC_BRIDGE_DEBUG_TRACE=FILE): every tick, allocated up front, written at shut-down.
  struct DbgTick {
    double mono, tau;
    int64_t last_cycle;
    int held;
    double cmd[3], fe[3], act[3];
  };
  struct DbgSetpoint {
    double mono;
    int64_t cycle;
  };
  std::vector<DbgTick> dbg_ticks_;
  std::vector<DbgSetpoint> dbg_sp_;
  std::string dbg_file_;
};

const char* state_name(DriveBridgeNode::State s);

}  // namespace cnc::bridge
