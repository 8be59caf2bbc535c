#pragma once
// cnc-ctl's verbs (--do): operator commands to a running cell, each sent again
// until its effect is seen, and the run of a program to its end.
#include <cstdint>
#include <initializer_list>
#include <map>
#include <string>
#include <vector>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_joint_status.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_command_answers.hpp"
#include "cnc/lcmt_io_status.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_spindle_status.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/service/service.h"

namespace cnc::ctl {

// What the bus told cnc-ctl about the cell.
struct CellView {
  std::map<std::string, cnc::lcmt_heartbeat> heartbeats;
  std::map<std::string, double> heartbeat_s;  // monotonic time each service's last heartbeat arrived
  double axes_s = -1e9;                       // ... and the last AXIS_STATUS
  cnc::lcmt_program_state program{};
  bool have_program = false;
  cnc::lcmt_command_answers answers{};  // the server's last decisions (PROGRAM_ANSWERS)
  cnc::lcmt_interp_state interp{};
  bool have_interp = false;
  cnc::lcmt_axis_status axes{};
  bool have_axes = false;
  cnc::lcmt_joint_status joints{};
  bool have_joints = false;
  cnc::lcmt_spindle_status spindle{};
  bool have_spindle = false;
  cnc::lcmt_io_status io{};
  bool have_io = false;
  std::vector<cnc::lcmt_alarm> alarms;
};

// The cell as cnc-ctl sees it and what every verb needs: the bus, the last command's
// seq, sending with and without waiting for a refusal. One member function per verb.
class Ctl {
 public:
  // Subscribes to the cell's state.
  Ctl(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args);

  // --do's verb run: its exit code (2 and the verbs' names for an unknown one).
  int run_verb();

  // The verbs, each a named member function.
  int status();
  int disable();
  int fault_reset();
  // An ALARM of the drive bridge with `code` since index `from`: its text, else "".
  std::string bridge_alarm_since(size_t from, const char* code) const;
  int reset();
  int enable();
  int confirm();
  int program_switch();
  int plain();
  int home_or_jog();
  int run();

 private:
  // Runs the bus until `done()` or `timeout_s`; false on timeout or stop signal.
  template <class Pred>
  bool wait(double timeout_s, Pred done);
  bool server_validating() const;
  void send(int8_t command, const std::string& path = "", double value = 1.0);
  std::string refused() const;
  bool answered() const;
  std::string send_checked(int8_t command, double wait_s, const std::string& path = "", double value = 1.0);
  void drive_command(int8_t command);
  bool all_in(int8_t state) const;
  int enable_drives(double limit_s);
  int confirm_approach();
  int axis_arg() const;
  // coolant and output: the line of codes an operator would give MDI for them; "" and
  // *why when the machine file has no such point.
  std::string io_line(std::string* why) const;
  void send_op(int8_t command, int axis, double value, double feed, int8_t flag, const std::string& text);
  bool interp_active() const;
  std::string alarm_since(size_t from, std::initializer_list<const char*> codes) const;
  void print_position(const char* what_done) const;
  // run, load, mdi, touch-off, in steps.
  bool services_up();
  int load(const std::string& program, bool line_cmd);
  int wait_for_confirm(int64_t token);
  int start(int64_t token);
  int watch_to_end(int64_t token);
  int check_at_end(double t0);

  const cnc::config::MachineConfig& cfg_;
  const cnc::service::Args& args_;
  const std::string what_;
  const double timeout_s_;
  cnc::bus::Bus bus_;
  CellView view_;
  double largest_fe_ = 0;
  std::string largest_fe_axis_;
  std::string mdi_line_;  // mdi, coolant, output: the line sent
  int64_t sent_seq_ = -1;  // the last program command sent: the server names it when it refuses it
  int from_line_ = 0;
};

}  // namespace cnc::ctl
