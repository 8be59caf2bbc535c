#pragma once
// A device on a link, as a fieldbus master sees it (EtherCAT's PDO mapping, SOEM's
// and EtherLab's process image): each device owns a fixed-size slice of one cyclic
// process image, outputs (master to device) and inputs (device to master). The
// master writes the outputs of a slice, the cycle exchanges it, the device logic
// reads the inputs back. Acyclic traffic (the state machine's steps, parameter
// reads) stays off the cycle, in control().
//
// An axis drive over Modbus (axis_drive.h), a drive on a future fieldbus and a
// device that is no axis (a spindle drive, an I/O module) are each one
// implementation. A Modbus link exchanges slice by slice in register
// transactions; a fieldbus would exchange the whole image in one frame.
#include <cstddef>
#include <cstring>
#include <span>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "common/drive/link.h"
#include "common/drive/profile_logic.h"

namespace cnc::drive {

// The sizes of a device's slices, in bytes, fixed for its life.
struct PdoLayout {
  std::size_t inputs = 0;
  std::size_t outputs = 0;
};

class Device {
 public:
  virtual ~Device() = default;
  virtual PdoLayout layout() const = 0;
  // One cycle: `outputs` to the device, its answer into `inputs`. The inputs
  // change only when the exchange succeeds (they hold the last good cycle).
  virtual TxResult exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs, LinkCounters& c) = 0;
  // The state-machine hook, between cycles: at most one acyclic step toward
  // `goal`; kOk when nothing was to do.
  virtual TxResult control(Goal goal, LinkCounters& c) = 0;
  // After the link was lost: what the device reports and what it was told are
  // unknown; `inputs` is cleared to "no answer yet".
  virtual void forget(std::span<std::byte> inputs) = 0;
};

// One cyclic process image: the devices' slices side by side, reserved before
// the first cycle (no allocation after that).
class ProcessImage {
 public:
  // Reserves the slices of a device; returns its index.
  std::size_t add(const PdoLayout& l) {
    slices_.push_back({inputs_.size(), l.inputs, outputs_.size(), l.outputs});
    inputs_.resize(inputs_.size() + l.inputs);
    outputs_.resize(outputs_.size() + l.outputs);
    return slices_.size() - 1;
  }
  std::size_t devices() const { return slices_.size(); }
  std::span<std::byte> inputs(std::size_t device) {
    const Slice& s = slices_.at(device);
    return {inputs_.data() + s.in, s.in_n};
  }
  std::span<std::byte> outputs(std::size_t device) {
    const Slice& s = slices_.at(device);
    return {outputs_.data() + s.out, s.out_n};
  }
  std::size_t input_bytes() const { return inputs_.size(); }
  std::size_t output_bytes() const { return outputs_.size(); }

 private:
  struct Slice {
    std::size_t in, in_n, out, out_n;
  };
  std::vector<Slice> slices_;
  std::vector<std::byte> inputs_;
  std::vector<std::byte> outputs_;
};

// Typed process data in a slice (a device's fixed layout as a plain struct).
template <class T>
void put_pdo(std::span<std::byte> slice, const T& v) {
  static_assert(std::is_trivially_copyable_v<T>);
  if (slice.size() < sizeof(T)) throw std::logic_error("process data larger than its slice");
  std::memcpy(slice.data(), &v, sizeof(T));
}
template <class T>
T get_pdo(std::span<const std::byte> slice) {
  static_assert(std::is_trivially_copyable_v<T>);
  if (slice.size() < sizeof(T)) throw std::logic_error("process data larger than its slice");
  T v;
  std::memcpy(&v, slice.data(), sizeof(T));
  return v;
}

}  // namespace cnc::drive
