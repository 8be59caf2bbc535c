#!/usr/bin/python3
"""A Huanyang HY-series spindle VFD emulated with pyserial (Debian's python3-serial),
for the spindle's live test: a counterpart written from the drive's frame format as
LinuxCNC's hy_vfd documents it, not from this project's C++ code.

  huanyang_vfd.py --device PTY [--unit 1] [--max-hz 400] [--rpm-per-hz 60] [--tau 0.2]

Frames: unit, function, length, data, CRC-16 (Modbus's, low byte first).
  0x01 read PDnnn       0x02 write PDnnn      0x03 command (0x01 run forward,
  0x11 run reverse, 0x08 stop; replies with the status byte)
  0x04 status by index (0 set frequency, 1 output frequency, 2 current, 3 rpm)
  0x05 set frequency (0.01 Hz)
The motor follows the frequency with a first-order lag (--tau). Every change of
command prints a line; SIGTERM ends it with status 0."""
import argparse
import math
import signal
import sys
import time

import serial


def crc16(data):
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return bytes([crc & 0xFF, crc >> 8])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", required=True)
    ap.add_argument("--unit", type=int, default=1)
    ap.add_argument("--max-hz", type=float, default=400.0)
    ap.add_argument("--rpm-per-hz", type=float, default=60.0)
    ap.add_argument("--tau", type=float, default=0.2)
    a = ap.parse_args()
    done = []
    signal.signal(signal.SIGTERM, lambda *_: done.append(1))
    line = serial.Serial(a.device, 19200, timeout=0.002)
    pd = {1: 2, 2: 2, 4: 5000, 5: int(round(a.max_hz * 100)), 11: 0, 144: int(round(a.rpm_per_hz * 50))}
    set_raw, run, reverse, hz, amps = 0, False, False, 0.0, 0.0
    frames = resyncs = 0
    buf = bytearray()
    last = time.monotonic()
    print(f"huanyang_vfd: unit {a.unit} on {a.device}, tau {a.tau} s", flush=True)
    while not done:
        buf += line.read(64)
        now = time.monotonic()
        target = 0.0
        if run:
            target = min(set_raw, pd[5]) / 100.0 * (-1 if reverse else 1)
        before = hz
        hz = target + (hz - target) * math.exp(-(now - last) / a.tau)
        accel = abs(hz - before) / max(now - last, 1e-6)
        amps = 2.0 * abs(hz) / a.max_hz + 6.0 * accel / (a.max_hz / a.tau)
        last = now
        while len(buf) >= 3:
            # Out of step (a frame read in part, a byte lost): slide on by one byte until a
            # frame's CRC holds again; clearing the buffer could keep it out of step for good.
            n = buf[2]
            if not 1 <= n <= 8:
                del buf[0]
                resyncs += 1
                continue
            if len(buf) < 5 + n:
                break
            frame = bytes(buf[:5 + n])
            if crc16(frame[:-2]) != frame[-2:]:
                del buf[0]
                resyncs += 1
                continue
            del buf[:5 + n]
            if frame[0] != a.unit:
                continue
            fn, data = frame[1], frame[3:3 + n]
            if fn == 0x01:
                v = pd.get(data[0], 0)
                out = bytes([data[0], v >> 8, v & 0xFF])
            elif fn == 0x02:
                pd[data[0]] = (data[1] << 8) | data[2]
                out = data
            elif fn == 0x03:
                cmd = data[0]
                was = (run, reverse)
                if cmd == 0x08:
                    run = False
                elif cmd in (0x01, 0x11):
                    run, reverse = True, cmd == 0x11
                if (run, reverse) != was:
                    print(f"huanyang_vfd: {'stop' if not run else 'run reverse' if reverse else 'run forward'}"
                          f" at {set_raw / 100:.2f} Hz (output {hz:.2f} Hz)", flush=True)
                status = (0x09 if run else 0) | (0x04 if reverse else 0) | (0x20 if hz < 0 else 0)
                out = bytes([status])
            elif fn == 0x04:
                v = {0: set_raw, 1: round(abs(hz) * 100), 2: round(amps * 10), 3: round(abs(hz) * a.rpm_per_hz)}.get(data[0], 0)
                v = min(int(v), 0xFFFF)
                out = bytes([data[0], v >> 8, v & 0xFF])
            elif fn == 0x05:
                set_raw = (data[0] << 8) | data[1]
                out = data
            else:
                continue
            reply = bytes([a.unit, fn, len(out)]) + out
            line.write(reply + crc16(reply))
            frames += 1
    print(f"huanyang_vfd: {frames} frames answered, {resyncs} bytes skipped to find a frame", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
