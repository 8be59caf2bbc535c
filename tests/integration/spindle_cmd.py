#!/usr/bin/env python3
"""A spindle orientation sent to a live cell's bridge as the interpolator would send it.

  spindle_cmd.py --port P --prefix PFX --py DIR [--key FILE] --orient DEG [--mode 0|1|2] [--timeout S]

The interpolator does not carry out M19 yet, so this sends SPINDLE_CMD itself: an
orientation to DEG degrees (mode 0 shortest way, 1 clockwise, 2 counterclockwise) with
a command_seq newer than any the interpolator made (the wall clock in microseconds; the
interpolator's are its stream's start plus its count of changes), signed with the cell's
key (FILE, as common/bus/auth.h signs), again every 0.1 s as the interpolator repeats its
commands. It listens to SPINDLE_STATUS (the generated Python types in DIR) and prints,
once the bridge answers that command_seq with ORIENTED or ORIENT_FAULT:

  orient: STATE after T s at ANGLE deg (position P rev, valid V) fault: TEXT

and, after ORIENTED, where the bridge's loop holds it 0.5 s later:

  held: at ANGLE deg, STATE

Exit 0 on ORIENTED, 1 on ORIENT_FAULT or no answer within the timeout.
"""
import argparse
import hashlib
import hmac
import random
import socket
import struct
import sys
import time

GROUP = "239.255.76.67"
MAGIC = b"CNM\x01"


def read_key(path):
    """The key that signs now: (id bytes, secret) of the latest SIGN_FROM not in the future."""
    now = time.time() * 1e6
    best = None
    for line in open(path):
        w = line.split()
        if len(w) != 5 or w[0] != "key":
            continue
        kid, secret, sign_from = bytes.fromhex(w[1]), bytes.fromhex(w[2]), int(w[3])
        if sign_from <= now and (best is None or sign_from >= best[2]):
            best = (kid, secret, sign_from)
    if best is None:
        sys.exit(f"spindle_cmd: no key in {path} signs now")
    return best[0], best[1]


def signed(channel, payload, key):
    if key is None:
        return payload
    kid, secret = key
    msg = struct.pack(">I", len(channel)) + channel.encode() + payload + kid + MAGIC
    tag = hmac.new(secret, msg, hashlib.sha512).digest()[:32]  # HMAC-SHA-512-256 (libsodium's crypto_auth)
    return payload + kid + tag + MAGIC


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--prefix", required=True)
    ap.add_argument("--py", required=True)
    ap.add_argument("--key")
    ap.add_argument("--orient", type=float, required=True)
    ap.add_argument("--mode", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=10.0)
    a = ap.parse_args()
    sys.path.insert(0, a.py)
    from cnc import lcmt_spindle_command, lcmt_spindle_status  # noqa: E402

    key = read_key(a.key) if a.key else None
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    rx.bind(("", a.port))
    rx.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, socket.inet_aton(GROUP) + socket.inet_aton("0.0.0.0"))
    rx.settimeout(0.02)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
    tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)

    cmd_ch, st_ch = a.prefix + "SPINDLE_CMD", a.prefix + "SPINDLE_STATUS"
    sender = random.randrange(1 << 30)
    seqno = random.randrange(1 << 30)
    command_seq = int(time.time() * 1e6)
    msg_seq = 0
    t0 = time.monotonic()
    next_send = t0
    while time.monotonic() < t0 + a.timeout:
        if time.monotonic() >= next_send:
            m = lcmt_spindle_command()
            msg_seq += 1
            m.utime, m.seq, m.sender = int(time.time() * 1e6), msg_seq, sender
            m.command_seq, m.direction, m.rpm = command_seq, 0, 0.0
            m.orient, m.orient_deg, m.orient_mode = True, a.orient, a.mode
            seqno += 1
            data = struct.pack(">II", 0x4C433032, seqno) + cmd_ch.encode() + b"\0" + signed(cmd_ch, m.encode(), key)
            tx.sendto(data, (GROUP, a.port))
            next_send += 0.1
        try:
            data, _ = rx.recvfrom(65536)
        except socket.timeout:
            continue
        if len(data) < 8 or struct.unpack_from(">I", data, 0)[0] != 0x4C433032:
            continue
        end = data.index(b"\0", 8)
        if data[8:end].decode() != st_ch:
            continue
        payload = data[end + 1:]
        if payload.endswith(MAGIC):
            payload = payload[:-40]
        s = lcmt_spindle_status.decode(payload)
        if s.command_seq != command_seq or s.orient_state not in (s.ORIENTED, s.ORIENT_FAULT):
            continue
        angle = (s.position_rev % 1.0) * 360.0
        state = "ORIENTED" if s.orient_state == s.ORIENTED else "ORIENT_FAULT"
        print(f"orient: {state} after {time.monotonic() - t0:.3f} s at {angle:.4f} deg "
              f"(position {s.position_rev:.6f} rev, valid {int(s.position_valid)}) fault: {s.fault}", flush=True)
        if s.orient_state != s.ORIENTED:
            sys.exit(1)
        held, until = s, time.monotonic() + 0.5
        while time.monotonic() < until:
            try:
                data, _ = rx.recvfrom(65536)
            except socket.timeout:
                continue
            if len(data) >= 8 and struct.unpack_from(">I", data, 0)[0] == 0x4C433032:
                end = data.index(b"\0", 8)
                if data[8:end].decode() == st_ch:
                    held = lcmt_spindle_status.decode(data[end + 1:])
        print(f"held: at {(held.position_rev % 1.0) * 360.0:.4f} deg, "
              f"{'ORIENTED' if held.orient_state == held.ORIENTED else held.orient_state}", flush=True)
        sys.exit(0)
    print(f"orient: no answer to command_seq {command_seq} within {a.timeout:.1f} s", flush=True)
    sys.exit(1)


if __name__ == "__main__":
    main()
