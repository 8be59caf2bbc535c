// cnc-servo-sim: emulates the cell's servo drives over Modbus TCP and Modbus RTU,
// one unit id per axis, each axis with the drive profile its machine config names
// (config/drives/*.yaml) and the servo dynamics of its `sim:` section; and the
// spindle's VFD when the config has one (spindle:, its unit id on the same port or
// line; a first-order speed response and a load figure, spindle.sim; a Huanyang VFD,
// which speaks no Modbus, on a line of its own: --spindle-device); and the I/O
// modules of io: (coils, discrete inputs, input and holding registers) on the same
// port or line, each coil's change logged with where the axes stand. The control
// FIFO's "input NAME VALUE" sets a point (a switch or sensor of the module) now, and
// "at AXIS MM input NAME VALUE" when AXIS next passes MM (a switch the axis runs
// into, or a test pressing the E-stop mid-move); each change is logged with the wall
// clock and where and how fast the axes go, and each drive's enable and disable too.
// Hard-limit switches (safety.hard_limits) open as their axis passes
// axes[].sim.limit_min_mm / limit_max_mm; "cut NAME" cuts a switch's wire (it reads 0
// until "mend NAME"; also after "at AXIS MM"). The E-stop starts released, the guard
// door shut (safety.door.input 1: "input NAME 0" opens it).
//
//   cnc-servo-sim --machine M [--port P] [--bind ADDR]      TCP axes: one port
//                 [--device PTY] [--rtu-timing real|none]   RTU axes: the simulator's end of the line
//                 [--spindle-device PTY]                    a Huanyang VFD's own line (the simulator's end)
//                 [--control FIFO] [--inject "T:CMD; ..."]  fault injection (fault_injector.h)
//                 [--trace CSV] [--persist FILE] [--final-state FILE]
//                 [--latency-dir DIR]                       cycle timing at the end (or $CNC_LATENCY_DIR)
//                 [--master-stall-pause-s S]                how long a master's dry stream stops the simulated
//                                                           world (default timing.setpoint_timeout_s; 0: never)
//
// --rtu-timing real (default) holds each RTU reply until a real line at the
// configured baud would have carried request and reply (a pseudo-terminal moves
// bytes at once). --persist keeps the axes' positions in FILE (every 50 ms) and
// starts from them: drives with absolute encoders, for restarts mid-run.
// Single-threaded: select() on the sockets, the serial line and the control FIFO,
// with the dynamics stepped on a 1 ms grid between requests.
#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <modbus.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/config/yaml_reader.h"
#include "common/drive/delta_vfd_profile.h"
#include "common/drive/huanyang_frame.h"
#include "common/drive/drive_profile.h"
#include "common/drive/io_emulator.h"
#include "common/drive/vfd_emulator.h"
#include "common/drive/link_factory.h"
#include "common/service/service.h"
#include "common/util/clock.h"
#include "common/util/realtime.h"
#include "common/util/signals.h"
#include "common/util/spsc_ring.h"
#include "tools/servo_sim/fault_injector.h"
#include "tools/servo_sim/rtu_frame.h"
#include "tools/servo_sim/sim_drive.h"

namespace {

using cnc::servo_sim::SimDrive;

double wall_s() {
  timespec t{};
  clock_gettime(CLOCK_REALTIME, &t);
  return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec) * 1e-9;
}

void sleep_until_mono(double t_s) {
  const double now = cnc::util::monotonic_s();
  if (t_s <= now) return;
  timespec ts{};
  const double d = t_s - now;
  ts.tv_sec = static_cast<time_t>(d);
  ts.tv_nsec = static_cast<long>((d - static_cast<double>(ts.tv_sec)) * 1e9);
  nanosleep(&ts, nullptr);
}

speed_t baud_constant(int baud) {
  switch (baud) {
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    case 230400: return B230400;
    case 460800: return B460800;
    case 921600: return B921600;
    default: return B115200;  // a pseudo-terminal ignores it; the timing model uses the configured baud
  }
}

int open_serial(const std::string& device, int baud) {
  const int fd = ::open(device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
  if (fd < 0) return -1;
  termios t{};
  if (tcgetattr(fd, &t) == 0) {
    cfmakeraw(&t);
    cfsetispeed(&t, baud_constant(baud));
    cfsetospeed(&t, baud_constant(baud));
    t.c_cflag |= CLOCAL | CREAD;
    tcsetattr(fd, TCSANOW, &t);
  }
  return fd;
}

// The holding registers a request wrote: [addr, addr + n); n = 0 when none.
void written_range(const uint8_t* pdu, int* addr, int* n) {
  *addr = 0;
  *n = 0;
  switch (pdu[0]) {
    case MODBUS_FC_WRITE_SINGLE_REGISTER:
      *addr = (pdu[1] << 8) | pdu[2];
      *n = 1;
      break;
    case MODBUS_FC_WRITE_MULTIPLE_REGISTERS:
      *addr = (pdu[1] << 8) | pdu[2];
      *n = (pdu[3] << 8) | pdu[4];
      break;
    case MODBUS_FC_WRITE_AND_READ_REGISTERS:
      *addr = (pdu[5] << 8) | pdu[6];
      *n = (pdu[7] << 8) | pdu[8];
      break;
    default: break;
  }
}

// The persisted positions ({"X": mm, ...}); an axis missing or not a number starts
// where the config says. A file that is not JSON is refused naming it.
std::map<std::string, double> read_positions(const std::string& file) {
  std::map<std::string, double> out;
  std::ifstream in(file);
  if (!in || in.peek() == std::ifstream::traits_type::eof()) return out;
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::parse_error& e) {
    throw std::runtime_error(file + ": not the simulator's positions: " + e.what());
  }
  if (!j.is_object()) throw std::runtime_error(file + ": not the simulator's positions (a JSON object)");
  for (const auto& [name, v] : j.items())
    if (v.is_number()) out[name] = v.get<double>();
  return out;
}

// {"X": mm, ...} to 0.1 nm (as "%.7f" gave them), finite.
std::string positions_json(const std::vector<std::string>& names, const double* pos) {
  nlohmann::ordered_json j = nlohmann::ordered_json::object();
  for (size_t i = 0; i < names.size(); ++i)
    j[names[i]] = std::isfinite(pos[i]) ? nlohmann::ordered_json(std::round(pos[i] * 1e7) / 1e7) : nlohmann::ordered_json();
  return j.dump();
}

std::string positions_json(const std::vector<SimDrive*>& drives) {
  std::vector<std::string> names;
  std::vector<double> pos;
  for (const SimDrive* d : drives) {
    names.push_back(d->name());
    pos.push_back(d->position_mm());
  }
  return positions_json(names, pos.data());
}

// The trace and the persisted positions are files: written on a thread of normal
// priority, never on the simulation loop (a file write that blocks for tens of ms
// on a busy disk would stall every simulated drive, and the bridge would rightly
// see a following error). The loop hands over fixed-size samples through a
// lock-free ring; a full ring drops the sample (counted) instead of waiting.
class SideWriter {
 public:
  static constexpr size_t kMaxAxes = 16;
  struct Sample {
    double wall_s = 0;
    double world_s = 0;  // wall_s less the time the simulated world stood (SimWorld)
    double pos[kMaxAxes]{};
    double vel[kMaxAxes]{};
    bool on[kMaxAxes]{};
    bool trace = false;  // a trace row (else only the newest positions to persist)
  };

  SideWriter(std::vector<std::string> names, std::string trace_file, std::string persist_file)
      : names_(std::move(names)), persist_(std::move(persist_file)), ring_(4096) {
    if (!trace_file.empty()) {
      trace_.open(trace_file);
      trace_ << "wall_s";
      for (const auto& n : names_) trace_ << "," << n << "_mm," << n << "_mm_s," << n << "_on";
      trace_ << ",world_s\n" << std::flush;
    }
    thread_ = std::thread([this] { run(); });
  }
  ~SideWriter() {
    stop_.store(true, std::memory_order_release);
    thread_.join();
  }
  bool tracing() const { return trace_.is_open(); }
  // Simulation loop: wait-free.
  void push(const Sample& s) {
    if (!ring_.push(s)) dropped_.fetch_add(1, std::memory_order_relaxed);
  }
  int64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }

 private:
  void run() {
    sched_param sp{};
    pthread_setschedparam(pthread_self(), SCHED_OTHER, &sp);
    pthread_setname_np(pthread_self(), "sim-writer");
    Sample last;
    bool have = false;
    double next_persist = 0;
    for (;;) {
      const bool stopping = stop_.load(std::memory_order_acquire);
      while (Sample* s = ring_.front()) {
        if (s->trace && trace_.is_open()) {
          // One write per row, so a reader never sees half a row.
          char buf[64];
          std::snprintf(buf, sizeof buf, "%.4f", s->wall_s);
          std::string row = buf;
          for (size_t i = 0; i < names_.size(); ++i) {
            std::snprintf(buf, sizeof buf, ",%.6f,%.4f,%d", s->pos[i], s->vel[i], s->on[i] ? 1 : 0);
            row += buf;
          }
          std::snprintf(buf, sizeof buf, ",%.4f\n", s->world_s);
          row += buf;
          trace_ << row << std::flush;
        }
        last = *s;
        have = true;
        ring_.pop();
      }
      const double now = cnc::util::monotonic_s();
      if (have && !persist_.empty() && (now >= next_persist || stopping)) {
        next_persist = now + 0.05;
        std::ofstream(persist_ + ".tmp") << positions_json(names_, last.pos) << "\n";
        std::filesystem::rename(persist_ + ".tmp", persist_);
      }
      if (stopping) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }

  std::vector<std::string> names_;
  std::string persist_;
  std::ofstream trace_;
  cnc::util::SpscRing<Sample> ring_;
  std::atomic<int64_t> dropped_{0};
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

// Diagnostics (CNC_SIM_DEBUG_TRACE=FILE): every grid step and every target write,
// in memory allocated up front, written to FILE (and FILE.writes) at exit.
struct DebugTrace {
  static constexpr int kAx = 3;
  struct Step {
    double mono, grid, shifted;
    double demand[kAx], actual[kAx], vel[kAx], fe[kAx], ahead[kAx];
  };
  struct Write {
    double mono;
    int axis;
    double target, ahead;
  };
  std::vector<Step> steps;
  std::vector<Write> writes;
  std::string file;
};

// A change of the VFD's command: a line in the log (not on every step).
void spindle_log(bool run, double command_hz, double output_hz) {
  if (run)
    spdlog::info("cnc-servo-sim: spindle: run at {:.2f} Hz (output {:.2f} Hz)", command_hz, output_hz);
  else
    spdlog::info("cnc-servo-sim: spindle: stop (output {:.2f} Hz)", output_hz);
}

class Simulator {
 public:
  Simulator(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args);
  ~Simulator();
  int run();

 private:
  SimDrive* drive_for(std::vector<SimDrive*>& list, int unit);
  // The drive reacts to what the request wrote (modbus_reply wrote the registers).
  void after_reply(SimDrive& d, const uint8_t* pdu);
  void step_dynamics();
  void open_listener();
  void close_tcp();
  void serve_tcp_client(int fd, std::vector<int>& closed);
  void serve_rtu_input();
  void serve_vfd_line();
  void answer_rtu(const uint8_t* frame, int len, double rx_end_s);
  void read_control();
  void housekeeping(double now);
  void reply_vfd(modbus_t* ctx, const uint8_t* query, int len, int header);
  void step_vfd(double now);
  // The I/O module of `unit` on TCP (tcp) or on the RTU line, else nullptr.
  struct IoSim {
    std::unique_ptr<cnc::drive::IoEmulator> emu;
    int unit = 0;
    bool tcp = true;
    std::vector<uint8_t> coils;  // as last logged
    std::vector<uint16_t> regs;  // holding registers, as last logged
  };
  IoSim* io_for(int unit, bool tcp);
  void reply_io(IoSim& io, modbus_t* ctx, const uint8_t* query, int len);
  bool set_io_point(const std::string& line);
  // "cut NAME", "mend NAME": a hard-limit switch's wire.
  bool cut_wire(const std::string& line);
  // The hard-limit switches, opened by their axis's position (poll_limits).
  struct LimitSwitch {
    size_t drive;
    int end;          // -1 min, +1 max
    double at_mm;     // open at and beyond
    std::string input;
    bool cut = false;
    int value = -1;   // as last set
  };
  std::vector<LimitSwitch> limit_switches_;
  void poll_limits();
  // "at AXIS MM input NAME VALUE": armed now, applied when AXIS passes MM (poll_triggers).
  bool arm_trigger(const std::string& line);
  void poll_triggers();
  // The probe's fixture (probe.sim_box): the probe input 1 while the tool tip (the
  // first three axes' positions) is inside the box, evaluated on every grid step.
  // Every drive's touch probe is wired to the probe too: at each edge it latches its own
  // position where the tip crossed the box's face (the drive's capture, exact here but
  // for its counts' resolution) and counts the edge.
  void probe_fixture();
  bool probe_in_ = false;
  bool probe_seen_ = false;
  double probe_prev_[3] = {0, 0, 0};
  std::vector<double> probe_prev_all_;  // every drive's position at the last grid step
  int64_t probe_rises_ = 0, probe_falls_ = 0;
  struct Trigger {
    size_t drive;
    double at_mm;
    bool below;           // the axis was below at_mm when armed
    std::string command;  // "input NAME VALUE"
  };
  std::vector<Trigger> triggers_;

  const cnc::config::MachineConfig& cfg_;
  const cnc::service::Args& args_;
  std::vector<std::unique_ptr<cnc::drive::DriveProfile>> profiles_;
  std::vector<std::unique_ptr<SimDrive>> drives_;
  std::vector<SimDrive*> all_, tcp_, rtu_;
  std::unique_ptr<cnc::servo_sim::SimWorld> world_;
  // The spindle's VFD (nullptr: none); on TCP or on the RTU line, by its unit id.
  std::unique_ptr<cnc::drive::VfdEmulator> vfd_;
  int vfd_unit_ = -1;
  bool vfd_tcp_ = false;
  double vfd_t_ = -1;
  double vfd_logged_hz_ = 0;
  // A Huanyang VFD on a line of its own (--spindle-device): its frames are no Modbus.
  std::string vfd_device_;
  int vfd_fd_ = -1;
  std::vector<uint8_t> vfd_rx_;
  bool vfd_logged_run_ = false;
  std::vector<IoSim> ios_;
  cnc::servo_sim::FaultInjector injector_;
  // TCP
  std::string bind_;
  int port_ = -1;
  modbus_t* tcp_ctx_ = nullptr;
  int listen_fd_ = -1;
  std::vector<int> clients_;
  // RTU
  std::string device_;
  int baud_ = 115200;
  double char_s_ = 0;
  bool line_timing_ = true;
  modbus_t* rtu_ctx_ = nullptr;
  int serial_fd_ = -1;
  int capture_[2] = {-1, -1};
  std::vector<uint8_t> rx_;
  double rx_first_s_ = 0;
  double line_free_s_ = 0;
  // control, trace, persistence
  int control_fd_ = -1;
  int control_keep_fd_ = -1;
  std::string control_buf_;
  std::unique_ptr<SideWriter> writer_;
  double next_trace_s_ = 0;
  double next_persist_s_ = 0;
  double dt_;
  std::vector<bool> follows_seen_;  // per drive: enabled as last logged
  std::vector<std::pair<int64_t, bool>> comm_seen_;  // per drive: watchdog trips and faults logged
  int64_t stalls_ = 0;     // process stalls the simulated world paused for
  double stalled_s_ = 0;
  double next_step_s_;
  DebugTrace dbg_;
  double dbg_shift_ = 0;
};

Simulator::Simulator(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args)
    : cfg_(cfg), args_(args), injector_([this](const std::string& axis, uint16_t code) {
        for (SimDrive* d : all_) {
          if (d->name() != axis) continue;
          d->emulator().inject_fault(code);
          return true;
        }
        if (axis == "spindle" && vfd_) {
          vfd_->inject_fault(code);
          return true;
        }
        return false;
      },
      [this](const std::string& axis, bool on) {
        bool found = axis.empty();
        for (SimDrive* d : all_)
          if (axis.empty() || d->name() == axis) {
            d->set_jammed(on);
            found = true;
          }
        return found;
      }),
      dt_(cfg.servo_period_s) {
  std::map<std::string, const cnc::drive::DriveProfile*> by_file;
  std::map<std::string, double> start;
  const std::string persist = args.option("persist");
  if (!persist.empty() && std::filesystem::exists(persist)) {
    start = read_positions(persist);
    spdlog::info("cnc-servo-sim: starting from the positions in {}", persist);
  }
  // One simulated drive per axis (in axes[] order), then each gantry's second drive
  // (named axes[].gantry.name, with its own sim: section and switch).
  const auto add_drive = [&](const cnc::config::AxisConfig& a, const std::string& name,
                             const cnc::config::DriveConfig& d, const cnc::config::ServoSimAxisConfig& sim,
                             const std::string& key) {
    const cnc::drive::Transport transport = cnc::drive::transport_of(d);
    if (transport == cnc::drive::Transport::kLoopback) return;  // emulated inside the bridge
    const std::string file = cnc::drive::find_drive_profile(d.profile, cfg.source_file, cfg.drive_profile_dir);
    if (!by_file.count(file)) {
      if (!std::filesystem::exists(file))
        throw cnc::config::ConfigError(cfg.source_file, key + ".profile",
                                       "no drive profile '" + d.profile + "' (looked for " + file + ")");
      profiles_.push_back(std::make_unique<cnc::drive::DriveProfile>(cnc::drive::load_drive_profile(file)));
      by_file[file] = profiles_.back().get();
    }
    const double at = start.count(name) ? std::clamp(start[name], a.min_mm, a.max_mm) : a.home_mm;
    drives_.push_back(std::make_unique<SimDrive>(name, d.unit_id, *by_file[file], sim, a.max_velocity_mm_s, at,
                                                 a.max_accel_mm_s2));
    drives_.back()->set_home_switch(sim, a.home.direction);
    all_.push_back(drives_.back().get());
    if (transport == cnc::drive::Transport::kModbusTcp) {
      if (port_ < 0) port_ = d.port;
      if (d.port != port_)
        throw std::runtime_error("axis " + name + ": the simulator serves one TCP port; axes use " +
                                 std::to_string(port_) + " and " + std::to_string(d.port));
      tcp_.push_back(all_.back());
    } else {
      if (rtu_.empty()) baud_ = d.baud;
      rtu_.push_back(all_.back());
      const int bits = 1 + 8 + (d.parity == "none" ? 0 : 1) + d.stop_bits;
      char_s_ = bits / static_cast<double>(baud_);
    }
  };
  for (size_t i = 0; i < cfg.axes.size(); ++i)
    add_drive(cfg.axes[i], cfg.axes[i].name, cfg.axes[i].drive, cfg.axes[i].sim, "axes[" + std::to_string(i) + "].drive");
  for (size_t i = 0; i < cfg.axes.size(); ++i)
    if (cfg.axes[i].gantry.enabled)
      add_drive(cfg.axes[i], cfg.axes[i].gantry.name, cfg.axes[i].gantry.drive, cfg.axes[i].gantry.sim,
                "axes[" + std::to_string(i) + "].gantry.drive");
  if (cfg.spindle.enabled && cnc::drive::transport_of(cfg.spindle.drive) != cnc::drive::Transport::kLoopback) {
    const auto& d = cfg.spindle.drive;
    const cnc::drive::Transport transport = cnc::drive::transport_of(d);
    const std::string file = cnc::drive::find_drive_profile(d.profile, cfg.source_file, cfg.drive_profile_dir);
    if (!std::filesystem::exists(file))
      throw cnc::config::ConfigError(cfg.source_file, "spindle.drive.profile",
                                     "no drive profile '" + d.profile + "' (looked for " + file + ")");
    profiles_.push_back(std::make_unique<cnc::drive::DriveProfile>(cnc::drive::load_drive_profile(file)));
    if (!cnc::drive::is_spindle_profile(*profiles_.back()))
      throw cnc::config::ConfigError(cfg.source_file, "spindle.drive.profile",
                                     "'" + d.profile + "' is no spindle drive's profile");
    vfd_ = std::make_unique<cnc::drive::VfdEmulator>(*profiles_.back(), cfg.spindle.sim,
                                                     cfg.spindle.max_rpm / cfg.spindle.rpm_per_hz, cfg.spindle.rpm_per_hz,
                                                     cfg.spindle.encoder_counts_per_rev);
    vfd_unit_ = d.unit_id;
    vfd_tcp_ = transport == cnc::drive::Transport::kModbusTcp;
    if (vfd_->profile().huanyang.present) {
      if (vfd_tcp_)
        throw cnc::config::ConfigError(cfg.source_file, "spindle.drive.transport",
                                       "modbus_tcp cannot carry the Huanyang protocol: use modbus_rtu");
      for (const auto& a : cfg.axes)
        if (cnc::drive::transport_of(a.drive) == cnc::drive::Transport::kModbusRtu && a.drive.device == d.device)
          throw std::runtime_error("the spindle's Huanyang VFD is served on a line of its own, not on the axes' " +
                                   d.device);
      vfd_device_ = args.option("spindle-device");
      if (vfd_device_.empty()) {
        // Whatever else is on its line answers it (a test's counterpart).
        spdlog::info("cnc-servo-sim: the spindle's Huanyang VFD on {} is not served here (no --spindle-device)",
                     d.device);
        vfd_.reset();
      }
    } else if (vfd_tcp_) {
      if (port_ < 0) port_ = d.port;
      if (d.port != port_)
        throw std::runtime_error("the spindle: the simulator serves one TCP port; the axes use " +
                                 std::to_string(port_) + ", the spindle " + std::to_string(d.port));
    } else if (rtu_.empty()) {
      throw std::runtime_error("the spindle's VFD on RTU is served only on the axes' line");
    }
  }
  for (size_t m = 0; cfg.io.enabled && m < cfg.io.modules.size(); ++m) {
    const auto& d = cfg.io.modules[m].link;
    IoSim io;
    io.emu = std::make_unique<cnc::drive::IoEmulator>(cfg.io, static_cast<int>(m));
    io.unit = d.unit_id;
    io.tcp = cnc::drive::transport_of(d) == cnc::drive::Transport::kModbusTcp;
    io.coils.assign(static_cast<size_t>(io.emu->mapping()->nb_bits), 0);
    io.regs.assign(static_cast<size_t>(io.emu->mapping()->nb_registers), 0);
    if (io.tcp) {
      if (port_ < 0) port_ = d.port;
      if (d.port != port_)
        throw std::runtime_error("I/O module " + cfg.io.modules[m].name + ": the simulator serves one TCP port; " +
                                 std::to_string(port_) + " is in use, the module has " + std::to_string(d.port));
    } else if (rtu_.empty()) {
      throw std::runtime_error("I/O module " + cfg.io.modules[m].name + " on RTU is served only on the axes' line");
    }
    // The E-stop button (safety.estop.input, normally closed) starts released, its wire
    // whole; the guard door shut; limit switches closed (until their axis opens them).
    for (int point : {cfg.safety.estop_input, cfg.safety.door_input})
      if (point >= 0) io.emu->set_point(cfg.io.points[static_cast<size_t>(point)].name, 1);
    for (const auto& h : cfg.safety.hard_limits)
      for (int point : {h.min_input, h.max_input})
        if (point >= 0) io.emu->set_point(cfg.io.points[static_cast<size_t>(point)].name, 1);
    ios_.push_back(std::move(io));
  }
  if (all_.empty() && !vfd_ && ios_.empty() && !cfg.spindle.enabled) throw std::runtime_error("no axis uses transport modbus_tcp or modbus_rtu");
  probe_prev_all_.assign(all_.size(), 0.0);
  for (const auto& h : cfg.safety.hard_limits) {
    const auto& ax = cfg.axes[static_cast<size_t>(h.axis)];
    for (int end : {-1, 1}) {
      const int point = end < 0 ? h.min_input : h.max_input;
      const double at = end < 0 ? ax.sim.limit_min_mm : ax.sim.limit_max_mm;
      if (point < 0 || std::isnan(at)) continue;
      for (size_t i = 0; i < all_.size(); ++i)
        if (all_[i]->name() == ax.name)
          limit_switches_.push_back(LimitSwitch{i, end, at, cfg.io.points[static_cast<size_t>(point)].name});
    }
  }
  {
    // How long a stalled master's dry stream stops the simulated world (SimWorld).
    const std::string p = args.option("master-stall-pause-s");
    double pause = cfg.setpoint_timeout_s;
    if (!p.empty()) {
      char* end = nullptr;
      pause = std::strtod(p.c_str(), &end);
      if (end == p.c_str() || *end != '\0' || !std::isfinite(pause) || pause < 0)
        throw cnc::config::ConfigError("", "--master-stall-pause-s", "'" + p + "' is not a number of seconds >= 0");
    }
    world_ = std::make_unique<cnc::servo_sim::SimWorld>(all_, pause);
  }
  if (!args.option("port").empty()) port_ = std::stoi(args.option("port"));
  bind_ = args.option("bind", "127.0.0.1");
  device_ = args.option("device");
  const std::string timing = args.option("rtu-timing", "real");
  if (timing != "real" && timing != "none") throw std::runtime_error("--rtu-timing must be real or none");
  line_timing_ = timing == "real";
  if (!rtu_.empty() && device_.empty())
    throw std::runtime_error("RTU axes need --device: the simulator's end of the serial line");
  if (!args.option("inject").empty()) {
    try {
      injector_.schedule(args.option("inject"), cnc::util::monotonic_s());
    } catch (const std::invalid_argument& e) {
      throw cnc::config::ConfigError("", "--inject", e.what());
    }
  }
}

Simulator::~Simulator() {
  close_tcp();
  if (tcp_ctx_) modbus_free(tcp_ctx_);
  if (serial_fd_ >= 0) ::close(serial_fd_);
  if (vfd_fd_ >= 0) ::close(vfd_fd_);
  if (rtu_ctx_) modbus_free(rtu_ctx_);
  for (int fd : capture_)
    if (fd >= 0) ::close(fd);
  if (control_fd_ >= 0) ::close(control_fd_);
  if (control_keep_fd_ >= 0) ::close(control_keep_fd_);
}

SimDrive* Simulator::drive_for(std::vector<SimDrive*>& list, int unit) {
  for (SimDrive* d : list)
    if (d->unit() == unit) return d;
  return nullptr;
}

void Simulator::after_reply(SimDrive& d, const uint8_t* pdu) {
  int addr = 0, n = 0;
  written_range(pdu, &addr, &n);
  const int first = d.emulator().profile().first_address();
  const int end = d.emulator().profile().end_address();
  const int64_t before = d.emulator().target_writes();
  if (n > 0 && addr >= first && addr + n <= end) d.emulator().after_write(addr, n);
  // The world first: the drive takes the write at the moment the world has reached
  // (a dry stream stood until now), not stepping itself alone past its newest target.
  const double now = cnc::util::monotonic_s();
  world_->advance_to(now);
  d.after_request(now);
  if (!dbg_.file.empty() && before != d.emulator().target_writes() && dbg_.writes.size() < dbg_.writes.capacity()) {
    dbg_.writes.push_back({now, d.unit(), d.emulator().target_mm(), d.buffer_end_s() - now});
  }
}

void Simulator::reply_vfd(modbus_t* ctx, const uint8_t* query, int len, int header) {
  step_vfd(cnc::util::monotonic_s());  // the reply reads the motor and its encoder as they are at this moment
  modbus_reply(ctx, query, len, vfd_->mapping());
  int addr = 0, n = 0;
  written_range(query + header, &addr, &n);
  const int first = vfd_->profile().first_address();
  const int end = vfd_->profile().end_address();
  if (n > 0 && addr >= first && addr + n <= end) vfd_->after_write(addr, n);
}

Simulator::IoSim* Simulator::io_for(int unit, bool tcp) {
  for (IoSim& io : ios_)
    if (io.unit == unit && io.tcp == tcp) return &io;
  return nullptr;
}

void Simulator::reply_io(IoSim& io, modbus_t* ctx, const uint8_t* query, int len) {
  modbus_reply(ctx, query, len, io.emu->mapping());
  // Each coil's change, with where the axes stand when the module takes it.
  for (size_t a = 0; a < io.coils.size(); ++a) {
    const uint8_t now = io.emu->coil(static_cast<int>(a));
    if (now == io.coils[a]) continue;
    io.coils[a] = now;
    std::string name = "coil " + std::to_string(a);
    for (const auto& p : cfg_.io.points)
      if (p.kind == cnc::config::IoKind::kCoil && p.address == static_cast<int>(a) &&
          cfg_.io.modules[static_cast<size_t>(p.module)].name == io.emu->name())
        name = p.name;
    std::string where;
    for (const SimDrive* d : all_) where += fmt::format(" {} {:.4f}", d->name(), d->position_mm());
    spdlog::info("cnc-servo-sim: io {}: {} {} at{}", io.emu->name(), name, now ? "on" : "off", where);
  }
  // Each holding register's change (an analog output written by the master), scaled.
  for (size_t a = 0; a < io.regs.size(); ++a) {
    const uint16_t now = io.emu->mapping()->tab_registers[a];
    if (now == io.regs[a]) continue;
    io.regs[a] = now;
    std::string name = "register " + std::to_string(a);
    double value = now;
    for (const auto& p : cfg_.io.points)
      if (p.kind == cnc::config::IoKind::kHoldingRegister && p.address == static_cast<int>(a) &&
          cfg_.io.modules[static_cast<size_t>(p.module)].name == io.emu->name()) {
        name = p.name;
        value = (p.is_signed ? static_cast<double>(static_cast<int16_t>(now)) : static_cast<double>(now)) * p.scale;
      }
    std::string where;
    for (const SimDrive* d : all_) where += fmt::format(" {} {:.4f}", d->name(), d->position_mm());
    spdlog::info("cnc-servo-sim: io {}: {} = {} (raw {}) at{}", io.emu->name(), name, value, now, where);
  }
}

bool Simulator::set_io_point(const std::string& line) {
  // "input NAME VALUE": a point's raw value (a bit 0/1, a register's count).
  std::istringstream in(line);
  std::string what, name;
  long value = 0;
  if (!(in >> what) || what != "input") return false;
  if (!(in >> name >> value)) {
    spdlog::error("cnc-servo-sim: control command '{}': input needs a point's name and a value", line);
    return true;
  }
  for (IoSim& io : ios_)
    if (io.emu->set_point(name, static_cast<int>(value))) {
      // The wall clock of the edge, and where and how fast the axes go then: a reaction
      // (the E-stop's) is measured from here.
      std::string where;
      for (const SimDrive* d : all_)
        where += fmt::format(" {} {:.4f} mm {:.3f} mm/s", d->name(), d->position_mm(), d->velocity_mm_s());
      spdlog::warn("cnc-servo-sim: io {}: {} set to {} at utime {} with{}", io.emu->name(), name, value,
                   cnc::util::wall_utime(), where);
      return true;
    }
  spdlog::error("cnc-servo-sim: control command '{}': no I/O point '{}'", line, name);
  return true;
}

void Simulator::probe_fixture() {
  const auto& pc = cfg_.probe;
  if (!pc.sim_box || pc.input < 0 || all_.size() < 3) return;
  double p[3];
  bool in = true;
  for (int i = 0; i < 3; ++i) {
    p[i] = all_[static_cast<size_t>(i)]->position_mm();
    in = in && p[i] >= pc.box_min_mm[i] && p[i] <= pc.box_max_mm[i];
  }
  const double R = 0.5 * pc.bore_diameter_mm;
  if (R > 0 && std::hypot(p[0] - pc.bore_xy_mm[0], p[1] - pc.bore_xy_mm[1]) < R) in = false;
  if (probe_seen_ && in != probe_in_) {
    const std::string& name = cfg_.io.points[static_cast<size_t>(pc.input)].name;
    for (IoSim& io : ios_)
      if (io.emu->set_point(name, in ? 1 : 0)) break;
    // Where the straight line between the last two grid points crossed the box's faces
    // (the truth the latch is measured against) and where the step ended.
    double t_cross = 1.0;
    for (int i = 0; i < 3; ++i) {
      const double a = probe_prev_[i], b = p[i];
      if (a == b) continue;
      for (double f : {pc.box_min_mm[i], pc.box_max_mm[i]}) {
        const double t = (f - a) / (b - a);
        if (t >= 0 && t <= 1) t_cross = std::min(t_cross, t);
      }
    }
    if (R > 0) {
      // The bore's wall: |a + t (b - a) - c| = R in XY.
      const double ax = probe_prev_[0] - pc.bore_xy_mm[0], ay = probe_prev_[1] - pc.bore_xy_mm[1];
      const double dx = p[0] - probe_prev_[0], dy = p[1] - probe_prev_[1];
      const double qa = dx * dx + dy * dy, qb = 2 * (ax * dx + ay * dy), qc = ax * ax + ay * ay - R * R;
      const double disc = qb * qb - 4 * qa * qc;
      if (qa > 0 && disc >= 0)
        for (double sgn : {-1.0, 1.0}) {
          const double t = (-qb + sgn * std::sqrt(disc)) / (2 * qa);
          if (t >= 0 && t <= 1) t_cross = std::min(t_cross, t);
        }
    }
    const int64_t count = in ? ++probe_rises_ : ++probe_falls_;
    for (size_t d = 0; d < all_.size(); ++d) {
      const double a = probe_prev_all_[d], b = all_[d]->position_mm();
      all_[d]->emulator().set_probe_latch(in, a + t_cross * (b - a), count);
    }
    spdlog::info("cnc-servo-sim: probe {} {}: crossed at X {:.6f} Y {:.6f} Z {:.6f}, step ended at X {:.6f} Y {:.6f} Z {:.6f}",
                 name, in ? "contact" : "released", probe_prev_[0] + t_cross * (p[0] - probe_prev_[0]),
                 probe_prev_[1] + t_cross * (p[1] - probe_prev_[1]), probe_prev_[2] + t_cross * (p[2] - probe_prev_[2]),
                 p[0], p[1], p[2]);
  } else if (!probe_seen_) {
    const std::string& name = cfg_.io.points[static_cast<size_t>(pc.input)].name;
    for (IoSim& io : ios_)
      if (io.emu->set_point(name, in ? 1 : 0)) break;
  }
  probe_seen_ = true;
  probe_in_ = in;
  for (int i = 0; i < 3; ++i) probe_prev_[i] = p[i];
  for (size_t d = 0; d < all_.size(); ++d) probe_prev_all_[d] = all_[d]->position_mm();
}

bool Simulator::arm_trigger(const std::string& line) {
  std::istringstream in(line);
  std::string what, axis;
  double at = 0;
  if (!(in >> what) || what != "at") return false;
  std::string rest;
  if (!(in >> axis >> at) || !std::getline(in, rest) || rest.find_first_not_of(' ') == std::string::npos) {
    spdlog::error("cnc-servo-sim: control command '{}': at needs AXIS MM input NAME VALUE (or cut NAME, mend NAME)", line);
    return true;
  }
  for (size_t i = 0; i < all_.size(); ++i)
    if (all_[i]->name() == axis) {
      triggers_.push_back(Trigger{i, at, all_[i]->position_mm() < at, rest.substr(rest.find_first_not_of(' '))});
      spdlog::info("cnc-servo-sim: armed: '{}' when {} passes {:.4f} mm", triggers_.back().command, axis, at);
      return true;
    }
  spdlog::error("cnc-servo-sim: control command '{}': no simulated axis {}", line, axis);
  return true;
}

bool Simulator::cut_wire(const std::string& line) {
  std::istringstream in(line);
  std::string what, name;
  if (!(in >> what) || (what != "cut" && what != "mend")) return false;
  in >> name;
  for (LimitSwitch& l : limit_switches_)
    if (l.input == name) {
      l.cut = what == "cut";
      spdlog::info("cnc-servo-sim: the wire of limit switch {} {}", name, l.cut ? "cut" : "mended");
      poll_limits();
      return true;
    }
  spdlog::error("cnc-servo-sim: control command '{}': no simulated limit switch '{}'", line, name);
  return true;
}

void Simulator::poll_limits() {
  for (LimitSwitch& l : limit_switches_) {
    const double x = all_[l.drive]->position_mm();
    const int value = !l.cut && (l.end > 0 ? x < l.at_mm : x > l.at_mm) ? 1 : 0;
    if (value == l.value) continue;
    l.value = value;
    set_io_point("input " + l.input + " " + std::to_string(value));
  }
}

void Simulator::poll_triggers() {
  for (size_t k = 0; k < triggers_.size();) {
    const Trigger& t = triggers_[k];
    if ((all_[t.drive]->position_mm() < t.at_mm) == t.below) {
      ++k;
      continue;
    }
    if (!cut_wire(t.command)) set_io_point(t.command);
    triggers_.erase(triggers_.begin() + static_cast<std::ptrdiff_t>(k));
  }
}

void Simulator::open_listener() {
  listen_fd_ = modbus_tcp_listen(tcp_ctx_, 8);
  if (listen_fd_ < 0)
    throw std::runtime_error("cannot listen on " + bind_ + ":" + std::to_string(port_) + ": " + modbus_strerror(errno));
}

void Simulator::close_tcp() {
  for (int fd : clients_) ::close(fd);
  clients_.clear();
  if (listen_fd_ >= 0) ::close(listen_fd_);
  listen_fd_ = -1;
}

void Simulator::step_dynamics() {
  const double now = cnc::util::monotonic_s();
  // The simulated drives stand in for drives on hardware of their own, which a
  // stall of this process (the VM paused, the scheduler starved it) does not stop.
  // A grid step more than kStall late is such a stall: the simulated world pauses
  // with it (every drive's clock is shifted by the lost time), instead of the
  // drives running out of targets and losing their stream. Counted and logged.
  constexpr double kStall = 0.005;
  const double late = now - next_step_s_;
  if (late > kStall) {
    const double lost = late - dt_;
    world_->stand(lost);
    next_step_s_ += lost;
    ++stalls_;
    stalled_s_ += lost;
    dbg_shift_ += lost;
  }
  int steps = 0;
  while (now >= next_step_s_ && steps < 1000) {
    world_->advance_to(next_step_s_);
    probe_fixture();
    if (!dbg_.file.empty() && dbg_.steps.size() < dbg_.steps.capacity()) {
      DebugTrace::Step st{};
      st.mono = cnc::util::monotonic_s();
      st.grid = next_step_s_;
      st.shifted = dbg_shift_;
      dbg_shift_ = 0;
      for (size_t i = 0; i < all_.size() && i < DebugTrace::kAx; ++i) {
        st.demand[i] = all_[i]->last_demand_mm();
        st.actual[i] = all_[i]->position_mm();
        st.vel[i] = all_[i]->velocity_mm_s();
        st.fe[i] = all_[i]->last_fe_mm();
        st.ahead[i] = all_[i]->buffer_end_s() - next_step_s_;
      }
      dbg_.steps.push_back(st);
    }
    next_step_s_ += dt_;
    ++steps;
  }
  if (steps >= 1000) next_step_s_ = now + dt_;
  if (vfd_) step_vfd(now);
}

void Simulator::step_vfd(double now) {
  // The VFD is a motor of its own: it runs on the wall's time, stalls or not.
  if (vfd_t_ >= 0 && now > vfd_t_) vfd_->step(now - vfd_t_);
  vfd_t_ = std::max(vfd_t_, now);
}

void Simulator::serve_tcp_client(int fd, std::vector<int>& closed) {
  uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
  modbus_set_socket(tcp_ctx_, fd);
  const int len = modbus_receive(tcp_ctx_, query);
  if (len <= 0) {
    if (len < 0) closed.push_back(fd);
    return;
  }
  const int header = modbus_get_header_length(tcp_ctx_);
  if (IoSim* io = io_for(query[header - 1], true)) {
    if (const int code = injector_.take_exception()) {
      modbus_reply_exception(tcp_ctx_, query, static_cast<unsigned>(code));
    } else {
      reply_io(*io, tcp_ctx_, query, len);
    }
    return;
  }
  if (vfd_ && vfd_tcp_ && query[header - 1] == vfd_unit_) {
    if (const int code = injector_.take_exception()) {
      modbus_reply_exception(tcp_ctx_, query, static_cast<unsigned>(code));
    } else {
      reply_vfd(tcp_ctx_, query, len, header);
    }
    return;
  }
  SimDrive* d = drive_for(tcp_, query[header - 1]);
  const double delay = injector_.reply_delay_s(cnc::util::monotonic_s());
  if (delay > 0) sleep_until_mono(cnc::util::monotonic_s() + delay);
  if (d == nullptr) {
    modbus_reply_exception(tcp_ctx_, query, MODBUS_EXCEPTION_GATEWAY_TARGET);
    return;
  }
  if (const int code = injector_.take_exception()) {
    modbus_reply_exception(tcp_ctx_, query, static_cast<unsigned>(code));
    return;
  }
  world_->advance_to(cnc::util::monotonic_s());  // the reply reads the registers as they are at this moment
  modbus_reply(tcp_ctx_, query, len, d->emulator().mapping());
  after_reply(*d, query + header);
}

void Simulator::answer_rtu(const uint8_t* frame, int len, double rx_end_s) {
  SimDrive* d = drive_for(rtu_, frame[0]);
  const bool vfd = vfd_ && !vfd_tcp_ && frame[0] == vfd_unit_;
  IoSim* io = io_for(frame[0], false);
  if (d == nullptr && !vfd && io == nullptr) return;  // another unit's request: on a real line nobody here answers
  // The reply is built into a socket pair first: its length sets the line time,
  // and a CRC injection corrupts it before it goes out.
  modbus_set_slave(rtu_ctx_, frame[0]);
  modbus_set_socket(rtu_ctx_, capture_[0]);
  if (const int code = injector_.take_exception()) {
    modbus_reply_exception(rtu_ctx_, frame, static_cast<unsigned>(code));
  } else if (io) {
    reply_io(*io, rtu_ctx_, frame, len);
  } else if (vfd) {
    reply_vfd(rtu_ctx_, frame, len, 1);
  } else {
    world_->advance_to(cnc::util::monotonic_s());  // the reply reads the registers as they are at this moment
    modbus_reply(rtu_ctx_, frame, len, d->emulator().mapping());
    after_reply(*d, frame + 1);
  }
  uint8_t reply[MODBUS_RTU_MAX_ADU_LENGTH];
  const ssize_t n = ::read(capture_[1], reply, sizeof reply);
  if (n <= 0) return;
  if (injector_.take_crc()) reply[n - 1] ^= 0x5A;
  double due = rx_end_s + injector_.reply_delay_s(cnc::util::monotonic_s());
  if (line_timing_) due += (3.5 + static_cast<double>(n)) * char_s_;
  sleep_until_mono(due);
  if (::write(serial_fd_, reply, static_cast<size_t>(n)) != n) spdlog::warn("cnc-servo-sim: short write on the serial line");
  line_free_s_ = cnc::util::monotonic_s() + (line_timing_ ? 3.5 * char_s_ : 0.0);
}

void Simulator::serve_rtu_input() {
  uint8_t buf[512];
  const ssize_t n = ::read(serial_fd_, buf, sizeof buf);
  const double now = cnc::util::monotonic_s();
  if (n < 0) {
    if (errno == EAGAIN || errno == EINTR) return;
    // The other end went away (EIO on a pseudo-terminal): reopen it.
    ::close(serial_fd_);
    serial_fd_ = -1;
    rx_.clear();
    return;
  }
  if (rx_.empty()) rx_first_s_ = std::max(now, line_free_s_);
  rx_.insert(rx_.end(), buf, buf + n);
  while (!rx_.empty()) {
    const int need = cnc::servo_sim::rtu_request_length(rx_.data(), static_cast<int>(rx_.size()));
    if (need < 0) {  // not a function this simulator frames: drop the buffer, the master times out
      rx_.clear();
      break;
    }
    if (need == 0 || static_cast<int>(rx_.size()) < need) break;
    const double rx_end = rx_first_s_ + (line_timing_ ? need * char_s_ : 0.0);
    if (injector_.dropped(now)) {
      // Silent line.
    } else if (cnc::servo_sim::rtu_crc_ok(rx_.data(), need)) {
      answer_rtu(rx_.data(), need, rx_end);
    } else {
      spdlog::warn("cnc-servo-sim: request with a bad CRC ignored");
    }
    rx_.erase(rx_.begin(), rx_.begin() + need);
    rx_first_s_ = std::max(cnc::util::monotonic_s(), line_free_s_);
  }
}

void Simulator::serve_vfd_line() {
  uint8_t buf[64];
  const ssize_t n = ::read(vfd_fd_, buf, sizeof buf);
  if (n < 0) {
    if (errno == EAGAIN || errno == EINTR) return;
    ::close(vfd_fd_);  // the other end went away: reopened by housekeeping
    vfd_fd_ = -1;
    vfd_rx_.clear();
    return;
  }
  vfd_rx_.insert(vfd_rx_.end(), buf, buf + n);
  while (!vfd_rx_.empty()) {
    const int need = cnc::drive::huanyang::frame_length(vfd_rx_.data(), static_cast<int>(vfd_rx_.size()));
    if (need < 0) {  // no frame: drop the buffer, the master times out
      vfd_rx_.clear();
      break;
    }
    if (need == 0 || static_cast<int>(vfd_rx_.size()) < need) break;
    uint8_t reply[cnc::drive::huanyang::kMaxFrame];
    step_vfd(cnc::util::monotonic_s());
    const int len = vfd_rx_[0] == vfd_unit_ && !injector_.dropped(cnc::util::monotonic_s())
                        ? vfd_->answer_frame(vfd_rx_.data(), need, reply)
                        : 0;
    if (len > 0) {
      if (injector_.take_crc()) reply[len - 1] ^= 0x5A;
      if (::write(vfd_fd_, reply, static_cast<size_t>(len)) != len)
        spdlog::warn("cnc-servo-sim: short write on the spindle's line");
    }
    vfd_rx_.erase(vfd_rx_.begin(), vfd_rx_.begin() + need);
  }
}

void Simulator::read_control() {
  char buf[256];
  const ssize_t n = ::read(control_fd_, buf, sizeof buf);
  if (n <= 0) return;
  control_buf_.append(buf, static_cast<size_t>(n));
  size_t nl;
  while ((nl = control_buf_.find('\n')) != std::string::npos) {
    const std::string line = control_buf_.substr(0, nl);
    control_buf_.erase(0, nl + 1);
    if (arm_trigger(line) || cut_wire(line) || set_io_point(line)) continue;
    const std::string why = injector_.apply(line, cnc::util::monotonic_s());
    if (why.empty()) {
      spdlog::warn("cnc-servo-sim: injected '{}'", line);
    } else {
      spdlog::error("cnc-servo-sim: control command '{}': {}", line, why);
    }
  }
}

void Simulator::housekeeping(double now) {
  injector_.poll(now);
  poll_triggers();
  poll_limits();
  comm_seen_.resize(all_.size());
  for (size_t i = 0; i < all_.size(); ++i) {
    const SimDrive& d = *all_[i];
    auto& seen = comm_seen_[i];
    if (d.comm_trips() != seen.first) {
      seen.first = d.comm_trips();
      spdlog::warn("cnc-servo-sim: axis {}: communication watchdog: no request for {:.3f} s: quick stop from "
                   "{:.3f} mm at {:.1f} mm/s, {:g} mm/s^2",
                   d.name(), d.comm_timeout_s(), d.comm_stop_x0(), d.comm_stop_v0(), d.comm_decel());
    }
    if (d.comm_faulted() != seen.second) {
      seen.second = d.comm_faulted();
      if (seen.second)
        spdlog::warn("cnc-servo-sim: axis {}: stopped at {:.3f} mm: fault 0x{:04x} (communication lost); a fault "
                     "reset and enable move it again",
                     d.name(), d.position_mm(), SimDrive::kCommFaultCode);
    }
  }
  if (tcp_ctx_ != nullptr) {
    if (injector_.dropped(now) && listen_fd_ >= 0) {
      spdlog::warn("cnc-servo-sim: dropping every connection");
      close_tcp();
    } else if (!injector_.dropped(now) && listen_fd_ < 0) {
      open_listener();
      spdlog::info("cnc-servo-sim: listening again");
    }
  }
  if (!rtu_.empty() && serial_fd_ < 0) serial_fd_ = open_serial(device_, baud_);
  if (vfd_ && !vfd_device_.empty() && vfd_fd_ < 0) vfd_fd_ = open_serial(vfd_device_, cfg_.spindle.drive.baud);
  follows_seen_.resize(all_.size(), false);
  for (size_t i = 0; i < all_.size(); ++i) {
    // Each drive's power stage: following (enabled) or not, with where it stands then.
    const bool f = all_[i]->follows();
    if (f == follows_seen_[i]) continue;
    follows_seen_[i] = f;
    spdlog::info("cnc-servo-sim: axis {}: {} at {:.4f} mm, {:.3f} mm/s, utime {}", all_[i]->name(),
                 f ? "enabled" : "disabled", all_[i]->position_mm(), all_[i]->velocity_mm_s(), cnc::util::wall_utime());
  }
  if (vfd_ && (vfd_->running() != vfd_logged_run_ || std::fabs(vfd_->command_hz() - vfd_logged_hz_) > 1e-9)) {
    vfd_logged_run_ = vfd_->running();
    vfd_logged_hz_ = vfd_->command_hz();
    spindle_log(vfd_logged_run_, vfd_logged_hz_, vfd_->output_hz());
  }
  const bool trace_row = writer_->tracing() && now >= next_trace_s_;
  if (trace_row || now >= next_persist_s_) {
    if (trace_row) next_trace_s_ = now + 0.01;
    if (now >= next_persist_s_) next_persist_s_ = now + 0.05;
    SideWriter::Sample smp;
    smp.wall_s = wall_s();
    smp.world_s = smp.wall_s - world_->stood_s();
    smp.trace = trace_row;
    for (size_t i = 0; i < all_.size(); ++i) {
      smp.pos[i] = all_[i]->position_mm();
      smp.vel[i] = all_[i]->velocity_mm_s();
      smp.on[i] = all_[i]->follows();
    }
    writer_->push(smp);
  }
}

int Simulator::run() {
  const bool io_tcp = std::any_of(ios_.begin(), ios_.end(), [](const IoSim& io) { return io.tcp; });
  if (!tcp_.empty() || (vfd_ && vfd_tcp_) || io_tcp) {
    tcp_ctx_ = modbus_new_tcp(bind_.c_str(), port_);
    if (tcp_ctx_ == nullptr) throw std::runtime_error("cannot create a Modbus TCP context");
    open_listener();
    spdlog::info("cnc-servo-sim: {} drive(s) on tcp://{}:{}", tcp_.size(), bind_, port_);
  }
  if (!rtu_.empty()) {
    rtu_ctx_ = modbus_new_rtu(device_.c_str(), baud_, 'N', 8, 1);
    if (rtu_ctx_ == nullptr || socketpair(AF_UNIX, SOCK_STREAM, 0, capture_) != 0)
      throw std::runtime_error("cannot set up the RTU reply path");
    serial_fd_ = open_serial(device_, baud_);
    if (serial_fd_ < 0) throw std::runtime_error("cannot open " + device_ + ": " + std::strerror(errno));
    spdlog::info("cnc-servo-sim: {} drive(s) on rtu://{} at {} baud ({} line timing)", rtu_.size(), device_, baud_,
                 line_timing_ ? "real" : "no");
  }
  for (SimDrive* d : all_)
    spdlog::info("cnc-servo-sim: axis {} unit {} profile {} at {:.4f} mm", d->name(), d->unit(),
                 d->emulator().profile().name, d->position_mm());
  if (vfd_ && !vfd_device_.empty()) {
    vfd_fd_ = open_serial(vfd_device_, cfg_.spindle.drive.baud);
    if (vfd_fd_ < 0) throw std::runtime_error("cannot open " + vfd_device_ + ": " + std::strerror(errno));
  }
  if (vfd_)
    spdlog::info("cnc-servo-sim: spindle unit {} profile {}: time constant {:g} s{}{}", vfd_unit_, vfd_->profile().name,
                 cfg_.spindle.sim.time_constant_s, vfd_device_.empty() ? "" : " on ", vfd_device_);
  for (const IoSim& io : ios_)
    spdlog::info("cnc-servo-sim: io {} unit {}: {} coils, {} discrete inputs, {} input and {} holding registers",
                 io.emu->name(), io.unit, io.emu->mapping()->nb_bits, io.emu->mapping()->nb_input_bits,
                 io.emu->mapping()->nb_input_registers, io.emu->mapping()->nb_registers);
  if (!args_.option("control").empty()) {
    const std::string path = args_.option("control");
    if (!std::filesystem::exists(path) && mkfifo(path.c_str(), 0600) != 0)
      throw std::runtime_error("cannot create the control FIFO " + path + ": " + std::strerror(errno));
    control_fd_ = ::open(path.c_str(), O_RDONLY | O_NONBLOCK);
    // Our own writer keeps the FIFO from signalling end-of-file between writers.
    control_keep_fd_ = ::open(path.c_str(), O_WRONLY | O_NONBLOCK);
    if (control_fd_ < 0) throw std::runtime_error("cannot open the control FIFO " + path);
  }
  {
    if (all_.size() > SideWriter::kMaxAxes) throw std::runtime_error("more simulated drives than the trace holds");
    std::vector<std::string> names;
    for (const SimDrive* d : all_) names.push_back(d->name());
    writer_ = std::make_unique<SideWriter>(names, args_.option("trace"), args_.option("persist"));
  }
  if (const char* f = std::getenv("CNC_SIM_DEBUG_TRACE")) {
    dbg_.file = f;
    dbg_.steps.reserve(400000);
    dbg_.writes.reserve(1200000);
  }
  cnc::util::apply_realtime("cnc-servo-sim", cfg_.realtime_priority, cfg_.realtime_cpus);

  // Cycle timing of the dynamics grid: how late a due step starts (wake-up latency)
  // and how long the step with the housekeeping takes (compute).
  cnc::util::LatencyHistogram lat_wake, lat_compute;
  int64_t lat_overruns = 0;
  next_step_s_ = cnc::util::monotonic_s();
  while (!cnc::util::stop_requested()) {
    const double woke = cnc::util::monotonic_s();
    const bool due = woke >= next_step_s_;
    if (due) {
      lat_wake.record_s(woke - next_step_s_);
      if (woke - next_step_s_ >= dt_) ++lat_overruns;
    }
    step_dynamics();
    const double now = cnc::util::monotonic_s();
    housekeeping(now);
    if (due) lat_compute.record_s(cnc::util::monotonic_s() - woke);
    fd_set rd;
    FD_ZERO(&rd);
    int maxfd = -1;
    auto watch = [&](int fd) {
      if (fd < 0) return;
      FD_SET(fd, &rd);
      maxfd = std::max(maxfd, fd);
    };
    watch(listen_fd_);
    for (int fd : clients_) watch(fd);
    watch(serial_fd_);
    watch(vfd_fd_);
    watch(control_fd_);
    const double wait = std::clamp(next_step_s_ - cnc::util::monotonic_s(), 0.0, 0.01);
    timeval tv{0, static_cast<suseconds_t>(wait * 1e6)};
    const int n = select(maxfd + 1, &rd, nullptr, nullptr, &tv);
    if (n <= 0) continue;
    // Before any request is served: a stall of this process inside select() (it
    // was asleep there when the VM paused it) must pause the simulated world before
    // a request steps the drives across the lost time.
    step_dynamics();
    if (control_fd_ >= 0 && FD_ISSET(control_fd_, &rd)) read_control();
    if (listen_fd_ >= 0 && FD_ISSET(listen_fd_, &rd)) {
      int fd = listen_fd_;
      const int c = modbus_tcp_accept(tcp_ctx_, &fd);
      if (c >= 0) clients_.push_back(c);
    }
    std::vector<int> closed;
    for (int fd : std::vector<int>(clients_)) {
      if (FD_ISSET(fd, &rd)) serve_tcp_client(fd, closed);
    }
    for (int fd : closed) {
      ::close(fd);
      clients_.erase(std::remove(clients_.begin(), clients_.end(), fd), clients_.end());
    }
    if (serial_fd_ >= 0 && FD_ISSET(serial_fd_, &rd)) serve_rtu_input();
    if (vfd_fd_ >= 0 && FD_ISSET(vfd_fd_, &rd)) serve_vfd_line();
  }

  // The last positions reach the persisted file before the writer ends.
  {
    SideWriter::Sample smp;
    smp.wall_s = wall_s();
    for (size_t i = 0; i < all_.size(); ++i) smp.pos[i] = all_[i]->position_mm();
    writer_->push(smp);
  }
  if (writer_->dropped() > 0) spdlog::warn("cnc-servo-sim: {} trace samples dropped (the writer fell behind)", writer_->dropped());
  writer_.reset();
  {
    cnc::util::LatencyReport lat;
    lat.service = "cnc-servo-sim";
    lat.loop = "dynamics step (T_servo grid, select() wake-ups)";
    lat.period_s = dt_;
    lat.cycles = lat_wake.count();
    lat.overruns = lat_overruns;
    lat.overruns_what = "steps started a whole period late or more";
    lat.wake_what = "wake-up latency: loop start minus the due step's time";
    lat.compute_what = "compute: the due steps and the housekeeping";
    lat.wake = &lat_wake;
    lat.compute = &lat_compute;
    cnc::util::report_latency(lat, cnc::util::latency_dir(args_.option("latency-dir")));
  }
  if (!dbg_.file.empty()) {
    FILE* f = std::fopen(dbg_.file.c_str(), "w");
    if (f) {
      std::fprintf(f, "mono,grid,shifted");
      for (int i = 0; i < DebugTrace::kAx; ++i) std::fprintf(f, ",dem%d,act%d,vel%d,fe%d,ahead%d", i, i, i, i, i);
      std::fprintf(f, "\n");
      for (const auto& st : dbg_.steps) {
        std::fprintf(f, "%.6f,%.6f,%.6f", st.mono, st.grid, st.shifted);
        for (int i = 0; i < DebugTrace::kAx; ++i)
          std::fprintf(f, ",%.6f,%.6f,%.3f,%.6f,%.6f", st.demand[i], st.actual[i], st.vel[i], st.fe[i], st.ahead[i]);
        std::fprintf(f, "\n");
      }
      std::fclose(f);
    }
    f = std::fopen((dbg_.file + ".writes").c_str(), "w");
    if (f) {
      std::fprintf(f, "mono,unit,target,ahead\n");
      for (const auto& w : dbg_.writes) std::fprintf(f, "%.6f,%d,%.6f,%.6f\n", w.mono, w.axis, w.target, w.ahead);
      std::fclose(f);
    }
  }
  const std::string report = positions_json(all_);
  if (stalls_ > 0)
    spdlog::warn("cnc-servo-sim: the process stalled {} time(s) over {} ms; the simulated drives paused with it", stalls_,
                 static_cast<int64_t>(stalled_s_ * 1e3));
  spdlog::info("cnc-servo-sim: the master's stream ran dry {} time(s), {:.1f} ms in all, the longest {:.1f} ms; the "
               "simulated world stood meanwhile (--master-stall-pause-s)",
               world_->pauses(), world_->paused_s() * 1e3, world_->longest_pause_s() * 1e3);
  spdlog::info("cnc-servo-sim: final positions {}", report);
  if (!args_.option("final-state").empty()) std::ofstream(args_.option("final-state")) << report << "\n";
  return cnc::service::kExitOk;
}

int run_sim(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
  Simulator sim(cfg, args);
  return sim.run();
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{"cnc-servo-sim",
                          "Modbus TCP / RTU servo drive simulator",
                          {{"port", "P", "the TCP axes' port (default: the config's)", true},
                           {"bind", "ADDR", "the TCP address to listen on (default 127.0.0.1)"},
                           {"device", "PTY", "the RTU axes' serial line (the simulator's end)"},
                           {"spindle-device", "PTY", "a Huanyang spindle VFD's own line (the simulator's end)"},
                           {"rtu-timing", "real|none", "hold RTU replies as long as a real line takes (default real)"},
                           {"control", "FIFO", "fault injection commands read from FIFO"},
                           {"inject", "\"T:CMD; ...\"", "fault injection at given times"},
                           {"trace", "CSV", "the axes every 10 ms"},
                           {"persist", "FILE", "keep the positions in FILE (every 50 ms) and start from them"},
                           {"final-state", "FILE", "the final positions (JSON) at the end"},
                           {"latency-dir", "DIR", "where the simulation loop's timing goes at the end (cnc-servo-sim.json; default $CNC_LATENCY_DIR)"},
                           {"master-stall-pause-s", "S",
                            "how long a master's dry stream stops the simulated world (default "
                            "timing.setpoint_timeout_s; 0: never)", true}},
                          {}};
  return cnc::service::run(spec, argc, argv, run_sim);
}
