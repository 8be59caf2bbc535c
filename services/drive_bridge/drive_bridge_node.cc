#include "services/drive_bridge/drive_bridge_node.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <map>

#include "cnc/lcmt_alarm.hpp"
#include "cnc/lcmt_axis_status.hpp"
#include "common/drive/sim_profile.h"

namespace cnc::bridge {

namespace ch = config::channels;
namespace sim = drive::sim;

DriveBridgeNode::DriveBridgeNode(const config::MachineConfig& cfg, bus::Bus& bus)
    : cfg_(cfg), bus_(bus), core_(cfg), ch_status_(cfg.channel(ch::kAxisStatus)),
      ticks_per_ipo_(static_cast<int>(std::lround(cfg.ipo_period_s / cfg.servo_period_s))),
      ch_alarm_(cfg.channel(ch::kAlarm)) {
  std::map<std::string, drive::ModbusLink*> by_endpoint;
  for (const auto& a : cfg.axes) {
    if (a.drive.transport != "modbus_tcp" || a.drive.profile != "sim") {
      throw std::runtime_error("axis " + a.name + ": transport '" + a.drive.transport + "' with profile '" +
                               a.drive.profile + "' is not available in this build (modbus_tcp + sim only)");
    }
    const std::string key = a.drive.host + ":" + std::to_string(a.drive.port);
    auto it = by_endpoint.find(key);
    if (it == by_endpoint.end()) {
      links_.push_back(std::make_unique<drive::ModbusLink>(a.drive.host, a.drive.port, a.drive.response_timeout_s));
      it = by_endpoint.emplace(key, links_.back().get()).first;
    }
    Axis ax;
    ax.link = it->second;
    ax.unit = a.drive.unit_id;
    axes_.push_back(ax);
  }
  bus_.subscribe<cnc::lcmt_setpoint>(cfg.channel(ch::kSetpoints), [this](const auto& m) { on_setpoint(m); });
}

bool DriveBridgeNode::bring_up(double now_s) {
  bool all = true;
  for (auto& l : links_) {
    const bool was = l->connected();
    if (!l->ensure_connected(now_s)) {
      all = false;
    } else if (!was) {
      spdlog::info("connected to {}", l->name());
    }
  }
  if (!all) return false;
  AxisArray actual{};
  for (size_t i = 0; i < axes_.size(); ++i) {
    Axis& ax = axes_[i];
    // Fault reset (rising edge), then enable operation.
    ax.link->write_register(ax.unit, sim::kControlword, sim::kCwFaultReset, ax.counters);
    if (ax.link->write_register(ax.unit, sim::kControlword, sim::kCwEnable, ax.counters) != drive::TxResult::kOk)
      return false;
    uint16_t regs[sim::kNumRegisters] = {};
    if (ax.link->read_registers(ax.unit, 0, sim::kNumRegisters, regs, ax.counters) != drive::TxResult::kOk)
      return false;
    if ((regs[sim::kStatusword] & sim::kSwEnabled) == 0) return false;
    ax.statusword = regs[sim::kStatusword];
    ax.actual_mm = sim::counts_to_mm(sim::get_i32_low_first(&regs[sim::kActualPosition]));
    ax.state = cnc::lcmt_axis_status::ENABLED;
    ax.fault.clear();
    actual[i] = ax.actual_mm;
  }
  core_.reset(actual);
  up_ = true;
  fault_reported_ = false;
  spdlog::info("{} drives enabled", axes_.size());
  return true;
}

void DriveBridgeNode::on_setpoint(const cnc::lcmt_setpoint& m) {
  if (!up_) return;
  if (m.num_axes != static_cast<int32_t>(axes_.size())) {
    core_.fault("setpoint seq " + std::to_string(m.seq) + " has " + std::to_string(m.num_axes) + " axes, machine has " +
                std::to_string(axes_.size()));
    return;
  }
  AxisArray p{};
  for (size_t i = 0; i < axes_.size(); ++i) p[i] = m.position_mm[i];
  core_.on_setpoint(m.cycle, p);
}

void DriveBridgeNode::exchange(size_t i, double target_mm) {
  Axis& ax = axes_[i];
  uint16_t target[2];
  sim::put_i32_low_first(target, sim::mm_to_counts(target_mm));
  uint16_t regs[sim::kNumRegisters - sim::kStatusword] = {};
  const drive::TxResult r = ax.link->write_and_read(ax.unit, sim::kTargetPosition, 2, target, sim::kStatusword,
                                                    sim::kNumRegisters - sim::kStatusword, regs, ax.counters);
  if (r == drive::TxResult::kOk) {
    ax.statusword = regs[0];
    ax.actual_mm = sim::counts_to_mm(sim::get_i32_low_first(&regs[sim::kActualPosition - sim::kStatusword]));
    if (ax.statusword & sim::kSwFault) core_.fault("axis " + cfg_.axes[i].name + ": drive reports a fault");
  } else if (r == drive::TxResult::kLinkLost) {
    core_.fault("axis " + cfg_.axes[i].name + ": connection to " + ax.link->name() + " lost (" +
                ax.link->last_error() + ")");
  }
}

void DriveBridgeNode::servo_tick(double now_s) {
  bus_.drain();
  ++tick_;
  if (!up_) return;
  const bool was_faulted = core_.faulted();
  const AxisArray& cmd = core_.tick();
  if (!core_.faulted()) {
    for (size_t i = 0; i < axes_.size(); ++i) exchange(i, cmd[i]);
    AxisArray actual{};
    for (size_t i = 0; i < axes_.size(); ++i) actual[i] = axes_[i].actual_mm;
    core_.check_following(actual);
  }
  if (core_.faulted() && !was_faulted) {
    // Nothing moves: disable every drive still reachable.
    for (auto& ax : axes_) {
      ax.link->write_register(ax.unit, sim::kControlword, 0, ax.counters);
      ax.state = cnc::lcmt_axis_status::FAULT;
      ax.fault = core_.fault_reason();
    }
    spdlog::error("fault: {}", core_.fault_reason());
  }
  if (core_.faulted() && !fault_reported_) {
    fault_reported_ = true;
    cnc::lcmt_alarm al{};
    al.source = "cnc-drive-bridge";
    al.severity = cnc::lcmt_alarm::FAULT;
    al.code = "drive_fault";
    al.text = core_.fault_reason();
    bus_.publish(ch_alarm_, al);
  }
  (void)now_s;
}

void DriveBridgeNode::publish_status(int64_t overruns) {
  if (tick_ % ticks_per_ipo_ != 0) return;
  cnc::lcmt_axis_status s{};
  s.setpoint_cycle = core_.last_cycle();
  s.num_axes = static_cast<int32_t>(axes_.size());
  for (size_t i = 0; i < axes_.size(); ++i) {
    const Axis& ax = axes_[i];
    s.axis_name.push_back(cfg_.axes[i].name);
    s.commanded_mm.push_back(core_.commanded()[i]);
    s.actual_mm.push_back(ax.actual_mm);
    s.following_error_mm.push_back(core_.following_error(static_cast<int>(i), ax.actual_mm));
    int8_t st = ax.state;
    if (!up_) st = cnc::lcmt_axis_status::DISABLED;
    else if (core_.stopping()) st = cnc::lcmt_axis_status::STOPPING;
    s.drive_state.push_back(st);
    s.fault.push_back(ax.fault);
    s.transactions.push_back(ax.counters.transactions);
    s.timeouts.push_back(ax.counters.timeouts);
    s.exceptions.push_back(ax.counters.exceptions);
    s.crc_errors.push_back(ax.counters.crc_errors);
    s.reconnects.push_back(ax.counters.reconnects);
  }
  s.setpoint_gaps = core_.setpoint_gaps();
  s.servo_overruns = overruns;
  bus_.publish(ch_status_, s);
}

void DriveBridgeNode::shut_down() {
  spdlog::info("setpoint gaps {}, servo ticks without a setpoint to follow {}", core_.setpoint_gaps(),
               core_.starved_ticks());
  for (auto& ax : axes_) {
    if (ax.link->connected()) ax.link->write_register(ax.unit, sim::kControlword, 0, ax.counters);
  }
  for (auto& l : links_) l->disconnect();
  up_ = false;
}

}  // namespace cnc::bridge
