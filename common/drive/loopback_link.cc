#include "common/drive/loopback_link.h"

#include <modbus.h>

#include <cerrno>

#include "common/util/clock.h"

namespace cnc::drive {

LoopbackLink::LoopbackLink() : Link("loopback"), clock_(util::monotonic_s) {}

void LoopbackLink::add_drive(int unit, const DriveProfile& profile, double start_mm) {
  drives_[unit] = std::make_unique<DriveEmulator>(profile, start_mm);
}

void LoopbackLink::add_vfd(int unit, const DriveProfile& profile, const config::SpindleSimConfig& sim, double max_hz,
                           double rpm_per_hz, int64_t counts_per_rev) {
  vfds_[unit] = std::make_unique<VfdEmulator>(profile, sim, max_hz, rpm_per_hz, counts_per_rev);
}

VfdEmulator* LoopbackLink::vfd(int unit) {
  auto it = vfds_.find(unit);
  return it == vfds_.end() ? nullptr : it->second.get();
}

void LoopbackLink::add_io_module(int unit, const config::IoConfig& io, int module) {
  ios_[unit] = std::make_unique<IoEmulator>(io, module);
}

IoEmulator* LoopbackLink::io_module(int unit) {
  auto it = ios_.find(unit);
  return it == ios_.end() ? nullptr : it->second.get();
}

DriveEmulator* LoopbackLink::drive(int unit) {
  auto it = drives_.find(unit);
  return it == drives_.end() ? nullptr : it->second.get();
}

void LoopbackLink::set_reachable(bool reachable) { reachable_ = reachable; }

void LoopbackLink::inject_exceptions(int count, int code) {
  exceptions_left_ = count;
  exception_code_ = code;
}

void LoopbackLink::inject_timeouts(int count) { timeouts_left_ = count; }

void LoopbackLink::inject_short_replies(int count) { short_left_ = count; }

void LoopbackLink::set_stalled(bool stalled) { stalled_ = stalled; }

int LoopbackLink::do_open(std::string& error) {
  if (reachable_) return 0;
  error = "loopback unreachable (injected)";
  return ECONNREFUSED;
}

int LoopbackLink::injected() {
  if (!reachable_) return ECONNRESET;
  if (timeouts_left_ > 0) {
    --timeouts_left_;
    return ETIMEDOUT;
  }
  if (exceptions_left_ > 0) {
    --exceptions_left_;
    return MODBUS_ENOBASE + exception_code_;
  }
  return 0;
}

void LoopbackLink::move(DriveEmulator& d) {
  // The ideal axis reaches each target by the next write: a read after a write
  // answers the previous command, as a real drive's would.
  const Field& f = d.profile().field(Role::kActualPosition);
  uint16_t regs[2];
  d.read(f.address, 2, regs);
  const auto jam = jammed_.find(&d);
  const bool jammed = jam != jammed_.end() && jam->second;
  d.set_actual(d.follows() && !stalled_ && !jammed ? d.target_mm() : f.decode(regs), 0.0);
}

void LoopbackLink::set_jammed(int unit, bool jammed) {
  if (DriveEmulator* d = drive(unit)) jammed_[d] = jammed;
}

void LoopbackLink::turn(VfdEmulator& v) {
  const double now = clock_();
  if (vfd_t_ >= 0 && !stalled_) v.advance(now - vfd_t_);
  vfd_t_ = now;
}

void LoopbackLink::move(VfdEmulator& v) {
  if (!stalled_) v.settle();
}

int LoopbackLink::do_read(int unit, int addr, int n, uint16_t* dest) {
  if (const int e = injected()) return e;
  if (IoEmulator* m = io_module(unit)) {
    const int x = m->read_registers(addr, n, dest, false);
    return x ? MODBUS_ENOBASE + x : 0;
  }
  if (VfdEmulator* v = vfd(unit)) {
    turn(*v);
    const int x = v->read(addr, n, dest);
    return x ? MODBUS_ENOBASE + x : 0;
  }
  DriveEmulator* d = drive(unit);
  if (d == nullptr) return ETIMEDOUT;
  const int x = d->read(addr, n, dest);
  return x ? MODBUS_ENOBASE + x : 0;
}

int LoopbackLink::do_write1(int unit, int addr, uint16_t value) { return do_write(unit, addr, 1, &value); }

int LoopbackLink::do_write(int unit, int addr, int n, const uint16_t* src) {
  if (const int e = injected()) return e;
  if (IoEmulator* m = io_module(unit)) {
    const int x = m->write_registers(addr, n, src);
    return x ? MODBUS_ENOBASE + x : 0;
  }
  if (VfdEmulator* v = vfd(unit)) {
    turn(*v);
    move(*v);
    const int x = v->write(addr, n, src);
    return x ? MODBUS_ENOBASE + x : 0;
  }
  DriveEmulator* d = drive(unit);
  if (d == nullptr) return ETIMEDOUT;
  move(*d);
  const int x = d->write(addr, n, src);
  return x ? MODBUS_ENOBASE + x : 0;
}

int LoopbackLink::do_write_read(int unit, int waddr, int wn, const uint16_t* src, int raddr, int rn, uint16_t* dest) {
  if (const int e = injected()) return e;
  if (VfdEmulator* v = vfd(unit)) {
    turn(*v);
    move(*v);
    int x = v->write(waddr, wn, src);
    if (x == 0) x = v->read(raddr, rn, dest);
    return x ? MODBUS_ENOBASE + x : 0;
  }
  DriveEmulator* d = drive(unit);
  if (d == nullptr) return ETIMEDOUT;
  move(*d);
  int x = d->write(waddr, wn, src);
  if (x == 0) x = d->read(raddr, rn, dest);
  return x ? MODBUS_ENOBASE + x : 0;
}

int LoopbackLink::do_frame(const uint8_t* request, int n, uint8_t* reply, int, int* got) {
  *got = 0;
  if (const int e = injected()) return e;
  VfdEmulator* v = vfd(request[0]);
  if (v == nullptr) return ETIMEDOUT;
  turn(*v);
  move(*v);
  *got = v->answer_frame(request, n, reply);
  if (short_left_ > 0 && *got > 3) {
    --short_left_;
    *got -= 3;
  }
  return 0;
}

int LoopbackLink::do_read_bits(int unit, int addr, int n, uint8_t* dest, bool discrete_inputs) {
  if (const int e = injected()) return e;
  IoEmulator* m = io_module(unit);
  if (m == nullptr) return drive(unit) || vfd(unit) ? MODBUS_ENOBASE + MODBUS_EXCEPTION_ILLEGAL_FUNCTION : ETIMEDOUT;
  const int x = m->read_bits(addr, n, dest, discrete_inputs);
  return x ? MODBUS_ENOBASE + x : 0;
}

int LoopbackLink::do_write_bit(int unit, int addr, bool on) {
  const uint8_t v = on ? 1 : 0;
  return do_write_bits(unit, addr, 1, &v);
}

int LoopbackLink::do_write_bits(int unit, int addr, int n, const uint8_t* src) {
  if (const int e = injected()) return e;
  IoEmulator* m = io_module(unit);
  if (m == nullptr) return drive(unit) || vfd(unit) ? MODBUS_ENOBASE + MODBUS_EXCEPTION_ILLEGAL_FUNCTION : ETIMEDOUT;
  const int x = m->write_bits(addr, n, src);
  return x ? MODBUS_ENOBASE + x : 0;
}

int LoopbackLink::do_read_input_registers(int unit, int addr, int n, uint16_t* dest) {
  if (const int e = injected()) return e;
  IoEmulator* m = io_module(unit);
  if (m == nullptr) return drive(unit) || vfd(unit) ? MODBUS_ENOBASE + MODBUS_EXCEPTION_ILLEGAL_FUNCTION : ETIMEDOUT;
  const int x = m->read_registers(addr, n, dest, true);
  return x ? MODBUS_ENOBASE + x : 0;
}

}  // namespace cnc::drive
