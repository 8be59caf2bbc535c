#pragma once
// A Huanyang VFD as the spindle device (device.h; its frames huanyang_frame.h, its
// bits huanyang_profile.h, its data the profile's huanyang: section). The same
// process data as the register-mapped VFD (SpindleOutputs, SpindleInputs), so the
// bridge drives both alike. Each cycle: the frequency (function 0x05) when it
// changed, the command byte (0x03, whose reply is the status byte), and the output
// frequency and current (0x04, one index each). The first exchange after the link
// was (re)opened reads the PD parameters the link needs set (run and frequency from
// the communication port, PD005 and PD144 against spindle.max_rpm and rpm_per_hz)
// and reports what is wrong in SpindleInputs::setup_error. No allocation after
// construction: it runs on the bridge's link workers.
#include <array>
#include <cstdint>
#include <span>

#include "common/drive/device.h"
#include "common/drive/drive_profile.h"
#include "common/drive/huanyang_frame.h"
#include "common/drive/link.h"
#include "common/drive/spindle_device.h"

namespace cnc::drive {

class HuanyangSpindleDevice final : public Device {
 public:
  static constexpr PdoLayout kLayout{sizeof(SpindleInputs), sizeof(SpindleOutputs)};
  // `max_hz`: the frequency spindle.max_rpm needs; `rpm_per_hz`: spindle.rpm_per_hz.
  // Throws std::invalid_argument when the profile is no Huanyang's.
  HuanyangSpindleDevice(const DriveProfile& profile, int unit, Link& link, double max_hz, double rpm_per_hz);
  PdoLayout layout() const override { return kLayout; }
  TxResult exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs, LinkCounters& c) override;
  // Nothing: the protocol has no fault reset (a tripped drive is reset at its panel).
  TxResult control(Goal, LinkCounters&) override { return TxResult::kOk; }
  void forget(std::span<std::byte> inputs) override;

 private:
  TxResult ask(uint8_t function, const uint8_t* data, int n, LinkCounters& c);
  TxResult read_pd(int pd, uint16_t* value, LinkCounters& c);
  TxResult read_status(int index, double scale, double* value, LinkCounters& c);
  TxResult read_setup(LinkCounters& c);

  const HuanyangMap& map_;
  int unit_;
  Link& link_;
  double max_hz_;
  double rpm_per_hz_;
  std::array<uint8_t, huanyang::kMaxFrame> request_{};
  std::array<uint8_t, huanyang::kMaxFrame> reply_{};
  int reply_n_ = 0;
  bool setup_read_ = false;
  std::array<char, 160> setup_error_{};
  bool frequency_sent_ = false;
  uint16_t frequency_ = 0;
  uint8_t status_ = 0;  // the last status byte
};

}  // namespace cnc::drive
