#include "common/drive/spindle_device.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/drive/delta_vfd_profile.h"
#include "common/drive/huanyang_device.h"

namespace cnc::drive {

namespace {
constexpr Role kReadRoles[] = {Role::kStatusword, Role::kErrorCode, Role::kActualSpeed, Role::kOutputCurrent};
}

SpindleDevice::SpindleDevice(const DriveProfile& profile, int unit, Link& link)
    : profile_(profile), unit_(unit), link_(link) {
  if (!is_spindle_profile(profile) || profile.huanyang.present)
    throw std::invalid_argument("drive profile " + profile.name + " (" + profile.file +
                                ") is no register-mapped spindle drive's: its state_machine is " + profile.state_machine);
  int lo = 65536, hi = -1;
  for (Role r : kReadRoles) {
    if (!profile.has(r)) continue;
    lo = std::min(lo, profile.field(r).address);
    hi = std::max(hi, profile.field(r).end());
  }
  read_addr_ = lo;
  read_n_ = hi - lo;
  if (read_n_ > static_cast<int>(buf_.size()))
    throw std::invalid_argument("drive profile " + profile.name + ": the spindle's input fields span " +
                                std::to_string(read_n_) + " registers, more than one read (125)");
  const Field& cw = profile.field(Role::kControlword);
  const Field& sp = profile.field(Role::kSpeedSetpoint);
  command_adjacent_ = sp.address == cw.end() && sp.words == 1;
}

TxResult SpindleDevice::exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs, LinkCounters& c) {
  const auto out = get_pdo<SpindleOutputs>(outputs);
  if (out.write) {
    const Field& cw = profile_.field(Role::kControlword);
    const Field& sp = profile_.field(Role::kSpeedSetpoint);
    uint16_t w[3];
    w[0] = delta_vfd_command(out.direction);
    sp.encode(std::fabs(out.hz), w + 1);
    TxResult r;
    if (command_adjacent_) {
      r = link_.write_registers(unit_, cw.address, 2, w, c);
    } else {
      // The frequency first: the run command then starts towards the new one.
      r = link_.write_registers(unit_, sp.address, sp.words, w + 1, c);
      if (r == TxResult::kOk) r = link_.write_register(unit_, cw.address, w[0], c);
    }
    if (r != TxResult::kOk) return r;
  }
  const TxResult r = link_.read_registers(unit_, read_addr_, read_n_, buf_.data(), c);
  if (r != TxResult::kOk) return r;
  const auto at = [&](Role role) { return buf_.data() + (profile_.field(role).address - read_addr_); };
  SpindleInputs in;
  in.valid = true;
  in.statusword = *at(Role::kStatusword);
  const DriveStatus st = profile_logic(profile_).decode(in.statusword);
  in.running = st.enabled;
  in.reverse = delta_vfd_reverse(in.statusword);
  in.error_code = *at(Role::kErrorCode);
  last_error_ = in.error_code;
  const double hz = std::fabs(profile_.field(Role::kActualSpeed).decode(at(Role::kActualSpeed)));
  in.output_hz = in.reverse ? -hz : hz;
  in.has_current = profile_.has(Role::kOutputCurrent);
  if (in.has_current) in.current_a = profile_.field(Role::kOutputCurrent).decode(at(Role::kOutputCurrent));
  put_pdo(inputs, in);
  return TxResult::kOk;
}

TxResult SpindleDevice::control(Goal goal, LinkCounters& c) {
  if (goal != Goal::kFaultReset || last_error_ == 0) return TxResult::kOk;
  const auto w = profile_logic(profile_).next_write(goal, 0, MasterMemory{}, profile_);
  if (!w) return TxResult::kOk;
  return link_.write_register(unit_, profile_.field(w->role).address, w->value, c);
}

void SpindleDevice::forget(std::span<std::byte> inputs) {
  last_error_ = 0;
  put_pdo(inputs, SpindleInputs{});
}

std::unique_ptr<Device> make_spindle_device(const DriveProfile& profile, int unit, Link& link, double max_hz,
                                            double rpm_per_hz) {
  if (profile.huanyang.present) return std::make_unique<HuanyangSpindleDevice>(profile, unit, link, max_hz, rpm_per_hz);
  return std::make_unique<SpindleDevice>(profile, unit, link);
}

}  // namespace cnc::drive
