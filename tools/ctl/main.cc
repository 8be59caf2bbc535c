// cnc-ctl: operator commands to a running cell, and `--do run`, which loads a
// program, starts it, waits for its end and for the axes to settle.
//
//   cnc-ctl --machine M --do run --program P [--timeout S]
//   cnc-ctl --machine M --do load --program P | start | hold | resume | stop | override --value 0.8
//   cnc-ctl --machine M --do rapid-override --value 0.25    G0 at a quarter of its speed (0 .. 1)
//   cnc-ctl --machine M --do enable [--timeout S] | disable | fault-reset    (drive bridge, DRIVE_CMD)
//   cnc-ctl --machine M --do reset [--timeout S]   after a fault: enable the drives (DRIVE_CMD), then
//                                                  RESET (the interpolator takes their position)
//   cnc-ctl --machine M --do home [--axis X]       home one axis, or all in the configured order
//   cnc-ctl --machine M --do jog --axis X --value D [--feed F]          incremental jog by D mm
//   cnc-ctl --machine M --do jog --axis X --value +1|-1 --hold S [--feed F]
//                                                  continuous jog, held for S s (a keepalive every
//                                                  50 ms; SIGINT/SIGTERM releases it), then STOP
//   cnc-ctl --machine M --do touch-off --axis X --value V   G10 L20 P0 (--tool: G10 L10, the length of the tool in the spindle)
//   cnc-ctl --machine M --do mdi --line "G0 X10"   one line through the program server's interpreter
//   cnc-ctl --machine M --do status [--timeout S]  the cell's services (host, pid, version, state)
//   cnc-ctl --machine M --do run|load --program P --from N [--confirm]
//                                                  run from line N: the approach is printed; run waits
//                                                  for a CONFIRM (--confirm: its own, or --do confirm)
//   cnc-ctl --machine M --do confirm               accept the approach of a program loaded from a line
//   cnc-ctl --machine M --do single-block|optional-stop|block-delete --value on|off
//                                                  the switches (at the next block boundary; block
//                                                  delete at the next load). With single block on,
//                                                  start and resume run one line and wait until the
//                                                  path holds again (or the program ends)
//
// A command the cell refuses in its state (LOAD or START while a program runs, ...)
// ends cnc-ctl at once with the reason from PROGRAM_STATE and exit 3.
// Exit codes: 0 done; 1 the command could not be sent; 2 bad flags or config;
// 3 program or command refused; 4 timeout; 5 fault.
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_drive_command.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/bus/bus.h"
#include "common/service/operator_commands.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/install.h"
#include "common/util/signals.h"

namespace ch = cnc::config::channels;
using cnc::lcmt_program_command;

namespace {

constexpr int kExitSendFailed = 1;
constexpr int kExitRefused = 3;
constexpr int kExitTimeout = 4;
constexpr int kExitFault = 5;

struct CellView {
  std::map<std::string, cnc::lcmt_heartbeat> heartbeats;
  std::map<std::string, double> heartbeat_s;  // monotonic time each service's last heartbeat arrived
  double axes_s = -1e9;                       // ... and the last AXIS_STATUS
  cnc::lcmt_program_state program{};
  bool have_program = false;
  cnc::lcmt_interp_state interp{};
  bool have_interp = false;
  cnc::lcmt_axis_status axes{};
  bool have_axes = false;
  std::vector<cnc::lcmt_alarm> alarms;
};

// Runs the bus until `done()` or the deadline; false on timeout or stop signal.
template <class Pred>
bool wait_for(cnc::bus::Bus& bus, double timeout_s, Pred done) {
  const double end = cnc::util::monotonic_s() + timeout_s;
  while (!done()) {
    if (cnc::util::stop_requested() || cnc::util::monotonic_s() > end) return false;
    // Everything queued before the predicate looks again: after a stall of this
    // process, the heartbeats waiting in the queue are news, not a silence.
    if (bus.handle(10) > 0) bus.drain();
  }
  return true;
}

int run_ctl(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
  const std::string what = args.option("do", "run");
  const double timeout_s = std::stod(args.option("timeout", "600"));
  cnc::bus::Bus bus(cfg.lcm_url, 0, 1000, cnc::service::bus_security(cfg, "cnc-ctl"));
  CellView view;
  bus.subscribe<cnc::lcmt_heartbeat>(cfg.channel(ch::kHeartbeat),
                                     [&](const auto& m) {
                                       view.heartbeats[m.service] = m;
                                       view.heartbeat_s[m.service] = cnc::util::monotonic_s();
                                     });
  bus.subscribe<cnc::lcmt_program_state>(cfg.channel(ch::kProgramState), [&](const auto& m) {
    view.program = m;
    view.have_program = true;
  });
  bus.subscribe<cnc::lcmt_interp_state>(cfg.channel(ch::kInterpState), [&](const auto& m) {
    view.interp = m;
    view.have_interp = true;
  });
  double largest_fe = 0;
  std::string largest_fe_axis;
  bus.subscribe<cnc::lcmt_axis_status>(cfg.channel(ch::kAxisStatus), [&](const auto& m) {
    view.axes = m;
    view.have_axes = true;
    view.axes_s = cnc::util::monotonic_s();
    for (int i = 0; i < m.num_axes; ++i) {
      if (std::fabs(m.following_error_mm[i]) > largest_fe) {
        largest_fe = std::fabs(m.following_error_mm[i]);
        largest_fe_axis = m.axis_name[i];
      }
    }
  });
  bus.subscribe<cnc::lcmt_alarm>(cfg.channel(ch::kAlarm), [&](const auto& m) {
    view.alarms.push_back(m);
    std::fprintf(stderr, "ALARM %s [%s] %s\n", m.source.c_str(), m.code.c_str(), m.text.c_str());
  });

  // status: every service heard on HEARTBEAT within a listening window (two heartbeat
  // timeouts, or --timeout): its host, pid, version, state and the time since it was
  // last heard; then the program's and the interpolator's state. Exit 4 when none was heard.
  if (what == "status") {
    const double listen_s = args.options.count("timeout") ? timeout_s : 2 * cfg.heartbeat_timeout_s;
    const double t0 = cnc::util::monotonic_s();
    wait_for(bus, listen_s, [] { return false; });
    if (cnc::util::stop_requested()) return cnc::service::kExitFailure;
    const double now = cnc::util::monotonic_s();
    static const char* const kStates[] = {"starting", "running", "stopping", "fault"};
    std::printf("%-20s %-16s %8s  %-26s %-9s %s\n", "service", "host", "pid", "version", "state", "last heard");
    for (const auto& [name, hb] : view.heartbeats) {
      const char* state = hb.state >= 0 && hb.state <= 3 ? kStates[hb.state] : "?";
      std::printf("%-20s %-16s %8d  %-26s %-9s %.2f s ago\n", name.c_str(), hb.host.empty() ? "?" : hb.host.c_str(),
                  hb.pid, hb.version.empty() ? "?" : hb.version.c_str(), state, now - view.heartbeat_s[name]);
    }
    static const char* const kProgram[] = {"idle", "loaded", "running", "held", "done", "refused", "stopped", "fault"};
    static const char* const kInterp[] = {"idle", "running", "held", "done", "starved", "fault"};
    if (view.have_program)
      std::printf("program: %s %s\n", view.program.state >= 0 && view.program.state <= 7 ? kProgram[view.program.state] : "?",
                  view.program.program_path.empty() ? "(none loaded)" : view.program.program_path.c_str());
    if (view.have_interp)
      std::printf("interpolator: %s, feed override %.2f, rapid override %.2f, line %d, single block %s, optional stop %s\n",
                  view.interp.state >= 0 && view.interp.state <= 5 ? kInterp[view.interp.state] : "?",
                  view.interp.feed_override, view.interp.rapid_override, view.interp.source_line, view.interp.single_block ? "on" : "off",
                  view.interp.optional_stop ? "on" : "off");
    if (view.have_interp) {
      std::printf("position:");
      for (int i = 0; i < view.interp.num_axes && static_cast<size_t>(i) < cfg.axes.size(); ++i)
        std::printf(" %s %.4f", cfg.axes[static_cast<size_t>(i)].name.c_str(), view.interp.position_mm[static_cast<size_t>(i)]);
      std::printf("\n");
    }
    if (view.have_program) std::printf("block delete %s\n", view.program.block_delete ? "on" : "off");
    std::printf("cnc-ctl %s: %zu services heard in %.1f s\n", cnc::util::version(), view.heartbeats.size(), now - t0);
    return view.heartbeats.empty() ? kExitTimeout : 0;
  }

  // The seq of the last program command sent: the server names it when it refuses it.
  int64_t sent_seq = -1;
  const int from_line = std::stoi(args.option("from", "0"));
  auto send = [&](int8_t command, const std::string& path = "", double value = 1.0) {
    cnc::service::OperatorCommand c;
    c.command = command;
    c.program_path = path;
    c.feed_override = value;
    if (command == lcmt_program_command::LOAD) c.from_line = from_line;
    sent_seq = cnc::service::send_program_command(bus, cfg, c);
    if (sent_seq < 0) {
      std::fprintf(stderr, "cnc-ctl: %s\n", bus.last_publish_error());
      std::exit(kExitSendFailed);
    }
  };
  // The refusal of the last command sent, "" while none came.
  auto refused = [&]() -> std::string {
    if (!view.have_program) return "";
    return cnc::service::refusal_of(view.program, bus.sender(), sent_seq);
  };
  // Sends a program command and waits up to `wait_s` for its refusal: "" when none came.
  auto send_checked = [&](int8_t command, double wait_s, const std::string& path = "", double value = 1.0) {
    send(command, path, value);
    wait_for(bus, wait_s, [&] { return !refused().empty(); });
    return refused();
  };

  // Drive bridge commands. `enable` waits until every axis reports ENABLED.
  auto drive_command = [&](int8_t command) {
    if (!cnc::service::send_drive_command(bus, cfg, command)) {
      std::fprintf(stderr, "cnc-ctl: %s\n", bus.last_publish_error());
      std::exit(kExitSendFailed);
    }
  };
  auto all_in = [&](int8_t state) {
    if (!view.have_axes || view.axes.num_axes == 0) return false;
    for (int8_t s : view.axes.drive_state)
      if (s != state) return false;
    return true;
  };
  // ENABLE until every axis reports ENABLED: 0, or an exit code.
  auto enable_drives = [&](double limit_s) {
    const double end = cnc::util::monotonic_s() + limit_s;
    double next_send = 0;
    while (!all_in(cnc::lcmt_axis_status::ENABLED)) {
      if (cnc::util::stop_requested() || cnc::util::monotonic_s() > end) {
        std::fprintf(stderr, "cnc-ctl: the drives did not enable: %s\n",
                     view.have_axes && !view.axes.fault.empty() ? view.axes.fault[0].c_str() : "no axis status");
        return view.have_axes ? kExitFault : kExitTimeout;
      }
      // Sent again every second while not enabled: a lost datagram only delays.
      if (cnc::util::monotonic_s() >= next_send) {
        drive_command(cnc::lcmt_drive_command::ENABLE);
        next_send = cnc::util::monotonic_s() + 1.0;
      }
      bus.handle(10);
    }
    return 0;
  };
  if (what == "disable") return drive_command(cnc::lcmt_drive_command::DISABLE), 0;
  if (what == "fault-reset") return drive_command(cnc::lcmt_drive_command::FAULT_RESET), 0;
  if (what == "reset") {
    // 1. The drives: enabled through their profiles' state machines (a drive fault is
    //    reset on the way), unless they are already.
    wait_for(bus, 1.0, [&] { return view.have_axes && view.have_interp && view.have_program; });
    if (!view.have_axes) {
      std::fprintf(stderr, "cnc-ctl: no AXIS_STATUS from the drive bridge: cannot reset\n");
      return kExitTimeout;
    }
    if (const int rc = enable_drives(std::min(timeout_s, 30.0)); rc != 0) return rc;
    // 2. RESET: the interpolator takes the position of the drives and leaves FAULT.
    //    Sent again while it says why not yet (the path still braking after a fault).
    const double end = cnc::util::monotonic_s() + std::min(timeout_s, 30.0);
    auto in_place = [&] {
      if (!view.have_interp || view.interp.state == cnc::lcmt_setpoint::FAULT) return false;
      if (view.have_program && view.program.state == cnc::lcmt_program_state::FAULT) return false;
      if (view.interp.num_axes != view.axes.num_axes) return false;
      for (int i = 0; i < view.axes.num_axes; ++i)
        if (std::fabs(view.interp.position_mm[static_cast<size_t>(i)] - view.axes.actual_mm[static_cast<size_t>(i)]) >
            0.01)
          return false;
      return true;
    };
    size_t alarms_seen = view.alarms.size();
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
      for (; alarms_seen < view.alarms.size(); ++alarms_seen)
        if (view.alarms[alarms_seen].code == "reset") applied = true;
    }
    wait_for(bus, 1.0, in_place);
    if (!in_place()) {
      std::fprintf(stderr, "cnc-ctl: after the reset the interpolator does not stand where the drives are\n");
      return kExitFault;
    }
    std::printf("reset: the drives are enabled and the interpolator stands where they are\n");
    return 0;
  }
  if (what == "enable") {
    if (const int rc = enable_drives(std::min(timeout_s, 30.0)); rc != 0) return rc;
    std::printf("drives enabled\n");
    return 0;
  }
  // CONFIRM: the approach of a program loaded from a line; done when no approach waits.
  auto confirm = [&]() -> int {
    for (int attempt = 0; attempt < 5; ++attempt) {
      if (const std::string why = send_checked(lcmt_program_command::CONFIRM, 0.3); !why.empty()) {
        if (attempt > 0 && view.have_program && !view.program.approach_pending) return 0;  // a copy after a lost answer
        std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
        return kExitRefused;
      }
      if (wait_for(bus, 0.7, [&] { return view.have_program && !view.program.approach_pending; })) return 0;
    }
    std::fprintf(stderr, "cnc-ctl: CONFIRM was sent 5 times and the program server does not show it\n");
    return kExitTimeout;
  };
  if (what == "confirm") {
    wait_for(bus, 0.5, [&] { return view.have_program; });
    const std::string approach = view.have_program ? view.program.approach : "";
    if (const int rc = confirm(); rc != 0) return rc;
    std::printf("approach confirmed: %s\n", approach.c_str());
    return 0;
  }
  // The switches: sent until the state shows the value, or refused with the reason.
  if (what == "single-block" || what == "optional-stop" || what == "block-delete") {
    const std::string v = args.option("value");
    if (v != "on" && v != "off" && v != "1" && v != "0") {
      std::fprintf(stderr, "cnc-ctl: --do %s needs --value on or off\n", what.c_str());
      return cnc::service::kExitBadInput;
    }
    const int8_t on = v == "on" || v == "1" ? 1 : 0;
    const int8_t cmd = what == "single-block"    ? lcmt_program_command::SINGLE_BLOCK
                       : what == "optional-stop" ? lcmt_program_command::OPTIONAL_STOP
                                                 : lcmt_program_command::BLOCK_DELETE;
    wait_for(bus, 0.5, [&] { return view.have_program && view.have_interp; });
    auto shown = [&] {
      if (cmd == lcmt_program_command::BLOCK_DELETE) return view.have_program && view.program.block_delete == on;
      if (!view.have_interp) return false;
      return (cmd == lcmt_program_command::SINGLE_BLOCK ? view.interp.single_block : view.interp.optional_stop) == on;
    };
    for (int attempt = 0; attempt < 5; ++attempt) {
      cnc::service::OperatorCommand c;
      c.command = cmd;
      c.value = on;
      c.axis = -1;
      c.feed_override = 0;
      sent_seq = cnc::service::send_program_command(bus, cfg, c);
      if (sent_seq < 0) {
        std::fprintf(stderr, "cnc-ctl: %s\n", bus.last_publish_error());
        return kExitSendFailed;
      }
      // Answered (the server names the command it decided on), then shown in the state.
      auto answered = [&] {
        return view.have_program && view.program.answered_sender == bus.sender() && view.program.answered_seq == sent_seq;
      };
      if (wait_for(bus, 0.7, [&] { return !refused().empty() || (answered() && shown()); }) && refused().empty()) {
        std::printf("%s %s\n", what.c_str(), on ? "on" : "off");
        return 0;
      }
      if (!refused().empty()) {
        std::fprintf(stderr, "cnc-ctl: %s\n", refused().c_str());
        return kExitRefused;
      }
    }
    std::fprintf(stderr, "cnc-ctl: --do %s was sent 5 times and the cell does not show it\n", what.c_str());
    return kExitTimeout;
  }
  // Plain program commands: sent, and refused at once with the server's reason.
  const std::map<std::string, int8_t> plain = {{"start", lcmt_program_command::START},
                                               {"hold", lcmt_program_command::HOLD},
                                               {"resume", lcmt_program_command::RESUME},
                                               {"stop", lcmt_program_command::STOP},
                                               {"override", lcmt_program_command::OVERRIDE},
                                               {"rapid-override", lcmt_program_command::RAPID_OVERRIDE}};
  if (auto it = plain.find(what); it != plain.end()) {
    wait_for(bus, 0.5, [&] { return view.have_program && view.have_interp; });  // the states first
    const double value = what == "override" || what == "rapid-override" ? args.number("value", 1.0) : 1.0;
    // Sent again until the interpolator's state shows its effect (a datagram lost on
    // the way, or the state report that answered it): a hold that was never seen is
    // not reported as done. Each command is idempotent in the state it asks for.
    const int8_t cmd = it->second;
    const int64_t blocks0 = view.interp.blocks_done, cycle0 = view.interp.cycle;
    const bool stepping = view.have_interp && view.interp.single_block &&
                          (cmd == lcmt_program_command::START || cmd == lcmt_program_command::RESUME);
    // Single block: START and RESUME run one line; done when the path holds again
    // (or the program ended, or stopped).
    auto step_end = [&]() -> int {
      if (!stepping) return 0;
      bool seen_active = false;
      const bool fin = wait_for(bus, timeout_s, [&] {
        const int8_t st = view.interp.state;
        if (view.interp.cycle <= cycle0) return false;
        if (st == cnc::lcmt_setpoint::RUNNING || st == cnc::lcmt_setpoint::STARVED) seen_active = true;
        if (st == cnc::lcmt_setpoint::HELD || st == cnc::lcmt_setpoint::DONE) return view.interp.blocks_done != blocks0;
        return st == cnc::lcmt_setpoint::FAULT || (st == cnc::lcmt_setpoint::IDLE && seen_active);
      });
      if (!fin) {
        std::fprintf(stderr, "cnc-ctl: the line did not end within %.0f s\n", timeout_s);
        return kExitTimeout;
      }
      static const char* const kInterp[] = {"idle", "running", "held", "done", "starved", "fault"};
      const int8_t st = view.interp.state;
      std::printf("single block: %s %s line %d (%lld blocks done)\n", st >= 0 && st <= 5 ? kInterp[st] : "?",
                  st == cnc::lcmt_setpoint::HELD ? "before" : "at", view.interp.source_line,
                  static_cast<long long>(view.interp.blocks_done));
      return st == cnc::lcmt_setpoint::FAULT ? kExitFault : 0;
    };
    auto effect_seen = [&] {
      if (!view.have_interp) return false;
      const int8_t st = view.interp.state;
      const bool active = st == cnc::lcmt_setpoint::RUNNING || st == cnc::lcmt_setpoint::HELD ||
                          st == cnc::lcmt_setpoint::STARVED;
      switch (cmd) {
        case lcmt_program_command::HOLD: return !active || st == cnc::lcmt_setpoint::HELD;
        case lcmt_program_command::RESUME: return st != cnc::lcmt_setpoint::HELD || view.interp.blocks_done != blocks0;
        case lcmt_program_command::STOP: return !active;
        case lcmt_program_command::OVERRIDE: return std::fabs(view.interp.feed_override - value) < 1e-9;
        case lcmt_program_command::RAPID_OVERRIDE: return std::fabs(view.interp.rapid_override - value) < 1e-9;
        default: return true;  // START: answered by a refusal or by the run state
      }
    };
    for (int attempt = 0; attempt < 5; ++attempt) {
      const std::string why = send_checked(cmd, attempt == 0 ? 0.5 : 0.3, "", value);
      if (!why.empty()) {
        // A copy sent again after a lost answer may be refused for what the first did.
        if (attempt > 0 && wait_for(bus, 0.3, effect_seen)) return step_end();
        std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
        return kExitRefused;
      }
      if (wait_for(bus, 0.7, effect_seen)) return step_end();
    }
    std::fprintf(stderr, "cnc-ctl: --do %s was sent 5 times and the interpolator does not show it\n", what.c_str());
    return kExitTimeout;
  }
  // The axis named by --axis (-1: none given).
  auto axis_arg = [&]() -> int {
    const std::string name = args.option("axis");
    if (name.empty()) return -1;
    const int a = cfg.axis_index(name);
    if (a < 0) {
      std::fprintf(stderr, "cnc-ctl: --axis %s: the machine has no such axis\n", name.c_str());
      std::exit(cnc::service::kExitBadInput);
    }
    return a;
  };
  // An operator command with its fields; refused at once with the server's reason.
  auto send_op = [&](int8_t command, int axis, double value, double feed, int8_t flag, const std::string& text) {
    cnc::service::OperatorCommand c;
    c.command = command;
    c.axis = axis;
    c.value = value;
    c.feed_mm_per_min = feed;
    c.jog_continuous = flag;
    c.text = text;
    c.feed_override = 0;
    sent_seq = cnc::service::send_program_command(bus, cfg, c);
    if (sent_seq < 0) {
      std::fprintf(stderr, "cnc-ctl: %s\n", bus.last_publish_error());
      std::exit(kExitSendFailed);
    }
  };
  auto interp_active = [&] {
    const int8_t st = view.interp.state;
    return st == cnc::lcmt_setpoint::RUNNING || st == cnc::lcmt_setpoint::HELD || st == cnc::lcmt_setpoint::STARVED;
  };
  // An alarm from the interpolator with one of these codes since index `from`: its text.
  auto alarm_since = [&](size_t from, std::initializer_list<const char*> codes) -> std::string {
    for (size_t i = from; i < view.alarms.size(); ++i)
      for (const char* c : codes)
        if (view.alarms[i].source == "cnc-interpolator" && view.alarms[i].code == c) return view.alarms[i].text;
    return "";
  };
  auto print_position = [&](const char* what_done) {
    std::printf("%s:", what_done);
    for (int i = 0; i < view.interp.num_axes; ++i)
      std::printf(" %s %.4f%s", cfg.axes[static_cast<size_t>(i)].name.c_str(),
                  view.interp.position_mm[static_cast<size_t>(i)],
                  static_cast<size_t>(i) < view.interp.homed.size() && view.interp.homed[static_cast<size_t>(i)]
                      ? " (homed)"
                      : "");
    std::printf("\n");
  };
  if (what == "home" || what == "jog") {
    wait_for(bus, 1.0, [&] { return view.have_program && view.have_interp && view.have_axes; });
    if (!view.have_interp) {
      std::fprintf(stderr, "cnc-ctl: no INTERP_STATE: is the interpolator running?\n");
      return kExitTimeout;
    }
    const int axis = axis_arg();
    const size_t alarms0 = view.alarms.size();
    const int8_t mode = what == "home" ? cnc::lcmt_interp_state::MODE_HOME : cnc::lcmt_interp_state::MODE_JOG;
    const double hold_s = std::stod(args.option("hold", "0"));
    const bool continuous = hold_s > 0;
    if (what == "home") {
      send_op(lcmt_program_command::HOME, axis, 0.0, 0.0, 0, "");
    } else {
      if (axis < 0) {
        std::fprintf(stderr, "cnc-ctl: --do jog needs --axis\n");
        return cnc::service::kExitBadInput;
      }
      send_op(lcmt_program_command::JOG, axis, args.number("value", 0),
              std::stod(args.option("feed", "0")), continuous ? 1 : 0, "");
    }
    auto op_refused = [&] {
      return !refused().empty() || !alarm_since(alarms0, {"home_refused", "jog_refused"}).empty();
    };
    // Started: the interpolator reports the mode; or refused.
    if (!wait_for(bus, 2.0, [&] {
          // Its own: a jog of this axis (another axis's jog that runs is not this one's start).
          const bool mine = what == "home" || view.interp.mode_text.rfind("jog " + cfg.axes[static_cast<size_t>(axis)].name, 0) == 0;
          return op_refused() || (view.interp.mode == mode && interp_active() && mine) ||
                 !alarm_since(alarms0, {"home_done", "home_aborted"}).empty();
        })) {
      std::fprintf(stderr, "cnc-ctl: the interpolator did not start the %s\n", what.c_str());
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
        if (bus.handle(10) > 0) bus.drain();
      }
      send(lcmt_program_command::STOP);
    }
    // Ended: the path stands (homing: home_done or aborted).
    auto ended = [&] { return !interp_active() || view.interp.state == cnc::lcmt_setpoint::FAULT; };
    const bool fin = what == "home" ? wait_for(bus, timeout_s, [&] {
      return !alarm_since(alarms0, {"home_done", "home_aborted", "interp_fault"}).empty();
    })
                                    : wait_for(bus, timeout_s, ended);
    if (!fin) {
      std::fprintf(stderr, "cnc-ctl: the %s did not end within %.0f s\n", what.c_str(), timeout_s);
      return kExitTimeout;
    }
    if (const std::string why = alarm_since(alarms0, {"home_aborted"}); !why.empty()) {
      std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
      return kExitFault;
    }
    if (view.interp.state == cnc::lcmt_setpoint::FAULT) {
      std::fprintf(stderr, "cnc-ctl: fault: %s\n", alarm_since(alarms0, {"interp_fault"}).c_str());
      return kExitFault;
    }
    wait_for(bus, 0.5, [&] { return !interp_active() && view.interp.mode == cnc::lcmt_interp_state::MODE_PROGRAM; });
    print_position(what == "home" ? "homed" : "jogged");
    if (const std::string lost = alarm_since(alarms0, {"jog_keepalive_lost"}); !lost.empty())
      std::printf("%s\n", lost.c_str());
    return 0;
  }
  const bool line_cmd = what == "mdi" || what == "touch-off";
  if (what != "run" && what != "load" && !line_cmd) {
    std::fprintf(stderr, "cnc-ctl: --do must be one of run load start hold resume stop override rapid-override reset enable "
                         "disable fault-reset home jog touch-off mdi status single-block optional-stop block-delete confirm\n");
    return cnc::service::kExitBadInput;
  }
  const std::string program_arg = line_cmd ? std::string("(") + what + ")" : args.option("program");
  if (program_arg.empty()) {
    std::fprintf(stderr, "cnc-ctl: --program FILE is required\n");
    return cnc::service::kExitBadInput;
  }
  // The server may run elsewhere: send the path as given when it is not a local file.
  const std::string program = std::filesystem::exists(program_arg)
                                  ? std::filesystem::absolute(program_arg).lexically_normal().string()
                                  : program_arg;

  // The services must be up first.
  const std::set<std::string> needed = {"cnc-program-server", "cnc-interpolator", "cnc-drive-bridge"};
  auto all_up = [&] {
    for (const auto& s : needed) {
      auto it = view.heartbeats.find(s);
      if (it == view.heartbeats.end() || it->second.state != cnc::lcmt_heartbeat::RUNNING) return false;
    }
    return true;
  };
  if (!wait_for(bus, 30, all_up)) {
    std::fprintf(stderr, "cnc-ctl: services not running after 30 s:");
    for (const auto& s : needed)
      if (!view.heartbeats.count(s)) std::fprintf(stderr, " %s", s.c_str());
    std::fprintf(stderr, "\n");
    return kExitTimeout;
  }

  // LOAD; repeated if no answer (a lost datagram), the answer names the path.
  const int64_t old_token = view.have_program ? view.program.program_token : 0;
  // MDI and touch-off: the server writes the line to mdi-SENDER-SEQ.ngc and loads it.
  std::string line_suffix;
  auto answered = [&] {
    if (line_cmd)
      return view.have_program && view.program.program_path.ends_with(line_suffix) &&
             (view.program.state == cnc::lcmt_program_state::REFUSED ||
              (view.program.state == cnc::lcmt_program_state::LOADED && view.program.program_token != old_token));
    // Its own LOAD's answer (the server names the command it decided on): a refusal of
    // an earlier LOAD of the same path is not this one's.
    return view.have_program && view.program.program_path == program && view.program.answered_sender == bus.sender() &&
           view.program.answered_seq == sent_seq &&
           (view.program.state == cnc::lcmt_program_state::REFUSED ||
            (view.program.state == cnc::lcmt_program_state::LOADED && view.program.program_token != old_token));
  };
  bool got = false;
  for (int attempt = 0; attempt < 5 && !got; ++attempt) {
    if (what == "mdi") {
      send_op(lcmt_program_command::MDI, -1, 0.0, 0.0, 0, args.option("line"));
    } else if (what == "touch-off") {
      const int axis = axis_arg();
      if (axis < 0) {
        std::fprintf(stderr, "cnc-ctl: --do touch-off needs --axis\n");
        return cnc::service::kExitBadInput;
      }
      send_op(lcmt_program_command::TOUCH_OFF, axis, args.number("value", 0), 0.0,
              args.flags.count("tool") ? 2 : 0, "");
    } else {
      send(lcmt_program_command::LOAD, program);
    }
    line_suffix = cnc::service::mdi_program_suffix(bus.sender(), sent_seq);
    got = wait_for(bus, 2.0, [&] { return answered() || !refused().empty(); });
  }
  if (const std::string why = refused(); !why.empty()) {
    std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
    return kExitRefused;
  }
  if (!got) {
    std::fprintf(stderr, "cnc-ctl: the program server did not answer the load of %s\n", program.c_str());
    return kExitTimeout;
  }
  if (view.program.state == cnc::lcmt_program_state::REFUSED) {
    std::fprintf(stderr, "cnc-ctl: program refused: %s\n", view.program.error.c_str());
    return kExitRefused;
  }
  const int64_t token = view.program.program_token;
  std::printf("loaded %s: %lld blocks\n", program.c_str(), static_cast<long long>(view.program.num_blocks));
  if (view.program.approach_pending) std::printf("approach %s\n", view.program.approach.c_str());
  if (what == "load") return 0;
  if (view.program.approach_pending) {
    // Run from a line: nothing moves before the approach is confirmed.
    if (args.flags.count("confirm")) {
      if (const int rc = confirm(); rc != 0) return rc;
      std::printf("approach confirmed\n");
    } else {
      std::printf("waiting for the approach to be confirmed (cnc-ctl --do confirm)\n");
      std::fflush(stdout);
      if (!wait_for(bus, timeout_s, [&] { return view.program.program_token != token || !view.program.approach_pending; }) ||
          view.program.program_token != token) {
        std::fprintf(stderr, "cnc-ctl: the approach was not confirmed\n");
        return kExitTimeout;
      }
    }
  }

  if (!wait_for(bus, 5.0, [&] { return view.have_interp && view.interp.program_token == token; })) {
    std::fprintf(stderr, "cnc-ctl: the interpolator did not take the program\n");
    return kExitTimeout;
  }
  auto started = [&] {
    return view.interp.program_token == token && view.interp.state != 0 /* idle */;
  };
  got = false;
  for (int attempt = 0; attempt < 5 && !got; ++attempt) {
    send(lcmt_program_command::START);
    got = wait_for(bus, 1.0, [&] { return started() || !refused().empty(); });
  }
  if (const std::string why = refused(); !why.empty()) {
    std::fprintf(stderr, "cnc-ctl: %s\n", why.c_str());
    return kExitRefused;
  }
  if (!got) {
    std::fprintf(stderr, "cnc-ctl: the interpolator did not start\n");
    return kExitTimeout;
  }
  const double t0 = cnc::util::monotonic_s();
  auto bridge_fault = [&] {
    if (!view.have_axes) return false;
    for (int8_t s : view.axes.drive_state)
      if (s == cnc::lcmt_axis_status::FAULT) return true;
    return false;
  };
  auto block_refused = [&] {
    for (const auto& a : view.alarms)
      if (a.code == "block_refused") return true;
    return false;
  };
  auto cell_fault = [&] {
    return (view.interp.program_token == token || view.interp.program_token == 0) &&
           view.interp.state == cnc::lcmt_setpoint::FAULT;
  };
  // A peer the run cannot go on without: its heartbeat missing for the cell's
  // heartbeat_timeout_s, or its last one said it stopped. The program server may be
  // away for a while: the interpolator stops at the end of the blocks it has and
  // goes on when the server is back (warned once, bounded by --timeout).
  std::string lost;
  bool server_warned = false;
  auto peer_lost = [&] {
    const double now = cnc::util::monotonic_s();
    for (const char* s : {"cnc-interpolator", "cnc-drive-bridge", "cnc-program-server"}) {
      const auto it = view.heartbeats.find(s);
      if (it == view.heartbeats.end()) continue;
      const double silent = now - view.heartbeat_s[s];
      const bool stopped = it->second.state == cnc::lcmt_heartbeat::STOPPING;
      if (!stopped && silent <= cfg.heartbeat_timeout_s) continue;
      char why[256];
      if (stopped) {
        std::snprintf(why, sizeof why, "%s stopped (its last heartbeat said STOPPING)", s);
      } else {
        std::snprintf(why, sizeof why, "%s is lost: no heartbeat for %.1f s (timeout %.1f s)", s, silent,
                      cfg.heartbeat_timeout_s);
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
  const bool done = wait_for(bus, timeout_s, [&] {
    return bridge_fault() || block_refused() || cell_fault() || peer_lost() ||
           (view.interp.program_token == token && view.interp.state == 3 /* done */);
  });
  if (block_refused()) {
    std::fprintf(stderr, "cnc-ctl: the interpolator refused a block; the program was stopped\n");
    return kExitRefused;
  }
  if (cell_fault() && !bridge_fault()) {
    std::string why = "the interpolator is in FAULT";
    for (const auto& a : view.alarms)
      if (a.source == "cnc-interpolator" && a.code == "interp_fault") why = a.text;
    std::fprintf(stderr, "cnc-ctl: fault: %s\n", why.c_str());
    return kExitFault;
  }
  if (bridge_fault()) {
    std::fprintf(stderr, "cnc-ctl: drive fault: %s\n", view.axes.fault.empty() ? "" : view.axes.fault[0].c_str());
    return kExitFault;
  }
  if (!lost.empty()) {
    std::fprintf(stderr, "cnc-ctl: the program did not reach its end: %s\n", lost.c_str());
    return kExitFault;
  }
  if (!done) {
    std::fprintf(stderr, "cnc-ctl: program did not finish within %.0f s\n", timeout_s);
    return kExitTimeout;
  }
  // Let the servo loops settle on the end point (1 µm), for at most 3 s.
  auto settled = [&] {
    if (!view.have_axes) return false;
    for (double fe : view.axes.following_error_mm)
      if (std::fabs(fe) > 1e-4) return false;
    return true;
  };
  const bool is_settled = wait_for(bus, 3.0, settled);
  // Done means the axes are at the program's end: the bridge still reports, and
  // every axis stands within 0.01 mm of where the interpolator ended.
  auto at_end = [&] {
    if (!view.have_axes || cnc::util::monotonic_s() - view.axes_s > 0.5) return false;
    if (view.interp.num_axes != view.axes.num_axes) return false;
    for (int i = 0; i < view.axes.num_axes; ++i)
      if (!(std::fabs(view.interp.position_mm[static_cast<size_t>(i)] - view.axes.actual_mm[static_cast<size_t>(i)]) <=
            0.01))
        return false;
    return true;
  };
  if (!wait_for(bus, 1.0, at_end)) {
    if (!view.have_axes || cnc::util::monotonic_s() - view.axes_s > 0.5) {
      std::fprintf(stderr, "cnc-ctl: the interpolator ended the program, but the drive bridge reports nothing "
                           "(no AXIS_STATUS for 0.5 s): the axes did not follow it to its end\n");
    } else {
      std::fprintf(stderr, "cnc-ctl: the interpolator ended the program, but the axes stand away from its end:");
      for (int i = 0; i < view.axes.num_axes; ++i)
        std::fprintf(stderr, " %s %.4f (end %.4f)", view.axes.axis_name[static_cast<size_t>(i)].c_str(),
                     view.axes.actual_mm[static_cast<size_t>(i)],
                     i < view.interp.num_axes ? view.interp.position_mm[static_cast<size_t>(i)] : 0.0);
      std::fprintf(stderr, "\n");
    }
    return kExitFault;
  }
  std::printf("program done: %.3f s program time (%.1f s wall), %lld blocks, largest following error %.4f mm (%s)%s\n",
              view.interp.program_time_s, cnc::util::monotonic_s() - t0, static_cast<long long>(view.interp.blocks_done),
              largest_fe, largest_fe_axis.c_str(), is_settled ? "" : ", axes not settled within 3 s");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-ctl",
                          "operator commands to a running cell",
                          {{"do", "CMD",
                            "run (default), load, start, hold, resume, stop, override, enable, disable, fault-reset, "
                            "reset, home, jog, touch-off, mdi, status, single-block, optional-stop, block-delete, confirm"},
                           {"program", "FILE", "the part program of run and load"},
                           {"value", "X",
                            "override factor, jog distance or direction (+1|-1), touch-off value; on|off for the switches"},
                           {"timeout", "S", "how long run, enable, reset and status wait (default 600)", true},
                           {"axis", "NAME", "the axis of home, jog and touch-off"},
                           {"feed", "F", "jog feed, mm/min", true},
                           {"hold", "S", "continuous jog held for S s, then STOP", true},
                           {"line", "TEXT", "the line of mdi (e.g. \"G0 X10\")"},
                           {"from", "N", "run or load from line N (an approach first, confirmed before START)", true}},
                          {{"tool", "", "touch-off of the tool (refused: not available yet)"},
                           {"confirm", "", "run --from: confirm the approach itself"}}};
  return cnc::service::run(spec, argc, argv, run_ctl);
}
