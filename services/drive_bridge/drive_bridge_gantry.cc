// The drive bridge's gantries (axes[].gantry): the second drive's squaring, the skew
// fault and JOINT_STATUS. See drive_bridge_node.h.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_program_command.hpp"
#include "services/drive_bridge/drive_bridge_node.h"

namespace cnc::bridge {

void DriveBridgeNode::on_interp_input(const cnc::lcmt_interp_input& m) {
  // The interpolator's HOMED of a gantry axis carries the second side's offset
  // (position_mm[0]) beside the first's (value): the squaring is their difference.
  if (m.kind != cnc::lcmt_interp_input::COMMAND || m.command.command != cnc::lcmt_program_command::HOMED) return;
  const cnc::lcmt_program_command& c = m.command;
  if (c.num_axes != 1 || c.position_mm.size() != 1 || !std::isfinite(c.value) || !std::isfinite(c.position_mm[0]))
    return;
  for (Joint& j : joints_) {
    if (static_cast<int32_t>(j.axis) != c.axis) continue;
    const double target = c.position_mm[0] - c.value;
    if (j.homed && target == j.target_mm) return;  // a resent input
    j.homed = true;
    j.target_mm = target;
    spdlog::info("gantry {}: homed; squaring {} - {} = {:.4f} mm (from {:.4f} mm)", cfg_.axes[j.axis].name,
                 cfg_.axes[j.axis].gantry.name, cfg_.axes[j.axis].name, target, j.squaring_mm);
  }
}

void DriveBridgeNode::gantry_tick(double now_s) {
  const bool watch = state_ == State::kEnabled && !core_.faulted() && core_.mode() == BridgeCore::Mode::kFollowing;
  for (Joint& j : joints_) {
    const Axis& first = axes_[j.axis];
    const config::GantryConfig& g = cfg_.axes[j.axis].gantry;
    if (!first.rep.have_status || !j.drv.rep.have_status) continue;
    j.skew_mm = (j.drv.rep.actual_mm - first.rep.actual_mm) - j.squaring_mm;
    if (!watch) {
      j.prev_s = -1;
      continue;
    }
    const double abs_skew = std::fabs(j.skew_mm);
    j.max_skew_mm = std::max(j.max_skew_mm, abs_skew);
    if (abs_skew > g.skew_limit_mm) {
      // The crossing, on the straight line between the read before and this one.
      double cross_s = now_s;
      if (j.prev_s >= 0 && abs_skew > j.prev_abs_skew_mm)
        cross_s = j.prev_s + (g.skew_limit_mm - j.prev_abs_skew_mm) / (abs_skew - j.prev_abs_skew_mm) * (now_s - j.prev_s);
      skew_.latched = true;
      skew_.stood = false;
      skew_.at_s = now_s;
      skew_.reaction_ms = (now_s - std::min(cross_s, now_s)) * 1e3;
      skew_.stop_ms = -1;
      skew_.command_stood_s = -1;
      const std::string& name = cfg_.axes[j.axis].name;
      char b[400];
      std::snprintf(b, sizeof b,
                    "gantry skew: axis %s's drives %s (unit %d) at %.4f mm and %s (unit %d) at %.4f mm differ by "
                    "%.4f mm from their squaring %.4f mm, over the limit %g mm (axes[].gantry.skew_limit_mm; crossed "
                    "%.2f ms before this read, between it and the one before): controlled stop, drives disabled",
                    name.c_str(), name.c_str(), cfg_.axes[j.axis].drive.unit_id, first.rep.actual_mm, g.name.c_str(),
                    g.drive.unit_id, j.drv.rep.actual_mm, j.skew_mm, j.squaring_mm, g.skew_limit_mm,
                    skew_.reaction_ms);
      const std::string text(b);
      spdlog::error("{}", text);
      alarm(cnc::lcmt_alarm::FAULT, "gantry_skew", text);
      fault(j.axis, text, false);  // brakes in this tick's core step
      return;
    }
    j.prev_abs_skew_mm = abs_skew;
    j.prev_s = now_s;
  }
  if (skew_.latched && !skew_.stood && core_.mode() != BridgeCore::Mode::kStopping &&
      settled(skew_.command_stood_s, now_s)) {
    skew_.stood = true;
    skew_.stop_ms = (now_s - skew_.at_s) * 1e3;
    for (auto& a : axes_) a.cmd.goal = drive::Goal::kDisable;
    for (auto& j : joints_) j.drv.cmd.goal = drive::Goal::kDisable;
    spdlog::info("gantry skew: the axes stand {:.1f} ms after the fault; drives disabled", skew_.stop_ms);
  }
}

void DriveBridgeNode::advance_squaring() {
  // The squaring moves only while the bridge follows a stream, enabled and not
  // braking: at the axis's home search velocity, its acceleration limited to the axis's.
  if (state_ != State::kEnabled || core_.faulted() || core_.mode() != BridgeCore::Mode::kFollowing) return;
  const double dt = cfg_.servo_period_s;
  for (Joint& j : joints_) {
    const double d = j.target_mm - j.squaring_mm;
    if (d == 0 && j.v_mm_s == 0) continue;
    const config::AxisConfig& ax = cfg_.axes[j.axis];
    const double a = ax.max_accel_mm_s2;
    const double vmax = ax.home.search_velocity_mm_s;
    if (std::fabs(d) <= a * dt * dt && std::fabs(j.v_mm_s) <= a * dt) {
      j.squaring_mm = j.target_mm;
      j.v_mm_s = 0;
      continue;
    }
    const double want = std::copysign(std::min(vmax, std::sqrt(2 * a * std::fabs(d))), d);
    j.v_mm_s += std::clamp(want - j.v_mm_s, -a * dt, a * dt);
    j.squaring_mm += j.v_mm_s * dt;
  }
}

void DriveBridgeNode::publish_joint_status() {
  cnc::lcmt_joint_status& s = joint_msg_;
  const size_t n = joints_.size();
  if (s.name.size() != n) {
    s.num_joints = static_cast<int32_t>(n);
    s.axis.resize(n);
    s.name.resize(n);
    s.commanded_mm.resize(n);
    s.actual_mm.resize(n);
    s.following_error_mm.resize(n);
    s.squaring_mm.resize(n);
    s.squaring_target_mm.resize(n);
    s.skew_mm.resize(n);
    s.max_skew_mm.resize(n);
    s.drive_state.resize(n);
    s.fault.resize(n);
    s.transactions.resize(n);
    s.timeouts.resize(n);
    s.home_latch_count.resize(n);
    s.home_latch_mm.resize(n);
    for (size_t k = 0; k < n; ++k) {
      s.axis[k] = static_cast<int32_t>(joints_[k].axis);
      s.name[k] = cfg_.axes[joints_[k].axis].gantry.name;
      s.fault[k].reserve(256);
    }
  }
  s.setpoint_cycle = core_.last_cycle();
  for (size_t k = 0; k < n; ++k) {
    const Joint& j = joints_[k];
    const AxisReport& r = j.drv.rep;
    s.commanded_mm[k] = j.drv.cmd.cmd_mm;
    s.actual_mm[k] = r.actual_mm;
    s.following_error_mm[k] = r.fe_mm;
    s.squaring_mm[k] = j.squaring_mm;
    s.squaring_target_mm[k] = j.target_mm;
    s.skew_mm[k] = j.skew_mm;
    s.max_skew_mm[k] = j.max_skew_mm;
    // The joint's state is its axis's, or a fault of its own drive.
    const bool own_fault = j.drv.link_down || (r.have_status && r.status.fault);
    s.drive_state[k] = own_fault ? cnc::lcmt_axis_status::FAULT : status_msg_.drive_state[j.axis];
    s.fault[k].clear();
    if (j.drv.link_down) s.fault[k].append("no answer: ").append(r.last_error.data());
    else if (r.have_status && r.status.fault) s.fault[k].append("drive fault (").append(r.status.state).append(")");
    else s.fault[k].append(status_msg_.fault[j.axis]);
    s.transactions[k] = r.counters.transactions;
    s.timeouts[k] = r.counters.timeouts;
    s.home_latch_count[k] = r.has_home_latch ? static_cast<int32_t>(r.home_latch_count) : -1;
    s.home_latch_mm[k] = r.home_latch_mm;
  }
  bus_.publish(ch_joint_status_, s);
}

}  // namespace cnc::bridge
