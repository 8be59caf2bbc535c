#pragma once
// The in-process link: drives emulated by DriveEmulator with an ideal axis (the
// actual position is the target once the drive follows), and spindle VFDs emulated
// by VfdEmulator with an ideal motor (at the commanded frequency by the next request;
// its encoder counts the time between requests on the link's clock at the frequency
// it had, the monotonic clock unless a test sets its own). The whole bridge runs on
// it without a simulator or a network, as ros2_control's mock hardware does; tests
// inject link loss, exceptions and drive faults through it.
#include <functional>
#include <map>
#include <memory>

#include "common/drive/drive_emulator.h"
#include "common/drive/io_emulator.h"
#include "common/drive/vfd_emulator.h"
#include "common/drive/link.h"

namespace cnc::drive {

class LoopbackLink final : public Link {
 public:
  LoopbackLink();
  void add_drive(int unit, const DriveProfile& profile, double start_mm);
  DriveEmulator* drive(int unit);
  // A spindle drive (a spindle profile: delta_vfd, huanyang, cia402_velocity) under `unit`;
  // `max_hz`: its frequency at max_rpm; `counts_per_rev`: its encoder's, 0 none.
  void add_vfd(int unit, const DriveProfile& profile, const config::SpindleSimConfig& sim, double max_hz,
               double rpm_per_hz, int64_t counts_per_rev = 0);
  VfdEmulator* vfd(int unit);
  // The clock the spindles' encoders count on (seconds).
  void set_clock(std::function<double()> clock) { clock_ = std::move(clock); }
  // An I/O module (io.modules[module] with its points) under `unit`.
  void add_io_module(int unit, const config::IoConfig& io, int module);
  IoEmulator* io_module(int unit);

  // Fault injection.
  void set_reachable(bool reachable);          // false: the link breaks and cannot be opened
  void inject_exceptions(int count, int code);  // the next `count` transactions answer with `code`
  void inject_timeouts(int count);
  void inject_short_replies(int count);         // the next `count` Huanyang replies lose their last 3 bytes
  void set_stalled(bool stalled);               // the axes and motors stop moving (a blocked axis: following error)
  void set_jammed(int unit, bool jammed);       // that one axis stops moving (a gantry side jammed)

 private:
  int do_open(std::string& error) override;
  void do_close() override {}
  int do_read(int unit, int addr, int n, uint16_t* dest) override;
  int do_write1(int unit, int addr, uint16_t value) override;
  int do_write(int unit, int addr, int n, const uint16_t* src) override;
  int do_write_read(int unit, int waddr, int wn, const uint16_t* src, int raddr, int rn, uint16_t* dest) override;
  int do_read_bits(int unit, int addr, int n, uint8_t* dest, bool discrete_inputs) override;
  int do_write_bit(int unit, int addr, bool on) override;
  int do_write_bits(int unit, int addr, int n, const uint8_t* src) override;
  int do_read_input_registers(int unit, int addr, int n, uint16_t* dest) override;
  int do_frame(const uint8_t* request, int n, uint8_t* reply, int cap, int* got) override;
  int injected();
  void move(DriveEmulator& d);
  void move(VfdEmulator& v);
  void turn(VfdEmulator& v);  // its encoder over the time since the spindles' last request

  std::map<int, std::unique_ptr<DriveEmulator>> drives_;
  std::map<int, std::unique_ptr<VfdEmulator>> vfds_;
  std::map<int, std::unique_ptr<IoEmulator>> ios_;
  bool reachable_ = true;
  int exceptions_left_ = 0;
  int exception_code_ = 0;
  int timeouts_left_ = 0;
  int short_left_ = 0;
  bool stalled_ = false;
  std::map<const DriveEmulator*, bool> jammed_;
  std::function<double()> clock_;
  double vfd_t_ = -1;  // the clock at the spindles' last request
};

}  // namespace cnc::drive
