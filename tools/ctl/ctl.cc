#include "tools/ctl/ctl.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <set>

#include "cnc/lcmt_drive_command.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/service/heartbeat.h"
#include "common/service/operator_commands.h"
#include "common/util/clock.h"
#include "common/util/install.h"
#include "common/util/signals.h"
#include "common/service/machine_status.h"

namespace cnc::ctl {

namespace ch = cnc::config::channels;
using cnc::lcmt_program_command;

namespace {

constexpr int kExitSendFailed = 1;
constexpr int kExitRefused = 3;
constexpr int kExitTimeout = 4;
constexpr int kExitFault = 5;
constexpr int kExitStopped = 6;

}  // namespace

template <class Pred>
bool Ctl::wait(double timeout_s, Pred done) {
  const double end = cnc::util::monotonic_s() + timeout_s;
  while (!done()) {
    if (cnc::util::stop_requested() || cnc::util::monotonic_s() > end) return false;
    // Everything queued before the predicate looks again: after a stall of this
    // process, the heartbeats waiting in the queue are news, not a silence.
    if (bus_.handle(10) > 0) bus_.drain();
  }
  return true;
}

Ctl::Ctl(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args)
    : cfg_(cfg),
      args_(args),
      what_(args.option("do", "run")),
      timeout_s_(std::stod(args.option("timeout", "600"))),
      bus_(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-ctl")) {
  bus_.subscribe<cnc::lcmt_heartbeat>(cfg.channel(ch::kHeartbeat), [this](const auto& m) {
    view_.heartbeats[m.service] = m;
    view_.heartbeat_s[m.service] = cnc::util::monotonic_s();
  });
  bus_.subscribe<cnc::lcmt_program_state>(cfg.channel(ch::kProgramState), [this](const auto& m) {
    view_.program = m;
    view_.have_program = true;
  });
  bus_.subscribe<cnc::lcmt_command_answers>(cfg.channel(ch::kProgramAnswers),
                                            [this](const auto& m) { view_.answers = m; });
  bus_.subscribe<cnc::lcmt_interp_state>(cfg.channel(ch::kInterpState), [this](const auto& m) {
    view_.interp = m;
    view_.have_interp = true;
  });
  bus_.subscribe<cnc::lcmt_axis_status>(cfg.channel(ch::kAxisStatus), [this](const auto& m) {
    view_.axes = m;
    view_.have_axes = true;
    view_.axes_s = cnc::util::monotonic_s();
    for (int i = 0; i < m.num_axes; ++i) {
      if (std::fabs(m.following_error_mm[i]) > largest_fe_) {
        largest_fe_ = std::fabs(m.following_error_mm[i]);
        largest_fe_axis_ = m.axis_name[i];
      }
    }
  });
  // The machine's devices, for status (their channels exist with their config sections).
  if (what_ == "status") {
    bus_.subscribe<cnc::lcmt_spindle_status>(cfg.channel(ch::kSpindleStatus), [this](const auto& m) {
      view_.spindle = m;
      view_.have_spindle = true;
    });
    bus_.subscribe<cnc::lcmt_io_status>(cfg.channel(ch::kIoStatus), [this](const auto& m) {
      view_.io = m;
      view_.have_io = true;
    });
    bus_.subscribe<cnc::lcmt_joint_status>(cfg.channel(ch::kJointStatus), [this](const auto& m) {
      view_.joints = m;
      view_.have_joints = true;
    });
  }
  bus_.subscribe<cnc::lcmt_alarm>(cfg.channel(ch::kAlarm), [this](const auto& m) {
    view_.alarms.push_back(m);
    std::fprintf(stderr, "ALARM %s [%s] %s\n", m.source.c_str(), m.code.c_str(), m.text.c_str());
  });
  if (what_ != "status") from_line_ = std::stoi(args.option("from", "0"));
}

// ---- what the verbs share ----

void Ctl::send(int8_t command, const std::string& path, double value) {
  cnc::service::OperatorCommand c;
  c.command = command;
  c.program_path = path;
  c.feed_override = value;
  if (command == lcmt_program_command::LOAD) c.from_line = from_line_;
  sent_seq_ = cnc::service::send_program_command(bus_, cfg_, c);
  if (sent_seq_ < 0) {
    std::fprintf(stderr, "cnc-ctl: %s\n", bus_.last_publish_error());
    std::exit(kExitSendFailed);
  }
}

// The refusal of the last command sent, "" while none came.
std::string Ctl::refused() const {
  std::string why;
  if (cnc::service::answer_of(view_.answers, bus_.sender(), sent_seq_, &why)) return why;
  if (!view_.have_program) return "";
  return cnc::service::refusal_of(view_.program, bus_.sender(), sent_seq_);
}

// Whether the program server has decided on the last command sent (its state names it,
// with the refusal when it refused).
bool Ctl::answered() const {
  if (cnc::service::answer_of(view_.answers, bus_.sender(), sent_seq_, nullptr)) return true;
  return view_.have_program && view_.program.answered_sender == bus_.sender() &&
         view_.program.answered_seq == sent_seq_;
}

// Sends a program command and waits up to `wait_s` for its refusal: "" when none came.
std::string Ctl::send_checked(int8_t command, double wait_s, const std::string& path, double value) {
  send(command, path, value);
  wait(wait_s, [&] { return !refused().empty(); });
  return refused();
}

// Drive bridge commands.
void Ctl::drive_command(int8_t command) {
  if (!cnc::service::send_drive_command(bus_, cfg_, command)) {
    std::fprintf(stderr, "cnc-ctl: %s\n", bus_.last_publish_error());
    std::exit(kExitSendFailed);
  }
}

bool Ctl::all_in(int8_t state) const {
  if (!view_.have_axes || view_.axes.num_axes == 0) return false;
  for (int8_t s : view_.axes.drive_state)
    if (s != state) return false;
  return true;
}

// ENABLE until every axis reports ENABLED: 0, or an exit code.
int Ctl::enable_drives(double limit_s) {
  const double end = cnc::util::monotonic_s() + limit_s;
  double next_send = 0;
  const size_t from = view_.alarms.size();
  while (!all_in(cnc::lcmt_axis_status::ENABLED)) {
    // Refused (the E-stop): no use sending it again.
    if (const std::string why = bridge_alarm_since(from, "enable_refused"); !why.empty()) {
      std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
      return kExitRefused;
    }
    if (cnc::util::stop_requested() || cnc::util::monotonic_s() > end) {
      std::fprintf(stderr, "cnc-ctl: the drives did not enable: %s\n",
                   view_.have_axes && !view_.axes.fault.empty() ? view_.axes.fault[0].c_str() : "no axis status");
      return view_.have_axes ? kExitFault : kExitTimeout;
    }
    // Sent again every second while not enabled: a lost datagram only delays.
    if (cnc::util::monotonic_s() >= next_send) {
      drive_command(cnc::lcmt_drive_command::ENABLE);
      next_send = cnc::util::monotonic_s() + 1.0;
    }
    bus_.handle(10);
  }
  return 0;
}

// CONFIRM: the approach of a program loaded from a line; done when no approach waits.
int Ctl::confirm_approach() {
  for (int attempt = 0; attempt < 5; ++attempt) {
    if (const std::string why = send_checked(lcmt_program_command::CONFIRM, 0.3); !why.empty()) {
      if (attempt > 0 && view_.have_program && !view_.program.approach_pending) return 0;  // a copy after a lost answer
      std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
      return kExitRefused;
    }
    if (wait(0.7, [&] { return view_.have_program && !view_.program.approach_pending; })) return 0;
  }
  std::fprintf(stderr, "cnc-ctl: CONFIRM was sent 5 times and the program server does not show it\n");
  return kExitTimeout;
}

// The axis named by --axis (-1: none given).
int Ctl::axis_arg() const {
  const std::string name = args_.option("axis");
  if (name.empty()) return -1;
  const int a = cfg_.axis_index(name);
  if (a < 0) {
    std::fprintf(stderr, "cnc-ctl: --axis %s: the machine has no such axis\n", name.c_str());
    std::exit(cnc::service::kExitBadInput);
  }
  return a;
}

// An operator command with its fields; refused at once with the server's reason.
void Ctl::send_op(int8_t command, int axis, double value, double feed, int8_t flag, const std::string& text) {
  cnc::service::OperatorCommand c;
  c.command = command;
  c.axis = axis;
  c.value = value;
  c.feed_mm_per_min = feed;
  c.jog_continuous = flag;
  c.text = text;
  c.feed_override = 0;
  sent_seq_ = cnc::service::send_program_command(bus_, cfg_, c);
  if (sent_seq_ < 0) {
    std::fprintf(stderr, "cnc-ctl: %s\n", bus_.last_publish_error());
    std::exit(kExitSendFailed);
  }
}

bool Ctl::interp_active() const {
  const int8_t st = view_.interp.state;
  return st == cnc::lcmt_setpoint::RUNNING || st == cnc::lcmt_setpoint::HELD || st == cnc::lcmt_setpoint::STARVED;
}

// An alarm from the interpolator with one of these codes since index `from`: its text.
std::string Ctl::alarm_since(size_t from, std::initializer_list<const char*> codes) const {
  for (size_t i = from; i < view_.alarms.size(); ++i)
    for (const char* c : codes)
      if (view_.alarms[i].source == "cnc-interpolator" && view_.alarms[i].code == c) return view_.alarms[i].text;
  return "";
}

// A wrapped rotary axis is shown modulo 360, in [0, 360) (its position keeps counting turns).
static double displayed(const config::AxisConfig& a, double v) {
  if (!a.wrapped) return v;
  const double m = std::fmod(v, 360.0);
  return m < 0 ? m + 360.0 : m;
}

void Ctl::print_position(const char* what_done) const {
  std::printf("%s:", what_done);
  for (int i = 0; i < view_.interp.num_axes; ++i)
    std::printf(" %s %.4f%s", cfg_.axes[static_cast<size_t>(i)].name.c_str(),
                displayed(cfg_.axes[static_cast<size_t>(i)], view_.interp.position_mm[static_cast<size_t>(i)]),
                static_cast<size_t>(i) < view_.interp.homed.size() && view_.interp.homed[static_cast<size_t>(i)]
                    ? " (homed)"
                    : "");
  std::printf("\n");
}

// ---- the verbs ----

// status: every service heard on HEARTBEAT within a listening window (two heartbeat
// timeouts, or --timeout): its host, pid, version, state and the time since it was
// last heard; then the program's and the interpolator's state. Exit 4 when none was heard.
int Ctl::status() {
  const double listen_s = args_.options.count("timeout") ? timeout_s_ : 2 * cfg_.heartbeat_timeout_s;
  const double t0 = cnc::util::monotonic_s();
  wait(listen_s, [] { return false; });
  if (cnc::util::stop_requested()) return cnc::service::kExitFailure;
  const double now = cnc::util::monotonic_s();
  static const char* const kStates[] = {"starting", "running", "stopping", "fault"};
  std::printf("%-20s %-16s %8s  %-26s %-9s %s\n", "service", "host", "pid", "version", "state", "last heard");
  for (const auto& [name, hb] : view_.heartbeats) {
    const char* state = hb.state >= 0 && hb.state <= 3 ? kStates[hb.state] : "?";
    std::printf("%-20s %-16s %8d  %-26s %-9s %.2f s ago\n", name.c_str(), hb.host.empty() ? "?" : hb.host.c_str(),
                hb.pid, hb.version.empty() ? "?" : hb.version.c_str(), state, now - view_.heartbeat_s[name]);
  }
  static const char* const kProgram[] = {"idle", "loaded", "running", "held", "done", "refused", "stopped", "fault"};
  static const char* const kInterp[] = {"idle", "running", "held", "done", "starved", "fault"};
  if (view_.have_program)
    std::printf("program: %s %s\n", view_.program.state >= 0 && view_.program.state <= 7 ? kProgram[view_.program.state] : "?",
                view_.program.program_path.empty() ? "(none loaded)" : view_.program.program_path.c_str());
  if (view_.have_interp)
    std::printf("interpolator: %s, feed override %.2f, rapid override %.2f, spindle override %.2f%s, line %d, "
                "single block %s, optional stop %s\n",
                view_.interp.state >= 0 && view_.interp.state <= 5 ? kInterp[view_.interp.state] : "?",
                view_.interp.feed_override, view_.interp.rapid_override, view_.interp.spindle_override,
                view_.interp.spindle_override_enabled ? "" : " (off: M51 P0)", view_.interp.source_line,
                view_.interp.single_block ? "on" : "off", view_.interp.optional_stop ? "on" : "off");
  if (view_.have_interp) {
    std::printf("position:");
    for (int i = 0; i < view_.interp.num_axes && static_cast<size_t>(i) < cfg_.axes.size(); ++i)
      std::printf(" %s %.4f", cfg_.axes[static_cast<size_t>(i)].name.c_str(),
                  displayed(cfg_.axes[static_cast<size_t>(i)], view_.interp.position_mm[static_cast<size_t>(i)]));
    std::printf("\n");
  }
  if (view_.have_program) std::printf("block delete %s\n", view_.program.block_delete ? "on" : "off");
  cnc::service::MachineView machine;
  machine.spindle = view_.have_spindle ? &view_.spindle : nullptr;
  machine.io = view_.have_io ? &view_.io : nullptr;
  machine.axes = view_.have_axes ? &view_.axes : nullptr;
  machine.interp = view_.have_interp ? &view_.interp : nullptr;
  machine.joints = view_.have_joints ? &view_.joints : nullptr;
  std::fputs(cnc::service::machine_status(cfg_, machine).c_str(), stdout);
  std::printf("cnc-ctl %s: %zu services heard in %.1f s\n", cnc::util::version(), view_.heartbeats.size(), now - t0);
  return view_.heartbeats.empty() ? kExitTimeout : 0;
}

int Ctl::disable() { return drive_command(cnc::lcmt_drive_command::DISABLE), 0; }

int Ctl::fault_reset() {
  const bool gantry = std::any_of(cfg_.axes.begin(), cfg_.axes.end(),
                                  [](const cnc::config::AxisConfig& a) { return a.gantry.enabled; });
  if (cfg_.safety.estop_input < 0 && cfg_.safety.hard_limits.empty() && !gantry)
    return drive_command(cnc::lcmt_drive_command::FAULT_RESET), 0;
  // With an E-stop or hard limits the bridge answers: done (fault_reset_done), or
  // refused while the E-stop's input reads 0 or the axes still brake
  // (estop_reset_refused, limit_reset_refused): exit 3 with its text.
  const size_t from = view_.alarms.size();
  drive_command(cnc::lcmt_drive_command::FAULT_RESET);
  std::string why, done;
  wait(std::min(timeout_s_, 5.0), [&] {
    why = bridge_alarm_since(from, "estop_reset_refused");
    if (why.empty()) why = bridge_alarm_since(from, "limit_reset_refused");
    if (why.empty()) why = bridge_alarm_since(from, "skew_reset_refused");
    done = bridge_alarm_since(from, "fault_reset_done");
    return !why.empty() || !done.empty();
  });
  if (!why.empty()) {
    std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
    return kExitRefused;
  }
  if (done.empty()) {
    std::fprintf(stderr, "cnc-ctl: the drive bridge did not answer the FAULT_RESET\n");
    return kExitTimeout;
  }
  std::printf("%s\n", done.c_str());
  return 0;
}

std::string Ctl::bridge_alarm_since(size_t from, const char* code) const {
  for (size_t i = from; i < view_.alarms.size(); ++i)
    if (view_.alarms[i].source == "cnc-drive-bridge" && view_.alarms[i].code == code) return view_.alarms[i].text;
  return "";
}

int Ctl::reset() {
  // 1. The drives: enabled through their profiles' state machines (a drive fault is
  //    reset on the way), unless they are already.
  wait(1.0, [&] { return view_.have_axes && view_.have_interp && view_.have_program; });
  if (!view_.have_axes) {
    std::fprintf(stderr, "cnc-ctl: no AXIS_STATUS from the drive bridge: cannot reset\n");
    return kExitTimeout;
  }
  if (const int rc = enable_drives(std::min(timeout_s_, 30.0)); rc != 0) return rc;
  // 2. RESET: the interpolator takes the position of the drives and leaves FAULT.
  //    Sent again while it says why not yet (the path still braking after a fault).
  const double end = cnc::util::monotonic_s() + std::min(timeout_s_, 30.0);
  auto in_place = [&] {
    if (!view_.have_interp || view_.interp.state == cnc::lcmt_setpoint::FAULT) return false;
    if (view_.have_program && view_.program.state == cnc::lcmt_program_state::FAULT) return false;
    if (view_.interp.num_axes != view_.axes.num_axes) return false;
    for (int i = 0; i < view_.axes.num_axes; ++i)
      if (std::fabs(view_.interp.position_mm[static_cast<size_t>(i)] - view_.axes.actual_mm[static_cast<size_t>(i)]) >
          0.01)
        return false;
    return true;
  };
  size_t alarms_seen = view_.alarms.size();
  bool applied = false;
  while (!applied) {
    if (cnc::util::stop_requested() || cnc::util::monotonic_s() > end) {
      std::fprintf(stderr, "cnc-ctl: the reset did not take effect\n");
      return kExitTimeout;
    }
    if (const std::string why = send_checked(lcmt_program_command::RESET, 0.5); !why.empty()) {
      std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
      return kExitRefused;
    }
    for (; alarms_seen < view_.alarms.size(); ++alarms_seen)
      if (view_.alarms[alarms_seen].code == "reset") applied = true;
  }
  wait(1.0, in_place);
  if (!in_place()) {
    std::fprintf(stderr, "cnc-ctl: after the reset the interpolator does not stand where the drives are\n");
    return kExitFault;
  }
  std::printf("reset: the drives are enabled and the interpolator stands where they are\n");
  return 0;
}

// enable waits until every axis reports ENABLED.
int Ctl::enable() {
  if (const int rc = enable_drives(std::min(timeout_s_, 30.0)); rc != 0) return rc;
  std::printf("drives enabled\n");
  return 0;
}

int Ctl::confirm() {
  wait(0.5, [&] { return view_.have_program; });
  const std::string approach = view_.have_program ? view_.program.approach : "";
  if (const int rc = confirm_approach(); rc != 0) return rc;
  std::printf("approach confirmed: %s\n", approach.c_str());
  return 0;
}

// The switches: sent until the state shows the value, or refused with the reason.
int Ctl::program_switch() {
  const std::string v = args_.option("value");
  if (v != "on" && v != "off" && v != "1" && v != "0") {
    std::fprintf(stderr, "cnc-ctl: --do %s needs --value on or off\n", what_.c_str());
    return cnc::service::kExitBadInput;
  }
  const int8_t on = v == "on" || v == "1" ? 1 : 0;
  const int8_t cmd = what_ == "single-block"    ? lcmt_program_command::SINGLE_BLOCK
                     : what_ == "optional-stop" ? lcmt_program_command::OPTIONAL_STOP
                                                : lcmt_program_command::BLOCK_DELETE;
  wait(0.5, [&] { return view_.have_program && view_.have_interp; });
  auto shown = [&] {
    if (cmd == lcmt_program_command::BLOCK_DELETE) return view_.have_program && view_.program.block_delete == on;
    if (!view_.have_interp) return false;
    return (cmd == lcmt_program_command::SINGLE_BLOCK ? view_.interp.single_block : view_.interp.optional_stop) == on;
  };
  for (int attempt = 0; attempt < 5; ++attempt) {
    cnc::service::OperatorCommand c;
    c.command = cmd;
    c.value = on;
    c.axis = -1;
    c.feed_override = 0;
    sent_seq_ = cnc::service::send_program_command(bus_, cfg_, c);
    if (sent_seq_ < 0) {
      std::fprintf(stderr, "cnc-ctl: %s\n", bus_.last_publish_error());
      return kExitSendFailed;
    }
    // Answered (the server names the command it decided on), then shown in the state.
    if (wait(0.7, [&] { return !refused().empty() || (answered() && shown()); }) && refused().empty()) {
      std::printf("%s %s\n", what_.c_str(), on ? "on" : "off");
      return 0;
    }
    if (!refused().empty()) {
      std::fprintf(stderr, "cnc-ctl: %s\n", refused().c_str());
      return kExitRefused;
    }
  }
  std::fprintf(stderr, "cnc-ctl: --do %s was sent 5 times and the cell does not show it\n", what_.c_str());
  return kExitTimeout;
}

// Plain program commands: sent, and refused at once with the server's reason.
int Ctl::plain() {
  // By value: the pair would bind a reference to the constants, which LCM declares
  // and never defines (an undefined symbol where the sanitizers keep the reference).
  using PC = lcmt_program_command;
  static const std::map<std::string, int8_t> kPlain = {
      {"start", int8_t{PC::START}},       {"hold", int8_t{PC::HOLD}},
      {"resume", int8_t{PC::RESUME}},     {"stop", int8_t{PC::STOP}},
      {"override", int8_t{PC::OVERRIDE}}, {"rapid-override", int8_t{PC::RAPID_OVERRIDE}},
      {"spindle-override", int8_t{PC::SPINDLE_OVERRIDE}}};
  wait(0.5, [&] { return view_.have_program && view_.have_interp; });  // the states first
  const double value = what_ == "override" || what_ == "rapid-override" || what_ == "spindle-override"
                           ? args_.number("value", 1.0)
                           : 1.0;
  // Sent again until the interpolator's state shows its effect (a datagram lost on
  // the way, or the state report that answered it): a hold that was never seen is
  // not reported as done. Each command is idempotent in the state it asks for.
  const int8_t cmd = kPlain.at(what_);
  const int64_t blocks0 = view_.interp.blocks_done, cycle0 = view_.interp.cycle;
  const bool stepping = view_.have_interp && view_.interp.single_block &&
                        (cmd == lcmt_program_command::START || cmd == lcmt_program_command::RESUME);
  // Single block: START and RESUME run one line; done when the path holds again
  // (or the program ended, or stopped).
  auto step_end = [&]() -> int {
    if (!stepping) return 0;
    bool seen_active = false;
    const bool fin = wait(timeout_s_, [&] {
      const int8_t st = view_.interp.state;
      if (view_.interp.cycle <= cycle0) return false;
      if (st == cnc::lcmt_setpoint::RUNNING || st == cnc::lcmt_setpoint::STARVED) seen_active = true;
      if (st == cnc::lcmt_setpoint::HELD || st == cnc::lcmt_setpoint::DONE) return view_.interp.blocks_done != blocks0;
      return st == cnc::lcmt_setpoint::FAULT || (st == cnc::lcmt_setpoint::IDLE && seen_active);
    });
    if (!fin) {
      std::fprintf(stderr, "cnc-ctl: the line did not end within %.0f s\n", timeout_s_);
      return kExitTimeout;
    }
    static const char* const kInterp[] = {"idle", "running", "held", "done", "starved", "fault"};
    const int8_t st = view_.interp.state;
    std::printf("single block: %s %s line %d (%lld blocks done)\n", st >= 0 && st <= 5 ? kInterp[st] : "?",
                st == cnc::lcmt_setpoint::HELD ? "before" : "at", view_.interp.source_line,
                static_cast<long long>(view_.interp.blocks_done));
    return st == cnc::lcmt_setpoint::FAULT ? kExitFault : 0;
  };
  auto effect_seen = [&] {
    if (!view_.have_interp) return false;
    const int8_t st = view_.interp.state;
    const bool active = st == cnc::lcmt_setpoint::RUNNING || st == cnc::lcmt_setpoint::HELD ||
                        st == cnc::lcmt_setpoint::STARVED;
    switch (cmd) {
      case lcmt_program_command::HOLD: return !active || st == cnc::lcmt_setpoint::HELD;
      case lcmt_program_command::RESUME: return st != cnc::lcmt_setpoint::HELD || view_.interp.blocks_done != blocks0;
      case lcmt_program_command::STOP: return !active;
      case lcmt_program_command::OVERRIDE: return std::fabs(view_.interp.feed_override - value) < 1e-9;
      case lcmt_program_command::RAPID_OVERRIDE: return std::fabs(view_.interp.rapid_override - value) < 1e-9;
      case lcmt_program_command::SPINDLE_OVERRIDE: return std::fabs(view_.interp.spindle_override - value) < 1e-9;
      default: return true;  // START: taken once the server answered without a refusal
    }
  };
  for (int attempt = 0; attempt < 5; ++attempt) {
    // The server's answer first: a refusal that comes late (a loaded machine) is still
    // this command's, and the run state alone cannot tell a START that was refused
    // ("running already") from one that was taken.
    send(cmd, "", value);
    wait(attempt == 0 ? 2.0 : 1.0, [&] { return answered() || !refused().empty(); });
    const std::string why = refused();
    if (!why.empty()) {
      // A copy sent again after a lost answer may be refused for what the first did.
      if (attempt > 0 && wait(0.3, effect_seen)) return step_end();
      std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
      return kExitRefused;
    }
    // START is the server's to take; the others act in the interpolator, whose state shows them.
    if (!answered() && cmd == lcmt_program_command::START) continue;  // lost on the way: sent again
    if (wait(0.7, effect_seen)) return step_end();
  }
  std::fprintf(stderr, "cnc-ctl: --do %s was sent 5 times and the interpolator does not show it\n", what_.c_str());
  return kExitTimeout;
}

int Ctl::home_or_jog() {
  wait(1.0, [&] { return view_.have_program && view_.have_interp && view_.have_axes; });
  if (!view_.have_interp) {
    std::fprintf(stderr, "cnc-ctl: no INTERP_STATE: is the interpolator running?\n");
    return kExitTimeout;
  }
  const int axis = axis_arg();
  const size_t alarms0 = view_.alarms.size();
  const int8_t mode = what_ == "home" ? cnc::lcmt_interp_state::MODE_HOME : cnc::lcmt_interp_state::MODE_JOG;
  const double hold_s = std::stod(args_.option("hold", "0"));
  const bool continuous = hold_s > 0;
  if (what_ == "home") {
    send_op(lcmt_program_command::HOME, axis, 0.0, 0.0, 0, "");
  } else {
    if (axis < 0) {
      std::fprintf(stderr, "cnc-ctl: --do jog needs --axis\n");
      return cnc::service::kExitBadInput;
    }
    send_op(lcmt_program_command::JOG, axis, args_.number("value", 0), std::stod(args_.option("feed", "0")),
            continuous ? 1 : 0, "");
  }
  auto op_refused = [&] {
    return !refused().empty() || !alarm_since(alarms0, {"home_refused", "jog_refused"}).empty();
  };
  // Started: the interpolator reports the mode; or refused.
  if (!wait(2.0, [&] {
        // Its own: a jog of this axis (another axis's jog that runs is not this one's start).
        const bool mine =
            what_ == "home" || view_.interp.mode_text.rfind("jog " + cfg_.axes[static_cast<size_t>(axis)].name, 0) == 0;
        return op_refused() || (view_.interp.mode == mode && interp_active() && mine) ||
               !alarm_since(alarms0, {"home_done", "home_aborted"}).empty();
      })) {
    std::fprintf(stderr, "cnc-ctl: the interpolator did not start the %s\n", what_.c_str());
    return kExitTimeout;
  }
  if (op_refused()) {
    const std::string why = !refused().empty() ? refused() : alarm_since(alarms0, {"home_refused", "jog_refused"});
    std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
    return kExitRefused;
  }
  if (continuous) {
    // Held: a keepalive every 50 ms until the hold time is over or a signal releases it.
    const double end = cnc::util::monotonic_s() + hold_s;
    double next = 0;
    while (cnc::util::monotonic_s() < end && !cnc::util::stop_requested() && interp_active()) {
      if (cnc::util::monotonic_s() >= next) {
        send_op(lcmt_program_command::JOG_KEEPALIVE, axis, 0.0, 0.0, 0, "");
        next = cnc::util::monotonic_s() + 0.05;
      }
      if (bus_.handle(10) > 0) bus_.drain();
    }
    send(lcmt_program_command::STOP);
  }
  // Ended: the path stands (homing: home_done or aborted).
  auto ended = [&] { return !interp_active() || view_.interp.state == cnc::lcmt_setpoint::FAULT; };
  const bool fin = what_ == "home" ? wait(timeout_s_, [&] {
    return !alarm_since(alarms0, {"home_done", "home_aborted", "interp_fault"}).empty();
  })
                                   : wait(timeout_s_, ended);
  if (!fin) {
    std::fprintf(stderr, "cnc-ctl: the %s did not end within %.0f s\n", what_.c_str(), timeout_s_);
    return kExitTimeout;
  }
  if (const std::string why = alarm_since(alarms0, {"home_aborted"}); !why.empty()) {
    std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
    return kExitFault;
  }
  if (view_.interp.state == cnc::lcmt_setpoint::FAULT) {
    std::fprintf(stderr, "cnc-ctl: fault: %s\n", alarm_since(alarms0, {"interp_fault"}).c_str());
    return kExitFault;
  }
  wait(0.5, [&] { return !interp_active() && view_.interp.mode == cnc::lcmt_interp_state::MODE_PROGRAM; });
  print_position(what_ == "home" ? "homed" : "jogged");
  if (const std::string lost = alarm_since(alarms0, {"jog_keepalive_lost"}); !lost.empty())
    std::printf("%s\n", lost.c_str());
  return 0;
}

// run, load, mdi and touch-off: the program (or the line's program) loaded, and for
// all but load started, watched to its end and checked where the axes stand.
int Ctl::run() {
  const bool io_cmd = what_ == "coolant" || what_ == "output";
  const bool line_cmd = what_ == "mdi" || what_ == "touch-off" || io_cmd;
  if (what_ == "mdi") mdi_line_ = args_.option("line");
  if (io_cmd) {
    std::string why;
    mdi_line_ = io_line(&why);
    if (mdi_line_.empty()) {
      std::fprintf(stderr, "cnc-ctl: --do %s: %s\n", what_.c_str(), why.c_str());
      return cnc::service::kExitBadInput;
    }
  }
  const std::string program_arg = line_cmd ? std::string("(") + what_ + ")" : args_.option("program");
  if (program_arg.empty()) {
    std::fprintf(stderr, "cnc-ctl: --program FILE is required\n");
    return cnc::service::kExitBadInput;
  }
  // The server may run elsewhere: send the path as given when it is not a local file.
  const std::string program = std::filesystem::exists(program_arg)
                                  ? std::filesystem::absolute(program_arg).lexically_normal().string()
                                  : program_arg;
  if (!services_up()) return kExitTimeout;
  if (const int rc = load(program, line_cmd); rc != 0) return rc;
  const int64_t token = view_.program.program_token;
  std::printf("loaded %s: %lld blocks\n", program.c_str(), static_cast<long long>(view_.program.num_blocks));
  if (view_.program.approach_pending) std::printf("approach %s\n", view_.program.approach.c_str());
  if (what_ == "load") return 0;
  if (const int rc = wait_for_confirm(token); rc != 0) return rc;
  if (const int rc = start(token); rc != 0) return rc;
  const double t0 = cnc::util::monotonic_s();
  if (const int rc = watch_to_end(token); rc != 0) return rc;
  return check_at_end(t0);
}

std::string Ctl::io_line(std::string* why) const {
  const auto& io = cfg_.io;
  const std::string value = args_.option("value");
  if (what_ == "coolant") {
    const bool mist = value == "mist", flood = value == "flood";
    if (!mist && !flood && value != "off") {
      *why = "--value must be flood, mist or off, not '" + value + "'";
      return "";
    }
    if ((mist && io.coolant_mist < 0) || (flood && io.coolant_flood < 0)) {
      *why = "the machine file switches no " + value + " coolant (io.coolant." + value + ")";
      return "";
    }
    return mist ? "M7" : flood ? "M8" : "M9";
  }
  const std::string name = args_.option("point");
  const int p = io.point_index(name);
  auto find = [&](const std::vector<int>& list) {
    const auto it = std::find(list.begin(), list.end(), p);
    return it == list.end() ? -1 : static_cast<int>(it - list.begin());
  };
  if (const int n = p < 0 ? -1 : find(io.digital_outputs); n >= 0) {
    if (value != "on" && value != "off") {
      *why = "--value must be on or off for the digital output " + name + ", not '" + value + "'";
      return "";
    }
    return (value == "on" ? "M64 P" : "M65 P") + std::to_string(n);  // immediate, as from the panel
  }
  if (const int n = p < 0 ? -1 : find(io.analog_outputs); n >= 0) {
    char* end = nullptr;
    const double v = std::strtod(value.c_str(), &end);
    if (value.empty() || *end != '\0' || !std::isfinite(v)) {
      *why = "--value must be a number for the analog output " + name + ", not '" + value + "'";
      return "";
    }
    char line[64];
    std::snprintf(line, sizeof line, "M68 E%d Q%.17g", n, v);
    return line;
  }
  std::string outputs;
  for (const int i : io.digital_outputs) outputs += (outputs.empty() ? "" : ", ") + io.points[static_cast<size_t>(i)].name;
  for (const int i : io.analog_outputs) outputs += (outputs.empty() ? "" : ", ") + io.points[static_cast<size_t>(i)].name;
  *why = "--point '" + name + "' is no output of the machine file (io.digital_outputs, io.analog_outputs: " +
         (outputs.empty() ? std::string("none") : outputs) + ")";
  return "";
}

// The services must be up first.
bool Ctl::services_up() {
  const std::set<std::string> needed = {"cnc-program-server", "cnc-interpolator", "cnc-drive-bridge"};
  auto all_up = [&] {
    for (const auto& s : needed) {
      auto it = view_.heartbeats.find(s);
      if (it == view_.heartbeats.end() || it->second.state != cnc::lcmt_heartbeat::RUNNING) return false;
    }
    return true;
  };
  if (!wait(30, all_up)) {
    std::fprintf(stderr, "cnc-ctl: services not running after 30 s:");
    for (const auto& s : needed)
      if (!view_.heartbeats.count(s)) std::fprintf(stderr, " %s", s.c_str());
    std::fprintf(stderr, "\n");
    return false;
  }
  return true;
}

// The program server's last heartbeat, at most 5 s old, says it validates a load.
bool Ctl::server_validating() const {
  const auto it = view_.heartbeats.find("cnc-program-server");
  return it != view_.heartbeats.end() && it->second.detail.starts_with(cnc::service::kValidatingDetail) &&
         cnc::util::wall_utime() - it->second.utime < 5'000'000;
}

// LOAD; repeated if no answer (a lost datagram), the answer names the path.
int Ctl::load(const std::string& program, bool line_cmd) {
  const int64_t old_token = view_.have_program ? view_.program.program_token : 0;
  // MDI and touch-off: the server writes the line to mdi-SENDER-SEQ.ngc and loads it.
  std::string line_suffix;
  auto answered = [&] {
    if (line_cmd)
      return view_.have_program && view_.program.program_path.ends_with(line_suffix) &&
             (view_.program.state == cnc::lcmt_program_state::REFUSED ||
              (view_.program.state == cnc::lcmt_program_state::LOADED && view_.program.program_token != old_token));
    // Its own LOAD's answer (the server names the command it decided on): a refusal of
    // an earlier LOAD of the same path is not this one's.
    return view_.have_program && view_.program.program_path == program &&
           view_.program.answered_sender == bus_.sender() && view_.program.answered_seq == sent_seq_ &&
           (view_.program.state == cnc::lcmt_program_state::REFUSED ||
            (view_.program.state == cnc::lcmt_program_state::LOADED && view_.program.program_token != old_token));
  };
  bool got = false;
  for (int attempt = 0; attempt < 5 && !got; ++attempt) {
    if (!mdi_line_.empty()) {
      send_op(lcmt_program_command::MDI, -1, 0.0, 0.0, 0, mdi_line_);
    } else if (what_ == "touch-off") {
      const int axis = axis_arg();
      if (axis < 0) {
        std::fprintf(stderr, "cnc-ctl: --do touch-off needs --axis\n");
        return cnc::service::kExitBadInput;
      }
      send_op(lcmt_program_command::TOUCH_OFF, axis, args_.number("value", 0), 0.0, args_.flags.count("tool") ? 2 : 0,
              "");
    } else {
      send(lcmt_program_command::LOAD, program);
    }
    line_suffix = cnc::service::mdi_program_suffix(bus_.sender(), sent_seq_);
    got = wait(2.0, [&] { return answered() || !refused().empty(); });
    // A long program: the server's heartbeat says it validates; waited for, not sent again.
    while (!got && server_validating()) got = wait(2.0, [&] { return answered() || !refused().empty(); });
  }
  if (const std::string why = refused(); !why.empty()) {
    std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
    return kExitRefused;
  }
  if (!got) {
    std::fprintf(stderr, "cnc-ctl: the program server did not answer the load of %s\n", program.c_str());
    return kExitTimeout;
  }
  if (view_.program.state == cnc::lcmt_program_state::REFUSED) {
    std::fprintf(stderr, "cnc-ctl: program refused: %s\n", view_.program.error.c_str());
    return kExitRefused;
  }
  return 0;
}

// Run from a line: nothing moves before the approach is confirmed.
int Ctl::wait_for_confirm(int64_t token) {
  if (!view_.program.approach_pending) return 0;
  if (args_.flags.count("confirm")) {
    if (const int rc = confirm_approach(); rc != 0) return rc;
    std::printf("approach confirmed\n");
    return 0;
  }
  std::printf("waiting for the approach to be confirmed (cnc-ctl --do confirm)\n");
  std::fflush(stdout);
  if (!wait(timeout_s_, [&] { return view_.program.program_token != token || !view_.program.approach_pending; }) ||
      view_.program.program_token != token) {
    std::fprintf(stderr, "cnc-ctl: the approach was not confirmed\n");
    return kExitTimeout;
  }
  return 0;
}

// START once the interpolator has the program; sent again until it runs.
int Ctl::start(int64_t token) {
  if (!wait(5.0, [&] { return view_.have_interp && view_.interp.program_token == token; })) {
    std::fprintf(stderr, "cnc-ctl: the interpolator did not take the program\n");
    return kExitTimeout;
  }
  auto started = [&] {
    return view_.interp.program_token == token && view_.interp.state != 0 /* idle */;
  };
  bool got = false;
  for (int attempt = 0; attempt < 5 && !got; ++attempt) {
    send(lcmt_program_command::START);
    got = wait(1.0, [&] { return started() || !refused().empty(); });
  }
  // A START sent again after one that took effect late is refused because the program
  // runs: the run is the answer, not the refusal (the soak's false exit 3).
  if (!refused().empty()) wait(0.5, started);
  if (started()) return 0;
  if (const std::string why = refused(); !why.empty()) {
    std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
    return kExitRefused;
  }
  if (!got) {
    std::fprintf(stderr, "cnc-ctl: the interpolator did not start\n");
    return kExitTimeout;
  }
  return 0;
}

// The run to its end, or the fault, refusal or lost peer that ended it first.
int Ctl::watch_to_end(int64_t token) {
  auto bridge_fault = [&] {
    if (!view_.have_axes) return false;
    for (int8_t s : view_.axes.drive_state)
      if (s == cnc::lcmt_axis_status::FAULT) return true;
    return false;
  };
  auto block_refused = [&] {
    for (const auto& a : view_.alarms)
      if (a.code == "block_refused") return true;
    return false;
  };
  auto cell_fault = [&] {
    return (view_.interp.program_token == token || view_.interp.program_token == 0) &&
           view_.interp.state == cnc::lcmt_setpoint::FAULT;
  };
  // A peer the run cannot go on without: its heartbeat missing for the cell's
  // heartbeat_timeout_s, or its last one said it stopped. The program server may be
  // away for a while: the interpolator stops at the end of the blocks it has and
  // goes on when the server is back (warned once, bounded by --timeout).
  // The interpolator or the bridge with a new pid restarted within the timeout: what it
  // knew of the run is gone (the program server comes back with its --state).
  std::string lost;
  bool server_warned = false;
  std::map<std::string, int32_t> pid_at_start;
  for (const auto& [name, hb] : view_.heartbeats) pid_at_start[name] = hb.pid;
  auto peer_lost = [&] {
    const double now = cnc::util::monotonic_s();
    for (const char* s : {"cnc-interpolator", "cnc-drive-bridge", "cnc-program-server"}) {
      const auto it = view_.heartbeats.find(s);
      if (it == view_.heartbeats.end()) continue;
      const auto was = pid_at_start.find(s);
      if (std::string(s) != "cnc-program-server" && was != pid_at_start.end() && was->second != it->second.pid) {
        lost = std::string(s) + " restarted during the run (pid " + std::to_string(was->second) + ", now " +
               std::to_string(it->second.pid) + ")";
        return true;
      }
      const double silent = now - view_.heartbeat_s[s];
      const bool stopped = it->second.state == cnc::lcmt_heartbeat::STOPPING;
      if (!stopped && silent <= cfg_.heartbeat_timeout_s) continue;
      char why[256];
      if (stopped) {
        std::snprintf(why, sizeof why, "%s stopped (its last heartbeat said STOPPING)", s);
      } else {
        std::snprintf(why, sizeof why, "%s is lost: no heartbeat for %.1f s (timeout %.1f s)", s, silent,
                      cfg_.heartbeat_timeout_s);
      }
      if (std::string(s) == "cnc-program-server" && !stopped) {
        if (!server_warned) std::fprintf(stderr, "cnc-ctl: %s; waiting for it to come back\n", why);
        server_warned = true;
        continue;
      }
      lost = why;
      return true;
    }
    return false;
  };
  // Stopped (STOP from anywhere: another cnc-ctl, the page): the run ends there.
  auto stopped = [&] {
    return view_.have_program && view_.program.program_token == token &&
           view_.program.state == cnc::lcmt_program_state::STOPPED;
  };
  // Withdrawn by the program server while it ran (its rest invalid after a probe result or
  // an M66 value, or its file changed): REFUSED with this token; the interpolator stops it.
  auto withdrawn = [&] {
    return view_.have_program && view_.program.program_token == token &&
           view_.program.state == cnc::lcmt_program_state::REFUSED;
  };
  // The program server came back without the program (no --state): the interpolator stops it.
  auto program_lost = [&]() -> std::string {
    for (const auto& a : view_.alarms)
      if (a.source == "cnc-interpolator" && a.code == "program_lost") return a.text;
    return "";
  };
  const bool done = wait(timeout_s_, [&] {
    return bridge_fault() || block_refused() || cell_fault() || peer_lost() || stopped() || withdrawn() ||
           !program_lost().empty() ||
           (view_.interp.program_token == token && view_.interp.state == 3 /* done */);
  });
  if (withdrawn()) {
    std::fprintf(stderr, "cnc-ctl: the program was withdrawn while it ran: %s\n", view_.program.error.c_str());
    return kExitRefused;
  }
  if (const std::string why = program_lost(); !why.empty()) {
    std::fprintf(stderr, "cnc-ctl: the program stopped: %s\n", why.c_str());
    return kExitFault;
  }
  if (block_refused()) {
    std::fprintf(stderr, "cnc-ctl: the interpolator refused a block; the program was stopped\n");
    return kExitRefused;
  }
  if (cell_fault() && !bridge_fault()) {
    std::string why = "the interpolator is in FAULT";
    for (const auto& a : view_.alarms)
      if (a.source == "cnc-interpolator" && a.code == "interp_fault") why = a.text;
    std::fprintf(stderr, "cnc-ctl: fault: %s\n", why.c_str());
    return kExitFault;
  }
  if (bridge_fault()) {
    // Every axis's reason (the first axis's alone was empty when another axis faulted).
    std::string why;
    for (size_t i = 0; i < view_.axes.fault.size() && i < view_.axes.axis_name.size(); ++i) {
      if (view_.axes.fault[i].empty() || why.find(view_.axes.fault[i]) != std::string::npos) continue;
      why += (why.empty() ? "" : "; ") + view_.axes.axis_name[i] + ": " + view_.axes.fault[i];
    }
    std::fprintf(stderr, "cnc-ctl: drive fault: %s\n", why.empty() ? "(the drive bridge gave no reason)" : why.c_str());
    return kExitFault;
  }
  if (!lost.empty()) {
    std::fprintf(stderr, "cnc-ctl: the program did not reach its end: %s\n", lost.c_str());
    return kExitFault;
  }
  if (stopped() && !(view_.interp.program_token == token && view_.interp.state == 3)) {
    std::fprintf(stderr, "cnc-ctl: the program was stopped (STOP) before its end\n");
    return kExitStopped;
  }
  if (!done) {
    std::fprintf(stderr, "cnc-ctl: program did not finish within %.0f s\n", timeout_s_);
    return kExitTimeout;
  }
  return 0;
}

// Done means the axes are at the program's end: the bridge still reports, and
// every axis stands within 0.01 mm of where the interpolator ended.
int Ctl::check_at_end(double t0) {
  // The interpolator's position is in machine coordinates, the bridge's in the drives'
  // (they differ by each homed axis's offset): the end is judged on the bridge's side.
  // The bridge plays the stream back a few cycles late; once its playback has passed
  // the cycle at which the interpolator reported the end, its command stands on the
  // end point, and the following error is the distance from it.
  const int64_t end_cycle = view_.interp.cycle;
  auto fresh = [&] { return view_.have_axes && cnc::util::monotonic_s() - view_.axes_s <= 0.5; };
  auto largest_fe = [&] {
    double worst = 0;
    for (double fe : view_.axes.following_error_mm) worst = std::max(worst, std::fabs(fe));
    return worst;
  };
  auto played = [&] { return fresh() && view_.axes.playback_cycle >= static_cast<double>(end_cycle); };
  // Settled: within 0.1 um of the end, for at most 3 s.
  const bool is_settled = wait(3.0, [&] { return played() && largest_fe() <= 1e-4; });
  if (!wait(1.0, [&] { return played() && largest_fe() <= 0.01; })) {
    if (!fresh()) {
      std::fprintf(stderr, "cnc-ctl: the interpolator ended the program, but the drive bridge reports nothing "
                           "(no AXIS_STATUS for 0.5 s): the axes did not follow it to its end\n");
    } else if (!played()) {
      std::fprintf(stderr, "cnc-ctl: the interpolator ended the program at cycle %lld, but the drive bridge plays "
                           "cycle %.1f: the axes did not follow it to its end\n",
                   static_cast<long long>(end_cycle), view_.axes.playback_cycle);
    } else {
      std::fprintf(stderr, "cnc-ctl: the interpolator ended the program, but the axes stand away from its end:");
      for (int i = 0; i < view_.axes.num_axes; ++i)
        std::fprintf(stderr, " %s %.4f mm", view_.axes.axis_name[static_cast<size_t>(i)].c_str(),
                     view_.axes.following_error_mm[static_cast<size_t>(i)]);
      std::fprintf(stderr, "\n");
    }
    return kExitFault;
  }
  char unsettled[96] = "";
  if (!is_settled) std::snprintf(unsettled, sizeof unsettled, ", axes not settled within 3 s (%.2f um from the end)", 1e3 * largest_fe());
  std::printf("program done: %.3f s program time (%.1f s wall), %lld blocks, largest following error %.4f mm (%s)%s\n",
              view_.interp.program_time_s, cnc::util::monotonic_s() - t0,
              static_cast<long long>(view_.interp.blocks_done), largest_fe_, largest_fe_axis_.c_str(), unsettled);
  return 0;
}

// The --do verbs.
struct Verb {
  const char* name;
  int (Ctl::*run)();
};
// In the order the usage names them.
constexpr Verb kVerbs[] = {
    {"run", &Ctl::run},
    {"load", &Ctl::run},
    {"start", &Ctl::plain},
    {"hold", &Ctl::plain},
    {"resume", &Ctl::plain},
    {"stop", &Ctl::plain},
    {"override", &Ctl::plain},
    {"rapid-override", &Ctl::plain},
    {"spindle-override", &Ctl::plain},
    {"reset", &Ctl::reset},
    {"enable", &Ctl::enable},
    {"disable", &Ctl::disable},
    {"fault-reset", &Ctl::fault_reset},
    {"home", &Ctl::home_or_jog},
    {"jog", &Ctl::home_or_jog},
    {"touch-off", &Ctl::run},
    {"mdi", &Ctl::run},
    {"coolant", &Ctl::run},
    {"output", &Ctl::run},
    {"status", &Ctl::status},
    {"single-block", &Ctl::program_switch},
    {"optional-stop", &Ctl::program_switch},
    {"block-delete", &Ctl::program_switch},
    {"confirm", &Ctl::confirm},
};

int Ctl::run_verb() {
  for (const Verb& v : kVerbs)
    if (what_ == v.name) return (this->*v.run)();
  std::string names;
  for (const Verb& v : kVerbs) names += std::string(names.empty() ? "" : " ") + v.name;
  std::fprintf(stderr, "cnc-ctl: --do must be one of %s\n", names.c_str());
  return cnc::service::kExitBadInput;
}

}  // namespace cnc::ctl
