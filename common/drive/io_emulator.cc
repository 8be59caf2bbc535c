#include "common/drive/io_emulator.h"

#include <algorithm>
#include <stdexcept>

namespace cnc::drive {

IoEmulator::IoEmulator(const config::IoConfig& io, int module)
    : io_(io), module_(module), name_(io.modules.at(static_cast<size_t>(module)).name) {
  int n[4] = {0, 0, 0, 0};
  for (const auto& p : io.points)
    if (p.module == module) n[static_cast<int>(p.kind)] = std::max(n[static_cast<int>(p.kind)], p.address + 1);
  map_ = modbus_mapping_new(n[0], n[1], n[3], n[2]);
  if (map_ == nullptr) throw std::runtime_error("modbus_mapping_new failed for I/O module " + name_);
}

IoEmulator::~IoEmulator() { modbus_mapping_free(map_); }

int IoEmulator::read_bits(int addr, int n, uint8_t* dest, bool discrete_inputs) const {
  const int size = discrete_inputs ? map_->nb_input_bits : map_->nb_bits;
  const uint8_t* tab = discrete_inputs ? map_->tab_input_bits : map_->tab_bits;
  if (n < 1 || n > MODBUS_MAX_READ_BITS) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
  if (addr < 0 || addr + n > size) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
  std::copy(tab + addr, tab + addr + n, dest);
  return 0;
}

int IoEmulator::write_bits(int addr, int n, const uint8_t* src) {
  if (n < 1 || n > MODBUS_MAX_WRITE_BITS) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
  if (addr < 0 || addr + n > map_->nb_bits) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
  for (int i = 0; i < n; ++i) map_->tab_bits[addr + i] = src[i] ? 1 : 0;
  return 0;
}

int IoEmulator::read_registers(int addr, int n, uint16_t* dest, bool input_registers) const {
  const int size = input_registers ? map_->nb_input_registers : map_->nb_registers;
  const uint16_t* tab = input_registers ? map_->tab_input_registers : map_->tab_registers;
  if (n < 1 || n > MODBUS_MAX_READ_REGISTERS) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
  if (addr < 0 || addr + n > size) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
  std::copy(tab + addr, tab + addr + n, dest);
  return 0;
}

int IoEmulator::write_registers(int addr, int n, const uint16_t* src) {
  if (n < 1 || n > MODBUS_MAX_WRITE_REGISTERS) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
  if (addr < 0 || addr + n > map_->nb_registers) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
  std::copy(src, src + n, map_->tab_registers + addr);
  return 0;
}

bool IoEmulator::set_point(const std::string& name, int raw) {
  const int i = io_.point_index(name);
  if (i < 0 || io_.points[static_cast<size_t>(i)].module != module_) return false;
  const config::IoPointConfig& p = io_.points[static_cast<size_t>(i)];
  switch (p.kind) {
    case config::IoKind::kCoil: map_->tab_bits[p.address] = raw ? 1 : 0; break;
    case config::IoKind::kDiscreteInput: map_->tab_input_bits[p.address] = raw ? 1 : 0; break;
    case config::IoKind::kInputRegister: map_->tab_input_registers[p.address] = static_cast<uint16_t>(raw); break;
    case config::IoKind::kHoldingRegister: map_->tab_registers[p.address] = static_cast<uint16_t>(raw); break;
  }
  return true;
}

bool IoEmulator::point(const std::string& name, int* raw) const {
  const int i = io_.point_index(name);
  if (i < 0 || io_.points[static_cast<size_t>(i)].module != module_) return false;
  const config::IoPointConfig& p = io_.points[static_cast<size_t>(i)];
  switch (p.kind) {
    case config::IoKind::kCoil: *raw = map_->tab_bits[p.address]; break;
    case config::IoKind::kDiscreteInput: *raw = map_->tab_input_bits[p.address]; break;
    case config::IoKind::kInputRegister: *raw = map_->tab_input_registers[p.address]; break;
    case config::IoKind::kHoldingRegister: *raw = map_->tab_registers[p.address]; break;
  }
  return true;
}

}  // namespace cnc::drive
