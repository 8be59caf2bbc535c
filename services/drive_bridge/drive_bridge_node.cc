#include "services/drive_bridge/drive_bridge_node.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "common/config/yaml_reader.h"
#include "common/drive/delta_vfd_profile.h"
#include "common/drive/link_factory.h"
#include "common/drive/loopback_link.h"
#include "common/util/clock.h"

namespace cnc::bridge {

namespace ch = config::channels;
using cnc::lcmt_axis_status;

const char* state_name(DriveBridgeNode::State s) {
  switch (s) {
    case DriveBridgeNode::State::kStarting: return "starting";
    case DriveBridgeNode::State::kDisabled: return "disabled";
    case DriveBridgeNode::State::kEnabling: return "enabling";
    case DriveBridgeNode::State::kEnabled: return "enabled";
    case DriveBridgeNode::State::kStopping: return "stopping";
    case DriveBridgeNode::State::kFault: return "fault";
  }
  return "?";
}

DriveBridgeNode::DriveBridgeNode(const config::MachineConfig& cfg, bus::Bus& bus, Options opt)
    : cfg_(cfg), bus_(bus), opt_(opt), core_(cfg), ch_status_(cfg.channel(ch::kAxisStatus)),
      ch_alarm_(cfg.channel(ch::kAlarm)),
      ticks_per_ipo_(static_cast<int>(std::lround(cfg.ipo_period_s / cfg.servo_period_s))),
      health_(bus, cfg.channel(ch::kAlarm), "cnc-drive-bridge", cnc::lcmt_alarm::FAULT) {
  std::map<std::string, const drive::DriveProfile*> by_file;
  std::map<std::string, LinkWorker*> by_link;
  // An axis drive on its link: each axis's, then each gantry's second (`key` its config path).
  const auto make_drive = [&](size_t i, const config::DriveConfig& d, const std::string& key) {
    const std::string file = drive::find_drive_profile(d.profile, cfg.source_file, cfg.drive_profile_dir);
    if (!by_file.count(file)) {
      if (!std::filesystem::exists(file))
        throw config::ConfigError(cfg.source_file, key + ".profile",
                                  "no drive profile '" + d.profile + "' (looked for " + file + ")");
      profiles_.push_back(std::make_unique<drive::DriveProfile>(drive::load_drive_profile(file)));
      by_file[file] = profiles_.back().get();
    }
    const drive::DriveProfile* profile = by_file[file];
    if (drive::is_spindle_profile(*profile))
      throw config::ConfigError(cfg.source_file, key + ".profile",
                                "'" + d.profile + "' is a spindle drive's profile (state_machine " +
                                    profile->state_machine + "), not an axis drive's");
    LinkWorker* worker = worker_for(d, by_link);
    // The in-process link emulates its drives: each needs its profile and start.
    if (auto* loopback = dynamic_cast<drive::LoopbackLink*>(&worker->link()))
      loopback->add_drive(d.unit_id, *profile, cfg.axes[i].home_mm);
    Axis ax;
    ax.profile = profile;
    ax.worker = worker;
    ax.slot = ax.worker->axes().size();
    ax.worker->add_axis(static_cast<int>(i), *profile, d.unit_id);
    return ax;
  };
  for (size_t i = 0; i < cfg.axes.size(); ++i)
    axes_.push_back(make_drive(i, cfg.axes[i].drive, "axes[" + std::to_string(i) + "].drive"));
  for (size_t i = 0; i < cfg.axes.size(); ++i) {
    if (!cfg.axes[i].gantry.enabled) continue;
    Joint j;
    j.axis = i;
    j.drv = make_drive(i, cfg.axes[i].gantry.drive, "axes[" + std::to_string(i) + "].gantry.drive");
    joints_.push_back(j);
  }
  if (cfg.probe.enabled() && cfg.probe.drive_latch)
    for (size_t i = 0; i < axes_.size(); ++i) {
      const drive::DriveProfile& p = *axes_[i].profile;
      if (!(p.has(drive::Role::kProbeRisePosition) && p.has(drive::Role::kProbeRiseCount) &&
            p.has(drive::Role::kProbeFallPosition) && p.has(drive::Role::kProbeFallCount)))
        throw config::ConfigError(cfg.source_file, "probe.latch",
                                  "drives: axis " + cfg.axes[i].name + "'s drive profile '" + p.name + "' (" + p.file +
                                      ") maps no touch-probe latch (registers probe_rise_position, probe_rise_count, "
                                      "probe_fall_position, probe_fall_count)");
    }
  if (cfg.spindle.enabled) make_spindle(by_link);
  if (cfg_.io.enabled) make_io(by_link);
  pace_.assign(workers_.size(), LinkPace{});
  if (const char* f = std::getenv("CNC_BRIDGE_DEBUG_TRACE")) {
    dbg_file_ = f;
    dbg_ticks_.reserve(400000);
    dbg_sp_.reserve(200000);
  }
  bus_.subscribe<cnc::lcmt_setpoint>(cfg.channel(ch::kSetpoints), [this](const auto& m) { on_setpoint(m); });
  bus_.subscribe<cnc::lcmt_drive_command>(cfg.channel(ch::kDriveCmd),
                                          [this](const auto& m) { pending_command_ = m.command; });
  if (!joints_.empty()) {
    ch_joint_status_ = cfg.channel(ch::kJointStatus);
    bus_.subscribe<cnc::lcmt_interp_input>(cfg.channel(ch::kInterpInput),
                                           [this](const auto& m) { on_interp_input(m); });
  }
}

// The worker of d's link, made on first use: drives and devices on one link share it.
LinkWorker* DriveBridgeNode::worker_for(const config::DriveConfig& d, std::map<std::string, LinkWorker*>& by_link) {
  const std::string key = d.link_key();
  if (!by_link.count(key)) {
    links_.push_back(drive::make_link(d));
    workers_.push_back(std::make_unique<LinkWorker>(*links_.back(), cfg_.drive_bridge));
    by_link[key] = workers_.back().get();
  }
  return by_link[key];
}

DriveBridgeNode::~DriveBridgeNode() {
  for (auto& w : workers_) w->stop();
}

void DriveBridgeNode::set_write_probe(LinkWorker::WriteProbe p) {
  for (auto& w : workers_) w->set_probe(p);
}

void DriveBridgeNode::start() {
  for (const auto& w : workers_)
    spdlog::info("link {}: {} drive(s)", w->link().name(), w->axes().size());
  for (size_t i = 0; i < axes_.size(); ++i)
    spdlog::info("axis {}: profile {} ({}), unit {}", cfg_.axes[i].name, axes_[i].profile->name,
                 axes_[i].profile->file, cfg_.axes[i].drive.unit_id);
  for (const Joint& j : joints_)
    spdlog::info("axis {}'s gantry joint {}: profile {} ({}), unit {}, skew limit {} mm", cfg_.axes[j.axis].name,
                 cfg_.axes[j.axis].gantry.name, j.drv.profile->name, j.drv.profile->file,
                 cfg_.axes[j.axis].gantry.drive.unit_id, cfg_.axes[j.axis].gantry.skew_limit_mm);
  if (spindle_)
    spdlog::info("spindle: profile {} ({}), unit {} on {}", spindle_->profile->name, spindle_->profile->file,
                 cfg_.spindle.drive.unit_id, spindle_->worker->link().name());
  if (io_)
    for (size_t m = 0; m < io_->modules.size(); ++m)
      spdlog::info("io: module {} unit {} on {}: {} coil(s), {} discrete input(s), {} input and {} holding register(s)",
                   cfg_.io.modules[m].name, cfg_.io.modules[m].link.unit_id, io_->modules[m].worker->link().name(),
                   io_->modules[m].points[0].size(), io_->modules[m].points[1].size(),
                   io_->modules[m].points[2].size(), io_->modules[m].points[3].size());
  if (opt_.threaded)
    for (auto& w : workers_) w->start();
  started_ = true;
}

drive::Link& DriveBridgeNode::link_of(size_t axis) { return axes_[axis].worker->link(); }

void DriveBridgeNode::command(int8_t c) { pending_command_ = c; }

void DriveBridgeNode::explain_trip(const cnc::lcmt_setpoint& m) {
  // A restarted interpolator (another stream) or a new engagement explains nothing.
  if (m.stream != core_.stream() || m.engagement != core_.engagement() || m.cycle <= trip_.cycle) return;
  trip_.open = false;
  const double published_ms = static_cast<double>(m.utime - trip_.utime) * 1e-3;
  const double arrived_ms = (tick_s_ - trip_.arrived_s) * 1e3;
  const double due_ms = static_cast<double>(m.cycle - trip_.cycle) * cfg_.ipo_period_s * 1e3;
  // Published within half the timeout of when it was due: the interpolator kept its cycle.
  const bool delivery = published_ms <= due_ms + 0.5 * cfg_.setpoint_timeout_s * 1e3;
  char b[320];
  std::snprintf(b, sizeof b,
                "the setpoint watchdog's trip after cycle %lld: cycle %lld was published %.1f ms after it (due after "
                "%.0f ms) and arrived %.1f ms after it: %s",
                static_cast<long long>(trip_.cycle), static_cast<long long>(m.cycle), published_ms, due_ms, arrived_ms,
                delivery ? "the delivery between the processes stalled, not the interpolator"
                         : "the interpolator (or its host) stalled");
  const std::string text(b);
  spdlog::warn("{}", text);
  alarm(cnc::lcmt_alarm::WARNING, "watchdog_cause", text);
}

void DriveBridgeNode::on_setpoint(const cnc::lcmt_setpoint& m) {
  if (trip_.open) explain_trip(m);
  if (core_.mode() != BridgeCore::Mode::kFollowing) return;
  if (m.num_axes != static_cast<int32_t>(axes_.size())) {
    fault(0, "setpoint seq " + std::to_string(m.seq) + " has " + std::to_string(m.num_axes) + " axes, the machine " +
                 std::to_string(axes_.size()), false);
    return;
  }
  AxisArray p{};
  for (size_t i = 0; i < axes_.size(); ++i) p[i] = m.position_mm[i];
  // A late arrival is worth a line in the log: it explains a later watchdog stop.
  const double now = tick_s_;
  if (!dbg_file_.empty() && dbg_sp_.size() < dbg_sp_.capacity()) dbg_sp_.push_back({now, m.cycle});
  if (last_setpoint_s_ > 0 && now - last_setpoint_s_ > 3 * cfg_.ipo_period_s)
    spdlog::warn("setpoint cycle {} arrived {:.1f} ms after the one before (published {:.1f} ms after it)", m.cycle,
                 (now - last_setpoint_s_) * 1e3, static_cast<double>(m.utime - last_setpoint_utime_) * 1e-3);
  last_setpoint_s_ = now;
  last_setpoint_utime_ = m.utime;
  // Setpoints lost on the way (up to the history this one carries) come back
  // exactly, oldest first, before it: the path through a burst of loss is the
  // programmed one, not a line bridging it.
  const StreamStamp from{m.stream, m.engagement};
  const int n = static_cast<int>(axes_.size());
  const int64_t last = core_.last_cycle();
  if (from.engagement == core_.engagement() && from.stream == core_.stream() && last >= 0 && m.cycle - last > 1 &&
      m.num_prev_values > 0 &&
      static_cast<size_t>(m.num_prev_values) == m.prev_position_mm.size() && m.num_prev_values % n == 0) {
    const int64_t have = m.num_prev_values / n;
    for (int64_t j = std::min<int64_t>(have, m.cycle - last - 1); j >= 1; --j) {
      AxisArray q{};
      for (int i = 0; i < n; ++i) q[static_cast<size_t>(i)] = m.prev_position_mm[static_cast<size_t>((j - 1) * n + i)];
      if (core_.on_setpoint(m.cycle - j, q, from) != BridgeCore::Verdict::kAccepted) continue;
      ++recovered_setpoints_;
      if (!limits_.empty() && limits_refuse(q, m.cycle - j)) return;
    }
  }
  if (!limits_.empty() && limits_hold_off(p, from)) return;
  const BridgeCore::Verdict verdict = core_.on_setpoint(m.cycle, p, from);
  if (verdict == BridgeCore::Verdict::kAccepted && !limits_.empty() && limits_refuse(p, m.cycle)) return;
  if (verdict == BridgeCore::Verdict::kStale && now - stale_report_s_ >= 1.0) {
    stale_report_s_ = now;
    spdlog::warn("setpoint seq {} cycle {} dropped: {} (stream {}, engagement {}; following stream {} since "
                 "engagement {}); {} stale setpoint(s) dropped so far",
                 m.seq, m.cycle,
                 m.engagement != core_.engagement() ? "made before the drives were engaged" : "of an older stream",
                 m.stream, m.engagement, core_.stream(), core_.engagement(), core_.stale_setpoints());
  }
}

AxisArray DriveBridgeNode::actuals() const {
  AxisArray a{};
  for (size_t i = 0; i < axes_.size(); ++i) a[i] = axes_[i].rep.have_status ? axes_[i].rep.actual_mm : core_.commanded()[i];
  return a;
}

void DriveBridgeNode::alarm(int8_t severity, const std::string& code, const std::string& text) {
  cnc::lcmt_alarm al{};
  al.source = "cnc-drive-bridge";
  al.severity = severity;
  al.code = code;
  al.text = text;
  bus_.publish(ch_alarm_, al);
}

void DriveBridgeNode::fault(size_t axis, const std::string& why, bool disable_axis) {
  if (pending_command_ == cnc::lcmt_drive_command::ENABLE) pending_command_ = 0;  // sent before this fault
  if (disable_axis) axes_[axis].cmd.goal = drive::Goal::kDisable;
  if (state_ == State::kEnabling) {
    for (auto& a : axes_) a.cmd.goal = drive::Goal::kDisable;
    for (auto& j : joints_) j.drv.cmd.goal = drive::Goal::kDisable;
  }
  core_.fault(why);
}

void DriveBridgeNode::begin_enable(double now_s) {
  for (auto& a : axes_) {
    a.cmd.goal = drive::Goal::kEnable;
    a.link_down = false;
  }
  for (auto& j : joints_) {
    j.drv.cmd.goal = drive::Goal::kEnable;
    j.drv.link_down = false;
  }
  if (spindle_) {
    spindle_->ctl.clear_fault();
    spindle_->reset_pending = true;  // a fault the drive still reports is cleared
    spindle_->reset_deadline_s = now_s + SpindleControl::kNotRunningS;
  }
  core_.disengage(actuals());
  state_ = State::kEnabling;
  enable_deadline_s_ = now_s + cfg_.drive_bridge.enable_timeout_s;
  fault_text_.clear();
  waiting_reported_ = false;
  spdlog::info("enabling the drives");
}

void DriveBridgeNode::check_drives() {
  const bool expect_enabled = state_ == State::kEnabled || state_ == State::kStopping;
  for (size_t i = 0; i < axes_.size(); ++i) check_drive(axes_[i], i, cfg_.axes[i].name, expect_enabled);
  for (Joint& j : joints_) check_drive(j.drv, j.axis, cfg_.axes[j.axis].gantry.name, expect_enabled);
}

void DriveBridgeNode::check_drive(Axis& a, size_t i, const std::string& name, bool expect_enabled) {
  // A fault disables the drive that has it (and brakes every axis).
  const auto drive_fault = [&](const std::string& why) {
    a.cmd.goal = drive::Goal::kDisable;
    fault(i, why, false);
  };
  if (a.rep.lost_events > a.lost_seen) {
    a.lost_seen = a.rep.lost_events;
    a.link_down = true;
    drive_fault("axis " + name + ": link " + a.worker->link().name() + " lost (" + a.rep.last_error.data() + ")");
  }
  if (!expect_enabled || a.link_down || !a.rep.have_status) return;
  char code[16];
  std::snprintf(code, sizeof code, "0x%04X", a.rep.error_code);
  if (a.rep.status.fault) {
    drive_fault("axis " + name + ": the drive reports a fault (" + a.rep.status.state + ", error code " + code + ")");
  } else if (!a.rep.status.enabled && a.cmd.goal == drive::Goal::kEnable) {
    drive_fault("axis " + name + ": the drive left the enabled state (" + a.rep.status.state + ")");
  }
  if (a.rep.fe_samples > a.fe_seen) {
    a.fe_seen = a.rep.fe_samples;
    const double limit = cfg_.axes[i].max_following_error_mm;
    if (std::fabs(a.rep.fe_mm) > limit) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "axis %s: following error %.4f mm over its limit %g mm", name.c_str(),
                    a.rep.fe_mm, limit);
      drive_fault(buf);
    }
  }
}

void DriveBridgeNode::servo_tick(double now_s) {
  try {
    servo_tick_inner(now_s);
  } catch (const std::exception& e) {
    on_exception("servo tick", e.what());
  } catch (...) {
    on_exception("servo tick", "unknown exception");
  }
  // A failed publish (this tick's ALARM, the last AXIS_STATUS, a heartbeat): the
  // cell no longer sees the axes. Controlled stop, FAULT until ENABLE.
  if (health_.check(now_s)) {
    fault(0, std::string("the bus failed: ") + health_.cause(), false);  // logged with the fault
  }
  health_.report(now_s, "the drive bridge brought the axes to a controlled stop and is in FAULT until ENABLE");
}

void DriveBridgeNode::on_exception(const char* where, const char* what) {
  try {
    spdlog::error("fault: exception in the {}: {}", where, what);
    fault(0, std::string("exception in the ") + where + ": " + what, false);
  } catch (...) {
    core_.fault("exception");  // no memory for a text: the stop still happens
  }
}

void DriveBridgeNode::publish_status(int64_t overruns) {
  try {
    publish_status_inner(overruns);
  } catch (const std::exception& e) {
    on_exception("status publish", e.what());
  } catch (...) {
    on_exception("status publish", "unknown exception");
  }
}

void DriveBridgeNode::servo_tick_inner(double now_s) {
  tick_s_ = now_s;
  bus_.drain();
  ++tick_;
  for (auto& a : axes_) a.rep = a.worker->report(a.slot);
  for (auto& j : joints_) j.drv.rep = j.drv.worker->report(j.drv.slot);
  if (io_)
    for (auto& m : io_->modules) m.rep = m.worker->io_report(m.slot);
  safety_tick(now_s);
  probe_tick();
  take_operator_command(now_s);
  advance_state(now_s);
  if (!joints_.empty()) gantry_tick(now_s);
  report_reconnects();
  spindle_tick(now_s);
  io_tick();

  // A link that has not finished the round of the last tick's command is stalled
  // (the drive, its network or this process's worker did not get to run): the
  // playback waits for it, so the drive gets the next commands one tick after
  // another instead of a jump over the ticks it missed (a jump the drive takes
  // without feed-forward, as a following error of about v x the stall). The lag
  // is made up by the playback rate afterwards. No post while holding: the same
  // command written twice would be a standstill in the drive's demand.
  const bool hold = link_stalled() && core_.hold();
  const AxisArray& cmd = hold ? core_.commanded() : core_.tick();
  follow_core_state();
  if (!hold && !joints_.empty()) advance_squaring();
  set_axis_commands(cmd);
  if (spindle_) post_spindle_command(now_s);
  trace_tick(now_s, hold, cmd);
  if (hold) return;
  post_rounds(now_s);
}

void DriveBridgeNode::take_operator_command(double now_s) {
  // ENABLE acts only on drives that are disabled or stand in FAULT; it waits only
  // for the start-up. An ENABLE that arrives while a controlled stop runs was sent
  // before its sender knew of the fault (the drives looked enabled): kept, it would
  // enable them again once the stop ended, with nobody having asked after the fault.
  // It is refused; the operator sends it again.
  if (pending_command_ == 0) return;
  const int8_t c = pending_command_;
  pending_command_ = 0;
  if (c == cnc::lcmt_drive_command::ENABLE) {
    if (state_ == State::kDisabled || state_ == State::kFault) {
      if (!safety_refuses_enable()) begin_enable(now_s);
    } else if (state_ == State::kStarting) {
      pending_command_ = c;
    } else if (state_ == State::kStopping) {
      spdlog::warn("ENABLE ignored: a controlled stop is running ({}); send it again when it has ended", fault_text_);
      alarm(cnc::lcmt_alarm::WARNING, "enable_ignored",
            "ENABLE ignored: a controlled stop is running; send it again when the axes stand");
    }
  } else if (c == cnc::lcmt_drive_command::FAULT_RESET && limit_.latched && !limit_.stood) {
    const std::string text = "FAULT_RESET refused: the axes still brake for the hard limit";
    spdlog::warn("{}", text);
    alarm(cnc::lcmt_alarm::WARNING, "limit_reset_refused", text);
  } else if (c == cnc::lcmt_drive_command::FAULT_RESET && skew_.latched && !skew_.stood) {
    const std::string text = "FAULT_RESET refused: the axes still brake for the gantry's skew";
    spdlog::warn("{}", text);
    alarm(cnc::lcmt_alarm::WARNING, "skew_reset_refused", text);
  } else if (c == cnc::lcmt_drive_command::FAULT_RESET && estop_.latched && (!estop_.ok || !estop_.stood)) {
    const std::string name = cfg_.io.point_label(cfg_.safety.estop_input);
    const std::string text = !estop_.ok ? "FAULT_RESET refused: E-stop input " + name + " still reads 0"
                                        : "FAULT_RESET refused: the axes still brake for the E-stop";
    spdlog::warn("{}", text);
    alarm(cnc::lcmt_alarm::WARNING, "estop_reset_refused", text);
  } else if (c == cnc::lcmt_drive_command::DISABLE || c == cnc::lcmt_drive_command::FAULT_RESET) {
    if (c == cnc::lcmt_drive_command::FAULT_RESET && (estop_.module >= 0 || !limits_.empty() || !joints_.empty())) {
      // With an E-stop, hard limits or a gantry every FAULT_RESET is answered (cnc-ctl
      // waits for it or the refusal).
      alarm(cnc::lcmt_alarm::INFO, "fault_reset_done",
            estop_.latched   ? "FAULT_RESET: the E-stop reset, the drives disabled: ENABLE to move again"
            : limit_.latched ? "FAULT_RESET: the hard limit reset, the drives disabled: ENABLE, then move off the "
                               "switch (moves towards it are refused while it reads 0)"
            : skew_.latched  ? "FAULT_RESET: the gantry's skew fault reset, the drives disabled: ENABLE squares "
                               "the gantry again"
                             : "FAULT_RESET: the drives reset and disabled");
      if (estop_.latched) spdlog::info("E-stop reset by the operator");
      if (limit_.latched) spdlog::info("hard limit reset by the operator");
      estop_.latched = false;
      limit_.latched = false;
    }
    for (auto& a : axes_) {
      a.cmd.goal = c == cnc::lcmt_drive_command::DISABLE ? drive::Goal::kDisable : drive::Goal::kFaultReset;
      if (c == cnc::lcmt_drive_command::FAULT_RESET) a.link_down = false;
    }
    for (auto& j : joints_) {
      j.drv.cmd.goal = c == cnc::lcmt_drive_command::DISABLE ? drive::Goal::kDisable : drive::Goal::kFaultReset;
      if (c == cnc::lcmt_drive_command::FAULT_RESET) j.drv.link_down = false;
    }
    if (c == cnc::lcmt_drive_command::FAULT_RESET && skew_.latched) {
      skew_.latched = false;
      spdlog::info("gantry skew fault reset by the operator");
    }
    if (spindle_ && c == cnc::lcmt_drive_command::FAULT_RESET) {
      spindle_->ctl.clear_fault();
      spindle_->reset_pending = true;
      spindle_->reset_deadline_s = now_s + SpindleControl::kNotRunningS;
    }
    core_.disengage(actuals());
    if (state_ != State::kStarting) state_ = State::kDisabled;
    fault_text_.clear();
    spdlog::info("drives {}", c == cnc::lcmt_drive_command::DISABLE ? "disabled" : "reset and disabled");
  }
}

void DriveBridgeNode::advance_state(double now_s) {
  switch (state_) {
    case State::kStarting: {
      bool all = true;
      for (const auto& a : axes_) all = all && a.rep.answering && a.rep.have_status;
      for (const auto& j : joints_) all = all && j.drv.rep.answering && j.drv.rep.have_status;
      // And the E-stop's module: its input decides whether anything may be enabled.
      if (estop_.module >= 0) all = all && io_->modules[static_cast<size_t>(estop_.module)].rep.in.valid;
      if (all) {
        state_ = State::kDisabled;
        spdlog::info("every drive answers");
        if (cfg_.drive_bridge.enable_on_start && !safety_refuses_enable()) {
          begin_enable(now_s);
        } else {
          ready_ = true;
        }
      }
      break;
    }
    case State::kEnabling: advance_enabling(now_s); break;
    case State::kEnabled:
    case State::kStopping:
    case State::kFault: check_drives(); break;
    case State::kDisabled: break;
  }
}

void DriveBridgeNode::advance_enabling(double now_s) {
  check_drives();
  if (core_.faulted()) return;
  bool all = true;
  for (const auto& a : axes_) all = all && a.rep.answering && a.rep.status.enabled && a.rep.holding;
  for (const auto& j : joints_) all = all && j.drv.rep.answering && j.drv.rep.status.enabled && j.drv.rep.holding;
  if (all) {
    AxisArray hold{};
    for (size_t i = 0; i < axes_.size(); ++i) hold[i] = axes_[i].rep.hold_mm;
    // A gantry's squaring starts where its two drives stand, and moves from there to the
    // homed one (if known): ENABLE after a skew squares the axis again.
    for (Joint& j : joints_) {
      j.squaring_mm = j.drv.rep.hold_mm - hold[j.axis];
      if (!j.homed) j.target_mm = j.squaring_mm;
      j.v_mm_s = 0;
      j.skew_mm = 0;
      j.max_skew_mm = 0;
      j.prev_s = -1;
    }
    engagement_ = util::next_token(engagement_);
    core_.engage(hold, engagement_);
    state_ = State::kEnabled;
    ready_ = true;
    spdlog::info("{} drive(s) enabled", axes_.size() + joints_.size());
    alarm(cnc::lcmt_alarm::INFO, "drives_enabled", "drives enabled; following setpoints from where the axes stand");
  } else if (now_s > enable_deadline_s_) {
    bool named = false;
    for (size_t i = 0; i < axes_.size() && !named; ++i) {
      const Axis& a = axes_[i];
      if (a.rep.answering && a.rep.status.enabled) continue;
      fault(i, "axis " + cfg_.axes[i].name + " did not enable within " +
                   std::to_string(cfg_.drive_bridge.enable_timeout_s).substr(0, 4) + " s: " +
                   (a.rep.answering ? std::string("drive state ") + a.rep.status.state
                                    : std::string("no answer (") + a.rep.last_error.data() + ")"),
            true);
      named = true;
    }
    for (Joint& j : joints_) {
      if (named || (j.drv.rep.answering && j.drv.rep.status.enabled)) continue;
      j.drv.cmd.goal = drive::Goal::kDisable;
      fault(j.axis, "axis " + cfg_.axes[j.axis].gantry.name + " did not enable within " +
                        std::to_string(cfg_.drive_bridge.enable_timeout_s).substr(0, 4) + " s: " +
                        (j.drv.rep.answering ? std::string("drive state ") + j.drv.rep.status.state
                                             : std::string("no answer (") + j.drv.rep.last_error.data() + ")"),
            false);
      named = true;
    }
  }
}

void DriveBridgeNode::report_reconnects() {
  const auto report = [&](Axis& a, const std::string& name) {
    if (a.rep.counters.reconnects <= a.reconnects_seen) return;
    a.reconnects_seen = a.rep.counters.reconnects;
    const std::string text = "axis " + name + ": the drive answers again on " + a.worker->link().name() +
                             " (reconnect " + std::to_string(a.reconnects_seen) + "); it stays disabled until ENABLE";
    spdlog::warn("{}", text);
    alarm(cnc::lcmt_alarm::WARNING, "drive_reconnected", text);
  };
  for (size_t i = 0; i < axes_.size(); ++i) report(axes_[i], cfg_.axes[i].name);
  for (Joint& j : joints_) report(j.drv, cfg_.axes[j.axis].gantry.name);
}

void DriveBridgeNode::follow_core_state() {
  if (core_.faulted() && fault_text_.empty()) {
    fault_text_ = core_.fault_reason();
    spdlog::error("fault: {}", fault_text_);
    alarm(cnc::lcmt_alarm::FAULT, "drive_fault", fault_text_);
    if (core_.watchdog_tripped()) trip_ = Trip{true, core_.last_cycle(), last_setpoint_utime_, last_setpoint_s_};
  }
  if (core_.faulted()) {
    if (state_ == State::kEnabled) state_ = State::kStopping;
    if (state_ == State::kEnabling || state_ == State::kDisabled || state_ == State::kStarting) state_ = State::kFault;
    if (state_ == State::kStopping && core_.mode() == BridgeCore::Mode::kStopped) state_ = State::kFault;
    ready_ = true;
  }
  if (core_.waiting() && !waiting_reported_) {
    waiting_reported_ = true;
    spdlog::warn("{}", core_.waiting_reason());
    alarm(cnc::lcmt_alarm::WARNING, "setpoint_mismatch", core_.waiting_reason());
  }
  if (state_ != detail_state_) {
    detail_state_ = state_;
    detail_ = state_name(state_);
    if (!fault_text_.empty() && (state_ == State::kStopping || state_ == State::kFault)) detail_ += ": " + fault_text_;
  }
}

void DriveBridgeNode::set_axis_commands(const AxisArray& cmd) {
  const bool following_state = state_ == State::kEnabled || state_ == State::kStopping || state_ == State::kFault;
  for (size_t i = 0; i < axes_.size(); ++i) {
    Axis& a = axes_[i];
    a.cmd.follow = following_state && a.cmd.goal == drive::Goal::kEnable && !a.link_down &&
                   core_.mode() != BridgeCore::Mode::kIdle;
    a.cmd.cmd_mm = cmd[i];
    a.cmd.cmd_cycle = core_.segment_cycle();
    a.worker->set_command(a.slot, a.cmd);
  }
  for (Joint& j : joints_) {
    Axis& a = j.drv;
    a.cmd.follow = following_state && a.cmd.goal == drive::Goal::kEnable && !a.link_down &&
                   core_.mode() != BridgeCore::Mode::kIdle;
    a.cmd.cmd_mm = cmd[j.axis] + j.squaring_mm;
    a.cmd.cmd_cycle = core_.segment_cycle();
    a.worker->set_command(a.slot, a.cmd);
  }
}

void DriveBridgeNode::trace_tick(double now_s, bool hold, const AxisArray& cmd) {
  if (dbg_file_.empty() || dbg_ticks_.size() >= dbg_ticks_.capacity()) return;
  DbgTick t{};
  t.mono = now_s;
  t.tau = core_.playback_cycle();
  t.last_cycle = core_.last_cycle();
  t.held = hold ? 1 : 0;
  for (size_t i = 0; i < axes_.size() && i < 3; ++i) {
    t.cmd[i] = cmd[i];
    t.fe[i] = axes_[i].rep.fe_mm;
    t.act[i] = axes_[i].rep.actual_mm;
  }
  dbg_ticks_.push_back(t);
}

void DriveBridgeNode::post_rounds(double now_s) {
  for (size_t i = 0; i < workers_.size(); ++i) {
    auto& w = workers_[i];
    if (opt_.threaded) {
      if (!pace_[i].outstanding) {
        pace_[i].outstanding = true;
        pace_[i].ticks_waiting = 0;
      }
      w->post();
    } else {
      w->round(now_s);
    }
  }
}

bool DriveBridgeNode::link_stalled() {
  if (!opt_.threaded) return false;
  bool stalled = false;
  for (size_t i = 0; i < workers_.size(); ++i) {
    LinkPace& p = pace_[i];
    const int64_t r = workers_[i]->rounds();
    if (!p.outstanding) {
      p.rounds_seen = r;
      continue;
    }
    const int waited = ++p.ticks_waiting;
    if (r != p.rounds_seen) {
      // Its usual pace, learnt in every state (the start-up and enabling rounds
      // too); a stall teaches it only a little.
      p.usual_ticks += 0.05 * (std::min<double>(waited, 4.0 * p.usual_ticks + 1.0) - p.usual_ticks);
      p.rounds_seen = r;
      p.outstanding = false;
      continue;
    }
    // A link that answers within a tick is stalled when a tick passes without an
    // answer. A slower one (a serial line) is never held for: its drives get a target
    // every few ticks by design and space them by its usual interval, so a command
    // one tick after the last, written a whole round later, would be a dip in their
    // demand (Leadshine-style drives over RTU: a following error of 2.4 mm).
    if (p.usual_ticks <= 1.5 && waited >= 1) stalled = true;
  }
  // Also in a controlled stop (kStopping): the stop's commands are a stream too.
  return stalled && (state_ == State::kEnabled || state_ == State::kStopping);
}

void DriveBridgeNode::publish_status_inner(int64_t overruns) {
  if (tick_ % ticks_per_ipo_ != 0) return;
  // One message, sized at the first publish and filled in place from then on: the
  // vectors keep their size and the texts their capacity, so a status publish
  // allocates nothing (texts longer than the reserve grow once).
  lcmt_axis_status& s = status_msg_;
  const size_t n = axes_.size();
  if (s.axis_name.size() != n) {
    s.num_axes = static_cast<int32_t>(n);
    s.axis_name.resize(n);
    s.commanded_mm.resize(n);
    s.actual_mm.resize(n);
    s.following_error_mm.resize(n);
    s.drive_state.resize(n);
    s.fault.resize(n);
    s.transactions.resize(n);
    s.timeouts.resize(n);
    s.exceptions.resize(n);
    s.crc_errors.resize(n);
    s.reconnects.resize(n);
    for (size_t i = 0; i < n; ++i) {
      s.axis_name[i] = cfg_.axes[i].name;
      s.fault[i].reserve(256);
    }
    s.num_latches = static_cast<int32_t>(n);
    s.home_latch_count.resize(n);
    s.home_latch_mm.resize(n);
  }
  s.setpoint_cycle = core_.last_cycle();
  s.engagement = core_.mode() == BridgeCore::Mode::kFollowing ? core_.engagement() : 0;
  s.stale_setpoints = core_.stale_setpoints();
  s.playback_cycle = core_.mode() == BridgeCore::Mode::kFollowing && core_.last_cycle() >= 0 ? core_.playback_cycle() : -1.0;
  for (size_t i = 0; i < n; ++i) {
    const Axis& a = axes_[i];
    s.commanded_mm[i] = core_.commanded()[i];
    s.actual_mm[i] = a.rep.actual_mm;
    s.following_error_mm[i] = a.rep.fe_mm;
    int8_t st = lcmt_axis_status::DISABLED;
    std::string& text = s.fault[i];
    text.clear();
    switch (state_) {
      case State::kStarting:
      case State::kDisabled:
        st = a.rep.status.fault ? lcmt_axis_status::FAULT : lcmt_axis_status::DISABLED;
        if (a.rep.status.fault) text.append("drive fault (").append(a.rep.status.state).append(")");
        break;
      case State::kEnabling: st = lcmt_axis_status::ENABLING; break;
      case State::kEnabled:
        st = lcmt_axis_status::ENABLED;
        if (core_.waiting()) text.append(core_.waiting_reason());
        break;
      case State::kStopping: st = lcmt_axis_status::STOPPING; text.append(fault_text_); break;
      case State::kFault: st = lcmt_axis_status::FAULT; text.append(fault_text_); break;
    }
    if (a.link_down || (!a.rep.answering && state_ != State::kStarting)) {
      st = lcmt_axis_status::FAULT;
      if (text.empty()) text.append("no answer: ").append(a.rep.last_error.data());
    } else if (!a.rep.answering) {
      text.assign("waiting for the drive: ").append(a.rep.last_error.data());
    }
    s.drive_state[i] = st;
    s.transactions[i] = a.rep.counters.transactions;
    s.timeouts[i] = a.rep.counters.timeouts;
    s.exceptions[i] = a.rep.counters.exceptions;
    s.crc_errors[i] = a.rep.counters.crc_errors;
    s.reconnects[i] = a.rep.counters.reconnects;
    s.home_latch_count[i] = a.rep.has_home_latch ? static_cast<int32_t>(a.rep.home_latch_count) : -1;
    s.home_latch_mm[i] = a.rep.home_latch_mm;
  }
  s.setpoint_gaps = core_.setpoint_gaps();
  s.servo_overruns = overruns;
  s.probe = probe_.value;
  if (probe_.module >= 0) {
    s.num_probe_axes = static_cast<int32_t>(n);
    s.probe_rises = probe_.rises;
    s.probe_falls = probe_.falls;
    s.probe_rise_mm = probe_.rise_mm;  // same size every time: no allocation
    s.probe_fall_mm = probe_.fall_mm;
    s.probe_rise_cycle = probe_.rise_cycle;
    s.probe_fall_cycle = probe_.fall_cycle;
  }
  bus_.publish(ch_status_, s);
  if (!joints_.empty()) publish_joint_status();
  if (spindle_) publish_spindle_status();
  if (io_) publish_io_status();
}

void DriveBridgeNode::shut_down() {
  for (auto& w : workers_) w->stop();
  spdlog::info("setpoints lost and recovered from the next one's history {}, setpoint gaps {}, ticks bridged {}, "
               "ticks braking without setpoints {}, ticks held for a stalled link {}",
               recovered_setpoints_, core_.setpoint_gaps(), core_.bridged_ticks(), core_.starved_ticks(),
               core_.held_ticks());
  for (size_t i = 0; i < axes_.size(); ++i) {
    Axis& a = axes_[i];
    a.cmd.goal = drive::Goal::kDisable;
    a.cmd.follow = false;
    a.worker->set_command(a.slot, a.cmd);
  }
  for (Joint& j : joints_) {
    j.drv.cmd.goal = drive::Goal::kDisable;
    j.drv.cmd.follow = false;
    j.drv.worker->set_command(j.drv.slot, j.drv.cmd);
    spdlog::info("gantry {}: squaring {:.4f} mm (target {:.4f}), skew {:.4f} mm, largest since the last ENABLE {:.4f} mm",
                 cfg_.axes[j.axis].name, j.squaring_mm, j.target_mm, j.skew_mm, j.max_skew_mm);
  }
  if (spindle_) {
    spindle_->ctl.stop();
    spindle_->cmd.direction = 0;
    spindle_->cmd.hz = 0;
    spindle_->cmd.goal = drive::Goal::kDisable;  // a CiA-402 drive's power off, as the axes'
    spindle_->worker->set_spindle_command(spindle_->cmd);
  }
  if (io_) {
    io_->ctl.stop();  // the coolant off; the digital and analog outputs keep their state
    for (size_t m = 0; m < io_->modules.size(); ++m) {
      IoCommand c;
      c.coils = io_->ctl.module_coils(m);
      c.holding_write = io_->ctl.module_holding(m, c.holding.data());
      io_->modules[m].worker->set_io_command(io_->modules[m].slot, c);
    }
  }
  // Disable whatever answers: a few rounds, each at most one step of a state machine.
  for (int round = 0; round < 10; ++round) {
    bool busy = false;
    for (auto& w : workers_) {
      if (!w->link().is_open()) continue;
      w->round(util::monotonic_s());
      for (size_t s = 0; s < w->axes().size(); ++s) {
        const AxisReport r = w->report(s);
        busy = busy || (r.answering && r.status.enabled);
      }
    }
    if (!busy) break;
  }
  for (size_t i = 0; i < axes_.size(); ++i) {
    const AxisReport r = axes_[i].worker->report(axes_[i].slot);
    const auto& c = r.counters;
    const bool failed = c.timeouts + c.exceptions + c.crc_errors + c.other_errors > 0;
    spdlog::info("axis {}: {} transactions, {} timeouts, {} exceptions, {} CRC errors, {} other errors, {} reconnects{}{}",
                 cfg_.axes[i].name, c.transactions, c.timeouts, c.exceptions, c.crc_errors, c.other_errors,
                 c.reconnects, failed ? "; last error: " : "", failed ? r.last_error.data() : "");
  }
  if (spindle_) {
    const SpindleReport r = spindle_->worker->spindle_report();
    const auto& c = r.counters;
    spdlog::info("spindle: {} transactions, {} timeouts, {} exceptions, {} CRC errors, {} other errors{}{}",
                 c.transactions, c.timeouts, c.exceptions, c.crc_errors, c.other_errors,
                 c.timeouts + c.exceptions + c.crc_errors + c.other_errors > 0 ? "; last error: " : "",
                 c.timeouts + c.exceptions + c.crc_errors + c.other_errors > 0 ? r.last_error.data() : "");
  }
  for (auto& l : links_) l->close(util::monotonic_s());
  state_ = State::kDisabled;
  if (!dbg_file_.empty()) {
    if (FILE* f = std::fopen(dbg_file_.c_str(), "w")) {
      std::fprintf(f, "mono,tau,last_cycle,held,cmd0,cmd1,cmd2,fe0,fe1,fe2,act0,act1,act2\n");
      for (const auto& t : dbg_ticks_)
        // Commands to the nanometre: their third differences over 1 ms are jerks (a
        // micrometre's rounding there reads as 2,000 mm/s^3).
        std::fprintf(f, "%.6f,%.4f,%lld,%d,%.9f,%.9f,%.9f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f\n", t.mono, t.tau,
                     static_cast<long long>(t.last_cycle), t.held, t.cmd[0], t.cmd[1], t.cmd[2], t.fe[0], t.fe[1],
                     t.fe[2], t.act[0], t.act[1], t.act[2]);
      std::fclose(f);
    }
    if (FILE* f = std::fopen((dbg_file_ + ".setpoints").c_str(), "w")) {
      std::fprintf(f, "mono,cycle\n");
      for (const auto& t : dbg_sp_) std::fprintf(f, "%.6f,%lld\n", t.mono, static_cast<long long>(t.cycle));
      std::fclose(f);
    }
  }
}

}  // namespace cnc::bridge
