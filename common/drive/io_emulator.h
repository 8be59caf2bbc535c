#pragma once
// The module end of an I/O module (config io.modules[m] with its points): a Modbus
// register image of coils, discrete inputs, input registers and holding registers,
// each table from address 0 to its highest point. The servo simulator serves it
// (modbus_reply on mapping()); the loopback link and tests use the direct access.
// Its inputs change only when told (set_point), as a switch or a sensor would.
#include <modbus.h>

#include <cstdint>
#include <string>

#include "common/config/machine_config.h"

namespace cnc::drive {

class IoEmulator {
 public:
  IoEmulator(const config::IoConfig& io, int module);
  ~IoEmulator();
  IoEmulator(const IoEmulator&) = delete;
  IoEmulator& operator=(const IoEmulator&) = delete;

  modbus_mapping_t* mapping() { return map_; }
  const std::string& name() const { return name_; }
  // Direct access: 0 or a Modbus exception code.
  int read_bits(int addr, int n, uint8_t* dest, bool discrete_inputs) const;
  int write_bits(int addr, int n, const uint8_t* src);
  int read_registers(int addr, int n, uint16_t* dest, bool input_registers) const;
  int write_registers(int addr, int n, const uint16_t* src);
  // A point's raw value: a bit 0/1 or a register's count. False when no point has that name on this module.
  bool set_point(const std::string& name, int raw);
  bool point(const std::string& name, int* raw) const;
  uint8_t coil(int addr) const { return addr < map_->nb_bits ? map_->tab_bits[addr] : 0; }

 private:
  const config::IoConfig& io_;
  int module_;
  std::string name_;
  modbus_mapping_t* map_ = nullptr;
};

}  // namespace cnc::drive
