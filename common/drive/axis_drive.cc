#include "common/drive/axis_drive.h"

namespace cnc::drive {

TxResult ModbusAxisDrive::exchange(std::span<const std::byte> outputs, std::span<std::byte> inputs,
                                   LinkCounters& c) {
  const auto out = get_pdo<AxisOutputs>(outputs);
  const TxResult r = io_.exchange(out.write ? &out.target_mm : nullptr, c);
  if (r != TxResult::kOk) return r;
  AxisInputs in;
  in.valid = io_.have_status();
  in.statusword = io_.statusword();
  in.status = io_.status();
  in.error_code = io_.error_code();
  in.actual_mm = io_.actual_mm();
  in.written_mm = io_.written_mm();
  in.reports_following_error = io_.reports_following_error();
  in.following_error_mm = io_.drive_following_error_mm();
  in.has_home_latch = io_.has_home_latch();
  in.home_latch_mm = io_.home_latch_mm();
  in.home_latch_count = io_.home_latch_count();
  in.has_probe_latch = io_.has_probe_latch();
  in.probe = io_.probe_latches();
  put_pdo(inputs, in);
  return r;
}

void ModbusAxisDrive::forget(std::span<std::byte> inputs) {
  io_.forget();
  AxisInputs in = get_pdo<AxisInputs>(inputs);
  in.valid = false;
  put_pdo(inputs, in);
}

}  // namespace cnc::drive
