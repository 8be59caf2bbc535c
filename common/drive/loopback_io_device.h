#pragma once
// A process-data loopback with an I/O module's shape (device.h): its four output
// bytes come back as its inputs in the same cycle once it is enabled; enabling it
// takes one acyclic step. For tests of the process image and the device interface.
#include <cstdint>
#include <span>

#include "common/drive/device.h"

namespace cnc::drive {

class LoopbackIoDevice final : public Device {
 public:
  static constexpr PdoLayout kLayout{4, 4};
  PdoLayout layout() const override { return kLayout; }
  TxResult exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs, LinkCounters& c) override {
    ++c.transactions;
    if (!enabled_) return TxResult::kOk;  // a module not yet operational keeps its inputs
    put_pdo(inputs, get_pdo<uint32_t>(outputs));
    return TxResult::kOk;
  }
  TxResult control(Goal goal, LinkCounters&) override {
    enabled_ = goal == Goal::kEnable;
    return TxResult::kOk;
  }
  void forget(std::span<std::byte> inputs) override { put_pdo<uint32_t>(inputs, 0); }
  bool enabled() const { return enabled_; }

 private:
  bool enabled_ = false;
};

}  // namespace cnc::drive
