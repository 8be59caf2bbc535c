#include "services/interpolator/interpolator_node.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_block_request.hpp"
#include "cnc/lcmt_interp_input.hpp"
#include "cnc/lcmt_interp_state.hpp"
#include "cnc/lcmt_setpoint.hpp"
#include "cnc/lcmt_spindle_status.hpp"
#include "cnc/lcmt_config.hpp"
#include "common/motion/feed_override.h"
#include "common/program/block_msg.h"
#include "common/util/clock.h"
#include "services/interpolator/inputs.h"

namespace cnc::interp {

namespace ch = config::channels;

namespace {
// Inputs kept until the logger confirms them (every second) or, while the bus fails,
// for a later publish: 4 s of a program of 4,000 blocks/s (one input each; 4,096 ran
// out within a second at 6,000 blocks/s and the log did not replay).
constexpr size_t kMaxPendingInputs = 16384;
// An AXIS_STATUS older than this does not tell where the drives are now.
constexpr double kStatusFresh_s = 0.5;
// The bridge publishes AXIS_STATUS every T_ipo: silent this long while a program
// runs, the drives are not being driven (the bridge is gone or its host is).
constexpr double kStatusLost_s = 0.25;
constexpr size_t kPeerBridge = 0;
// [1]: the program server, watched for its ALARM only.

const char* drive_state_name(int8_t s) {
  switch (s) {
    case cnc::lcmt_axis_status::DISABLED: return "disabled";
    case cnc::lcmt_axis_status::ENABLING: return "enabling";
    case cnc::lcmt_axis_status::ENABLED: return "enabled";
    case cnc::lcmt_axis_status::STOPPING: return "stopping";
    case cnc::lcmt_axis_status::FAULT: return "in fault";
  }
  return "in an unknown state";
}

bool active(RunState s) { return s == RunState::kRunning || s == RunState::kHeld || s == RunState::kStarved; }
}  // namespace

InterpolatorNode::InterpolatorNode(const config::MachineConfig& cfg, bus::Bus& bus)
    : cfg_(cfg), bus_(bus), planner_(cfg), core_(cfg, planner_), feed_(cfg),
      ch_setpoints_(cfg.channel(ch::kSetpoints)), ch_request_(cfg.channel(ch::kBlockRequest)),
      ch_state_(cfg.channel(ch::kInterpState)), ch_input_(cfg.channel(ch::kInterpInput)),
      ch_config_(cfg.channel(ch::kInterpConfig)), ch_alarm_(cfg.channel(ch::kAlarm)),
      config_period_cycles_(std::max<int64_t>(1, std::llround(1.0 / cfg.ipo_period_s))),
      // Re-request after ~100 ms without the block (a lost request or block).
      resend_cycles_(std::max<int64_t>(2, std::llround(0.1 / cfg.ipo_period_s))),
      health_(bus, cfg.channel(ch::kAlarm), "cnc-interpolator", cnc::lcmt_alarm::FAULT),
      inputs_(kMaxPendingInputs),
      peers_(bus, cfg, "cnc-interpolator", {"cnc-drive-bridge", "cnc-program-server"}),
      stream_(util::next_token(0)), spindle_seq_base_(stream_), ch_spindle_cmd_(cfg.channel(ch::kSpindleCmd)),
      io_seq_base_(stream_), ch_io_cmd_(cfg.channel(ch::kIoCmd)) {
  // Recorded absolute: a replay elsewhere finds the files the machine file names beside it.
  std::error_code ec;
  const std::filesystem::path here = std::filesystem::absolute(cfg.source_file, ec);
  config_file_ = ec || cfg.source_file.empty() ? cfg.source_file : here.lexically_normal().string();
  bus_.subscribe<cnc::lcmt_program_command>(cfg.channel(ch::kProgramCmd),
                                            [this](const auto& m) { on_command(m); });
  bus_.subscribe<cnc::lcmt_program_state>(cfg.channel(ch::kProgramState),
                                          [this](const auto& m) { on_program_state(m); });
  bus_.subscribe<cnc::lcmt_program_block>(cfg.channel(ch::kProgramBlocks), [this](const auto& m) { on_block(m); });
  bus_.subscribe<cnc::lcmt_logger_stats>(cfg.channel("LOGGER_STATS"),
                                         [this](const cnc::lcmt_logger_stats& m) { on_logger_stats(m); });
  if (cfg.spindle.enabled)
    bus_.subscribe<cnc::lcmt_spindle_status>(cfg.channel(ch::kSpindleStatus), [this](const cnc::lcmt_spindle_status& m) {
      spindle_at_speed_seq_ = std::max(spindle_at_speed_seq_, m.at_speed_seq);
      if (m.orient_state == cnc::lcmt_spindle_status::ORIENTED)
        spindle_oriented_seq_ = std::max(spindle_oriented_seq_, m.command_seq);
      // The newest measured position for a synchronised move (G33, G33.1).
      if (m.position_valid && m.sample_playback_cycle >= 0 && std::isfinite(m.position_rev) &&
          std::isfinite(m.actual_rpm) && std::isfinite(m.sample_playback_cycle)) {
        spindle_pos_ = {m.position_rev, m.actual_rpm / 60.0, m.sample_playback_cycle};
        spindle_pos_new_ = true;
      }
      if (std::isfinite(m.actual_rpm)) {
        spindle_rpm_ = std::fabs(m.actual_rpm);
        spindle_rpm_new_ = true;
      }
    });
  if (cfg.safety.door_input >= 0) door_input_ = cfg.io.point_label(cfg.safety.door_input);
  io_msg_.num_analog = static_cast<int32_t>(std::min<size_t>(cfg.io.analog_outputs.size(), 64));
  io_msg_.analog.assign(static_cast<size_t>(io_msg_.num_analog), 0.0);  // sized once: the publish allocates nothing
  if (cfg.io.enabled)
    bus_.subscribe<cnc::lcmt_io_status>(cfg.channel(ch::kIoStatus), [this](const cnc::lcmt_io_status& m) {
      if (cfg_.safety.door_input >= 0) door_open_ = m.door == cnc::lcmt_io_status::DOOR_OPEN;
      if (m.num_points != static_cast<int32_t>(cfg_.io.points.size())) return;
      io_status_ = m;
      io_status_s_ = util::monotonic_s();
    });
  bus_.subscribe<cnc::lcmt_axis_status>(cfg.channel(ch::kAxisStatus), [this](const cnc::lcmt_axis_status& m) {
    if (m.num_axes != static_cast<int32_t>(cfg_.axes.size())) return;
    axis_status_ = m;
    axis_status_s_ = util::monotonic_s();
  });
  if (std::any_of(cfg.axes.begin(), cfg.axes.end(), [](const config::AxisConfig& a) { return a.gantry.enabled; }))
    bus_.subscribe<cnc::lcmt_joint_status>(cfg.channel(ch::kJointStatus),
                                           [this](const cnc::lcmt_joint_status& m) { joint_status_ = m; });
}

void InterpolatorNode::on_command(const cnc::lcmt_program_command& m) { pending_commands_.push_back(m); }

void InterpolatorNode::on_program_state(const cnc::lcmt_program_state& m) {
  const bool loaded = m.state == cnc::lcmt_program_state::LOADED || m.state == cnc::lcmt_program_state::RUNNING;
  if (m.program_token == token_ && m.approach_pending == 0) approach_pending_ = false;
  // A probing move's result may change the program's length (the server validates the rest again with it).
  if (m.program_token == token_ && token_ != 0 && m.num_blocks > 0) num_blocks_ = m.num_blocks;
  if (m.state == cnc::lcmt_program_state::REFUSED) program_withdrawn(m);
  else if (m.program_token != token_) program_lost(m);
  if (!loaded || m.program_token == token_) return;
  // In FAULT nothing new is taken; after it, no program loaded before it.
  if (fault_ || m.program_token <= retired_token_) return;
  if (manual_ != Manual::kNone) return;  // taken once the operator move has ended
  const RunState s = core_.state();
  if (s == RunState::kRunning || s == RunState::kHeld || s == RunState::kStarved) {
    spdlog::warn("program {} loaded while a program runs: ignored until it ends", m.program_path);
    return;
  }
  token_ = m.program_token;
  approach_pending_ = m.approach_pending != 0;
  num_blocks_ = m.num_blocks;
  program_path_ = m.program_path;
  reorder_.clear();
  load_pending_ = true;
}

void InterpolatorNode::program_withdrawn(const cnc::lcmt_program_state& m) {
  // The program server withdrew the program this core runs (the rest no longer
  // validates after a probe result or an M66 value, or its file changed): no block
  // comes after the ones held, so the path would wait at their end until an operator's
  // STOP. It stops here, as the operator's STOP would (recorded, so a replay does too).
  if (token_ == 0 || m.program_token != token_ || m.program_path != program_path_) return;
  const RunState s = core_.state();
  if (s != RunState::kRunning && s != RunState::kHeld && s != RunState::kStarved) return;
  const std::string text = "program " + program_path_ + " withdrawn by the program server: " + m.error;
  spdlog::error("{}: the program stops", text);
  stop_program("program_withdrawn", text);
}

void InterpolatorNode::program_lost(const cnc::lcmt_program_state& m) {
  // The program server serves another program, or none, while this core runs one: it was
  // started again without its state file (or with an older one). Blocks not held yet
  // never come; the run would wait at the last one held until an operator's STOP.
  if (token_ == 0 || manual_ != Manual::kNone) return;
  const RunState s = core_.state();
  if (s != RunState::kRunning && s != RunState::kHeld && s != RunState::kStarved) return;
  if (num_blocks_ > 0 && core_.next_block_index() >= num_blocks_) return;  // every block held: it ends
  std::string text = "program " + program_path_ + " lost: the program server ";
  if (m.program_token == 0) {
    text += "has no program loaded (started again without its --state?)";
  } else {
    text += "serves another program (";
    text += m.program_path;
    text += ", token " + std::to_string(m.program_token) + ")";
  }
  text += " and block " + std::to_string(core_.next_block_index()) + " of " + std::to_string(num_blocks_) +
          " was not served yet; load it again";
  spdlog::error("{}: the program stops", text);
  stop_program("program_lost", text);
}

void InterpolatorNode::stop_program(const char* code, const std::string& text) {
  alarm(cnc::lcmt_alarm::FAULT, code, text);
  cnc::lcmt_program_command stop{};
  stop.command = cnc::lcmt_program_command::STOP;
  apply_command(Command{Command::Kind::kStop, 1.0, {}}, stop);
  token_ = 0;
  reorder_.clear();
}

void InterpolatorNode::on_block(const cnc::lcmt_program_block& m) {
  if (m.program_token != token_ || token_ == 0) return;
  if (m.block_index < core_.next_block_index()) return;  // a duplicate of what the core has
  if (m.block_index >= core_.next_block_index() + cfg_.block_window) return;  // outside the window
  reorder_.emplace(m.block_index, m);
}

void InterpolatorNode::apply_command(const Command& c, const cnc::lcmt_program_command& m) {
  if (!core_.apply_command(c)) {
    // Only an override can be refused: the planner's request queue is full.
    spdlog::warn("command {} not applied: the planner is busy; send it again", m.command);
    return;
  }
  cnc::lcmt_interp_input in{};
  in.cycle = core_.cycle();
  in.kind = cnc::lcmt_interp_input::COMMAND;
  in.command = m;
  in.block.num_axes = 0;
  publish_input(in);
}

void InterpolatorNode::drop_oldest_input() {
  const bool sent = pending(0).sent;
  inputs_head_ = (inputs_head_ + 1) % inputs_.size();
  --inputs_size_;
  if (!sent) {
    --inputs_unsent_;
    if (inputs_dropped_++ == 0)
      spdlog::error("more than {} inputs could not be published: this run can no longer be replayed",
                    kMaxPendingInputs);
  } else if (inputs_unconfirmed_dropped_++ == 0 && logger_seen_) {
    spdlog::error("the logger has not confirmed {} inputs: the log of this run may not replay", kMaxPendingInputs);
    alarm(cnc::lcmt_alarm::WARNING, "inputs_unconfirmed",
          "the logger has not confirmed " + std::to_string(kMaxPendingInputs) +
              " interpolator inputs: the log of this run may not replay");
  }
}

void InterpolatorNode::publish_input(const cnc::lcmt_interp_input& input) {
  if (inputs_size_ == inputs_.size()) drop_oldest_input();
  PendingInput& e = pending(inputs_size_);
  ++inputs_size_;
  e.in = input;
  e.in.index = next_input_index_++;
  e.sent = false;
  ++inputs_unsent_;
  flush_inputs();  // this one goes now unless an older one still cannot
}

void InterpolatorNode::flush_inputs() {
  if (inputs_unsent_ == 0) return;
  const double now = util::monotonic_s();
  while (inputs_unsent_ > 0) {
    PendingInput& e = pending(inputs_size_ - inputs_unsent_);
    if (!bus_.publish(ch_input_, e.in)) return;
    e.sent = true;
    e.sent_s = now;
    --inputs_unsent_;
  }
}

void InterpolatorNode::on_logger_stats(const cnc::lcmt_logger_stats& m) {
  const int32_t me = bus_.sender();
  const int n = std::min<int>(m.num_input_senders, static_cast<int>(std::min(m.input_sender.size(), m.input_next.size())));
  int64_t next = -1;
  for (int i = 0; i < n; ++i)
    if (m.input_sender[static_cast<size_t>(i)] == me) next = m.input_next[static_cast<size_t>(i)];
  if (next < 0) {
    // A logger that has none of ours yet: everything a while old goes again.
    if (!m.closing) next = 0;
    else return;
  }
  logger_seen_ = true;
  while (inputs_size_ > 0 && pending(0).in.index < next) {
    if (!pending(0).sent) --inputs_unsent_;  // cannot be (confirmed before sent), kept consistent
    inputs_head_ = (inputs_head_ + 1) % inputs_.size();
    --inputs_size_;
  }
  // Sent again: what the logger lacks and should have had by now (sent over half a
  // second before this report). At most 64 a report, oldest first; a new seq each.
  // The never-sent ones are flush_inputs()'s, in order.
  const double now = util::monotonic_s();
  int resent = 0;
  for (size_t i = 0; i + inputs_unsent_ < inputs_size_; ++i) {
    PendingInput& e = pending(i);
    if (resent >= 64 || now - e.sent_s < 0.5) break;
    if (!bus_.publish(ch_input_, e.in)) break;
    e.sent_s = now;
    ++resent;
  }
  if (resent > 0) {
    inputs_resent_ += resent;
    spdlog::info("{} input(s) sent again that the logger did not confirm (from index {}; {} in all)", resent,
                 pending(0).in.index, inputs_resent_);
  }
}

void InterpolatorNode::alarm(int8_t severity, const std::string& code, const std::string& text) {
  cnc::lcmt_alarm al{};
  al.source = "cnc-interpolator";
  al.severity = severity;
  al.code = code;
  al.text = text;
  bus_.publish(ch_alarm_, al);  // a failure is counted and reported by health_
}

void InterpolatorNode::fault(const std::string& cause) {
  if (fault_) return;
  fault_ = true;
  fault_cause_ = cause;
  detail_ = "fault: " + cause;
  spdlog::error("fault: {}; the program is stopped, RESET to continue", cause);
  if (active(core_.state())) {
    cnc::lcmt_program_command stop{};
    stop.command = cnc::lcmt_program_command::STOP;
    apply_command(Command{Command::Kind::kStop, 1.0, {}}, stop);
  }
  retired_token_ = std::max(retired_token_, token_);
  token_ = 0;
  num_blocks_ = 0;
  load_pending_ = false;
  reorder_.clear();
  manual_ = Manual::kNone;
  manual_text_.clear();
  alarm(cnc::lcmt_alarm::FAULT, "interp_fault", "program stopped: " + cause + "; RESET to continue");
}

std::string InterpolatorNode::reset_position(cnc::lcmt_program_command* out) const {
  if (active(core_.state()))
    return fault_ ? "the path is still braking after the fault: try again when it stands"
                  : "a program is running: STOP it first";
  if (util::monotonic_s() - axis_status_s_ > kStatusFresh_s)
    return "no AXIS_STATUS from the drive bridge within the last 0.5 s: where the drives stand is unknown";
  const int n = static_cast<int>(cfg_.axes.size());
  for (int a = 0; a < n; ++a) {
    const auto i = static_cast<size_t>(a);
    if (axis_status_.drive_state[i] != cnc::lcmt_axis_status::ENABLED)
      return "axis " + cfg_.axes[i].name + " is " + drive_state_name(axis_status_.drive_state[i]) +
             ": enable the drives first (cnc-ctl --do reset does)";
    if (!std::isfinite(axis_status_.actual_mm[i]))
      return "axis " + cfg_.axes[i].name + ": the drive reports a position that is not a number";
  }
  out->num_axes = n;
  out->position_mm.assign(axis_status_.actual_mm.begin(), axis_status_.actual_mm.begin() + n);
  return "";
}

void InterpolatorNode::watch_drives() {
  const double now = util::monotonic_s();
  peers_.check(now);
  if (!active(core_.state()) || fault_) {
    drives_seen_enabled_ = false;
    return;
  }
  // The drive bridge gone: its heartbeat missing, or its status silent since the
  // program ran with it. Setpoints nobody follows are not streamed on.
  if (peers_.lost(kPeerBridge)) {
    fault(std::string("the drive bridge is lost: ") + peers_.last_lost_text());
    return;
  }
  if (drives_seen_enabled_ && now - axis_status_s_ > kStatusLost_s) {
    fault("no AXIS_STATUS from cnc-drive-bridge for " + std::to_string(now - axis_status_s_) +
          " s while the program runs: the drive bridge (or its host) is gone");
    return;
  }
  // A drive that leaves the enabled state while a program runs: the program cannot
  // go on where the machine is not following it.
  if (now - axis_status_s_ > kStatusFresh_s) return;
  drives_seen_enabled_ = true;
  for (size_t i = 0; i < cfg_.axes.size(); ++i) {
    if (axis_status_.drive_state[i] == cnc::lcmt_axis_status::ENABLED) continue;
    const std::string& text = axis_status_.fault[i];
    fault("axis " + cfg_.axes[i].name + " is " + drive_state_name(axis_status_.drive_state[i]) +
          (text.empty() ? std::string() : " (" + text + ")"));
    return;
  }
}

void InterpolatorNode::request_blocks() {
  const RunState s = core_.state();
  if (token_ == 0 || !(s == RunState::kRunning || s == RunState::kStarved || s == RunState::kHeld)) return;
  const int64_t first = core_.next_block_index();
  const int64_t capacity = feed_.room(core_);
  const int64_t end = std::min(first + capacity, num_blocks_);
  int64_t missing = first;
  while (missing < end && reorder_.count(missing)) ++missing;
  if (missing >= end) return;
  const int64_t now = core_.cycle();
  if (last_request_first_ < 0) requested_end_ = -1;  // a new load or START: nothing in flight
  if (missing != waiting_for_) {
    waiting_for_ = missing;
    waiting_since_ = now;
  }
  // Ask in batches of half a window (or for the tail of the program) for blocks not
  // asked for yet: those asked for are in flight. All of them again from the first
  // missing one when it has not come for a while: a lost request or block only
  // delays. (Asking for the window's whole rest each cycle made the server send each
  // block five times at 6,000 blocks/s, fall behind and miss its heartbeats.)
  const bool lost = now - waiting_since_ >= resend_cycles_ && now - last_resend_cycle_ >= resend_cycles_;
  const int64_t from = lost ? missing : std::max(missing, requested_end_);
  if (from >= end) return;
  const bool batch_ready = end - from >= std::max<int64_t>(1, cfg_.block_window / 2) || end == num_blocks_;
  if (!lost && !batch_ready) return;
  cnc::lcmt_block_request r{};
  r.program_token = token_;
  r.first_block = from;
  r.count = static_cast<int32_t>(end - from);
  bus_.publish(ch_request_, r);
  last_request_first_ = from;
  requested_end_ = std::max(requested_end_, end);
  if (lost) {
    last_resend_cycle_ = now;
    waiting_since_ = now;
  }
}

void InterpolatorNode::cycle() {
  try {
    run_cycle();
  } catch (const std::exception& e) {
    fault(std::string("exception in cycle ") + std::to_string(core_.cycle()) + ": " + e.what());
  } catch (...) {
    fault("unknown exception in cycle " + std::to_string(core_.cycle()));
  }
  const double now = util::monotonic_s();
  if (health_.check(now)) fault(health_.cause());
  health_.report(now, "the interpolator stopped the program (recorded STOP) and is in FAULT until RESET");
}

void InterpolatorNode::run_cycle() {
  bus_.drain();
  flush_inputs();
  watch_drives();
  const int64_t cyc = core_.cycle();
  publish_config(cyc);
  apply_pending_load();
  apply_pending_commands();
  door_cycle();
  probe_cycle();
  input_cycle();
  manual_cycle();
  take_spindle_at_speed();
  take_spindle_position();
  take_spindle_speed();
  feed_planner(cyc);
  request_blocks();

  const Setpoint& sp = core_.step();
  if (sp.state == RunState::kDone) done_token_ = token_;
  publish_setpoint(sp);
  publish_spindle(cyc);
  publish_io(cyc);
  publish_state(false);
}

void InterpolatorNode::take_spindle_at_speed() {
  if (!core_.spindle_waiting()) return;
  const int64_t seq = spindle_seq_base_ + core_.spindle().seq;
  // An orientation (M19 Q) is done when the bridge reports it oriented.
  if ((core_.spindle().orient ? spindle_oriented_seq_ : spindle_at_speed_seq_) < seq) return;
  cnc::lcmt_program_command m{};
  m.command = cnc::lcmt_program_command::SPINDLE_AT_SPEED;
  m.value = static_cast<double>(core_.spindle().seq);
  Command c;
  c.kind = Command::Kind::kSpindleAtSpeed;
  c.value = m.value;
  apply_command(c, m);
}

void InterpolatorNode::take_spindle_position() {
  // While a synchronised move is queued: the newest sample, once, a recorded input.
  if (!spindle_pos_new_ || !core_.wants_spindle_position()) return;
  spindle_pos_new_ = false;
  spindle_pos_cmd_.command = cnc::lcmt_program_command::SPINDLE_POSITION;
  spindle_pos_cmd_.num_axes = 3;
  spindle_pos_cmd_.position_mm.assign(spindle_pos_.begin(), spindle_pos_.end());  // capacity 3 from the first
  Command c;
  c.kind = Command::Kind::kSpindlePosition;
  for (size_t i = 0; i < 3; ++i) c.position_mm[i] = spindle_pos_[i];
  apply_command(c, spindle_pos_cmd_);
}

void InterpolatorNode::take_spindle_speed() {
  // Only when the process laws' scale would change: a steady spindle adds nothing to the log.
  if (!spindle_rpm_new_) return;
  spindle_rpm_new_ = false;
  if (core_.law_scale_for(spindle_rpm_) == core_.law_scale()) return;
  cnc::lcmt_program_command m{};
  m.command = cnc::lcmt_program_command::SPINDLE_SPEED;
  m.value = spindle_rpm_;
  Command c;
  c.kind = Command::Kind::kSpindleSpeed;
  c.value = m.value;
  apply_command(c, m);
}

void InterpolatorNode::publish_spindle(int64_t cyc) {
  // With every change, and again every 0.1 s: a lost datagram only delays the change.
  if (!cfg_.spindle.enabled) return;
  const SpindleState& s = core_.spindle();
  const int64_t seq = spindle_seq_base_ + s.seq;
  const int64_t repeat = std::max<int64_t>(1, std::llround(0.1 / cfg_.ipo_period_s));
  if (seq == spindle_sent_seq_ && cyc - spindle_sent_cycle_ < repeat) return;
  spindle_msg_.command_seq = seq;
  spindle_msg_.direction = static_cast<int8_t>(s.direction);
  spindle_msg_.rpm = s.rpm;
  spindle_msg_.stream = stream_;
  spindle_msg_.orient = s.orient;
  spindle_msg_.orient_deg = s.orient ? s.orient_deg : 0.0;
  spindle_msg_.orient_mode = static_cast<int8_t>(s.orient ? s.orient_mode : 0);
  if (bus_.publish(ch_spindle_cmd_, spindle_msg_)) {
    spindle_sent_seq_ = seq;
    spindle_sent_cycle_ = cyc;
  }
}

void InterpolatorNode::publish_io(int64_t cyc) {
  // As the spindle's: with every change, and again every 0.1 s.
  if (!cfg_.io.enabled) return;
  const MachineOutputs& o = core_.outputs();
  const int64_t seq = io_seq_base_ + o.seq;
  const int64_t repeat = std::max<int64_t>(1, std::llround(0.1 / cfg_.ipo_period_s));
  if (seq == io_sent_seq_ && cyc - io_sent_cycle_ < repeat) return;
  io_msg_.command_seq = seq;
  io_msg_.coolant = static_cast<int8_t>(o.coolant);
  io_msg_.outputs = static_cast<int64_t>(o.outputs);
  for (size_t n = 0; n < io_msg_.analog.size(); ++n) io_msg_.analog[n] = o.analog[n];
  io_msg_.stream = stream_;
  if (bus_.publish(ch_io_cmd_, io_msg_)) {
    io_sent_seq_ = seq;
    io_sent_cycle_ = cyc;
  }
}

void InterpolatorNode::publish_config(int64_t cyc) {
  // The config as loaded, at start and about once a second: a log alone replays.
  if (cyc % config_period_cycles_ != 0) return;
  cnc::lcmt_config c{};
  c.service = "cnc-interpolator";
  c.source_file = config_file_;
  c.yaml = cfg_.source_text;
  c.cycle = cyc;
  bus_.publish(ch_config_, c);
}

void InterpolatorNode::apply_pending_load() {
  if (!load_pending_) return;
  load_pending_ = false;
  cnc::lcmt_program_command m{};
  m.command = cnc::lcmt_program_command::LOAD;
  m.program_path = program_path_;
  apply_command(Command{Command::Kind::kLoad, 1.0}, m);
  last_request_first_ = -1;
  probe_.results = 0;
  probe_.result_block = -1;
  probe_.block = -1;
}

void InterpolatorNode::apply_pending_commands() {
  for (const auto& m : pending_commands_) apply_pending_command(m);
  pending_commands_.clear();
}

void InterpolatorNode::apply_pending_command(const cnc::lcmt_program_command& m) {
  using PC = cnc::lcmt_program_command;
  if (m.command == PC::RESET) {
    apply_reset(m);
    return;
  }
  if (door_open_ && door_refuses(m)) return;
  if (m.command == PC::HOME || m.command == PC::JOG || m.command == PC::JOG_KEEPALIVE) {
    on_manual_command(m);
    return;
  }
  if (m.command == PC::CONFIRM) {
    approach_pending_ = false;
    return;
  }
  if (m.command == PC::HOMED || m.command == PC::SPINDLE_AT_SPEED || m.command == PC::PROBE_TRIP ||
      m.command == PC::SPINDLE_POSITION || m.command == PC::SPINDLE_SPEED) {
    spdlog::warn("{} from sender {} ignored: it is this interpolator's own input",
                 m.command == PC::HOMED              ? "HOMED"
                 : m.command == PC::PROBE_TRIP       ? "PROBE_TRIP"
                 : m.command == PC::SPINDLE_POSITION ? "SPINDLE_POSITION"
                 : m.command == PC::SPINDLE_SPEED    ? "SPINDLE_SPEED"
                                                     : "SPINDLE_AT_SPEED",
                 m.sender);
    return;
  }
  if (m.command == PC::STOP && manual_ == Manual::kHome) manual_stop("homing stopped by the operator");
  Command c;
  if (m.command == PC::LOAD || !to_core_command(m, &c)) return;  // LOAD: via PROGRAM_STATE
  if (fault_ && (c.kind == Command::Kind::kStart || c.kind == Command::Kind::kResume)) {
    spdlog::warn("{} refused: in FAULT ({}); RESET first", c.kind == Command::Kind::kStart ? "START" : "RESUME",
                 fault_cause_);
    return;
  }
  if (c.kind == Command::Kind::kStart) {
    if (start_refused()) return;
    last_request_first_ = -1;
  }
  if (c.kind == Command::Kind::kOverride &&
      (!std::isfinite(m.feed_override) || m.feed_override < 0 || m.feed_override > motion::kMaxFeedOverride)) {
    spdlog::warn("feed override {} outside 0..{}: ignored (seq {})", m.feed_override, motion::kMaxFeedOverride, m.seq);
    return;
  }
  if (c.kind == Command::Kind::kRapidOverride &&
      (!std::isfinite(m.feed_override) || m.feed_override < 0 || m.feed_override > 1)) {
    spdlog::warn("rapid override {} outside 0..1: ignored (seq {})", m.feed_override, m.seq);
    return;
  }
  if (c.kind == Command::Kind::kSpindleOverride &&
      (!std::isfinite(m.feed_override) || m.feed_override < cfg_.spindle.min_override ||
       m.feed_override > cfg_.spindle.max_override)) {
    spdlog::warn("spindle override {} outside {}..{}: ignored (seq {})", m.feed_override, cfg_.spindle.min_override,
                 cfg_.spindle.max_override, m.seq);
    return;
  }
  if (c.kind == Command::Kind::kRapidOverride) spdlog::info("rapid override {}", m.feed_override);
  if (c.kind == Command::Kind::kSpindleOverride) spdlog::info("spindle override {}", m.feed_override);
  if (c.kind == Command::Kind::kStart) spdlog::info("START {} (token {})", program_path_, token_);
  apply_command(c, m);
  if (c.kind == Command::Kind::kSingleBlock || c.kind == Command::Kind::kOptionalStop) {
    spdlog::info("{} {}", c.kind == Command::Kind::kSingleBlock ? "single block" : "optional stop (M1)",
                 c.value != 0 ? "on" : "off");
    publish_state(true);
  }
}

bool InterpolatorNode::door_refuses(const cnc::lcmt_program_command& m) {
  using PC = cnc::lcmt_program_command;
  const char* what = m.command == PC::START    ? "START"
                     : m.command == PC::RESUME ? "RESUME"
                     : m.command == PC::JOG    ? "JOG"
                     : m.command == PC::HOME   ? "HOME"
                                               : nullptr;
  if (!what) return false;
  const std::string text = std::string(what) + " refused: the guard door (input " + door_input_ + ") is open: shut it first";
  spdlog::warn("{}", text);
  alarm(cnc::lcmt_alarm::WARNING, "door_refused", text);
  return true;
}

void InterpolatorNode::door_cycle() {
  if (!door_open_) {
    if (door_acted_) publish_state(true);  // shut: the program server's interlock lets motion go
    door_acted_ = false;
    return;
  }
  if (door_acted_) return;
  door_acted_ = true;
  publish_state(true);
  if (manual_ != Manual::kNone) {
    manual_stop("the guard door (input " + door_input_ + ") opened");
    return;
  }
  const RunState s = core_.state();
  if (s != RunState::kRunning && s != RunState::kStarved && s != RunState::kHeld) return;
  cnc::lcmt_program_command m{};
  m.command = cnc::lcmt_program_command::HOLD;
  m.value = 1;  // the door's: the spindle stops once the path stands
  apply_command(Command{Command::Kind::kHold, 1.0, {}, -1, 1.0}, m);
  const std::string text = "the guard door (input " + door_input_ +
                           ") opened: feed hold, the spindle stops once the path stands; shut it and RESUME";
  spdlog::warn("{}", text);
  alarm(cnc::lcmt_alarm::WARNING, "door_hold", text);
}

void InterpolatorNode::apply_reset(const cnc::lcmt_program_command& m) {
  cnc::lcmt_program_command r = m;
  const std::string why = reset_position(&r);
  Command c;
  if (!why.empty() || !to_core_command(r, &c)) {
    spdlog::warn("RESET refused: {}", why);
    alarm(cnc::lcmt_alarm::WARNING, "reset_refused", "RESET refused: " + why);
    return;
  }
  apply_command(c, r);
  // The path jumps to where the drives stand: receivers must not take the
  // setpoints before and after for one stream.
  stream_ = util::next_token(stream_);
  const bool was_fault = fault_;
  fault_ = false;
  fault_cause_.clear();
  detail_.clear();
  retired_token_ = std::max(retired_token_, token_);
  token_ = 0;
  num_blocks_ = 0;
  load_pending_ = false;
  reorder_.clear();
  std::string where;
  for (size_t a = 0; a < cfg_.axes.size(); ++a)
    where += (a ? ", " : "") + cfg_.axes[a].name + " " + std::to_string(r.position_mm[a]);
  spdlog::info("reset{}: the path stands where the drives are ({})", was_fault ? " from FAULT" : "", where);
  alarm(cnc::lcmt_alarm::INFO, "reset", std::string(was_fault ? "fault cleared; " : "") +
                                            "the path stands where the drives are: " + where + " mm");
}

bool InterpolatorNode::start_refused() {
  if (peers_.lost(kPeerBridge)) {
    spdlog::warn("START refused: the drive bridge is lost ({})", peers_.last_lost_text());
    alarm(cnc::lcmt_alarm::WARNING, "start_refused",
          std::string("START refused: the drive bridge is lost: ") + peers_.last_lost_text());
    return true;
  }
  if (util::monotonic_s() - axis_status_s_ <= kStatusFresh_s) {
    std::string why;
    for (size_t i = 0; i < cfg_.axes.size() && why.empty(); ++i)
      if (axis_status_.drive_state[i] != cnc::lcmt_axis_status::ENABLED)
        why = "axis " + cfg_.axes[i].name + " is " + drive_state_name(axis_status_.drive_state[i]);
    if (!why.empty()) {
      spdlog::warn("START refused: {}: enable the drives first", why);
      return true;
    }
  }
  if (manual_ != Manual::kNone || !unhomed().empty()) {
    const std::string why = manual_ != Manual::kNone ? manual_text_ + " runs: STOP it first" : unhomed() + ": HOME first";
    spdlog::warn("START refused: {}", why);
    alarm(cnc::lcmt_alarm::WARNING, "start_refused", "START refused: " + why);
    return true;
  }
  if (approach_pending_) {
    spdlog::warn("START refused: program {} runs from a line: its approach waits for CONFIRM", program_path_);
    return true;
  }
  if (core_.state() == RunState::kDone && token_ == done_token_) {
    // A START sent again (cnc-ctl repeats one whose answer it did not see) after the
    // program's end: the program ran once; it would stand STARVED with nothing to run.
    spdlog::warn("START ignored: program {} has ended (LOAD it again)", program_path_);
    return true;
  }
  if (token_ == 0) {
    spdlog::warn("START without a loaded program: ignored");
    return true;
  }
  return false;
}

void InterpolatorNode::feed_planner(int64_t cyc) {
  // Feed the planner and take its finished plans (the one feed policy of the core
  // library, feed_policy.h). Each block handed over and each group of plans taken is
  // an input recorded with this cycle: replay takes the plans at the same cycles.
  std::string bad;
  int64_t bad_index = -1;
  const bool fed = feed_.cycle(
      core_,
      [&](int64_t index) -> std::unique_ptr<program::Block> {
        const auto it = reorder_.find(index);
        if (it == reorder_.end()) return nullptr;
        auto b = std::make_unique<program::Block>();
        bad = program::from_msg(it->second, static_cast<int>(cfg_.axes.size()), b.get());
        if (!bad.empty()) {
          bad_index = index;
          return nullptr;
        }
        return b;
      },
      [&](int64_t index) {
        const auto it = reorder_.find(index);
        cnc::lcmt_interp_input in{};
        in.cycle = cyc;
        in.kind = cnc::lcmt_interp_input::BLOCK;
        in.block = it->second;
        if (it->second.event_kind == program::kProbeWire) {
          probe_.file = it->second.source_file;
          probe_.line = it->second.source_line;
        }
        publish_input(in);
        reorder_.erase(it);
      },
      [&](int n) {
        cnc::lcmt_interp_input in{};
        in.cycle = cyc;
        in.kind = cnc::lcmt_interp_input::PLAN;
        in.plans = n;
        in.block.num_axes = 0;
        publish_input(in);
      });
  std::string failure = core_.take_plan_failure();
  if (!fed || bad_index >= 0 || !failure.empty()) stop_on_refused_block(bad_index, bad, failure);
}

void InterpolatorNode::stop_on_refused_block(int64_t bad_index, const std::string& bad, const std::string& failure) {
  // A block the core cannot take ends the program: the path stops where it is
  // (a recorded STOP) and the operator is told why. Nothing more is requested.
  const int64_t index = bad_index >= 0 ? bad_index : core_.next_block_index();
  const auto it = reorder_.find(index);
  const std::string line = it != reorder_.end() ? " (line " + std::to_string(it->second.source_line) + ")" : "";
  const std::string text = failure.empty() ? "block " + std::to_string(index) + line + " refused: " +
                                                 (bad.empty() ? core_.last_refusal() : bad)
                                           : "refused: " + failure;
  spdlog::error("{}", text);
  cnc::lcmt_alarm al{};
  al.source = "cnc-interpolator";
  al.severity = cnc::lcmt_alarm::FAULT;
  al.code = "block_refused";
  al.text = text;
  bus_.publish(ch_alarm_, al);
  cnc::lcmt_program_command stop{};
  stop.command = cnc::lcmt_program_command::STOP;
  apply_command(Command{Command::Kind::kStop, 1.0, {}}, stop);
  token_ = 0;
  reorder_.clear();
}

void InterpolatorNode::publish_setpoint(const Setpoint& sp) {
  cnc::lcmt_setpoint& out = setpoint_msg_;
  out.cycle = sp.cycle;
  out.period_s = cfg_.ipo_period_s;
  out.num_axes = sp.num_axes;
  out.position_mm.assign(sp.position_mm.begin(), sp.position_mm.begin() + sp.num_axes);
  // The setpoints of the cycles just before, newest first, as far as they run
  // unbroken up to this one: a receiver that lost them gets them back exactly.
  const int na = std::min(sp.num_axes, program::kMaxAxes);
  int have = 0;
  out.prev_position_mm.resize(static_cast<size_t>(kSetpointHistory * na));
  for (int j = 1; j <= kSetpointHistory; ++j) {
    const PastSetpoint& p = past_[static_cast<size_t>((past_head_ - j + 2 * kSetpointHistory) % kSetpointHistory)];
    if (p.cycle != sp.cycle - j) break;
    for (int a = 0; a < na; ++a) out.prev_position_mm[static_cast<size_t>(have * na + a)] = p.pos[static_cast<size_t>(a)];
    ++have;
  }
  out.prev_position_mm.resize(static_cast<size_t>(have * na));
  out.num_prev_values = have * na;
  PastSetpoint& cur = past_[static_cast<size_t>(past_head_)];
  cur.cycle = sp.cycle;
  for (int a = 0; a < na; ++a) cur.pos[static_cast<size_t>(a)] = sp.position_mm[static_cast<size_t>(a)];
  past_head_ = (past_head_ + 1) % kSetpointHistory;
  out.feed_mm_per_min = sp.feed_mm_per_min;
  out.program_token = token_;
  out.block_index = sp.block_index;
  out.source_line = sp.source_line;
  out.u = sp.u;
  out.limit = static_cast<int8_t>(sp.limit);
  out.state = static_cast<int8_t>(sp.state);
  out.stream = stream_;
  out.engagement = axis_status_.engagement;
  bus_.publish(ch_setpoints_, out);
  ++setpoints_published_;
}

void InterpolatorNode::publish_state(bool force) {
  const RunState s = core_.state();
  const int64_t now = core_.cycle();
  if (!force && s == last_state_ && fault_ == last_fault_ && manual_ == last_manual_ &&
      now - last_state_cycle_ < resend_cycles_)
    return;
  last_manual_ = manual_;
  last_state_ = s;
  last_fault_ = fault_;
  last_state_cycle_ = now;
  cnc::lcmt_interp_state m{};
  m.cycle = now;
  m.state = fault_ ? cnc::lcmt_setpoint::FAULT : static_cast<int8_t>(s);
  m.program_token = token_;
  m.blocks_done = core_.blocks_done();
  m.blocks_buffered = static_cast<int64_t>(core_.queued_blocks() + reorder_.size()) + core_.blocks_in_planning();
  m.setpoints_published = setpoints_published_;
  m.starved_cycles = core_.starved_cycles();
  m.feed_override = core_.feed_override();
  m.rapid_override = core_.rapid_override();
  m.spindle_override = core_.spindle_override();
  m.spindle_override_enabled = core_.spindle_override_enabled() ? 1 : 0;
  m.door_open = door_open_ ? 1 : 0;
  m.program_time_s = core_.program_time_s();
  m.num_axes = core_.last().num_axes > 0 ? core_.last().num_axes : static_cast<int32_t>(cfg_.axes.size());
  // Machine coordinates (the setpoints are the drives', which differ by a homed axis's offset).
  for (int a = 0; a < m.num_axes; ++a) m.position_mm.push_back(core_.machine_position(a));
  m.mode = static_cast<int8_t>(manual_);
  m.num_homed = m.num_axes;
  for (int a = 0; a < m.num_axes; ++a) m.homed.push_back(core_.homed(a) ? 1 : 0);
  m.mode_text = manual_text_;
  m.single_block = core_.single_block() ? 1 : 0;
  m.optional_stop = core_.optional_stop() ? 1 : 0;
  m.source_line = core_.last().source_line;
  m.probe_results = probe_.results;
  m.probe_block = probe_.result_block;
  m.probe_tripped = probe_.tripped ? 1 : 0;
  m.num_probe_axes = probe_.results > 0 ? m.num_axes : 0;
  for (int a = 0; a < m.num_probe_axes; ++a) {
    m.probe_trip_mm.push_back(probe_.trip[static_cast<size_t>(a)]);
    m.probe_rest_mm.push_back(probe_.rest[static_cast<size_t>(a)]);
  }
  const InputWaitState& iw = core_.input_wait();
  m.input_results = static_cast<int32_t>(iw.results);
  m.input_block = iw.results > 0 ? iw.block_index : -1;
  m.input_value = iw.results > 0 ? iw.value : 0;
  m.input_waiting = iw.waiting ? 1 : 0;
  m.input_wait = iw.waiting ? iw.wait.number() : 0;
  m.input_wait_left_s =
      iw.waiting && iw.timeout_cycles > 0
          ? static_cast<double>(std::max<int64_t>(0, iw.timeout_cycles - (now - iw.start_cycle))) * cfg_.ipo_period_s
          : -1.0;
  bus_.publish(ch_state_, m);
}

}  // namespace cnc::interp
