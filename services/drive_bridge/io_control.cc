#include "services/drive_bridge/io_control.h"

#include <cmath>

namespace cnc::bridge {

IoControl::IoControl(const config::IoConfig& io, const std::vector<std::vector<int>>& module_coils,
                     const std::vector<std::vector<int>>& module_holding)
    : io_(io), module_coils_(module_coils), module_holding_(module_holding), role_(io.points.size(), -1),
      analog_role_(io.points.size(), -1), analog_(io.analog_outputs.size(), 0.0), raw_(io.analog_outputs.size(), 0),
      analog_set_(io.analog_outputs.size(), false) {
  for (size_t n = 0; n < io.analog_outputs.size(); ++n)
    analog_role_[static_cast<size_t>(io.analog_outputs[n])] = static_cast<int8_t>(n);
  if (io.coolant_mist >= 0) role_[static_cast<size_t>(io.coolant_mist)] = -2;
  if (io.coolant_flood >= 0) role_[static_cast<size_t>(io.coolant_flood)] = -3;
  for (size_t n = 0; n < io.digital_outputs.size(); ++n)
    role_[static_cast<size_t>(io.digital_outputs[n])] = static_cast<int8_t>(n);
}

bool IoControl::on_command(int64_t seq, int coolant, uint64_t outputs, const std::vector<double>& analog,
                           bool following) {
  if (seq <= seq_) return false;
  seq_ = seq;
  coolant_ = coolant & 3;
  outputs_ = outputs;
  coolant_on_ = following;
  for (size_t n = 0; n < analog.size() && n < analog_.size(); ++n) {
    if (!std::isfinite(analog[n])) continue;
    analog_[n] = analog[n];
    analog_set_[n] = true;
    const config::IoPointConfig& p = io_.points[static_cast<size_t>(io_.analog_outputs[n])];
    const double lo = p.is_signed ? -32768.0 : 0.0, hi = p.is_signed ? 32767.0 : 65535.0;
    const double count = std::round(analog[n] / p.scale);
    if (count < lo || count > hi) ++clamped_;
    const double held = std::fmin(std::fmax(count, lo), hi);
    raw_[n] = p.is_signed ? static_cast<uint16_t>(static_cast<int16_t>(held)) : static_cast<uint16_t>(held);
  }
  return true;
}

uint64_t IoControl::module_holding(size_t m, uint16_t* raw) const {
  if (m >= module_holding_.size()) return 0;
  uint64_t mask = 0;
  const std::vector<int>& regs = module_holding_[m];
  for (size_t i = 0; i < regs.size() && i < 64; ++i) {
    const int n = analog_role_[static_cast<size_t>(regs[i])];
    if (n < 0 || !analog_set_[static_cast<size_t>(n)]) continue;
    raw[i] = raw_[static_cast<size_t>(n)];
    mask |= uint64_t{1} << i;
  }
  return mask;
}

void IoControl::stop() {
  coolant_on_ = false;  // until a change newer than this stop
}

bool IoControl::wanted(int point) const {
  const int r = role_[static_cast<size_t>(point)];
  if (r == -2) return (coolant() & 1) != 0;
  if (r == -3) return (coolant() & 2) != 0;
  if (r >= 0) return ((outputs_ >> r) & 1) != 0;
  return false;
}

uint64_t IoControl::module_coils(size_t m) const {
  uint64_t v = 0;
  const std::vector<int>& coils = module_coils_[m];
  for (size_t i = 0; i < coils.size(); ++i)
    if (wanted(coils[i])) v |= uint64_t{1} << i;
  return v;
}

double IoControl::value(const config::IoPointConfig& p, uint16_t raw) {
  if (p.kind == config::IoKind::kCoil || p.kind == config::IoKind::kDiscreteInput) return raw ? 1.0 : 0.0;
  const double count = p.is_signed ? static_cast<double>(static_cast<int16_t>(raw)) : static_cast<double>(raw);
  return count * p.scale;
}

}  // namespace cnc::bridge
