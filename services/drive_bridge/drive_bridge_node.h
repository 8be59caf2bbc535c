#pragma once
// LCM and Modbus side of the drive bridge. The servo loop runs at T_servo: take
// the setpoints that arrived, advance the fine interpolation, exchange target and
// actual position with every drive (one read-write transaction each), check the
// following error, and publish the axis status every T_ipo.
#include <memory>
#include <string>
#include <vector>

#include "cnc/lcmt_setpoint.hpp"
#include "common/bus/bus.h"
#include "common/drive/modbus_link.h"
#include "services/drive_bridge/drive_bridge.h"

namespace cnc::bridge {

class DriveBridgeNode {
 public:
  DriveBridgeNode(const config::MachineConfig& cfg, bus::Bus& bus);
  // Connects and enables every drive; false if not all are ready yet (call again).
  bool bring_up(double now_s);
  void servo_tick(double now_s);
  // Disables the drives (controlword 0) and closes the links.
  void shut_down();
  void publish_status(int64_t overruns);
  bool up() const { return up_; }

 private:
  struct Axis {
    drive::ModbusLink* link = nullptr;
    int unit = 1;
    drive::LinkCounters counters;
    double actual_mm = 0;
    uint16_t statusword = 0;
    int8_t state = 0;
    std::string fault;
  };
  void on_setpoint(const cnc::lcmt_setpoint& m);
  void exchange(size_t axis, double target_mm);

  config::MachineConfig cfg_;
  bus::Bus& bus_;
  BridgeCore core_;
  std::vector<std::unique_ptr<drive::ModbusLink>> links_;
  std::vector<Axis> axes_;
  std::string ch_status_;
  int ticks_per_ipo_;
  int64_t tick_ = 0;
  bool up_ = false;
  bool fault_reported_ = false;
  std::string ch_alarm_;
};

}  // namespace cnc::bridge
