#!/usr/bin/python3
"""Servo drives emulated with pymodbus (Debian's python3-pymodbus), for the drive
bridge's interoperation test: a Modbus TCP server written by somebody else than
this project, serving one or more units with the register map of a drive profile
(config/drives/*.yaml: sim or leadshine state machine), and moving each axis's
actual position toward its target at a limited speed while the drive is enabled.

  bridge_pymodbus_drive.py --port P --profile FILE --units 1,2,3 [--start mm] [--final FILE]

On SIGTERM it writes {"unit": position_mm, ...} to --final and exits 0.
The state machines are written here from the profiles' documentation, not taken
from the project's C++ code."""
import argparse
import asyncio
import json
import logging
import os
import signal
import sys

import yaml
from pymodbus.datastore import ModbusServerContext, ModbusSlaveContext, ModbusSparseDataBlock
from pymodbus.server import StartAsyncTcpServer

SPEED_MM_S = 300.0  # the emulated axis's speed limit
STEP_S = 0.002


class Field:
    def __init__(self, spec):
        self.address = int(spec["address"])
        self.words = int(spec.get("words", 1))
        self.signed = bool(spec.get("signed", False))
        self.high_first = spec.get("word_order", "low_first") == "high_first"
        self.scale = float(spec.get("scale", 1.0))

    def regs(self, value_mm):
        raw = int(round(value_mm * self.scale))
        if self.words == 1:
            return [raw & 0xFFFF]
        u = raw & 0xFFFFFFFF
        lo, hi = u & 0xFFFF, u >> 16
        return [hi, lo] if self.high_first else [lo, hi]

    def value(self, regs):
        if self.words == 1:
            raw = regs[0]
            if self.signed and raw >= 0x8000:
                raw -= 0x10000
        else:
            hi, lo = (regs[0], regs[1]) if self.high_first else (regs[1], regs[0])
            raw = (hi << 16) | lo
            if self.signed and raw >= 0x80000000:
                raw -= 0x100000000
        return raw / self.scale


class Drive(ModbusSlaveContext):
    """One unit: holding registers at the profile's addresses only (a read across
    an address the drive does not have is answered with exception 2)."""

    def __init__(self, profile, start_mm):
        self.kind = profile["state_machine"]
        self.f = {name: Field(spec) for name, spec in profile["registers"].items()}
        values = {}
        for field in self.f.values():
            for i in range(field.words):
                values[field.address + i] = 0
        super().__init__(hr=ModbusSparseDataBlock(values), zero_mode=True)
        self.enabled = False
        self.alarm = False
        self.actual = start_mm
        self.last_control = 0
        self._put("target_position", start_mm)
        self.publish()

    def _put(self, name, value):
        field = self.f[name]
        self.store["h"].setValues(field.address, field.regs(value))

    def _get(self, name):
        field = self.f[name]
        return field.value(self.store["h"].getValues(field.address, field.words))

    def setValues(self, fc_as_hex, address, values):  # noqa: N802 (pymodbus' name)
        super().setValues(fc_as_hex, address, values)
        if fc_as_hex not in (6, 16, 23):
            return
        written = range(address, address + len(values))
        cw = self.f["controlword"].address
        if cw in written:
            v = self.store["h"].getValues(cw, 1)[0]
            if self.kind == "sim":
                if v & 0x80 and not self.last_control & 0x80:
                    self.alarm = False
                self.enabled = bool(v & 1) and not self.alarm
            else:  # leadshine: 1 servo on, 0 off
                self.enabled = v == 1 and not self.alarm
            self.last_control = v
        if "fault_reset" in self.f and self.f["fault_reset"].address in written:
            if self.store["h"].getValues(self.f["fault_reset"].address, 1)[0] == 1:
                self.alarm = False
                self.enabled = False
            self.store["h"].setValues(self.f["fault_reset"].address, [0])
        self.publish()

    def publish(self):
        if self.kind == "sim":
            status = 0x08 if self.alarm else (0x01 if self.enabled else 0)
        else:
            status = 0x04 if self.alarm else (0x01 | (0x02 if self.enabled else 0))
        self.store["h"].setValues(self.f["statusword"].address, [status])
        self._put("actual_position", self.actual)

    def step(self, dt):
        if self.enabled:
            d = self._get("target_position") - self.actual
            self.actual += max(-SPEED_MM_S * dt, min(SPEED_MM_S * dt, d))
        self.publish()


async def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--profile", required=True)
    ap.add_argument("--units", default="1")
    ap.add_argument("--start", type=float, default=0.0)
    ap.add_argument("--final", default="")
    ap.add_argument("--state", default="", help="the actual positions, rewritten every 50 ms (JSON by unit)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    profile = yaml.safe_load(open(args.profile))
    if profile["state_machine"] not in ("sim", "leadshine"):
        sys.exit(f"state machine {profile['state_machine']} is not emulated here")
    drives = {int(u): Drive(profile, args.start) for u in args.units.split(",")}
    context = ModbusServerContext(slaves=drives, single=False)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGTERM, stop.set)
    loop.add_signal_handler(signal.SIGINT, stop.set)
    server = await StartAsyncTcpServer(context=context, address=("127.0.0.1", args.port), defer_start=True)
    serving = asyncio.create_task(server.serve_forever())

    async def dynamics():
        # Stepped by the time that really passed: an event loop that ran late (a loaded
        # test machine) catches up at once instead of falling behind its target for
        # good (fixed steps lagged 2.3 mm in 1 of 10 loaded suite runs, a following-
        # error fault that was the emulator's, not the bridge's).
        last = loop.time()
        written = last
        while True:
            now = loop.time()
            for d in drives.values():
                d.step(now - last)
            last = now
            if args.state and now - written >= 0.05:
                written = now
                with open(args.state + ".tmp", "w") as out:
                    json.dump({str(u): d.actual for u, d in drives.items()}, out)
                os.replace(args.state + ".tmp", args.state)
            await asyncio.sleep(STEP_S)

    moving = asyncio.create_task(dynamics())
    print(f"pymodbus drive: {profile['name']} units {sorted(drives)} on 127.0.0.1:{args.port}", flush=True)
    await stop.wait()
    moving.cancel()
    await server.shutdown()
    serving.cancel()
    if args.final:
        with open(args.final, "w") as out:
            json.dump({str(u): d.actual for u, d in drives.items()}, out)


if __name__ == "__main__":
    asyncio.run(main())
