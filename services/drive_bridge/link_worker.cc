#include "services/drive_bridge/link_worker.h"

#include <cstring>
#include <stdexcept>

#include "common/util/clock.h"

namespace cnc::bridge {

LinkWorker::LinkWorker(drive::Link& link, const config::DriveBridgeConfig& cfg) : link_(link), cfg_(cfg) {
  link_.set_backoff(cfg.reconnect_min_s, cfg.reconnect_max_s);
}

LinkWorker::~LinkWorker() { stop(); }

void LinkWorker::add_axis(int axis_index, const drive::DriveProfile& profile, int unit) {
  if (slots_.size() >= kMaxSlots) throw std::runtime_error("too many drives on link " + link_.name());
  Slot s;
  s.io = std::make_unique<drive::DriveIo>(profile, unit, link_);
  slots_.push_back(std::move(s));
  axis_index_.push_back(axis_index);
}

void LinkWorker::start() {
  stopping_ = false;
  thread_ = std::thread([this] { run(); });
}

void LinkWorker::stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void LinkWorker::post() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    ++posted_;
  }
  cv_.notify_one();
}

void LinkWorker::set_command(size_t slot, const AxisCommand& c) {
  std::lock_guard<std::mutex> lock(mu_);
  slots_[slot].cmd = c;
}

AxisReport LinkWorker::report(size_t slot) const {
  std::lock_guard<std::mutex> lock(mu_);
  return slots_[slot].rep;
}

void LinkWorker::run() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!stopping_) {
    // A closed link is retried on its back-off schedule even without new ticks.
    cv_.wait_for(lock, std::chrono::milliseconds(20), [this] { return stopping_ || posted_ > taken_; });
    if (stopping_) break;
    taken_ = posted_;
    lock.unlock();
    round(util::monotonic_s());
    lock.lock();
  }
}

void LinkWorker::mark_lost(Slot& s) {
  // Only a drive that answered can be lost; one never reached is just not there yet.
  if (s.work.answering) {
    s.lost = true;
    ++s.work.lost_events;
  }
  s.work.answering = false;
  s.have_written = false;
  s.hold_valid = false;
  s.io->forget();
  s.work.have_status = false;
}

void LinkWorker::round(double now_s) {
  AxisCommand cmds[kMaxSlots];
  const size_t n = slots_.size();
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (size_t i = 0; i < n; ++i) cmds[i] = slots_[i].cmd;
  }
  if (!link_.is_open()) {
    if (link_.ensure_open(now_s)) {
      for (size_t i = 0; i < n; ++i) slots_[i].io->forget();
    } else {
      for (size_t i = 0; i < n; ++i) {
        Slot& s = slots_[i];
        if (s.work.answering) mark_lost(s);
        std::snprintf(s.work.last_error.data(), s.work.last_error.size(), "%s", link_.last_error().c_str());
      }
    }
  }
  for (size_t i = 0; i < n && link_.is_open(); ++i) {
    Slot& s = slots_[i];
    const AxisCommand& c = cmds[i];
    drive::DriveIo& io = *s.io;
    // The target: the command while following an enabled drive; else where the
    // drive is (disabled: tracking its position, so enabling never jumps).
    double target = 0;
    bool write = false;
    bool holding = false;
    if (io.have_status()) {
      const bool enabled = io.status().enabled;
      if (c.follow && enabled) {
        target = c.cmd_mm;
        s.hold_valid = true;
        holding = true;
      } else if (enabled && s.hold_valid) {
        target = s.work.hold_mm;
        holding = true;
      } else {
        target = io.actual_mm();
        s.hold_valid = enabled;
      }
      s.work.hold_mm = target;
      write = true;
    }
    const drive::TxResult r = io.exchange(write ? &target : nullptr, s.work.counters);
    if (r == drive::TxResult::kOk) {
      if (write && s.have_written) {
        s.work.fe_mm = s.written_mm - io.actual_mm();
        ++s.work.fe_samples;
      }
      s.have_written = write;
      s.written_mm = io.written_mm();
      if (write && c.follow && probe_) probe_(axis_index_[i], c.cmd_cycle, now_s);
      s.last_answer_s = now_s;
      if (s.lost) {
        s.lost = false;
        if (s.work.lost_events > 0) ++s.work.counters.reconnects;
      }
      s.work.answering = true;
      s.work.holding = holding;
      s.work.have_status = true;
      s.work.statusword = io.statusword();
      s.work.status = io.status();
      s.work.error_code = io.error_code();
      s.work.actual_mm = io.actual_mm();
      const drive::TxResult rc = io.control(c.goal, s.work.counters);
      if (rc == drive::TxResult::kLinkLost) {
        for (auto& other : slots_) mark_lost(other);
      }
      continue;
    }
    std::snprintf(s.work.last_error.data(), s.work.last_error.size(), "%s: %s", drive::tx_result_name(r),
                  link_.last_error().c_str());
    s.have_written = false;
    if (r == drive::TxResult::kLinkLost) {
      for (auto& other : slots_) mark_lost(other);
      break;
    }
    if (s.work.answering && now_s - s.last_answer_s > cfg_.link_loss_timeout_s) {
      // Answers stopped without the connection breaking (a frozen peer, a drive
      // gone silent on a serial line): that drive's link is lost all the same.
      // When no drive on the link answers, reopen it, which drops stale replies.
      mark_lost(s);
      bool any = false;
      for (const auto& other : slots_) any = any || other.work.answering;
      if (!any) {
        link_.close(now_s);
        break;
      }
    }
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (size_t i = 0; i < n; ++i) slots_[i].rep = slots_[i].work;
  }
  ++rounds_;
}

}  // namespace cnc::bridge
