#pragma once
// An I/O module on Modbus as a device (device.h): its named points (config io.points)
// are coils, discrete inputs, input registers and holding registers. Its process data
// are the coils' wanted states out, and every point's value in. Each cycle writes the
// coils whose read-back differs from what is wanted (a run of adjacent coil points in
// one function 15, a single one with function 5) and each holding register that is an
// output and whose read-back differs (function 6), then reads each table that has
// points in one transaction over the span of its points (functions 1, 2, 4, 3).
// No allocation after construction: it runs on the bridge's link workers.
#include <modbus.h>

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "common/config/machine_config.h"
#include "common/drive/device.h"
#include "common/drive/link.h"

namespace cnc::drive {

// Points of one kind on one module, at most (a bit each in the process data).
inline constexpr int kMaxIoPointsPerKind = 64;

// Master to module, each cycle. Bit i: the module's i-th coil point (config order).
struct IoModuleOutputs {
  bool write = false;  // write the coils and registers that differ; otherwise only read
  uint64_t coils = 0;
  uint64_t holding_write = 0;  // bit i: the i-th holding-register point is written with holding[i]
  std::array<uint16_t, kMaxIoPointsPerKind> holding{};
};

// Module to master: the last good cycle's answer.
struct IoModuleInputs {
  bool valid = false;   // the module has answered since the link was (re)opened
  uint64_t coils = 0;   // bit i: the i-th coil point as read back
  uint64_t discrete = 0;  // bit i: the i-th discrete-input point
  std::array<uint16_t, kMaxIoPointsPerKind> input_registers{};    // raw, by input-register point
  std::array<uint16_t, kMaxIoPointsPerKind> holding_registers{};  // raw, by holding-register point
};

class IoModuleDevice final : public Device {
 public:
  static constexpr PdoLayout kLayout{sizeof(IoModuleInputs), sizeof(IoModuleOutputs)};
  // The points of io.modules[module]. Throws std::invalid_argument when a kind has more
  // than kMaxIoPointsPerKind points or its points span more than one read.
  IoModuleDevice(const config::IoConfig& io, int module, Link& link);
  PdoLayout layout() const override { return kLayout; }
  TxResult exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs, LinkCounters& c) override;
  TxResult control(Goal, LinkCounters&) override { return TxResult::kOk; }  // a module has no state machine
  void forget(std::span<std::byte> inputs) override;

  // The module's points of a kind, as indices into io.points (bit i / slot i is the i-th).
  const std::vector<int>& points(config::IoKind k) const { return points_[static_cast<size_t>(k)]; }
  // Transactions of the last exchange.
  int last_transactions() const { return last_tx_; }

 private:
  struct Span {
    int addr = 0;
    int n = 0;
  };
  // A run of adjacent coil addresses: bit_of[k] is the point bit at addr + k.
  struct Run {
    int addr = 0;
    std::vector<int> bit_of;
  };

  int unit_;
  Link& link_;
  std::array<std::vector<int>, 4> points_;
  std::array<std::vector<int>, 4> addr_;  // each point's address, by kind, in the same order
  std::array<Span, 4> read_;              // n == 0: nothing to read of that kind
  std::vector<Run> runs_;
  std::array<uint8_t, MODBUS_MAX_READ_BITS> bits_{};
  std::array<uint16_t, MODBUS_MAX_READ_REGISTERS> regs_{};
  uint64_t read_back_ = 0;
  std::array<uint16_t, kMaxIoPointsPerKind> holding_back_{};
  bool have_read_back_ = false;
  int last_tx_ = 0;
};

}  // namespace cnc::drive
