#pragma once
// The register transactions with one drive, planned from its profile: the cyclic
// exchange (write the target, read statusword and actual position in as few
// transactions as the profile allows: function 23 when the drive has it, fields
// merged into one read when they are close) and the steps of the profile's state
// machine. No allocation after construction: it runs on the bridge's I/O threads.
#include <array>
#include <cstdint>
#include <vector>

#include "common/drive/drive_profile.h"
#include "common/drive/link.h"
#include "common/drive/profile_logic.h"

namespace cnc::drive {

// A drive's touch-probe latches as last read: the positions at the input's last rising
// and falling edges, and the edge counters (the drive's, wrapping at its field's width).
struct ProbeLatches {
  double rise_mm = 0, fall_mm = 0;
  int64_t rises = 0, falls = 0;
};

class DriveIo {
 public:
  DriveIo(const DriveProfile& profile, int unit, Link& link);

  // One cyclic exchange: writes the target when `target_mm` is given, then reads.
  TxResult exchange(const double* target_mm, LinkCounters& c);
  // One step toward `goal`: at most one register write; kOk when nothing was to do.
  TxResult control(Goal goal, LinkCounters& c);
  // After the link was lost: what the drive reports and what it was told are unknown.
  void forget();

  bool have_status() const { return have_status_; }
  uint16_t statusword() const { return statusword_; }
  DriveStatus status() const { return logic_.decode(statusword_); }
  double actual_mm() const { return actual_mm_; }
  // The drive's own following error (its position demand minus actual), where the
  // profile maps it; read with every exchange.
  bool reports_following_error() const { return profile_.has(Role::kFollowingError); }
  double drive_following_error_mm() const { return drive_fe_mm_; }
  // The home switch latch, where the profile maps it (position and count, read with every exchange).
  bool has_home_latch() const { return profile_.has(Role::kHomeLatchPosition) && profile_.has(Role::kHomeLatchCount); }
  double home_latch_mm() const { return home_latch_mm_; }
  int64_t home_latch_count() const { return home_latch_count_; }
  // The touch probe's latches, where the profile maps all four fields (read with every exchange).
  bool has_probe_latch() const {
    return profile_.has(Role::kProbeRisePosition) && profile_.has(Role::kProbeRiseCount) &&
           profile_.has(Role::kProbeFallPosition) && profile_.has(Role::kProbeFallCount);
  }
  const ProbeLatches& probe_latches() const { return probe_; }
  // The last target written, as the drive has it (rounded to its counts).
  double written_mm() const { return written_mm_; }
  uint16_t error_code() const;
  // Transactions one cyclic exchange takes (with a target write).
  int transactions_per_exchange() const;
  const DriveProfile& profile() const { return profile_; }
  const ProfileLogic& logic() const { return logic_; }
  int unit() const { return unit_; }
  Link& link() { return link_; }

 private:
  struct Range {
    int addr;
    int n;
  };
  // Copies the fields that lie in a range just read out of `buf`.
  void take(const Range& g, const uint16_t* buf);
  const uint16_t* value(Role r) const { return values_[static_cast<size_t>(r)].data(); }

  const DriveProfile& profile_;
  const ProfileLogic& logic_;
  int unit_;
  Link& link_;
  std::vector<Range> reads_;
  std::array<uint16_t, 125> buf_{};  // one read (at most 125 registers, Modbus's limit)
  std::array<std::array<uint16_t, 2>, kRoleCount> values_{};
  MasterMemory memory_;
  bool error_in_reads_ = false;  // the error code comes with the cyclic reads
  bool error_read_ = false;      // read once after the drive reported its fault
  bool have_status_ = false;
  uint16_t statusword_ = 0;
  double actual_mm_ = 0;
  double drive_fe_mm_ = 0;
  double home_latch_mm_ = 0;
  int64_t home_latch_count_ = 0;
  ProbeLatches probe_;
  double written_mm_ = 0;
};

}  // namespace cnc::drive
