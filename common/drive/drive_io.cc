#include "common/drive/drive_io.h"

#include <algorithm>

namespace cnc::drive {

DriveIo::DriveIo(const DriveProfile& profile, int unit, Link& link)
    : profile_(profile), logic_(profile_logic(profile)), unit_(unit), link_(link) {
  // The fields every exchange reads, merged into one read where the gap between
  // them is at most read_gap_max; velocity and error code ride along only where
  // they merge into a read that is needed anyway.
  struct Want {
    Range r;
    bool required;
  };
  std::vector<Want> want;
  for (Role r : {Role::kStatusword, Role::kActualPosition, Role::kActualVelocity, Role::kErrorCode,
                 Role::kFollowingError, Role::kHomeLatchPosition, Role::kHomeLatchCount, Role::kProbeRisePosition,
                 Role::kProbeRiseCount, Role::kProbeFallPosition, Role::kProbeFallCount}) {
    if (!profile.has(r)) continue;
    const Field& f = profile.field(r);
    // The drive's following error, where the profile has it, is read every exchange:
    // the bridge checks the limit on it. So are the home and probe latches (homing and
    // probing wait on them).
    const bool latch = r == Role::kHomeLatchPosition || r == Role::kHomeLatchCount || r == Role::kProbeRisePosition ||
                       r == Role::kProbeRiseCount || r == Role::kProbeFallPosition || r == Role::kProbeFallCount;
    want.push_back({{f.address, f.words},
                    r == Role::kStatusword || r == Role::kActualPosition || r == Role::kFollowingError || latch});
  }
  std::sort(want.begin(), want.end(), [](const Want& a, const Want& b) { return a.r.addr < b.r.addr; });
  std::vector<Want> merged;
  for (const Want& w : want) {
    if (!merged.empty()) {
      Want& m = merged.back();
      const int end = m.r.addr + m.r.n;
      if (w.r.addr - end <= profile.read_gap_max && w.r.addr + w.r.n - m.r.addr <= 125) {
        m.r.n = std::max(end, w.r.addr + w.r.n) - m.r.addr;
        m.required = m.required || w.required;
        continue;
      }
    }
    merged.push_back(w);
  }
  for (const Want& m : merged)
    if (m.required) reads_.push_back(m.r);
  if (profile.has(Role::kErrorCode)) {
    const Field& e = profile.field(Role::kErrorCode);
    for (const Range& g : reads_) error_in_reads_ = error_in_reads_ || (e.address >= g.addr && e.end() <= g.addr + g.n);
  }
}

void DriveIo::take(const Range& g, const uint16_t* buf) {
  for (int i = 0; i < kRoleCount; ++i) {
    const Field& f = profile_.fields[static_cast<size_t>(i)];
    if (!f.present() || f.address < g.addr || f.end() > g.addr + g.n) continue;
    for (int w = 0; w < f.words; ++w) values_[static_cast<size_t>(i)][static_cast<size_t>(w)] = buf[f.address - g.addr + w];
  }
}

int DriveIo::transactions_per_exchange() const { return static_cast<int>(reads_.size()) + (profile_.write_and_read ? 0 : 1); }

void DriveIo::forget() {
  have_status_ = false;
  memory_ = MasterMemory{};
}

uint16_t DriveIo::error_code() const { return profile_.has(Role::kErrorCode) ? *value(Role::kErrorCode) : 0; }

TxResult DriveIo::exchange(const double* target_mm, LinkCounters& c) {
  size_t next = 0;
  if (target_mm != nullptr) {
    const Field& t = profile_.field(Role::kTargetPosition);
    uint16_t w[2];
    t.encode(*target_mm, w);
    written_mm_ = t.decode(w);
    TxResult r;
    if (profile_.write_and_read) {
      const Range& g = reads_[0];
      r = link_.write_and_read(unit_, t.address, t.words, w, g.addr, g.n, buf_.data(), c);
      if (r == TxResult::kOk) take(g, buf_.data());
      next = 1;
    } else {
      r = link_.write_registers(unit_, t.address, t.words, w, c);
    }
    if (r != TxResult::kOk) return r;
  }
  for (; next < reads_.size(); ++next) {
    const Range& g = reads_[next];
    const TxResult r = link_.read_registers(unit_, g.addr, g.n, buf_.data(), c);
    if (r != TxResult::kOk) return r;
    take(g, buf_.data());
  }
  statusword_ = *value(Role::kStatusword);
  actual_mm_ = profile_.field(Role::kActualPosition).decode(value(Role::kActualPosition));
  if (profile_.has(Role::kFollowingError))
    drive_fe_mm_ = profile_.field(Role::kFollowingError).decode(value(Role::kFollowingError));
  if (profile_.has(Role::kHomeLatchPosition) && profile_.has(Role::kHomeLatchCount)) {
    home_latch_mm_ = profile_.field(Role::kHomeLatchPosition).decode(value(Role::kHomeLatchPosition));
    home_latch_count_ = profile_.field(Role::kHomeLatchCount).decode_raw(value(Role::kHomeLatchCount));
  }
  if (has_probe_latch()) {
    probe_.rise_mm = profile_.field(Role::kProbeRisePosition).decode(value(Role::kProbeRisePosition));
    probe_.rises = profile_.field(Role::kProbeRiseCount).decode_raw(value(Role::kProbeRiseCount));
    probe_.fall_mm = profile_.field(Role::kProbeFallPosition).decode(value(Role::kProbeFallPosition));
    probe_.falls = profile_.field(Role::kProbeFallCount).decode_raw(value(Role::kProbeFallCount));
  }
  have_status_ = true;
  // The drive's error code, for the fault report: once per fault when the cyclic reads do not carry it.
  const bool fault = logic_.decode(statusword_).fault;
  if (fault && !error_in_reads_ && !error_read_ && profile_.has(Role::kErrorCode)) {
    const Field& e = profile_.field(Role::kErrorCode);
    if (link_.read_registers(unit_, e.address, 1, buf_.data(), c) == TxResult::kOk) {
      values_[static_cast<size_t>(Role::kErrorCode)][0] = buf_[0];
      error_read_ = true;
    }
  }
  if (!fault) error_read_ = false;
  return TxResult::kOk;
}

TxResult DriveIo::control(Goal goal, LinkCounters& c) {
  if (!have_status_) return TxResult::kOk;
  const auto w = logic_.next_write(goal, statusword_, memory_, profile_);
  if (!w) return TxResult::kOk;
  const Field& f = profile_.field(w->role);
  const TxResult r = link_.write_register(unit_, f.address, w->value, c);
  if (r == TxResult::kOk) {
    if (w->role == Role::kControlword) memory_.last_control = w->value;
    if (w->role == Role::kMode) memory_.mode_written = true;
    if (w->role == Role::kProbeFunction) memory_.probe_armed = true;
  }
  return r;
}

}  // namespace cnc::drive
