#include "common/drive/io_module_device.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace cnc::drive {
namespace {
constexpr size_t kCoil = static_cast<size_t>(config::IoKind::kCoil);
constexpr size_t kDiscrete = static_cast<size_t>(config::IoKind::kDiscreteInput);
constexpr size_t kInputReg = static_cast<size_t>(config::IoKind::kInputRegister);
constexpr size_t kHoldingReg = static_cast<size_t>(config::IoKind::kHoldingRegister);
}  // namespace

IoModuleDevice::IoModuleDevice(const config::IoConfig& io, int module, Link& link)
    : unit_(io.modules.at(static_cast<size_t>(module)).link.unit_id), link_(link) {
  const std::string& name = io.modules[static_cast<size_t>(module)].name;
  for (size_t i = 0; i < io.points.size(); ++i) {
    const config::IoPointConfig& p = io.points[i];
    if (p.module != module) continue;
    const auto k = static_cast<size_t>(p.kind);
    points_[k].push_back(static_cast<int>(i));
    addr_[k].push_back(p.address);
  }
  for (size_t k = 0; k < 4; ++k) {
    if (points_[k].empty()) continue;
    const char* kind = config::to_string(static_cast<config::IoKind>(k));
    if (points_[k].size() > static_cast<size_t>(kMaxIoPointsPerKind))
      throw std::invalid_argument("I/O module " + name + ": more than " + std::to_string(kMaxIoPointsPerKind) + " " +
                                  kind + " points");
    const auto [lo, hi] = std::minmax_element(addr_[k].begin(), addr_[k].end());
    read_[k] = {*lo, *hi - *lo + 1};
    const int limit = (k == kCoil || k == kDiscrete) ? MODBUS_MAX_READ_BITS : MODBUS_MAX_READ_REGISTERS;
    if (read_[k].n > limit)
      throw std::invalid_argument("I/O module " + name + ": its " + kind + " points span " +
                                  std::to_string(read_[k].n) + " addresses, more than one read (" +
                                  std::to_string(limit) + ")");
  }
  // Runs of adjacent coil addresses, each written in one transaction.
  std::vector<std::pair<int, int>> coils;  // address, bit
  for (size_t i = 0; i < addr_[kCoil].size(); ++i) coils.emplace_back(addr_[kCoil][i], static_cast<int>(i));
  std::sort(coils.begin(), coils.end());
  for (const auto& [a, bit] : coils) {
    if (runs_.empty() || a != runs_.back().addr + static_cast<int>(runs_.back().bit_of.size()))
      runs_.push_back(Run{a, {}});
    runs_.back().bit_of.push_back(bit);
  }
}

TxResult IoModuleDevice::exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs, LinkCounters& c) {
  const auto out = get_pdo<IoModuleOutputs>(outputs);
  auto in = get_pdo<IoModuleInputs>(inputs);
  last_tx_ = 0;
  if (out.write && have_read_back_) {
    for (const Run& r : runs_) {
      bool differs = false;
      const int n = static_cast<int>(r.bit_of.size());
      for (int k = 0; k < n; ++k) {
        const uint64_t bit = uint64_t{1} << r.bit_of[static_cast<size_t>(k)];
        bits_[static_cast<size_t>(k)] = (out.coils & bit) ? 1 : 0;
        differs = differs || ((out.coils ^ read_back_) & bit) != 0;
      }
      if (!differs) continue;
      ++last_tx_;
      const TxResult w = n == 1 ? link_.write_coil(unit_, r.addr, bits_[0] != 0, c)
                                : link_.write_coils(unit_, r.addr, n, bits_.data(), c);
      if (w != TxResult::kOk) return w;
    }
    const std::vector<int>& regs = addr_[kHoldingReg];
    for (size_t i = 0; i < regs.size(); ++i) {
      if (((out.holding_write >> i) & 1) == 0 || out.holding[i] == holding_back_[i]) continue;
      ++last_tx_;
      const TxResult w = link_.write_register(unit_, regs[i], out.holding[i], c);
      if (w != TxResult::kOk) return w;
    }
  }
  // Bits: the span of each kind's points in one read, then each point's bit.
  for (size_t k : {kCoil, kDiscrete}) {
    const Span& s = read_[k];
    if (s.n == 0) continue;
    ++last_tx_;
    const TxResult r = k == kCoil ? link_.read_coils(unit_, s.addr, s.n, bits_.data(), c)
                                  : link_.read_discrete_inputs(unit_, s.addr, s.n, bits_.data(), c);
    if (r != TxResult::kOk) return r;
    uint64_t v = 0;
    for (size_t i = 0; i < addr_[k].size(); ++i)
      if (bits_[static_cast<size_t>(addr_[k][i] - s.addr)]) v |= uint64_t{1} << i;
    (k == kCoil ? in.coils : in.discrete) = v;
  }
  for (size_t k : {kInputReg, kHoldingReg}) {
    const Span& s = read_[k];
    if (s.n == 0) continue;
    ++last_tx_;
    const TxResult r = k == kInputReg ? link_.read_input_registers(unit_, s.addr, s.n, regs_.data(), c)
                                      : link_.read_registers(unit_, s.addr, s.n, regs_.data(), c);
    if (r != TxResult::kOk) return r;
    auto& dest = k == kInputReg ? in.input_registers : in.holding_registers;
    for (size_t i = 0; i < addr_[k].size(); ++i) dest[i] = regs_[static_cast<size_t>(addr_[k][i] - s.addr)];
  }
  read_back_ = in.coils;
  holding_back_ = in.holding_registers;
  have_read_back_ = true;
  in.valid = true;
  put_pdo(inputs, in);
  return TxResult::kOk;
}

void IoModuleDevice::forget(std::span<std::byte> inputs) {
  have_read_back_ = false;
  read_back_ = 0;
  put_pdo(inputs, IoModuleInputs{});
}

}  // namespace cnc::drive
