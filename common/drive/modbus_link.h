#pragma once
// The libmodbus links: Modbus TCP (one socket to an endpoint) and Modbus RTU (one
// serial line, e.g. RS-485, with the drives as unit ids on it).
#include <modbus.h>

#include <memory>
#include <string>

#include "common/drive/link.h"

namespace cnc::drive {

class ModbusLink final : public Link {
 public:
  static std::unique_ptr<ModbusLink> tcp(const std::string& host, int port, double response_timeout_s);
  // parity 'N', 'E' or 'O'.
  static std::unique_ptr<ModbusLink> rtu(const std::string& device, int baud, char parity, int stop_bits,
                                         double response_timeout_s);
  ~ModbusLink() override;

 private:
  ModbusLink(std::string name, modbus_t* ctx, double response_timeout_s, bool serial);
  int do_open(std::string& error) override;
  void do_close() override;
  int do_read(int unit, int addr, int n, uint16_t* dest) override;
  int do_write1(int unit, int addr, uint16_t value) override;
  int do_write(int unit, int addr, int n, const uint16_t* src) override;
  int do_write_read(int unit, int waddr, int wn, const uint16_t* src, int raddr, int rn, uint16_t* dest) override;
  int do_read_bits(int unit, int addr, int n, uint8_t* dest, bool discrete_inputs) override;
  int do_write_bit(int unit, int addr, bool on) override;
  int do_write_bits(int unit, int addr, int n, const uint8_t* src) override;
  int do_read_input_registers(int unit, int addr, int n, uint16_t* dest) override;
  // Huanyang frames on the serial line's descriptor, framed here (not by libmodbus).
  int do_frame(const uint8_t* request, int n, uint8_t* reply, int cap, int* got) override;
  void discard_input() override;

  modbus_t* ctx_;
  bool serial_;
  double timeout_s_;
};

}  // namespace cnc::drive
