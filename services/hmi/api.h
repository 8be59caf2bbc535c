#pragma once
// The HMI's API, apart from its transport: the actions a client may ask for (one
// table: name, fields, what is sent to the cell, the answers) and the state pushed to
// the clients (hello, status, program, preview, alarms). It speaks JSON and the bus;
// HTTP and WebSocket are web.h's, and main wires the two. A client is only a number
// here, so any other transport (or a test) can drive the same API.
//
// docs/hmi-api.md documents the table; hmi_api_test keeps the two the same.
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <initializer_list>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cnc/lcmt_axis_status.hpp"
#include "cnc/lcmt_heartbeat.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_io_status.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "cnc/lcmt_spindle_status.hpp"
#include "common/bus/bus.h"
#include "common/config/machine_config.h"
#include "common/program/block.h"
#include "common/service/operator_commands.h"
#include "services/hmi/dry_run.h"
#include "services/hmi/runs_worker.h"

namespace cnc::hmi {

struct ApiOptions {
  std::string machine_file;   // the dry run's --machine
  std::string plan_exe;       // cnc-plan
  std::string logexport_exe;  // cnc-logexport
  std::string make_report;    // make_report.py
  std::string runs_dir;
  bool login_required = false;  // a users file: told to the page in `hello`
};

// Where the API's messages go: to every client (droppable: a status snapshot that a
// newer one replaces) or to one.
struct Outbox {
  std::function<void(const nlohmann::json&, bool droppable)> broadcast;
  std::function<void(uint64_t client, const nlohmann::json&)> send_to;
};

class Api {
 public:
  // One action as a client sent it.
  struct Request {
    uint64_t client;
    const nlohmann::json& id;
    const nlohmann::json& message;
    const std::string& action;
    const std::string& user;  // the logged-in user ("" without a login)
  };
  struct Action {
    const char* name;
    const char* fields;   // the message's fields besides `id` and `action`
    const char* sends;    // what goes to the cell
    const char* answers;  // the `result` (or other message) the client gets, refusals among them
    bool view_only;       // allowed to a client that may not control the machine
    void (Api::*handler)(const Request&);
  };
  // Every action, in the order docs/hmi-api.md lists them.
  static const std::vector<Action>& actions();
  static const Action* find_action(const std::string& name);

  // Subscribes to the cell's state on `bus`.
  Api(const config::MachineConfig& cfg, bus::Bus& bus, ApiOptions options, Outbox out);
  Api(const Api&) = delete;
  Api& operator=(const Api&) = delete;

  void open(uint64_t client, bool may_control, const std::string& user);  // hello, program, preview, alarms
  void close(uint64_t client);
  // One action; `user`: who is logged in on that client ("" without a login).
  void message(uint64_t client, bool may_control, const std::string& text, const std::string& user = "");
  // The pending actions followed, the loaded program's text and preview, the runs worker's answers.
  void update(double now);
  nlohmann::json status(double now, int64_t login_refusals, int clients) const;
  // A continuous jog a client holds is stopped; the dry run cancelled.
  void stop();

 private:
  // An action sent to the cell, waiting for its answer (a refusal, a load, a start).
  struct Pending {
    uint64_t client = 0;
    nlohmann::json id;
    std::string action;
    int8_t command = 0;
    int64_t seq = -1;
    double sent_s = 0;
    size_t alarms_at = 0;  // index into the alarm history at send time
    std::string path;      // LOAD: the absolute path
    int64_t old_token = 0;
    std::string suffix;    // MDI, touch-off: the line's program file
    int stage = 0;         // MDI: 0 loading, 1 waiting for the interpolator to take it, 2 started
    int64_t token = 0;
    int attempts = 0;
    double next_s = 0;
    double deadline_s = 0;
  };
  struct Seen {
    lcmt_heartbeat hb;
    double at_s;
  };
  struct BlockInfo {
    int line;
    bool in_program;  // the block's line is in the loaded program (not a subroutine file)
    double end[program::kMaxAxes];
  };

  void subscribe();
  // The machine's devices: what they are (hello) and where they stand (status).
  nlohmann::json devices() const;
  nlohmann::json machine() const;
  void on_alarm(const nlohmann::json& a);

  // The handlers of the table.
  void send_programs(const Request& r);
  void post_runs(const Request& r);
  void ping(const Request& r);
  void playback(const Request& r);
  void report(const Request& r);
  void load(const Request& r);
  void program_command(const Request& r);
  void program_switch(const Request& r);
  void override_command(const Request& r);
  void drive_command(const Request& r);
  void reset(const Request& r);
  void home(const Request& r);
  void jog(const Request& r);
  void jog_keepalive(const Request& r);
  void jog_stop(const Request& r);
  void touch_off(const Request& r);
  void mdi(const Request& r);
  void send_offsets(const Request& r);
  void set_offset(const Request& r);
  void clear_g92(const Request& r);
  void set_tool(const Request& r);
  void upload(const Request& r);

  // The work offsets and the tool table as the interpreter keeps them (program.var_file,
  // program.tool_table), for the `offsets` message.
  nlohmann::json offsets() const;
  // "" when the offsets and tools may be changed now, else why not (a program runs).
  std::string offsets_locked() const;
  // An offset or tool edit as the MDI line an operator would type (as AXIS's touch-off).
  void send_mdi_line(const Request& r, const std::string& line);

  int jog_axis(const Request& r);  // the axis of a jog message, -1 (answered) when the machine has none
  void send_line(const Request& r, service::OperatorCommand& c);
  void follow(double now);
  void follow_line(Pending& p, double now, bool& done);
  void follow_reset(Pending& p, double now, bool& done);
  void result(uint64_t client, const nlohmann::json& id, bool ok, const std::string& text);
  Pending* send_cmd(uint64_t client, const nlohmann::json& id, const std::string& action,
                    const service::OperatorCommand& c);
  int axis_index(const nlohmann::json& j) const;
  bool all_enabled() const;
  std::string alarm_since(size_t from, std::initializer_list<const char*> codes) const;

  const config::MachineConfig& cfg_;
  bus::Bus& bus_;
  const ApiOptions options_;
  const Outbox out_;
  const int naxes_;

  // The cell's state, as the bus tells it.
  lcmt_axis_status axes_{};
  bool have_axes_ = false;
  lcmt_interp_state interp_{};
  bool have_interp_ = false;
  lcmt_program_state program_{};
  bool have_program_ = false;
  lcmt_setpoint setpoint_{};
  bool have_setpoint_ = false;
  lcmt_spindle_status spindle_{};
  bool have_spindle_ = false;
  lcmt_io_status io_{};
  bool have_io_ = false;
  std::map<std::string, Seen> services_;
  std::vector<nlohmann::json> alarm_history_;  // every alarm (its index matters), the newest kAlarmsKept shown
  size_t alarms_total_ = 0;
  std::deque<nlohmann::json> alarms_shown_;
  std::map<int64_t, BlockInfo> blocks_;  // of the loaded program's token
  int64_t blocks_token_ = -1;

  DryRun dry_;
  RunsWorker runs_;
  std::vector<Pending> pending_;
  std::map<uint64_t, int> jogging_;  // client -> axis of its continuous jog
  std::string program_text_path_;
  nlohmann::json program_msg_ = {{"t", "program"}, {"path", ""}, {"text", ""}};
  nlohmann::json preview_msg_;
  int64_t preview_token_ = 0;
  // The var file's and the tool table's modification times: a change is broadcast.
  double offsets_stamp_ = -1;
  double offsets_checked_s_ = 0;
  bool offsets_locked_ = false;
};

}  // namespace cnc::hmi
