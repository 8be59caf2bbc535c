#include "common/drive/huanyang_device.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "common/drive/huanyang_profile.h"

namespace cnc::drive {

namespace hy = huanyang;

HuanyangSpindleDevice::HuanyangSpindleDevice(const DriveProfile& profile, int unit, Link& link, double max_hz,
                                             double rpm_per_hz)
    : map_(profile.huanyang), unit_(unit), link_(link), max_hz_(max_hz), rpm_per_hz_(rpm_per_hz) {
  if (!profile.huanyang.present)
    throw std::invalid_argument("drive profile " + profile.name + " (" + profile.file +
                                ") is no Huanyang VFD's: its state_machine is " + profile.state_machine);
}

TxResult HuanyangSpindleDevice::ask(uint8_t function, const uint8_t* data, int n, LinkCounters& c) {
  const int len = hy::encode(static_cast<uint8_t>(unit_), function, data, n, request_.data());
  return link_.exchange_frame(request_.data(), len, reply_.data(), &reply_n_, c);
}

TxResult HuanyangSpindleDevice::read_pd(int pd, uint16_t* value, LinkCounters& c) {
  const uint8_t data[3] = {static_cast<uint8_t>(pd), 0, 0};
  const TxResult r = ask(hy::kReadFunctionData, data, 3, c);
  if (r == TxResult::kOk) *value = reply_[2] == 2 ? reply_[4] : hy::be16(&reply_[4]);
  return r;
}

TxResult HuanyangSpindleDevice::read_status(int index, double scale, double* value, LinkCounters& c) {
  const uint8_t data = static_cast<uint8_t>(index);
  const TxResult r = ask(hy::kReadControlStatus, &data, 1, c);
  if (r == TxResult::kOk) *value = hy::be16(&reply_[4]) / scale;
  return r;
}

TxResult HuanyangSpindleDevice::read_setup(LinkCounters& c) {
  uint16_t run = 0, freq = 0, max = 0, rated = 0;
  for (auto [pd, v] : {std::pair{map_.run_source_pd, &run}, std::pair{map_.frequency_source_pd, &freq},
                       std::pair{map_.max_frequency_pd, &max}, std::pair{map_.rated_rpm_pd, &rated}}) {
    const TxResult r = read_pd(pd, v, c);
    if (r != TxResult::kOk) return r;
  }
  char* out = setup_error_.data();
  const size_t cap = setup_error_.size();
  out[0] = '\0';
  const double max_hz = max / map_.frequency_scale;
  const double drive_rpm_per_hz = rated / map_.rated_rpm_hz;
  if (run != map_.source_link || freq != map_.source_link) {
    std::snprintf(out, cap, "the VFD takes its run command (PD%03d = %u) or frequency (PD%03d = %u) elsewhere: both must be %d (the communication port)",
                  map_.run_source_pd, run, map_.frequency_source_pd, freq, map_.source_link);
  } else if (max_hz < max_hz_ * (1 - 1e-3)) {
    std::snprintf(out, cap, "spindle.max_rpm needs %.2f Hz, the VFD's max frequency (PD%03d) is %.2f Hz", max_hz_,
                  map_.max_frequency_pd, max_hz);
  } else if (std::fabs(drive_rpm_per_hz - rpm_per_hz_) > 0.01 * rpm_per_hz_) {
    std::snprintf(out, cap, "the VFD's rated speed (PD%03d) is %u rpm at %g Hz, %.2f rpm/Hz; spindle.rpm_per_hz is %g",
                  map_.rated_rpm_pd, rated, map_.rated_rpm_hz, drive_rpm_per_hz, rpm_per_hz_);
  }
  return TxResult::kOk;
}

TxResult HuanyangSpindleDevice::exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs,
                                         LinkCounters& c) {
  const auto out = get_pdo<SpindleOutputs>(outputs);
  if (!setup_read_) {
    const TxResult r = read_setup(c);
    if (r != TxResult::kOk) return r;
    setup_read_ = true;
  }
  if (out.write) {
    const double raw = std::round(std::fabs(out.hz) * map_.frequency_scale);
    const auto f = static_cast<uint16_t>(std::clamp(std::isfinite(raw) ? raw : 0.0, 0.0, 65535.0));
    if (!frequency_sent_ || f != frequency_) {
      // The frequency first: the run command then starts towards the new one.
      const uint8_t data[2] = {static_cast<uint8_t>(f >> 8), static_cast<uint8_t>(f & 0xFF)};
      const TxResult r = ask(hy::kWriteFrequency, data, 2, c);
      if (r != TxResult::kOk) return r;
      frequency_sent_ = true;
      frequency_ = f;
    }
    const uint8_t command = huanyang_command(out.direction);
    const TxResult r = ask(hy::kWriteControlData, &command, 1, c);
    if (r != TxResult::kOk) return r;
    status_ = reply_[3];
  }
  double hz = 0, amps = 0;
  TxResult r = read_status(map_.output_frequency_index, map_.frequency_scale, &hz, c);
  if (r == TxResult::kOk) r = read_status(map_.output_current_index, map_.current_scale, &amps, c);
  if (r != TxResult::kOk) return r;
  SpindleInputs in;
  in.valid = true;
  in.statusword = status_;
  in.running = (status_ & kHyRunning) != 0;
  in.reverse = (status_ & kHyTurnsReverse) != 0;
  in.output_hz = in.reverse ? -hz : hz;
  in.has_current = true;
  in.current_a = amps;
  in.setup_error = setup_error_;
  put_pdo(inputs, in);
  return TxResult::kOk;
}

void HuanyangSpindleDevice::forget(std::span<std::byte> inputs) {
  // A link (re)opened may be another drive, or this one set up anew.
  setup_read_ = false;
  frequency_sent_ = false;
  status_ = 0;
  put_pdo(inputs, SpindleInputs{});
}

}  // namespace cnc::drive
