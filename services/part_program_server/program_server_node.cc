#include "services/part_program_server/program_server_node.h"


#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <unistd.h>
#include <iterator>
#include <sstream>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_program_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "common/program/block_msg.h"
#include "common/rs274/parameters.h"
#include "common/rs274/tool_table.h"
#include "common/util/clock.h"

namespace cnc::pps {

namespace ch = config::channels;

ProgramServerNode::ProgramServerNode(const config::MachineConfig& cfg, bus::Bus& bus)
    : cfg_(cfg), bus_(bus), core_(cfg), ch_blocks_(cfg.channel(ch::kProgramBlocks)),
      ch_state_(cfg.channel(ch::kProgramState)), ch_answers_(cfg.channel(ch::kProgramAnswers)), state_(cnc::lcmt_program_state::IDLE),
      health_(bus, cfg.channel(ch::kAlarm), "cnc-program-server", cnc::lcmt_alarm::WARNING) {
  core_.set_live_probing(cfg.probe.enabled() || cfg.io.enabled);  // the machine answers G38.x and M66
  bus_.subscribe<cnc::lcmt_program_command>(cfg.channel(ch::kProgramCmd), [this](const auto& m) { on_command(m); });
  bus_.subscribe<cnc::lcmt_block_request>(cfg.channel(ch::kBlockRequest), [this](const auto& m) { on_request(m); });
  // Where the machine stands, for the start of the next program.
  bus_.subscribe<cnc::lcmt_interp_state>(cfg.channel(ch::kInterpState), [this](const cnc::lcmt_interp_state& m) {
    if (m.num_axes == static_cast<int32_t>(cfg_.axes.size())) machine_position_ = m.position_mm;
    door_open_ = cfg_.safety.door_input >= 0 && m.door_open != 0;  // the interpolator's view of IO_STATUS
    on_interp_state(m);
  });
  bus_.subscribe<cnc::lcmt_axis_status>(cfg.channel(ch::kAxisStatus), [this](const cnc::lcmt_axis_status& m) {
    if (m.num_axes != static_cast<int32_t>(cfg_.axes.size())) return;
    axes_ = m;
    axes_s_ = util::monotonic_s();
  });
  // The interpolator's fault, by its own words.
  if (!cfg.safety.hard_limits.empty())
    bus_.subscribe<cnc::lcmt_io_status>(cfg.channel(ch::kIoStatus), [this](const cnc::lcmt_io_status& m) { on_io(m); });
  bus_.subscribe<cnc::lcmt_alarm>(cfg.channel(ch::kAlarm), [this](const cnc::lcmt_alarm& m) {
    if (m.source == "cnc-interpolator" && (m.code == "interp_fault" || m.code == "publish_failed"))
      interp_fault_text_ = m.text;
  });
}

void ProgramServerNode::on_interp_state(const cnc::lcmt_interp_state& m) {
  using S = cnc::lcmt_program_state;
  using P = cnc::lcmt_setpoint;
  {
    const bool act = m.state == P::RUNNING || m.state == P::HELD || m.state == P::STARVED;
    const int8_t mode = act ? m.mode : int8_t{cnc::lcmt_interp_state::MODE_PROGRAM};
    if (mode != cnc::lcmt_interp_state::MODE_PROGRAM && program_ready_) {
      // An operator move: a program loaded before starts where the machine stood then.
      spdlog::info("{}: the program loaded before is unloaded (its start moved); load it again", m.mode_text);
      program_ready_ = false;
    }
    interp_active_ = act;
    interp_mode_ = mode;
    interp_mode_text_ = m.mode_text;
    if (m.num_homed == m.num_axes && m.num_homed == static_cast<int32_t>(cfg_.axes.size())) interp_homed_ = m.homed;
  }
  const bool fault = m.state == P::FAULT;
  if (fault != interp_fault_) {
    interp_fault_ = fault;
    if (fault) {
      program_ready_ = false;
      if (state_ == S::RUNNING || state_ == S::HELD) state_ = S::STOPPED;
    }
    publish_state(true);
  }
  if (restored_ && !fault && core_.loaded() && m.program_token == core_.token() &&
      (m.state == P::RUNNING || m.state == P::STARVED || m.state == P::HELD)) {
    // Reloaded after a restart, and the interpolator still runs it: it is running.
    spdlog::info("the interpolator runs the program loaded again from the state file: serving it");
    restored_ = false;
    state_ = m.state == P::HELD ? S::HELD : S::RUNNING;
    start_s_ = -1e9;
    publish_state(true);
  }
  if (fault || !core_.loaded() || m.program_token != core_.token()) return;
  if (m.input_results == core_.inputs_known() + 1 && core_.awaited_result_block() >= 0 &&
      !core_.awaited_result_is_probe()) {
    // An input wait's value (M66): the rest of the program is validated with it, then served.
    const std::string path = core_.path();
    const int64_t token = core_.token();
    const LoadResult lr = core_.input_result(m.input_block, m.input_value);
    if (!lr.ok) {
      withdrawn_token_ = token;
      spdlog::error("program {} withdrawn after the input wait (M66) of block {}: {}", path, m.input_block, lr.error);
      last_refusal_ = lr;
      refused_path_ = path;
      state_ = S::REFUSED;
      publish_state(true);
      return;
    }
    spdlog::info("input wait {} (block {}): #5399 = {}; the rest validated, {} blocks", m.input_results, m.input_block,
                 m.input_value, core_.num_blocks());
    publish_state(true);
    if (last_request_.program_token == core_.token()) {
      const cnc::lcmt_block_request again = last_request_;
      on_request(again);
    }
  }
  if (m.probe_results == core_.probes_known() + 1 && m.num_probe_axes == static_cast<int32_t>(cfg_.axes.size()) &&
      core_.awaited_result_block() >= 0 && core_.awaited_result_is_probe()) {
    // A probing move's result: the rest of the program is validated with it, then served.
    ProbeResult pr{m.probe_tripped != 0, m.probe_trip_mm, m.probe_rest_mm};
    const std::string path = core_.path();
    const int64_t token = core_.token();
    const LoadResult lr = core_.probe_result(m.probe_block, pr);
    if (!lr.ok) {
      withdrawn_token_ = token;
      spdlog::error("program {} withdrawn after the probing move of block {}: {}", path, m.probe_block, lr.error);
      last_refusal_ = lr;
      refused_path_ = path;
      state_ = S::REFUSED;
      publish_state(true);
      return;
    }
    spdlog::info("probe result {} (block {}, {}): the rest validated, {} blocks", m.probe_results, m.probe_block,
                 pr.tripped ? "tripped" : "no contact", core_.num_blocks());
    publish_state(true);
    if (last_request_.program_token == core_.token()) {
      const cnc::lcmt_block_request again = last_request_;
      on_request(again);
    }
  }
  int8_t next = state_;
  if (m.state == P::RUNNING || m.state == P::STARVED) {
    if (state_ == S::RUNNING || state_ == S::HELD) next = S::RUNNING;
    start_s_ = -1e9;  // the interpolator runs it: its state counts from now on
  } else if (m.state == P::HELD) {
    if (state_ == S::RUNNING || state_ == S::HELD) next = S::HELD;
    start_s_ = -1e9;
  } else if (m.state == P::DONE) {
    if (state_ == S::RUNNING || state_ == S::HELD) next = S::DONE;
  } else if (m.state == P::IDLE) {
    // Stopped, unless the START is still on its way to the interpolator.
    if ((state_ == S::RUNNING || state_ == S::HELD) && util::monotonic_s() - start_s_ > 1.0) next = S::STOPPED;
  }
  if (next != state_) {
    state_ = next;
    publish_state(true);
  }
}

CellView ProgramServerNode::view(double now_s) const {
  using S = cnc::lcmt_program_state;
  CellView v;
  v.spindle_min_override = cfg_.spindle.min_override;
  v.spindle_max_override = cfg_.spindle.max_override;
  v.program = core_.path();
  if (own_fault_ || interp_fault_) {
    v.state = CellState::kFault;
    v.fault = own_fault_ ? own_fault_text_
                         : (interp_fault_text_.empty() ? std::string("the interpolator is in FAULT") : interp_fault_text_);
  } else if (interp_mode_ == cnc::lcmt_interp_state::MODE_JOG) {
    v.state = CellState::kJogging;
    v.motion = interp_mode_text_;
  } else if (interp_mode_ == cnc::lcmt_interp_state::MODE_HOME) {
    v.state = CellState::kHoming;
    v.motion = interp_mode_text_;
  } else if (state_ == S::RUNNING) {
    v.state = CellState::kRunning;
  } else if (state_ == S::HELD) {
    v.state = CellState::kHeld;
  } else if (program_ready_ && core_.loaded()) {
    v.state = CellState::kLoaded;
    if (approach_pending_) v.approach = core_.approach_text();
  } else {
    v.state = CellState::kIdle;
  }
  v.limit_axis = open_limit_.axis;
  v.limit_side = open_limit_.side;
  v.limit_switch = open_limit_.name;
  if (door_open_)
    v.door = "the guard door (input " + cfg_.io.point_label(cfg_.safety.door_input) + ") is open";
  if (cfg_.operator_.homing_required) {
    for (size_t a = 0; a < cfg_.axes.size() && v.unhomed.empty(); ++a)
      if (cfg_.axes[a].home.method != "none" && (a >= interp_homed_.size() || interp_homed_[a] == 0))
        v.unhomed = "axis " + cfg_.axes[a].name + " is not homed";
  }
  if (now_s - axes_s_ <= 0.5) {
    for (size_t i = 0; i < axes_.drive_state.size() && v.drives.empty(); ++i) {
      if (axes_.drive_state[i] == cnc::lcmt_axis_status::ENABLED) continue;
      static const char* const kNames[] = {"disabled", "enabling", "enabled", "stopping", "in fault"};
      const int8_t st = axes_.drive_state[i];
      v.drives = "axis " + axes_.axis_name[i] + " is " + (st >= 0 && st <= 4 ? kNames[st] : "in an unknown state");
    }
  }
  return v;
}

void ProgramServerNode::refuse(const cnc::lcmt_program_command& m, const std::string& why) {
  static const char* const kNames[] = {"?",    "LOAD", "START",         "HOLD",      "RESUME", "STOP", "OVERRIDE",
                                       "RESET", "HOME", "JOG", "JOG_KEEPALIVE", "TOUCH_OFF", "MDI",    "HOMED",
                                       "SINGLE_BLOCK", "OPTIONAL_STOP", "BLOCK_DELETE", "CONFIRM", "RAPID_OVERRIDE",
                                       "SPINDLE_AT_SPEED", "PROBE_TRIP", "INPUT_VALUE", "SPINDLE_OVERRIDE",
                                       "SPINDLE_POSITION", "SPINDLE_SPEED"};
  constexpr int kLast = static_cast<int>(sizeof kNames / sizeof kNames[0]) - 1;
  static_assert(kLast == cnc::lcmt_program_command::SPINDLE_SPEED, "a command without its name");
  const char* name = m.command >= 1 && m.command <= kLast ? kNames[m.command] : "?";
  refusal_ = std::string(name) + (m.command == cnc::lcmt_program_command::LOAD ? " " + m.program_path : "") +
             " refused: " + why;
  refused_sender_ = m.sender;
  refused_seq_ = m.seq;
  ++refusals_;
  if (answers_.num_answers > 0 && answers_.answer_sender[0] == m.sender && answers_.answer_seq[0] == m.seq)
    answers_.refusal[0] = refusal_;
  spdlog::warn("{}", refusal_);
  publish_state(true);
}

void ProgramServerNode::remember_answer(int32_t sender, int64_t seq) {
  auto& a = answers_;
  if (a.num_answers < kAnswers) {
    ++a.num_answers;
    a.answer_sender.resize(static_cast<size_t>(a.num_answers));
    a.answer_seq.resize(static_cast<size_t>(a.num_answers));
    a.refusal.resize(static_cast<size_t>(a.num_answers));
  }
  std::move_backward(a.answer_sender.begin(), a.answer_sender.end() - 1, a.answer_sender.end());
  std::move_backward(a.answer_seq.begin(), a.answer_seq.end() - 1, a.answer_seq.end());
  std::move_backward(a.refusal.begin(), a.refusal.end() - 1, a.refusal.end());
  a.answer_sender[0] = sender;
  a.answer_seq[0] = seq;
  a.refusal[0].clear();
}

void ProgramServerNode::poll(double now_s) {
  if (health_.check(now_s) && !own_fault_) {
    own_fault_ = true;
    own_fault_text_ = std::string("the program server could not publish: ") + health_.cause();
    program_ready_ = false;
    spdlog::error("fault: {}", own_fault_text_);
  }
  health_.report(now_s, "the program server is in FAULT until RESET");
}

void ProgramServerNode::on_io(const cnc::lcmt_io_status& m) {
  open_limit_ = service::open_limit(cfg_, m);
}

void ProgramServerNode::on_command(const cnc::lcmt_program_command& m) {
  if (m.command == cnc::lcmt_program_command::JOG_KEEPALIVE) return decide(m);
  answered_sender_ = m.sender;
  answered_seq_ = m.seq;
  remember_answer(m.sender, m.seq);
  decide(m);
  bus_.publish(ch_answers_, answers_);  // every decision at once, not only with the next state
}

void ProgramServerNode::decide(const cnc::lcmt_program_command& m) {
  using C = cnc::lcmt_program_command;
  using S = cnc::lcmt_program_state;
  if (const std::string why = refusal(m, view(util::monotonic_s())); !why.empty()) {
    refuse(m, why);
    return;
  }
  switch (m.command) {
    case C::LOAD:
      mdi_modes_.reset();  // a program: the next MDI line starts as a program does
      load_program(m.program_path, m.from_line);
      break;
    case C::CONFIRM:
      approach_pending_ = false;
      spdlog::info("approach confirmed: {}", core_.approach_text());
      publish_state(true);
      break;
    case C::BLOCK_DELETE: {
      const bool on = m.value != 0;
      const bool changed = on != core_.block_delete();
      core_.set_block_delete(on);
      spdlog::info("block delete {}", on ? "on" : "off");
      // A program loaded and not started yet is read again with the new switch.
      if (changed && program_ready_ && core_.loaded()) {
        const std::string path = core_.path();
        const bool mdi = path == mdi_file_;
        load_program(path, core_.from_line());
        if (mdi && core_.path() == path) mdi_file_ = path;  // still the MDI line's file
      }
      publish_state(true);
      break;
    }
    case C::MDI: load_line(m, m.text); break;
    case C::TOUCH_OFF: {
      if (m.axis < 0 || m.axis >= static_cast<int32_t>(cfg_.axes.size())) {
        refuse(m, "no axis " + std::to_string(m.axis));
        return;
      }
      char v[64];
      std::snprintf(v, sizeof v, "%.6f", m.value);
      const std::string& name = cfg_.axes[static_cast<size_t>(m.axis)].name;
      if (m.jog_continuous != 2) {
        // LinuxCNC's touch-off: G10 L20 P0 (the active work offset) so that the current
        // position reads the value.
        load_line(m, "G10 L20 P0 " + name + v);
        break;
      }
      // The tool's length (LinuxCNC's G10 L10): the tool in the spindle's offset so that
      // the current position reads the value with it, written back to the tool table at
      // the line's end. The tool in the spindle is #5400 of the var file (the last
      // program that ended left it there: M6, M61).
      const std::string why = tool_touch_off_refusal();
      if (!why.empty()) {
        refuse(m, why);
        return;
      }
      load_line(m, "G10 L10 P" + std::to_string(spindle_tool_) + " " + name + v);
      break;
    }
    case C::SINGLE_BLOCK:
    case C::OPTIONAL_STOP: publish_state(true); break;  // the interpolator's: answered here
    case C::START:
      if (core_.loaded()) {
        state_ = S::RUNNING;
        program_ready_ = false;  // it runs once; after its end it is loaded again
        start_s_ = util::monotonic_s();
      }
      publish_state(true);
      break;
    case C::STOP:
      if (core_.loaded() && (state_ == S::RUNNING || state_ == S::HELD)) state_ = S::STOPPED;
      publish_state(true);
      break;
    case C::RESET:
      // The interpolator takes the position from the drives; a program loaded
      // before (from where the machine stood then) is not started any more.
      own_fault_ = false;
      own_fault_text_.clear();
      mdi_modes_.reset();
      program_ready_ = false;
      state_ = S::IDLE;
      publish_state(true);
      break;
    default: break;
  }
}

std::string ProgramServerNode::tool_touch_off_refusal() {
  spindle_tool_ = 0;
  if (cfg_.program.tool_table.empty()) return "tool touch-off: the cell has no tool table (program.tool_table)";
  if (cfg_.program.var_file.empty())
    return "tool touch-off: the cell keeps no var file (program.var_file), where the tool in the spindle is kept";
  std::error_code ec;
  if (std::filesystem::exists(cfg_.program.var_file, ec)) {
    rs274::Parameters p;
    try {
      p.read_var_file(cfg_.program.var_file);
    } catch (const std::exception& e) {
      return std::string("tool touch-off: ") + e.what();
    }
    spindle_tool_ = static_cast<int>(std::lround(p.get(5400)));
  }
  if (spindle_tool_ <= 0)
    return "tool touch-off: no tool in the spindle (put one there first: MDI T1 M6, or M61 Q1 when it is "
           "there already)";
  rs274::ToolTable t;
  try {
    t.read(cfg_.program.tool_table);
  } catch (const std::exception& e) {
    return std::string("tool touch-off: ") + e.what();
  }
  if (t.find(spindle_tool_) == nullptr)
    return "tool touch-off: tool T" + std::to_string(spindle_tool_) + " in the spindle is not in the tool table " +
           cfg_.program.tool_table;
  return "";
}

void ProgramServerNode::load_program(const std::string& path, int from_line) {
  using S = cnc::lcmt_program_state;
  // The token must differ from every earlier one, also across restarts.
  const int64_t token = std::max(util::wall_utime(), core_.token() + 1);
  const LoadResult r = core_.load_from(path, token, machine_position_, from_line);
  if (r.ok) {
    approach_pending_ = core_.from_line() > 0;
    if (approach_pending_) spdlog::info("{}: the approach waits for CONFIRM: {}", path, core_.approach_text());
    // The one-line program of an earlier MDI is not loaded any more: its file goes
    // (the folder would otherwise grow by a file a line for the life of the cell).
    if (!mdi_file_.empty() && mdi_file_ != path) {
      std::error_code ec;
      std::filesystem::remove(mdi_file_, ec);
    }
    mdi_file_.clear();  // load_line names its own file again
    spdlog::info("loaded {}: {} blocks (token {})", path, core_.num_blocks(), token);
    for (const std::string& w : r.warnings) spdlog::warn("{}", w);
    state_ = S::LOADED;
    withdrawn_token_ = 0;
    program_ready_ = true;
    last_refusal_ = LoadResult{};
    sent_.clear();
    blocks_sent_ = blocks_resent_ = 0;
    restored_ = false;
    write_state_file();
  } else {
    spdlog::error("program refused: {}", r.error);
    withdrawn_token_ = 0;
    last_refusal_ = r;
    refused_path_ = path;
    state_ = S::REFUSED;
  }
  publish_state(true);
}

void ProgramServerNode::load_line(const cnc::lcmt_program_command& m, const std::string& line) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path dir = cfg_.operator_.mdi_directory.empty()
                           ? fs::temp_directory_path(ec) / ("cnc-mdi-" + std::to_string(::getpid()))
                           : fs::path(cfg_.operator_.mdi_directory);
  fs::create_directories(dir, ec);
  // Named by the command's sender and seq, so cnc-ctl knows its program's answer.
  const fs::path file = dir / ("mdi-" + std::to_string(static_cast<uint32_t>(m.sender)) + "-" +
                               std::to_string(m.seq) + ".ngc");
  {
    std::ofstream out(file);
    // Between '%' lines, not ended by M2: M2's stops (spindle, coolant) and resets are a
    // program's end, and LinuxCNC's MDI leaves the spindle and coolant as the line set them.
    out << "%\n" << line << "\n%\n";
    if (!out) {
      refuse(m, "cannot write " + file.string());
      return;
    }
  }
  spdlog::info("MDI {}: {}", ++mdi_count_, line);
  core_.next_load_is_line(mdi_modes_ ? &*mdi_modes_ : nullptr);
  load_program(file.string());
  if (core_.path() == file.string()) {
    mdi_file_ = file.string();
    // The modes the line leaves are the next line's (until a program or a RESET).
    if (core_.modes_after()) mdi_modes_ = core_.modes_after();
  } else {
    std::filesystem::remove(file, ec);  // refused: not kept
  }
}

void ProgramServerNode::interpolator_lost() {
  using S = cnc::lcmt_program_state;
  if (state_ != S::RUNNING && state_ != S::HELD) return;
  spdlog::warn("the interpolator is lost: program {} is not running any more (stopped)", core_.path());
  state_ = S::STOPPED;
  restored_ = false;
  publish_state(true);
}

void ProgramServerNode::write_state_file() const {
  if (state_file_.empty()) return;
  const std::string tmp = state_file_ + ".tmp";
  std::FILE* f = std::fopen(tmp.c_str(), "w");
  bool ok = f != nullptr;
  if (ok) {
    ok = std::fprintf(f, "cnc-program-server state 1\ntoken %lld\nstart %zu", static_cast<long long>(core_.token()),
                      machine_position_.size()) > 0;
    for (double x : machine_position_) ok = ok && std::fprintf(f, " %a", x) > 0;  // exact (hex float)
    ok = ok && std::fprintf(f, "\npath %s\n", core_.path().c_str()) > 0;
    if (core_.from_line() > 0) ok = ok && std::fprintf(f, "from %d\n", core_.from_line()) > 0;
    ok = (std::fclose(f) == 0) && ok;
  }
  if (!ok || std::rename(tmp.c_str(), state_file_.c_str()) != 0)
    spdlog::warn("cannot write the state file {}: {} (a restart will not resume this program)", state_file_,
                 std::strerror(errno));
}

void ProgramServerNode::use_state_file(const std::string& path) {
  state_file_ = path;
  if (path.empty()) return;
  std::ifstream in(path);
  if (!in) return;  // nothing recorded yet
  std::string magic, line;
  std::getline(in, magic);
  long long token = 0;
  size_t n = 0;
  std::vector<double> start;
  std::string program;
  bool ok = magic == "cnc-program-server state 1";
  if (ok && std::getline(in, line)) ok = std::sscanf(line.c_str(), "token %lld", &token) == 1 && token > 0;
  if (ok && std::getline(in, line)) {
    std::istringstream ls(line);
    std::string word;
    ok = static_cast<bool>(ls >> word >> n) && word == "start" && n <= 64;
    for (size_t i = 0; ok && i < n; ++i) {
      std::string v;
      ok = static_cast<bool>(ls >> v);
      if (ok) start.push_back(std::strtod(v.c_str(), nullptr));
    }
  }
  if (ok && std::getline(in, line)) {
    ok = line.rfind("path ", 0) == 0;
    program = line.substr(5);
  }
  int from_line = 0;
  if (ok && std::getline(in, line) && !line.empty())
    ok = std::sscanf(line.c_str(), "from %d", &from_line) == 1 && from_line > 0;
  if (!ok || program.empty()) {
    spdlog::warn("state file {} is malformed: ignored", path);
    return;
  }
  const LoadResult r = core_.load_from(program, token, start, from_line);
  if (!r.ok) {
    spdlog::warn("state file {}: program {} no longer loads ({}): not resumed", path, program, r.error);
    return;
  }
  machine_position_ = start;
  // Idle (a LOAD replaces it) until INTERP_STATE says the interpolator runs it; its
  // blocks are served meanwhile (only an interpolator that runs it asks for them).
  state_ = cnc::lcmt_program_state::IDLE;
  program_ready_ = false;
  restored_ = true;
  spdlog::info("resumed {} from the state file {}: {} blocks (token {}), served to an interpolator that runs it",
               program, path, core_.num_blocks(), token);
}

void ProgramServerNode::on_request(const cnc::lcmt_block_request& m) {
  if (!core_.loaded() || m.program_token != core_.token()) return;
  if (m.count <= 0 || m.count > 4096) {
    spdlog::warn("block request seq {} asks for {} blocks: ignored", m.seq, m.count);
    return;
  }
  last_request_ = m;
  const int64_t token = core_.token();
  const std::string path = core_.path();
  if (m.first_block < 0 || m.first_block >= core_.num_blocks()) return;
  const int64_t end = m.first_block + std::min<int64_t>(m.count, core_.num_blocks() - m.first_block);
  for (int64_t i = m.first_block; i < end; ++i) {
    if (core_.awaiting_result(i)) break;  // after a probing move or an M66: served once its result is in
    const program::Block* b = core_.block(i);
    if (b == nullptr) {
      // The file no longer reads as validated: serve nothing more of it.
      spdlog::error("program {} withdrawn: {}", token, core_.serving_error());
      withdrawn_token_ = token;
      last_refusal_ = LoadResult{};
      last_refusal_.error = core_.serving_error();
      last_refusal_.file = path;
      refused_path_ = path;
      state_ = cnc::lcmt_program_state::REFUSED;
      publish_state(true);
      return;
    }
    cnc::lcmt_program_block msg = program::to_msg(*b, token);
    bus_.publish(ch_blocks_, msg);
    if (mark_sent(i)) {
      ++blocks_resent_;
    } else {
      ++blocks_sent_;
    }
  }
}

bool ProgramServerNode::mark_sent(int64_t i) {
  auto next = sent_.upper_bound(i);
  if (next != sent_.begin()) {
    auto prev = std::prev(next);
    if (i < prev->second) return true;
    if (i == prev->second) {
      prev->second = i + 1;
      if (next != sent_.end() && next->first == i + 1) {
        prev->second = next->second;
        sent_.erase(next);
      }
      return false;
    }
  }
  if (next != sent_.end() && next->first == i + 1) {
    const int64_t e = next->second;
    sent_.erase(next);
    sent_.emplace(i, e);
  } else {
    sent_.emplace(i, i + 1);
  }
  return false;
}

void ProgramServerNode::publish_state(bool force) {
  const double now = util::monotonic_s();
  if (!force && now - last_state_s_ < 0.1) return;
  last_state_s_ = now;
  cnc::lcmt_program_state s{};
  s.state = (own_fault_ || interp_fault_) ? cnc::lcmt_program_state::FAULT : state_;
  s.program_token = core_.token();
  s.program_path = state_ == cnc::lcmt_program_state::REFUSED ? refused_path_ : core_.path();
  if (s.state == cnc::lcmt_program_state::REFUSED && withdrawn_token_ != 0) s.program_token = withdrawn_token_;
  s.num_blocks = core_.num_blocks();
  s.blocks_sent = blocks_sent_;
  s.blocks_resent = blocks_resent_;
  s.error = last_refusal_.error;
  s.error_line = last_refusal_.line;
  s.error_column = last_refusal_.column;
  s.refusal = refusal_;
  s.refused_sender = refused_sender_;
  s.refused_seq = refused_seq_;
  s.refusals = refusals_;
  s.block_delete = core_.block_delete() ? 1 : 0;
  s.answered_sender = answered_sender_;
  s.answered_seq = answered_seq_;
  s.from_line = core_.from_line();
  s.approach = core_.approach_text();
  s.approach_pending = approach_pending_ && program_ready_ ? 1 : 0;
  bus_.publish(ch_state_, s);
  if (answers_.num_answers > 0) bus_.publish(ch_answers_, answers_);
}

}  // namespace cnc::pps
