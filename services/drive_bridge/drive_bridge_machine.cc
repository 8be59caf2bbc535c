#include "services/drive_bridge/drive_bridge_node.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "common/config/yaml_reader.h"
#include "common/drive/delta_vfd_profile.h"
#include "common/drive/link_factory.h"
#include "common/drive/loopback_link.h"
#include "common/util/clock.h"

// The machine beside the axes: the spindle drive, the I/O modules and what reads
// them (the E-stop, hard limits, guard door, probe), set up and run each servo tick.
namespace cnc::bridge {

namespace ch = config::channels;
// An E-stop disables the drives once they stand on the stopped command, at most this long after it.
constexpr double kStandstillWaitS = 0.2;
// A spindle drive slower than this has run down: a CiA-402 drive's power goes off.
constexpr double kStillRpm = 1.0;
using cnc::lcmt_axis_status;

// The spindle drive on its link (config spindle:), and its commands.
void DriveBridgeNode::make_spindle(std::map<std::string, LinkWorker*>& by_link) {
  const config::DriveConfig& d = cfg_.spindle.drive;
  const std::string file = drive::find_drive_profile(d.profile, cfg_.source_file, cfg_.drive_profile_dir);
  if (!std::filesystem::exists(file))
    throw config::ConfigError(cfg_.source_file, "spindle.drive.profile",
                              "no drive profile '" + d.profile + "' (looked for " + file + ")");
  profiles_.push_back(std::make_unique<drive::DriveProfile>(drive::load_drive_profile(file)));
  spindle_ = std::make_unique<Spindle>(cfg_.spindle);
  spindle_->profile = profiles_.back().get();
  if (!drive::is_spindle_profile(*spindle_->profile))
    throw config::ConfigError(cfg_.source_file, "spindle.drive.profile",
                              "'" + d.profile + "' is no spindle drive's profile (its state_machine is " +
                                  spindle_->profile->state_machine +
                                  ", a spindle needs delta_vfd, huanyang or cia402_velocity)");
  // A Huanyang's frames are no Modbus: TCP (or a Modbus gateway) cannot carry them.
  if (spindle_->profile->huanyang.present && drive::transport_of(d) == drive::Transport::kModbusTcp)
    throw config::ConfigError(cfg_.source_file, "spindle.drive.transport",
                              "modbus_tcp cannot carry the Huanyang protocol of profile '" + d.profile +
                                  "' (its own function codes on RS-485, no Modbus): use modbus_rtu");
  spindle_->worker = worker_for(d, by_link);
  const double max_hz = cfg_.spindle.max_rpm / cfg_.spindle.rpm_per_hz;
  if (auto* loopback = dynamic_cast<drive::LoopbackLink*>(&spindle_->worker->link()))
    loopback->add_vfd(d.unit_id, *spindle_->profile, cfg_.spindle.sim, max_hz, cfg_.spindle.rpm_per_hz,
                      cfg_.spindle.encoder_counts_per_rev);
  const drive::DriveProfile& p = *spindle_->profile;
  if (cfg_.spindle.encoder_counts_per_rev > 0) {
    if (!p.has(drive::Role::kEncoderPosition))
      throw config::ConfigError(cfg_.source_file, "spindle.encoder_counts_per_rev",
                                std::to_string(cfg_.spindle.encoder_counts_per_rev) + " counts: the spindle's drive profile '" +
                                    p.name + "' (" + p.file + ") maps no encoder (registers.encoder_position)");
    // The position loop's speed command in steps of the drive's: an error below half a step
    // over the gain commands nothing. That dead zone must lie within the tolerance.
    const double step_rpm = cfg_.spindle.rpm_per_hz / p.field(drive::Role::kSpeedSetpoint).scale;
    const double dead_deg = step_rpm / 60 / (2 * cfg_.spindle.orient_gain_per_s) * 360;
    if (dead_deg > cfg_.spindle.orient_tolerance_deg) {
      char b[320];
      std::snprintf(b, sizeof b,
                    "%g deg: the drive's speed step (%.3g rpm, profile '%s') at spindle.orient_gain_per_s %g leaves the "
                    "orientation's position loop a dead zone of %.3g deg: raise the tolerance or the gain",
                    cfg_.spindle.orient_tolerance_deg, step_rpm, p.name.c_str(), cfg_.spindle.orient_gain_per_s, dead_deg);
      throw config::ConfigError(cfg_.source_file, "spindle.orient_tolerance_deg", b);
    }
  }
  spindle_->worker->add_spindle(p, d.unit_id, max_hz, cfg_.spindle.rpm_per_hz);
  ch_spindle_status_ = cfg_.channel(ch::kSpindleStatus);
  bus_.subscribe<cnc::lcmt_spindle_command>(cfg_.channel(ch::kSpindleCmd), [this](const auto& m) {
    Spindle& sp = *spindle_;
    if (m.command_seq <= sp.pending_seq) return;  // the newest change wins; a repeat changes nothing
    sp.pending = true;
    sp.pending_seq = m.command_seq;
    sp.pending_direction = m.direction;
    sp.pending_rpm = m.rpm;
    sp.pending_orient = m.orient;
    sp.pending_orient_deg = m.orient_deg;
    sp.pending_orient_mode = m.orient_mode;
  });
}

// The I/O modules on their links (config io:), the status message's fixed part,
// the safety chain's and the probe's inputs, and the output commands.
void DriveBridgeNode::make_io(std::map<std::string, LinkWorker*>& by_link) {
  std::vector<IoModule> modules(cfg_.io.modules.size());
  std::vector<std::vector<int>> coils;
  for (size_t m = 0; m < cfg_.io.modules.size(); ++m) {
    const config::DriveConfig& d = cfg_.io.modules[m].link;
    IoModule& mod = modules[m];
    mod.worker = worker_for(d, by_link);
    if (auto* loopback = dynamic_cast<drive::LoopbackLink*>(&mod.worker->link()))
      loopback->add_io_module(d.unit_id, cfg_.io, static_cast<int>(m));
    try {
      mod.slot = mod.worker->add_io_module(cfg_.io, static_cast<int>(m));
    } catch (const std::invalid_argument& e) {
      throw config::ConfigError(cfg_.source_file, "io.points", e.what());
    }
    for (size_t k = 0; k < 4; ++k)
      mod.points[k] = mod.worker->io_module(mod.slot).points(static_cast<config::IoKind>(k));
    coils.push_back(mod.points[static_cast<size_t>(config::IoKind::kCoil)]);
  }
  std::vector<std::vector<int>> holding;
  for (const IoModule& mod : modules) holding.push_back(mod.points[static_cast<size_t>(config::IoKind::kHoldingRegister)]);
  io_ = std::make_unique<Io>(cfg_.io, coils, holding);
  io_->pending_analog.assign(cfg_.io.analog_outputs.size(), 0.0);
  io_->modules = std::move(modules);
  ch_io_status_ = cfg_.channel(ch::kIoStatus);
  cnc::lcmt_io_status& m = io_msg_;
  m.num_points = static_cast<int32_t>(cfg_.io.points.size());
  m.name.resize(cfg_.io.points.size());
  m.kind.resize(cfg_.io.points.size());
  m.value.assign(cfg_.io.points.size(), 0.0);
  m.valid.assign(cfg_.io.points.size(), false);
  for (size_t i = 0; i < cfg_.io.points.size(); ++i) {
    m.name[i] = cfg_.io.points[i].name;
    m.kind[i] = static_cast<int8_t>(cfg_.io.points[i].kind);
  }
  const size_t nm = cfg_.io.modules.size();
  m.num_modules = static_cast<int32_t>(nm);
  m.module.resize(nm);
  for (size_t i = 0; i < nm; ++i) m.module[i] = cfg_.io.modules[i].name;
  m.answering.assign(nm, false);
  m.transactions.assign(nm, 0);
  m.timeouts.assign(nm, 0);
  m.exceptions.assign(nm, 0);
  m.last_error.assign(nm, std::string());
  for (auto& e : m.last_error) e.reserve(96);
  m.estop = cnc::lcmt_io_status::ESTOP_NONE;
  m.estop_stop_ms = -1;
  auto bit_of = [&](int point, int& module, size_t& bit) {
    const config::IoPointConfig& p = cfg_.io.points[static_cast<size_t>(point)];
    const auto& di = io_->modules[static_cast<size_t>(p.module)].points[static_cast<size_t>(config::IoKind::kDiscreteInput)];
    for (size_t i = 0; i < di.size(); ++i)
      if (di[i] == point) bit = i;
    module = p.module;
  };
  for (const auto& h : cfg_.safety.hard_limits)
    for (int end : {-1, 1}) {
      const int point = end < 0 ? h.min_input : h.max_input;
      if (point < 0) continue;
      LimitInput l;
      l.axis = static_cast<size_t>(h.axis);
      l.end = end;
      l.point = point;
      bit_of(point, l.module, l.bit);
      limits_.push_back(l);
    }
  if (cfg_.safety.door_input >= 0) {
    bit_of(cfg_.safety.door_input, door_.module, door_.bit);
    m.door_input = cfg_.io.points[static_cast<size_t>(cfg_.safety.door_input)].name;
  }
  m.limit_stop_ms = -1;
  if (cfg_.safety.estop_input >= 0) {
    bit_of(cfg_.safety.estop_input, estop_.module, estop_.bit);
    m.estop_input = cfg_.io.points[static_cast<size_t>(cfg_.safety.estop_input)].name;
  }
  if (cfg_.probe.input >= 0) {
    bit_of(cfg_.probe.input, probe_.module, probe_.bit);
    probe_.rise_mm.assign(cfg_.axes.size(), 0.0);
    probe_.fall_mm.assign(cfg_.axes.size(), 0.0);
    for (int d : {0, 1}) {
      probe_.edge[d].sampled_mm.assign(cfg_.axes.size(), 0.0);
      probe_.counter[d].assign(cfg_.axes.size(), ProbeLatch::DriveCounter{});
    }
  }
  bus_.subscribe<cnc::lcmt_io_command>(cfg_.channel(ch::kIoCmd), [this](const auto& c) {
    Io& io = *io_;
    if (c.command_seq <= io.pending_seq) return;  // the newest change wins; a repeat changes nothing
    io.pending = true;
    io.pending_seq = c.command_seq;
    io.pending_coolant = c.coolant;
    io.pending_outputs = static_cast<uint64_t>(c.outputs);
    // The analog outputs' values (one per io.analog_outputs, finite); otherwise kept as they were.
    if (c.num_analog == static_cast<int32_t>(io.pending_analog.size()) && c.analog.size() == io.pending_analog.size()) {
      bool finite = true;
      for (double v : c.analog) finite = finite && std::isfinite(v);
      if (finite) {
        std::copy(c.analog.begin(), c.analog.end(), io.pending_analog.begin());
        io.analog_known = true;
      }
      else spdlog::warn("io: IO_CMD seq {} carries an analog output that is not finite: the analog outputs are kept", c.seq);
    } else if (!io.pending_analog.empty()) {
      spdlog::warn("io: IO_CMD seq {} carries {} analog outputs, the config has {}: the analog outputs are kept", c.seq,
                   c.num_analog, io.pending_analog.size());
    }
  });
}

void DriveBridgeNode::spindle_tick(double now_s) {
  if (!spindle_) return;
  Spindle& sp = *spindle_;
  sp.rep = sp.worker->spindle_report();
  // The spindle turns only while the bridge follows setpoints: a command that comes
  // otherwise is spent, and any fault or stop of the bridge stops it.
  const bool following = state_ == State::kEnabled && !core_.faulted();
  const bool was_at_speed = sp.ctl.at_speed();
  if (sp.pending) {
    sp.pending = false;
    const int64_t before = sp.ctl.command_seq();
    if (sp.pending_orient)
      sp.ctl.on_orient(sp.pending_seq, sp.pending_orient_deg, sp.pending_orient_mode, following, now_s);
    else
      sp.ctl.on_command(sp.pending_seq, sp.pending_direction, sp.pending_rpm, following, now_s);
    // A line per change (events, not every tick).
    if (sp.ctl.command_seq() != before && sp.pending_orient)
      spdlog::info("spindle: change {}: orient to {:.2f} deg ({}){}", sp.ctl.command_seq(), sp.pending_orient_deg,
                   sp.pending_orient_mode == 1 ? "clockwise" : sp.pending_orient_mode == 2 ? "counterclockwise" : "shortest way",
                   following ? "" : " (not followed: the drives do not follow setpoints)");
    else if (sp.ctl.command_seq() != before)
      spdlog::info("spindle: change {}: {} {:.0f} rpm{}", sp.ctl.command_seq(),
                   sp.ctl.direction() > 0 ? "clockwise" : sp.ctl.direction() < 0 ? "counterclockwise" : "stop",
                   sp.ctl.commanded_rpm(), following ? "" : " (not followed: the drives do not follow setpoints)");
  }
  if (!following) sp.ctl.stop();
  // A fault reset asked for (ENABLE, FAULT_RESET) takes a round or two to reach the
  // drive and come back: the fault it still reports meanwhile is not a new one.
  if (sp.reset_pending && now_s > sp.reset_deadline_s) sp.reset_pending = false;
  const bool resetting = sp.reset_pending && sp.rep.in.fault;
  sp.fb.answering = sp.rep.answering;
  sp.fb.have_status = sp.rep.in.valid;
  sp.fb.running = sp.rep.in.running;
  sp.fb.drive_fault = sp.rep.in.fault && !resetting;
  sp.fb.error_code = resetting ? 0 : sp.rep.in.error_code;
  sp.fb.output_hz = sp.rep.in.output_hz;
  sp.fb.lost_events = sp.rep.lost_events;
  sp.fb.last_error = sp.rep.last_error.data();
  sp.fb.setup_error = sp.rep.in.setup_error.data();
  sp.fb.has_position = sp.rep.in.valid && sp.rep.in.has_position;
  sp.fb.position_counts = sp.rep.in.position_counts;
  sp.fb.sample_s = sp.rep.sample_s;
  const OrientState orient_before = sp.ctl.orient_state();
  if (sp.ctl.update(sp.fb, now_s)) {
    if (state_ == State::kEnabled || state_ == State::kEnabling || state_ == State::kStopping) {
      fault(0, sp.ctl.fault_reason(), false);
    } else {
      spdlog::error("{}", sp.ctl.fault_reason());
      alarm(cnc::lcmt_alarm::FAULT, "spindle_fault", sp.ctl.fault_reason());
    }
  }
  if (!was_at_speed && sp.ctl.at_speed() && sp.ctl.direction() != 0)
    spdlog::info("spindle: at speed: {:.0f} rpm, {:.3f} s after change {}", sp.ctl.actual_rpm(sp.fb),
                 sp.ctl.time_to_speed_s(now_s), sp.ctl.command_seq());
  if (orient_before == OrientState::kOrienting && sp.ctl.orient_state() == OrientState::kOriented)
    spdlog::info("spindle: oriented: at {:.3f} deg, {:.3f} s after change {}",
                 (sp.ctl.position_rev() - std::floor(sp.ctl.position_rev())) * 360, sp.ctl.orient_age_s(now_s),
                 sp.ctl.command_seq());
  sp.cmd.direction = static_cast<int8_t>(sp.ctl.direction());
  sp.cmd.hz = sp.ctl.commanded_hz();
  // The drive's power (a CiA-402 drive's; a VFD runs by its command word): on while the
  // bridge follows setpoints, and after that until the spindle has run down at speed 0.
  // Its fault reset, asked for by ENABLE or FAULT_RESET, while it reports a fault.
  // A drive at fault is never enabled (a CiA-402 drive's enable would reset it unasked).
  const drive::SpindleInputs& in = sp.rep.in;
  if (in.valid && !in.fault) sp.reset_pending = false;
  const bool turning = in.valid && in.running && std::fabs(in.output_hz) * cfg_.spindle.rpm_per_hz > kStillRpm;
  const bool follows_now = state_ == State::kEnabled && !core_.faulted() && !sp.ctl.faulted();
  sp.cmd.goal = in.valid && in.fault ? (sp.reset_pending ? drive::Goal::kFaultReset : drive::Goal::kDisable)
                : follows_now || turning ? drive::Goal::kEnable
                                         : drive::Goal::kDisable;
}

void DriveBridgeNode::post_spindle_command(double now_s) {
  Spindle& sp = *spindle_;
  const bool playing = core_.mode() == BridgeCore::Mode::kFollowing && core_.last_cycle() >= 0;
  sp.cmd.tick_s = now_s;
  sp.cmd.playback_cycle = playing ? core_.playback_cycle() : -1.0;
  sp.cmd.playback_rate = core_.playback_rate();
  sp.worker->set_spindle_command(sp.cmd);
}

std::string DriveBridgeNode::limit_name(const LimitInput& l) const {
  return "axis " + cfg_.axes[l.axis].name + "'s " + (l.end < 0 ? "min" : "max") + " switch (input " +
         cfg_.io.point_label(l.point) + ")";
}

bool DriveBridgeNode::settled(double& since_s, double now_s) const {
  if (since_s < 0) since_s = now_s;
  bool still = true;
  for (const auto& a : axes_) still = still && (!a.rep.have_status || std::fabs(a.rep.fe_mm) <= 1e-3);
  for (const auto& j : joints_) still = still && (!j.drv.rep.have_status || std::fabs(j.drv.rep.fe_mm) <= 1e-3);
  return still || now_s - since_s >= kStandstillWaitS;
}

void DriveBridgeNode::limits_tick(double now_s) {
  const bool following = state_ == State::kEnabled && !core_.faulted();
  for (size_t k = 0; k < limits_.size(); ++k) {
    LimitInput& l = limits_[k];
    const IoModule& mod = io_->modules[static_cast<size_t>(l.module)];
    const bool answering = mod.rep.answering && mod.rep.in.valid;
    const bool ok = answering && ((mod.rep.in.discrete >> l.bit) & 1) != 0;
    const bool fell = l.ok && !ok;
    l.ok = ok;
    if (ok) continue;
    // Not following (standing, braking, disabled): setpoints of the next engagement may
    // take the axis no further towards the switch than where it comes to rest.
    if (core_.mode() != BridgeCore::Mode::kFollowing) l.bound_mm = core_.commanded()[l.axis];
    if (!fell || !following) continue;
    limit_.latched = true;
    limit_.stood = false;
    limit_.tripped = static_cast<int>(k);
    limit_.utime = util::wall_utime();
    limit_.at_s = now_s;
    limit_.stop_ms = -1;
    limit_.command_stood_s = -1;
    char at[64];
    std::snprintf(at, sizeof at, " at %.4f mm", core_.commanded()[l.axis]);
    const std::string text =
        "hard limit: " + limit_name(l) +
        (answering ? " reads 0 (the switch hit, or its wire cut)"
                   : std::string(" is not read: its module does not answer (") + mod.rep.last_error.data() + ")") +
        at + ": controlled stop, drives disabled";
    spdlog::error("{}", text);
    alarm(cnc::lcmt_alarm::FAULT, "hard_limit", text);
    fault(l.axis, text, false);  // brakes in this tick's core step
  }
  if (limit_.latched && !limit_.stood && core_.mode() != BridgeCore::Mode::kStopping &&
      settled(limit_.command_stood_s, now_s)) {
    limit_.stood = true;
    limit_.stop_ms = (now_s - limit_.at_s) * 1e3;
    for (auto& a : axes_) a.cmd.goal = drive::Goal::kDisable;
    for (auto& j : joints_) j.drv.cmd.goal = drive::Goal::kDisable;
    spdlog::info("hard limit: the axes stand {:.1f} ms after the trip ({}); drives disabled", limit_.stop_ms,
                 limit_name(limits_[static_cast<size_t>(limit_.tripped)]));
  }
}

int DriveBridgeNode::limit_towards(const AxisArray& p) const {
  // The stream starts where the drives stand, to within their following error at rest.
  constexpr double kJoinToleranceMm = 1e-3;
  for (size_t k = 0; k < limits_.size(); ++k) {
    const LimitInput& l = limits_[k];
    if (!l.ok && (p[l.axis] - l.bound_mm) * l.end > kJoinToleranceMm) return static_cast<int>(k);
  }
  return -1;
}

bool DriveBridgeNode::limits_hold_off(const AxisArray& p, const StreamStamp& from) {
  // A stream the core would join (the first since the engagement, or a newer one) that
  // stands towards a switch reading 0: not joined, no fault. It is the interpolator's
  // path from before the reset (its own brake ended beyond the bridge's); its RESET
  // makes a stream from where the drives stand.
  const bool joining = core_.last_cycle() < 0 || from.stream > core_.stream();
  if (!joining || from.engagement != core_.engagement() || from.stream < core_.stream()) return false;
  const int k = limit_towards(p);
  if (k < 0) return false;
  if (limit_.held_off != core_.engagement()) {
    limit_.held_off = core_.engagement();
    const LimitInput& l = limits_[static_cast<size_t>(k)];
    char b[160];
    std::snprintf(b, sizeof b, " reads 0: a setpoint stream at %.4f mm, towards it from %.4f mm, is not joined", p[l.axis],
                  l.bound_mm);
    const std::string text = "hard limit: " + limit_name(l) + b + ": RESET the interpolator (cnc-ctl --do reset)";
    spdlog::warn("{}", text);
    alarm(cnc::lcmt_alarm::WARNING, "hard_limit_not_joined", text);
  }
  return true;
}

bool DriveBridgeNode::limits_refuse(const AxisArray& p, int64_t cycle) {
  // A setpoint the core has just taken: the playback, a few cycles behind the newest
  // setpoint, has not moved towards it yet; refused, the stop begins from before it.
  // (One the core does not follow, a stale one or one it waits on, sets no bound.)
  const int k = limit_towards(p);
  if (k < 0) {
    for (LimitInput& l : limits_)
      if (!l.ok && (p[l.axis] - l.bound_mm) * l.end < 0) l.bound_mm = p[l.axis];  // moving off: no way back
    return false;
  }
  const LimitInput& l = limits_[static_cast<size_t>(k)];
  char b[160];
  std::snprintf(b, sizeof b, ": setpoint cycle %lld moves the axis towards it (to %.4f mm from %.4f mm)",
                static_cast<long long>(cycle), p[l.axis], l.bound_mm);
  const std::string text = "hard limit: " + limit_name(l) + " reads 0" + b + ": refused, controlled stop";
  spdlog::error("{}", text);
  alarm(cnc::lcmt_alarm::FAULT, "hard_limit_refused", text);
  fault(l.axis, text, false);
  return true;
}

void DriveBridgeNode::safety_tick(double now_s) {
  if (!limits_.empty()) limits_tick(now_s);
  if (door_.module >= 0) {
    const IoModule& mod = io_->modules[static_cast<size_t>(door_.module)];
    const bool ok = mod.rep.answering && mod.rep.in.valid && ((mod.rep.in.discrete >> door_.bit) & 1) != 0;
    if (!ok && door_.ok) door_.utime = util::wall_utime();
    if (ok != door_.ok && state_ != State::kStarting) {
      const std::string name = cfg_.io.point_label(cfg_.safety.door_input);
      const std::string text =
          ok ? "guard door: input " + name + " reads 1 (shut): RESUME to go on"
          : mod.rep.answering && mod.rep.in.valid ? "guard door: input " + name + " reads 0 (open): feed hold, motion refused until it is shut"
                              : "guard door: input " + name + " is not read: its module does not answer (" +
                                    mod.rep.last_error.data() + "): feed hold, motion refused until it is read shut";
      spdlog::warn("{}", text);
      alarm(ok ? cnc::lcmt_alarm::INFO : cnc::lcmt_alarm::WARNING, ok ? "door_closed" : "door_open", text);
    }
    door_.ok = ok;
  }
  if (estop_.module < 0) return;
  const IoModule& mod = io_->modules[static_cast<size_t>(estop_.module)];
  const bool answering = mod.rep.answering && mod.rep.in.valid;
  const bool ok = answering && ((mod.rep.in.discrete >> estop_.bit) & 1) != 0;
  // Named only where an alarm says it (the tick allocates nothing otherwise).
  auto label = [&] { return cfg_.io.point_label(cfg_.safety.estop_input); };
  if (ok && !estop_.ok && estop_.latched) {
    const std::string name = label();
    spdlog::warn("E-stop: input {} reads 1 again; the drives stay disabled until FAULT_RESET and ENABLE", name);
    alarm(cnc::lcmt_alarm::INFO, "estop_released",
          "E-stop input " + name + " reads 1 again: FAULT_RESET, then ENABLE (cnc-ctl --do fault-reset, --do reset)");
  }
  estop_.ok = ok;
  // Before the start-up ends (the module not read yet) there is nothing to stop.
  if (!ok && !estop_.latched && state_ != State::kStarting) {
    estop_.latched = true;
    estop_.stood = false;
    estop_.utime = util::wall_utime();
    estop_.at_s = now_s;
    estop_.stop_ms = -1;
    estop_.command_stood_s = -1;
    const std::string name = label();
    const std::string text =
        answering ? "E-stop: input " + name + " reads 0 (pressed, or its wire cut): controlled stop, drives disabled"
                  : "E-stop: input " + name + " is not read: its module does not answer (" + mod.rep.last_error.data() +
                        "): controlled stop, drives disabled";
    spdlog::error("{}", text);
    alarm(cnc::lcmt_alarm::FAULT, "estop", text);
    fault(0, text, false);  // brakes in this tick's core step; the spindle and coolant stop in this tick
  }
  if (estop_.latched && !estop_.stood && core_.mode() != BridgeCore::Mode::kStopping) {
    // The command stands (or was never engaged): the drives' power off once they have
    // settled on it (following error within 1 um), or kStandstillWaitS after it at most.
    if (!settled(estop_.command_stood_s, now_s)) return;
    estop_.stood = true;
    estop_.stop_ms = (now_s - estop_.at_s) * 1e3;
    for (auto& a : axes_) a.cmd.goal = drive::Goal::kDisable;
    for (auto& j : joints_) j.drv.cmd.goal = drive::Goal::kDisable;
    spdlog::info("E-stop: the axes stand {:.1f} ms after the E-stop (input {}); drives disabled", estop_.stop_ms, label());
  }
}

bool DriveBridgeNode::safety_refuses_enable() {
  if (limit_.latched) {
    const std::string text = "ENABLE refused: the hard limit (" +
                             limit_name(limits_[static_cast<size_t>(limit_.tripped)]) +
                             ") is latched: FAULT_RESET first (cnc-ctl --do fault-reset)";
    spdlog::warn("{}", text);
    alarm(cnc::lcmt_alarm::WARNING, "enable_refused", text);
    return true;
  }
  if (estop_.module < 0 || (estop_.ok && !estop_.latched)) return false;
  const std::string name = cfg_.io.point_label(cfg_.safety.estop_input);
  const std::string text = !estop_.ok ? "ENABLE refused: E-stop input " + name + " reads 0 (or its module does not answer)"
                                      : "ENABLE refused: the E-stop (input " + name +
                                            ") is latched: FAULT_RESET first (cnc-ctl --do fault-reset)";
  spdlog::warn("{}", text);
  alarm(cnc::lcmt_alarm::WARNING, "enable_refused", text);
  return true;
}

void DriveBridgeNode::probe_tick() {
  if (probe_.module < 0) return;
  ++probe_.tick;
  if (cfg_.probe.drive_latch) probe_drive_counters();
  const IoModule& mod = io_->modules[static_cast<size_t>(probe_.module)];
  if (!(mod.rep.answering && mod.rep.in.valid)) {
    probe_.value = -1;
    return;
  }
  const int8_t v = ((mod.rep.in.discrete >> probe_.bit) & 1) != 0 ? 1 : 0;
  if (probe_.value >= 0 && v != probe_.value) {
    // The positions read in the round that sampled the edge: accurate to the speed
    // times the time between two samples (a servo period) and the round's spread.
    const double cycle =
        core_.mode() == BridgeCore::Mode::kFollowing && core_.last_cycle() >= 0 ? core_.playback_cycle() : -1.0;
    if (cfg_.probe.drive_latch) {
      ProbeLatch::Edge& e = probe_.edge[v];
      if (e.pending) probe_settle(v, true);  // a bounce within the wait: the earlier edge first
      e.pending = true;
      e.tick = probe_.tick;
      e.cycle = cycle;
      for (size_t i = 0; i < axes_.size(); ++i) e.sampled_mm[i] = axes_[i].rep.actual_mm;
    } else {
      std::vector<double>& at = v ? probe_.rise_mm : probe_.fall_mm;
      for (size_t i = 0; i < axes_.size(); ++i) at[i] = axes_[i].rep.actual_mm;
      (v ? probe_.rise_cycle : probe_.fall_cycle) = cycle;
      ++(v ? probe_.rises : probe_.falls);
    }
  }
  probe_.value = v;
  if (cfg_.probe.drive_latch)
    for (int d : {0, 1})
      if (probe_.edge[d].pending) probe_settle(d, false);
}

// Each drive's touch-probe counters: when they changed, and the position latched then.
void DriveBridgeNode::probe_drive_counters() {
  for (size_t i = 0; i < axes_.size(); ++i) {
    const AxisReport& r = axes_[i].rep;
    for (int d : {0, 1}) {
      ProbeLatch::DriveCounter& c = probe_.counter[d][i];
      if (!(r.answering && r.have_status && r.has_probe_latch)) {
        c.known = false;
        continue;
      }
      const int64_t count = d ? r.probe.rises : r.probe.falls;
      if (c.known && count != c.count) {
        c.changed = probe_.tick;
        c.mm = d ? r.probe.rise_mm : r.probe.fall_mm;
      }
      c.known = true;  // the first read after (re)connection is the baseline, not an edge
      c.count = count;
    }
  }
}

// An input edge waiting for the drives' latches: taken with them once every drive has
// latched it, else with the sampled positions after kLatchTicks (or at the next edge).
void DriveBridgeNode::probe_settle(int rising, bool force) {
  ProbeLatch::Edge& e = probe_.edge[rising];
  std::vector<ProbeLatch::DriveCounter>& cs = probe_.counter[rising];
  const int64_t w = ProbeLatch::kLatchTicks;
  bool all = true;
  for (const ProbeLatch::DriveCounter& c : cs)
    all = all && c.changed > c.taken && c.changed >= e.tick - w && c.changed <= e.tick + w;
  if (!all && !force && probe_.tick - e.tick < w) return;
  std::vector<double>& at = rising ? probe_.rise_mm : probe_.fall_mm;
  for (size_t i = 0; i < cs.size(); ++i) {
    at[i] = all ? cs[i].mm : e.sampled_mm[i];
    cs[i].taken = cs[i].changed;
  }
  if (!all) {
    ++probe_.fallbacks;
    spdlog::warn("probe {} edge: not every drive latched it within {} servo periods: the positions sampled with "
                 "the input are used ({} so far)", rising ? "rising" : "falling", w, probe_.fallbacks);
  }
  (rising ? probe_.rise_cycle : probe_.fall_cycle) = e.cycle;
  ++(rising ? probe_.rises : probe_.falls);
  e.pending = false;
}

void DriveBridgeNode::io_tick() {
  if (!io_) return;
  Io& io = *io_;
  // The coolant runs only while the bridge follows setpoints (as the spindle turns).
  const bool following = state_ == State::kEnabled && !core_.faulted();
  if (io.pending) {
    io.pending = false;
    const int64_t clamped = io.ctl.clamped();
    static const std::vector<double> kNone;
    if (io.ctl.on_command(io.pending_seq, io.pending_coolant, io.pending_outputs,
                          io.analog_known ? io.pending_analog : kNone, following)) {
      spdlog::info("io: change {}: coolant {}{}, outputs 0x{:x}{}", io.ctl.command_seq(),
                   (io.pending_coolant & 1) ? "mist " : "", (io.pending_coolant & 2) ? "flood" : (io.pending_coolant & 1) ? "" : "off",
                   io.ctl.outputs(), following || io.pending_coolant == 0 ? "" : " (coolant not followed: the drives do not follow setpoints)");
      for (size_t n = 0; n < io.pending_analog.size() && io.ctl.clamped() != clamped; ++n) {
        const config::IoPointConfig& p = cfg_.io.points[static_cast<size_t>(cfg_.io.analog_outputs[n])];
        const double count = std::round(io.ctl.analog(n) / p.scale);
        if (count >= (p.is_signed ? -32768.0 : 0.0) && count <= (p.is_signed ? 32767.0 : 65535.0)) continue;
        spdlog::warn("io: analog output E{} ({}) = {}: beyond its register's range, held at raw {}", n,
                       cfg_.io.points[static_cast<size_t>(cfg_.io.analog_outputs[n])].name, io.ctl.analog(n), io.ctl.analog_raw(n));
      }
    }
  }
  if (!following && io.ctl.coolant() != 0) {
    io.ctl.stop();
    spdlog::info("io: coolant off: the drives do not follow setpoints");
  }
  for (size_t m = 0; m < io.modules.size(); ++m) {
    IoModule& mod = io.modules[m];
    IoCommand c;
    c.coils = io.ctl.module_coils(m);
    c.holding_write = io.ctl.module_holding(m, c.holding.data());
    mod.worker->set_io_command(mod.slot, c);
    // A line per change of a coil as read back from the module (events, not every tick).
    if (mod.rep.in.valid && (!mod.logged_valid || mod.rep.in.coils != mod.logged_coils)) {
      const uint64_t changed = mod.logged_valid ? mod.rep.in.coils ^ mod.logged_coils : ~uint64_t{0};
      const auto& coils = mod.points[static_cast<size_t>(config::IoKind::kCoil)];
      for (size_t i = 0; i < coils.size(); ++i) {
        if (((changed >> i) & 1) == 0) continue;
        spdlog::info("io: {} {}", cfg_.io.points[static_cast<size_t>(coils[i])].name,
                     ((mod.rep.in.coils >> i) & 1) ? "on" : "off");
      }
      mod.logged_coils = mod.rep.in.coils;
    }
    mod.logged_valid = mod.rep.in.valid;
  }
}

void DriveBridgeNode::publish_io_status() {
  Io& io = *io_;
  cnc::lcmt_io_status& m = io_msg_;
  m.command_seq = io.ctl.command_seq();
  m.coolant = static_cast<int8_t>(io.ctl.coolant());
  m.outputs = static_cast<int64_t>(io.ctl.outputs());
  for (size_t mi = 0; mi < io.modules.size(); ++mi) {
    const IoModule& mod = io.modules[mi];
    const drive::IoModuleInputs& in = mod.rep.in;
    for (size_t k = 0; k < 4; ++k) {
      const std::vector<int>& pts = mod.points[k];
      for (size_t i = 0; i < pts.size(); ++i) {
        const auto p = static_cast<size_t>(pts[i]);
        uint16_t raw = 0;
        switch (static_cast<config::IoKind>(k)) {
          case config::IoKind::kCoil: raw = (in.coils >> i) & 1; break;
          case config::IoKind::kDiscreteInput: raw = (in.discrete >> i) & 1; break;
          case config::IoKind::kInputRegister: raw = in.input_registers[i]; break;
          case config::IoKind::kHoldingRegister: raw = in.holding_registers[i]; break;
        }
        m.value[p] = IoControl::value(cfg_.io.points[p], raw);
        m.valid[p] = in.valid;
      }
    }
    m.answering[mi] = mod.rep.answering;
    m.transactions[mi] = mod.rep.counters.transactions;
    m.timeouts[mi] = mod.rep.counters.timeouts;
    m.exceptions[mi] = mod.rep.counters.exceptions;
    m.last_error[mi].assign(mod.rep.last_error.data());
  }
  if (estop_.module >= 0) {
    bool disabled = true;
    for (const auto& a : axes_) disabled = disabled && !(a.rep.answering && a.rep.status.enabled);
    m.estop = !estop_.latched      ? (estop_.ok ? cnc::lcmt_io_status::ESTOP_OK : cnc::lcmt_io_status::ESTOP_TRIPPED)
              : !estop_.stood || !disabled ? cnc::lcmt_io_status::ESTOP_TRIPPED
              : estop_.ok                   ? cnc::lcmt_io_status::ESTOP_RELEASED
                                            : cnc::lcmt_io_status::ESTOP_DISABLED;
    m.estop_utime = estop_.utime;
    m.estop_stop_ms = estop_.stop_ms;
  }
  if (!limits_.empty()) {
    int on = -1;
    for (size_t k = 0; k < limits_.size() && on < 0; ++k)
      if (!limits_[k].ok) on = static_cast<int>(k);
    const int named = limit_.latched ? limit_.tripped : on >= 0 ? on : limit_.tripped;
    m.limit = limit_.latched  ? (limit_.stood ? cnc::lcmt_io_status::LIMIT_DISABLED : cnc::lcmt_io_status::LIMIT_TRIPPED)
              : on >= 0       ? cnc::lcmt_io_status::LIMIT_ON_SWITCH
                              : cnc::lcmt_io_status::LIMIT_OK;
    if (named < 0) {
      m.limit_input.clear();
    } else if (const std::string& name =
                   cfg_.io.points[static_cast<size_t>(limits_[static_cast<size_t>(named)].point)].name;
               m.limit_input != name) {
      m.limit_input = name;  // on a change only
    }
    m.limit_utime = limit_.utime;
    m.limit_stop_ms = limit_.stop_ms;
  }
  if (door_.module >= 0) {
    m.door = door_.ok ? cnc::lcmt_io_status::DOOR_CLOSED : cnc::lcmt_io_status::DOOR_OPEN;
    m.door_utime = door_.utime;
  }
  bus_.publish(ch_io_status_, m);
}

void DriveBridgeNode::publish_spindle_status() {
  const Spindle& sp = *spindle_;
  cnc::lcmt_spindle_status& m = spindle_msg_;
  if (m.fault.capacity() < 256) m.fault.reserve(256);
  const bool faulted = sp.ctl.faulted() || (sp.rep.in.valid && sp.rep.in.error_code != 0);
  m.state = faulted ? cnc::lcmt_spindle_status::FAULT
            : !sp.rep.in.valid ? cnc::lcmt_spindle_status::STARTING
            : sp.rep.in.running ? cnc::lcmt_spindle_status::RUNNING
                                : cnc::lcmt_spindle_status::STOPPED;
  m.command_seq = sp.ctl.command_seq();
  m.at_speed_seq = sp.ctl.at_speed_seq();
  m.direction = static_cast<int8_t>(sp.ctl.direction());
  m.commanded_rpm = sp.ctl.commanded_rpm();
  m.actual_rpm = sp.ctl.actual_rpm(sp.fb);
  m.current_a = sp.rep.in.current_a;
  m.error_code = sp.rep.in.error_code;
  m.fault.assign(sp.ctl.fault_reason());
  m.transactions = sp.rep.counters.transactions;
  m.timeouts = sp.rep.counters.timeouts;
  m.position_valid = sp.ctl.position_valid();
  m.position_rev = sp.ctl.position_rev();
  // The playback cycle at the sample: the posting tick's, carried on at the playback rate
  // over the time from that tick to the drive's sampling.
  const SpindleCommand& c = sp.rep.cmd;
  m.sample_playback_cycle = m.position_valid && c.playback_cycle >= 0
                                ? c.playback_cycle + c.playback_rate * (sp.ctl.sample_s() - c.tick_s) / cfg_.ipo_period_s
                                : -1.0;
  m.orient_state = static_cast<int8_t>(sp.ctl.orient_state());
  bus_.publish(ch_spindle_status_, m);
}

}  // namespace cnc::bridge
