#include "services/drive_bridge/link_worker.h"

#include <pthread.h>
#include <sched.h>

#include <cerrno>
#include <cstring>
#include <ctime>
#include <stdexcept>

#include "common/util/clock.h"

namespace cnc::bridge {

LinkWorker::LinkWorker(drive::Link& link, const config::DriveBridgeConfig& cfg) : link_(link), cfg_(cfg) {
  link_.set_backoff(cfg.reconnect_min_s, cfg.reconnect_max_s);
  sem_init(&wake_, 0, 0);
}

LinkWorker::~LinkWorker() {
  stop();
  sem_destroy(&wake_);
}

void LinkWorker::add_axis(int axis_index, const drive::DriveProfile& profile, int unit) {
  if (slots_.size() >= kMaxSlots) throw std::runtime_error("too many drives on link " + link_.name());
  auto s = std::make_unique<Slot>();
  s->dev = std::make_unique<drive::ModbusAxisDrive>(profile, unit, link_);
  s->pdo = image_.add(s->dev->layout());
  slots_.push_back(std::move(s));
  axis_index_.push_back(axis_index);
}

void LinkWorker::add_spindle(const drive::DriveProfile& profile, int unit, double max_hz, double rpm_per_hz) {
  if (spindle_) throw std::runtime_error("a second spindle on link " + link_.name());
  spindle_ = std::make_unique<SpindleSlot>();
  spindle_->dev = drive::make_spindle_device(profile, unit, link_, max_hz, rpm_per_hz);
  spindle_->pdo = image_.add(spindle_->dev->layout());
}

size_t LinkWorker::add_io_module(const config::IoConfig& io, int module) {
  auto s = std::make_unique<IoSlot>();
  auto dev = std::make_unique<drive::IoModuleDevice>(io, module, link_);
  s->device = dev.get();
  s->dev = std::move(dev);
  s->pdo = image_.add(s->dev->layout());
  ios_.push_back(std::move(s));
  return ios_.size() - 1;
}

void LinkWorker::start() {
  stopping_.store(false, std::memory_order_release);
  thread_ = std::thread([this] { run(); });
}

void LinkWorker::stop() {
  stopping_.store(true, std::memory_order_release);
  sem_post(&wake_);
  if (thread_.joinable()) thread_.join();
}

void LinkWorker::post() { sem_post(&wake_); }

void LinkWorker::set_command(size_t slot, const AxisCommand& c) { slots_[slot]->cmd.write(c); }

const AxisReport& LinkWorker::report(size_t slot) { return slots_[slot]->rep.read(); }

void LinkWorker::run() {
  // One real-time priority below the servo thread that started it (nothing when
  // the process runs with normal scheduling).
  int policy = SCHED_OTHER;
  sched_param sp{};
  if (pthread_getschedparam(pthread_self(), &policy, &sp) == 0 && policy == SCHED_FIFO && sp.sched_priority > 1) {
    sp.sched_priority -= 1;
    pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  }
  pthread_setname_np(pthread_self(), "cnc-link");
  while (!stopping_.load(std::memory_order_acquire)) {
    // A closed link is retried on its back-off schedule even without new ticks.
    timespec until{};
    clock_gettime(CLOCK_MONOTONIC, &until);
    until.tv_nsec += 20'000'000;
    if (until.tv_nsec >= 1'000'000'000) {
      until.tv_nsec -= 1'000'000'000;
      ++until.tv_sec;
    }
    while (sem_clockwait(&wake_, CLOCK_MONOTONIC, &until) != 0 && errno == EINTR) {
    }
    while (sem_trywait(&wake_) == 0) {
    }  // posts that piled up while a round ran: one round serves them all
    if (stopping_.load(std::memory_order_acquire)) break;
    round(util::monotonic_s());
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
  forget(s);
  s.work.have_status = false;
}

void LinkWorker::mark_spindle_lost() {
  if (!spindle_) return;
  SpindleReport& w = spindle_->work;
  if (w.answering) ++w.lost_events;
  w.answering = false;
  spindle_->dev->forget(image_.inputs(spindle_->pdo));
  w.in = drive::SpindleInputs{};
}

void LinkWorker::mark_io_lost(IoSlot& io) {
  if (io.work.answering) ++io.work.lost_events;
  io.work.answering = false;
  io.dev->forget(image_.inputs(io.pdo));
  io.work.in = drive::IoModuleInputs{};
}

void LinkWorker::mark_all_lost() {
  for (auto& other : slots_) mark_lost(*other);
  mark_spindle_lost();
  for (auto& io : ios_) mark_io_lost(*io);
}

void LinkWorker::io_round(IoSlot& io, double now_s) {
  const IoCommand c = io.cmd.read();
  drive::IoModuleOutputs out;
  out.write = io.work.in.valid;  // the first exchange after (re)opening only reads
  out.coils = c.coils;
  out.holding_write = c.holding_write;
  out.holding = c.holding;
  drive::put_pdo(image_.outputs(io.pdo), out);
  const drive::TxResult r = io.dev->exchange(image_.outputs(io.pdo), image_.inputs(io.pdo), io.work.counters);
  if (r == drive::TxResult::kOk) {
    io.work.in = drive::get_pdo<drive::IoModuleInputs>(image_.inputs(io.pdo));
    io.work.answering = true;
    io.last_answer_s = now_s;
    return;
  }
  std::snprintf(io.work.last_error.data(), io.work.last_error.size(), "%s: %s", drive::tx_result_name(r),
                link_.last_error().c_str());
  if (r == drive::TxResult::kLinkLost) {
    mark_all_lost();
  } else if (io.work.answering && now_s - io.last_answer_s > cfg_.link_loss_timeout_s) {
    mark_io_lost(io);
  }
}

void LinkWorker::spindle_round(double now_s) {
  SpindleSlot& sp = *spindle_;
  const SpindleCommand c = sp.cmd.read();
  drive::SpindleOutputs out;
  out.write = sp.work.in.valid;  // the first exchange after (re)opening only reads
  out.direction = c.direction;
  out.hz = c.hz;
  drive::put_pdo(image_.outputs(sp.pdo), out);
  const drive::TxResult r = sp.dev->exchange(image_.outputs(sp.pdo), image_.inputs(sp.pdo), sp.work.counters);
  if (r == drive::TxResult::kOk) {
    sp.work.in = drive::get_pdo<drive::SpindleInputs>(image_.inputs(sp.pdo));
    // The reply is in: the drive sampled its counter the reply's time on the line before.
    sp.work.sample_s = now_s + (util::monotonic_s() - round_mono_) - sp.work.in.sample_age_s;
    sp.work.cmd = c;
    sp.work.answering = true;
    sp.last_answer_s = now_s;
    if (sp.dev->control(c.goal, sp.work.counters) == drive::TxResult::kLinkLost) mark_all_lost();
    return;
  }
  std::snprintf(sp.work.last_error.data(), sp.work.last_error.size(), "%s: %s", drive::tx_result_name(r),
                link_.last_error().c_str());
  if (r == drive::TxResult::kLinkLost) {
    mark_all_lost();
  } else if (sp.work.answering && now_s - sp.last_answer_s > cfg_.link_loss_timeout_s) {
    mark_spindle_lost();
  }
}

void LinkWorker::round(double now_s) {
  round_mono_ = util::monotonic_s();
  AxisCommand cmds[kMaxSlots];
  const size_t n = slots_.size();
  for (size_t i = 0; i < n; ++i) cmds[i] = slots_[i]->cmd.read();
  if (!link_.is_open()) {
    if (link_.ensure_open(now_s)) {
      for (size_t i = 0; i < n; ++i) forget(*slots_[i]);
      if (spindle_) mark_spindle_lost();
      for (auto& io : ios_) mark_io_lost(*io);
    } else {
      for (size_t i = 0; i < n; ++i) {
        Slot& s = *slots_[i];
        if (s.work.answering) mark_lost(s);
        std::snprintf(s.work.last_error.data(), s.work.last_error.size(), "%s", link_.last_error().c_str());
      }
      if (spindle_) {
        mark_spindle_lost();
        std::snprintf(spindle_->work.last_error.data(), spindle_->work.last_error.size(), "%s",
                      link_.last_error().c_str());
      }
      for (auto& io : ios_) {
        mark_io_lost(*io);
        std::snprintf(io->work.last_error.data(), io->work.last_error.size(), "%s", link_.last_error().c_str());
      }
    }
  }
  for (size_t i = 0; i < n && link_.is_open(); ++i) {
    Slot& s = *slots_[i];
    const AxisCommand& c = cmds[i];
    // The target: the command while following an enabled drive; else where the
    // drive is (disabled: tracking its position, so enabling never jumps).
    const drive::AxisInputs last = inputs(s);
    drive::AxisOutputs out;
    bool holding = false;
    if (last.valid) {
      const bool enabled = last.status.enabled;
      if (c.follow && enabled) {
        out.target_mm = c.cmd_mm;
        s.hold_valid = true;
        holding = true;
      } else if (enabled && s.hold_valid) {
        out.target_mm = s.work.hold_mm;
        holding = true;
      } else {
        out.target_mm = last.actual_mm;
        s.hold_valid = enabled;
      }
      s.work.hold_mm = out.target_mm;
      out.write = true;
    }
    const bool write = out.write;
    drive::put_pdo(image_.outputs(s.pdo), out);
    const drive::TxResult r = s.dev->exchange(image_.outputs(s.pdo), image_.inputs(s.pdo), s.work.counters);
    if (r == drive::TxResult::kOk) {
      const drive::AxisInputs in = inputs(s);
      if (write && s.have_written) {
        // The drive's own following error where its profile maps it (its position
        // demand, which ramps to the targets we write, minus actual); otherwise the
        // last target written minus actual, which also holds up to one write
        // interval of the link's delay.
        s.work.lag_mm = s.written_mm - in.actual_mm;
        s.work.fe_mm = in.reports_following_error ? in.following_error_mm : s.work.lag_mm;
        ++s.work.fe_samples;
      }
      s.have_written = write;
      s.written_mm = in.written_mm;
      s.work.has_home_latch = in.has_home_latch;
      s.work.home_latch_mm = in.home_latch_mm;
      s.work.home_latch_count = in.home_latch_count;
      s.work.has_probe_latch = in.has_probe_latch;
      s.work.probe = in.probe;
      if (write && c.follow && probe_) probe_(axis_index_[i], c.cmd_cycle, now_s);
      s.last_answer_s = now_s;
      if (s.lost) {
        s.lost = false;
        if (s.work.lost_events > 0) ++s.work.counters.reconnects;
      }
      s.work.answering = true;
      s.work.holding = holding;
      s.work.have_status = true;
      s.work.statusword = in.statusword;
      s.work.status = in.status;
      s.work.error_code = in.error_code;
      s.work.actual_mm = in.actual_mm;
      const drive::TxResult rc = s.dev->control(c.goal, s.work.counters);
      if (rc == drive::TxResult::kLinkLost) mark_all_lost();
      continue;
    }
    std::snprintf(s.work.last_error.data(), s.work.last_error.size(), "%s: %s", drive::tx_result_name(r),
                  link_.last_error().c_str());
    s.have_written = false;
    if (r == drive::TxResult::kLinkLost) {
      mark_all_lost();
      break;
    }
    if (s.work.answering && now_s - s.last_answer_s > cfg_.link_loss_timeout_s) {
      // Answers stopped without the connection breaking (a frozen peer, a drive
      // gone silent on a serial line): that drive's link is lost all the same.
      // When no drive on the link answers, reopen it, which drops stale replies.
      mark_lost(s);
      bool any = spindle_ && spindle_->work.answering;
      for (const auto& io : ios_) any = any || io->work.answering;
      for (const auto& other : slots_) any = any || other->work.answering;
      if (!any) {
        link_.close(now_s);
        break;
      }
    }
  }
  if (spindle_ && link_.is_open()) spindle_round(now_s);
  for (auto& io : ios_)
    if (link_.is_open()) io_round(*io, now_s);
  for (size_t i = 0; i < n; ++i) slots_[i]->rep.write(slots_[i]->work);
  if (spindle_) spindle_->rep.write(spindle_->work);
  for (auto& io : ios_) io->rep.write(io->work);
  ++rounds_;
}

}  // namespace cnc::bridge
