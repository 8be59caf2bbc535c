#include "services/drive_bridge/io_control.h"

namespace cnc::bridge {

IoControl::IoControl(const config::IoConfig& io, const std::vector<std::vector<int>>& module_coils)
    : io_(io), module_coils_(module_coils), role_(io.points.size(), -1) {
  if (io.coolant_mist >= 0) role_[static_cast<size_t>(io.coolant_mist)] = -2;
  if (io.coolant_flood >= 0) role_[static_cast<size_t>(io.coolant_flood)] = -3;
  for (size_t n = 0; n < io.digital_outputs.size(); ++n)
    role_[static_cast<size_t>(io.digital_outputs[n])] = static_cast<int8_t>(n);
}

bool IoControl::on_command(int64_t seq, int coolant, uint64_t outputs, bool following) {
  if (seq <= seq_) return false;
  seq_ = seq;
  coolant_ = coolant & 3;
  outputs_ = outputs;
  coolant_on_ = following;
  return true;
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
