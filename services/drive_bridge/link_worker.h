#pragma once
// The Modbus side of the drive bridge: one worker per link (TCP endpoint, serial
// line, loopback) runs the cycle of the drives on it (each a device with its slice
// of the link's process image, common/drive/device.h), on its own
// thread, so the servo loop never blocks on I/O (mb2hal keeps Modbus out of the
// real-time thread the same way). Each round it writes every drive's latest
// command, reads status and position, steps the profile's state machine toward
// the goal the servo loop set, and detects a lost link: a connection error, or no
// answer for drive_bridge.link_loss_timeout_s. A lost link is reopened with
// exponential back-off; the drives on it are then only ever disabled until the
// servo loop sets the goal "enable" again.
//
// Over a slow serial line a round takes longer than a servo tick: the worker then
// runs back to back and always writes the newest command.
//
// The servo thread and a worker share no lock: each axis's command and report
// cross in a wait-free triple buffer (the newest value wins), and the servo thread
// wakes the worker with a semaphore post. A worker runs one SCHED_FIFO priority
// below the servo thread when the process has real-time scheduling, so it never
// preempts the loop that feeds it and nothing the servo thread waits on can be
// held by a thread that lower-priority work preempts.
#include <semaphore.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "common/config/machine_config.h"
#include "common/drive/axis_drive.h"
#include "common/drive/device.h"
#include "common/drive/io_module_device.h"
#include "common/drive/link.h"
#include "common/drive/spindle_device.h"
#include "common/util/triple_buffer.h"

namespace cnc::bridge {

// What the servo loop and a worker exchange for one axis.
struct AxisCommand {
  drive::Goal goal = drive::Goal::kDisable;
  bool follow = false;    // write `cmd_mm`; otherwise hold where the drive is
  double cmd_mm = 0;
  int64_t cmd_cycle = -1;  // setpoint cycle the command heads for (latency probe)
};

struct AxisReport {
  bool answering = false;   // the drive answered within the link-loss timeout
  int64_t lost_events = 0;  // times its link was lost
  bool have_status = false;
  uint16_t statusword = 0;
  drive::DriveStatus status;
  uint16_t error_code = 0;
  double actual_mm = 0;
  double hold_mm = 0;       // the target the drive holds while not following
  bool holding = false;     // enabled, and its target is the command or the latched hold
  double fe_mm = 0;         // following error: the drive's own (demand - actual) where its profile maps it, else lag_mm
  double lag_mm = 0;        // last target written before this exchange, minus the actual position
  int64_t fe_samples = 0;
  bool has_home_latch = false;  // the profile maps a home switch latch
  double home_latch_mm = 0;     // its position and edge count, as last read
  int64_t home_latch_count = 0;
  bool has_probe_latch = false;  // the profile maps the touch probe's latches
  drive::ProbeLatches probe;     // as last read
  drive::LinkCounters counters;
  std::array<char, 96> last_error{};  // fixed size: reports are copied every tick
};

// What the servo loop and a worker exchange for the spindle drive (a VFD, a servo drive).
struct SpindleCommand {
  // kFaultReset: clear the drive's fault; kEnable / kDisable: a CiA-402 drive's power
  // (a VFD's run is the command word's, every cycle).
  drive::Goal goal = drive::Goal::kDisable;
  int8_t direction = 0;                      // 1, -1, 0 (stop)
  double hz = 0;
  // The servo tick that posted it: its time (monotonic clock) and the playback there
  // (cycle, -1 while the bridge follows no stream, and rate); they stamp the encoder's samples.
  double tick_s = 0;
  double playback_cycle = -1;
  double playback_rate = 1;
};

struct SpindleReport {
  bool answering = false;
  int64_t lost_events = 0;
  drive::SpindleInputs in;  // in.valid: a status since the link was (re)opened
  // When the drive sampled in.position_counts (the worker's monotonic clock, the
  // sample's age on the line taken off), and the command the round carried (its stamp).
  double sample_s = 0;
  SpindleCommand cmd;
  drive::LinkCounters counters;
  std::array<char, 96> last_error{};
};

// What the servo loop and a worker exchange for an I/O module.
struct IoCommand {
  uint64_t coils = 0;  // bit i: the module's i-th coil point (IoModuleDevice::points)
  uint64_t holding_write = 0;  // bit i: the i-th holding-register point is an output, holding[i] wanted
  std::array<uint16_t, drive::kMaxIoPointsPerKind> holding{};
};

struct IoReport {
  bool answering = false;
  int64_t lost_events = 0;
  drive::IoModuleInputs in;  // in.valid: an answer since the link was (re)opened
  drive::LinkCounters counters;
  std::array<char, 96> last_error{};
};

class LinkWorker {
 public:
  // Called on the worker's thread for every target write while following.
  using WriteProbe = std::function<void(int axis, int64_t cycle, double mono_s)>;

  LinkWorker(drive::Link& link, const config::DriveBridgeConfig& cfg);
  ~LinkWorker();
  void add_axis(int axis_index, const drive::DriveProfile& profile, int unit);
  const std::vector<int>& axes() const { return axis_index_; }
  // The spindle's VFD on this link (at most one); its exchange follows the axes' in a round.
  // `max_hz`, `rpm_per_hz`: spindle.max_rpm's frequency and spindle.rpm_per_hz.
  void add_spindle(const drive::DriveProfile& profile, int unit, double max_hz, double rpm_per_hz);
  bool has_spindle() const { return spindle_ != nullptr; }
  void set_spindle_command(const SpindleCommand& c) { spindle_->cmd.write(c); }
  const SpindleReport& spindle_report() { return spindle_->rep.read(); }
  // An I/O module on this link (io.modules[module]); its exchange follows the spindle's
  // in a round. Returns its slot for the two calls below.
  size_t add_io_module(const config::IoConfig& io, int module);
  const drive::IoModuleDevice& io_module(size_t slot) const { return *ios_[slot]->device; }
  void set_io_command(size_t slot, const IoCommand& c) { ios_[slot]->cmd.write(c); }
  const IoReport& io_report(size_t slot) { return ios_[slot]->rep.read(); }
  drive::Link& link() { return link_; }
  void set_probe(WriteProbe p) { probe_ = std::move(p); }

  // Threaded use: start(), then post() after every set_command().
  void start();
  void stop();
  void post();
  // Inline use (tests, shut-down): one round on the caller's thread.
  void round(double now_s);

  // One thread sets commands and reads reports (the servo thread); wait-free.
  void set_command(size_t slot, const AxisCommand& c);
  const AxisReport& report(size_t slot);
  int64_t rounds() const { return rounds_.load(); }

 private:
  static constexpr size_t kMaxSlots = 16;
  struct Slot {
    std::unique_ptr<drive::Device> dev;  // an axis drive: its slice of image_ is drive::kAxisLayout
    size_t pdo = 0;                      // its index in image_
    util::TripleBuffer<AxisCommand> cmd;  // servo thread -> worker
    util::TripleBuffer<AxisReport> rep;   // worker -> servo thread
    // Worker-only state.
    AxisReport work;
    double last_answer_s = -1;
    bool lost = false;
    bool have_written = false;
    double written_mm = 0;
    bool hold_valid = false;
  };
  struct SpindleSlot {
    std::unique_ptr<drive::Device> dev;  // drive::make_spindle_device's
    size_t pdo = 0;
    util::TripleBuffer<SpindleCommand> cmd;
    util::TripleBuffer<SpindleReport> rep;
    SpindleReport work;
    double last_answer_s = -1;
  };
  struct IoSlot {
    std::unique_ptr<drive::Device> dev;
    const drive::IoModuleDevice* device = nullptr;  // dev, typed
    size_t pdo = 0;
    util::TripleBuffer<IoCommand> cmd;
    util::TripleBuffer<IoReport> rep;
    IoReport work;
    double last_answer_s = -1;
  };
  void run();
  void io_round(IoSlot& io, double now_s);
  void mark_io_lost(IoSlot& io);
  void mark_lost(Slot& s);
  void mark_spindle_lost();
  void mark_all_lost();
  void spindle_round(double now_s);
  void forget(Slot& s) { s.dev->forget(image_.inputs(s.pdo)); }
  drive::AxisInputs inputs(const Slot& s) { return drive::get_pdo<drive::AxisInputs>(image_.inputs(s.pdo)); }

  drive::Link& link_;
  config::DriveBridgeConfig cfg_;
  std::vector<std::unique_ptr<Slot>> slots_;
  drive::ProcessImage image_;  // the cyclic process data of the drives on this link
  std::vector<int> axis_index_;
  std::unique_ptr<SpindleSlot> spindle_;
  std::vector<std::unique_ptr<IoSlot>> ios_;
  WriteProbe probe_;
  sem_t wake_;
  std::atomic<bool> stopping_{false};
  std::thread thread_;
  std::atomic<int64_t> rounds_{0};
  double round_mono_ = 0;  // the monotonic clock when the round began (its `now_s` may be a test's clock)
};

}  // namespace cnc::bridge
