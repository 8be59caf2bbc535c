#include "common/drive/spindle_device.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "common/drive/delta_vfd_profile.h"
#include "common/drive/huanyang_device.h"

namespace cnc::drive {

namespace {
constexpr Role kReadRoles[] = {Role::kStatusword, Role::kErrorCode, Role::kActualSpeed, Role::kOutputCurrent,
                               Role::kEncoderPosition};
}

SpindleDevice::SpindleDevice(const DriveProfile& profile, int unit, Link& link)
    : profile_(profile), logic_(profile_logic(profile)), cia402_(profile.state_machine == "cia402_velocity"),
      unit_(unit), link_(link) {
  if (!is_spindle_profile(profile) || profile.huanyang.present)
    throw std::invalid_argument("drive profile " + profile.name + " (" + profile.file +
                                ") is no register-mapped spindle drive's: its state_machine is " + profile.state_machine);
  // The input fields by address, merged where at most read_gap_max registers lie between.
  std::vector<Range> fields;
  for (Role r : kReadRoles)
    if (profile.has(r)) fields.push_back({profile.field(r).address, profile.field(r).words});
  std::sort(fields.begin(), fields.end(), [](const Range& a, const Range& b) { return a.addr < b.addr; });
  for (const Range& f : fields) {
    if (n_reads_ > 0) {
      Range& m = reads_[static_cast<size_t>(n_reads_ - 1)];
      if (f.addr - (m.addr + m.n) <= profile.read_gap_max && f.addr + f.n - m.addr <= static_cast<int>(buf_.size())) {
        m.n = std::max(m.addr + m.n, f.addr + f.n) - m.addr;
        continue;
      }
    }
    reads_[static_cast<size_t>(n_reads_++)] = f;
  }
  const Field& cw = profile.field(Role::kControlword);
  const Field& sp = profile.field(Role::kSpeedSetpoint);
  command_adjacent_ = !cia402_ && sp.address == cw.end() && sp.words == 1;
}

void SpindleDevice::take(const Range& g) {
  for (Role r : kReadRoles) {
    const Field& f = profile_.field(r);
    if (!f.present() || f.address < g.addr || f.end() > g.addr + g.n) continue;
    for (int w = 0; w < f.words; ++w)
      values_[static_cast<size_t>(r)][static_cast<size_t>(w)] = buf_[static_cast<size_t>(f.address - g.addr + w)];
  }
}

TxResult SpindleDevice::exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs, LinkCounters& c) {
  const auto out = get_pdo<SpindleOutputs>(outputs);
  int next = 0;
  if (out.write) {
    const Field& cw = profile_.field(Role::kControlword);
    const Field& sp = profile_.field(Role::kSpeedSetpoint);
    uint16_t w[3];
    TxResult r;
    if (cia402_) {
      // The signed target velocity; the controlword is the state machine's (control()).
      sp.encode(out.direction * std::fabs(out.hz), w);
      if (profile_.write_and_read) {
        const Range& g = reads_[0];
        r = link_.write_and_read(unit_, sp.address, sp.words, w, g.addr, g.n, buf_.data(), c);
        if (r == TxResult::kOk) take(g);
        next = 1;
      } else {
        r = link_.write_registers(unit_, sp.address, sp.words, w, c);
      }
    } else {
      w[0] = delta_vfd_command(out.direction);
      sp.encode(std::fabs(out.hz), w + 1);
      if (command_adjacent_) {
        r = link_.write_registers(unit_, cw.address, 2, w, c);
      } else {
        // The frequency first: the run command then starts towards the new one.
        r = link_.write_registers(unit_, sp.address, sp.words, w + 1, c);
        if (r == TxResult::kOk) r = link_.write_register(unit_, cw.address, w[0], c);
      }
    }
    if (r != TxResult::kOk) return r;
  }
  for (; next < n_reads_; ++next) {
    const Range& g = reads_[static_cast<size_t>(next)];
    const TxResult r = link_.read_registers(unit_, g.addr, g.n, buf_.data(), c);
    if (r != TxResult::kOk) return r;
    take(g);
  }
  SpindleInputs in;
  in.valid = true;
  in.statusword = *at(Role::kStatusword);
  statusword_ = in.statusword;
  have_status_ = true;
  const DriveStatus st = logic_.decode(in.statusword);
  in.running = st.enabled;
  in.error_code = profile_.has(Role::kErrorCode) ? *at(Role::kErrorCode) : 0;
  const Field& speed = profile_.field(Role::kActualSpeed);
  if (cia402_) {
    in.fault = st.fault;
    if (!in.fault) in.error_code = 0;  // 0x603F keeps the last fault's code after its reset
    in.output_hz = speed.decode(at(Role::kActualSpeed));
    in.reverse = in.output_hz < 0;
  } else {
    in.fault = in.error_code != 0;
    in.reverse = delta_vfd_reverse(in.statusword);
    const double hz = std::fabs(speed.decode(at(Role::kActualSpeed)));
    in.output_hz = in.reverse ? -hz : hz;
  }
  last_error_ = in.error_code;
  in.has_current = profile_.has(Role::kOutputCurrent);
  if (in.has_current) in.current_a = profile_.field(Role::kOutputCurrent).decode(at(Role::kOutputCurrent));
  in.has_position = profile_.has(Role::kEncoderPosition);
  if (in.has_position) {
    in.position_counts = encoder_.update(profile_.field(Role::kEncoderPosition).decode_raw(at(Role::kEncoderPosition)));
    // The counter is in the last read (the reads are by address; on a serial line, it
    // is the drive's sampling, at the end of that request, to the end of its reply).
    const Field& e = profile_.field(Role::kEncoderPosition);
    int n = 0;
    for (int i = 0; i < n_reads_; ++i)
      if (e.address >= reads_[static_cast<size_t>(i)].addr) n = reads_[static_cast<size_t>(i)].n;
    in.sample_age_s = link_.byte_time_s() * (3.5 + 5 + 2 * n);
    // Every read after the counter's: their time on the line too.
    for (int i = 0; i < n_reads_; ++i)
      if (reads_[static_cast<size_t>(i)].addr > e.address)
        in.sample_age_s += link_.byte_time_s() * (3.5 + 8 + 3.5 + 5 + 2 * reads_[static_cast<size_t>(i)].n);
  }
  put_pdo(inputs, in);
  return TxResult::kOk;
}

TxResult SpindleDevice::control(Goal goal, LinkCounters& c) {
  if (cia402_) {
    if (!have_status_) return TxResult::kOk;
    const auto w = logic_.next_write(goal, statusword_, memory_, profile_);
    if (!w) return TxResult::kOk;
    const TxResult r = link_.write_register(unit_, profile_.field(w->role).address, w->value, c);
    if (r == TxResult::kOk) {
      if (w->role == Role::kControlword) memory_.last_control = w->value;
      if (w->role == Role::kMode) memory_.mode_written = true;
    }
    return r;
  }
  if (goal != Goal::kFaultReset || last_error_ == 0) return TxResult::kOk;
  const auto w = logic_.next_write(goal, 0, MasterMemory{}, profile_);
  if (!w) return TxResult::kOk;
  return link_.write_register(unit_, profile_.field(w->role).address, w->value, c);
}

void SpindleDevice::forget(std::span<std::byte> inputs) {
  last_error_ = 0;
  memory_ = MasterMemory{};
  have_status_ = false;
  put_pdo(inputs, SpindleInputs{});
}

std::unique_ptr<Device> make_spindle_device(const DriveProfile& profile, int unit, Link& link, double max_hz,
                                            double rpm_per_hz) {
  if (profile.huanyang.present) return std::make_unique<HuanyangSpindleDevice>(profile, unit, link, max_hz, rpm_per_hz);
  return std::make_unique<SpindleDevice>(profile, unit, link);
}

}  // namespace cnc::drive
