#!/usr/bin/env python3
"""A stranger on the cell's network: a plain UDP socket, no key.

  stranger.py attack --group G --port P --prefix PFX --py DIR --out FILE.json
      Joins the multicast group, sniffs the cell's datagrams until it has seen a
      START on PROGRAM_CMD and 0.3 s of SETPOINTS, then sends, each N times:
        unsigned   STOP, HOLD, OVERRIDE 1.5, LOAD /etc/shadow (PROGRAM_CMD), a setpoint
                   100 mm off in X and Y (SETPOINTS), DISABLE (DRIVE_CMD): fresh time
                   stamps, the real senders' ids (masquerade), new sequence numbers
        forged     the same with a signature trailer under the cell's key id (sniffed)
                   and a made-up tag; and captured signed datagrams with one payload
                   bit changed (corruption)
        unknown    the same with a trailer under a key id the cell does not have
        replayed   captured signed datagrams (PROGRAM_CMD LOAD/START, SETPOINTS,
                   PROGRAM_BLOCKS, BLOCK_REQUEST, INTERP_INPUT), unchanged, >= 50 ms
                   after their capture (repetition, wrong order)
        delayed    the first setpoints captured, sent again 2.5 s later (delay)
      and writes what it sent per channel and kind into FILE.json.

  stranger.py check --log LOG --py DIR --sent FILE.json --prefix PFX
      Reads the cell's log (LCM log format) with the generated Python types and
      checks: the commands the interpolator applied (INTERP_INPUT) hold no STOP,
      HOLD or OVERRIDE and one START; no PROGRAM_STATE names /etc/shadow; every
      receiver's last heartbeat counts, per attacked channel it subscribes to, as
      many drops per cause as the stranger sent; ALARMs bus_* exist for every cause
      and come at most once a second per service and cause. Prints the figures.
"""
import argparse
import json
import os
import random
import socket
import struct
import sys
import time

import lcmlog

TRAILER_MAGIC = b"CNM\x01"
TRAILER = 4 + 32 + 4
N = 10  # of each message and kind


def lcm_datagram(seqno, channel, payload):
    return struct.pack(">II", 0x4C433032, seqno) + channel.encode() + b"\0" + payload


def parse_datagram(data):
    if len(data) < 8:
        return None
    magic, _ = struct.unpack_from(">II", data, 0)
    if magic != 0x4C433032:
        return None  # fragmented (large) messages are not needed here
    end = data.index(b"\0", 8)
    return data[8:end].decode(), data[end + 1:]


def header(payload):
    return struct.unpack_from(">qqi", payload, 8)


def attack(a):
    sys.path.insert(0, a.py)
    from cnc import lcmt_program_command, lcmt_setpoint, lcmt_drive_command  # noqa: E402

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    rx.bind(("", a.port))
    rx.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                  socket.inet_aton(a.group) + socket.inet_aton("0.0.0.0"))
    rx.settimeout(0.05)
    # The test starts the program only after this line: a START sent before the
    # group was joined would never be seen (Python's start-up is slow on a loaded VM).
    print("stranger: listening", flush=True)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
    tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)

    captured = {}   # channel -> [(time, payload)]
    senders = {}    # channel -> a real sender id
    key_id = None
    start_seen = None
    deadline = time.monotonic() + a.timeout

    def sniff(until):
        nonlocal key_id, start_seen
        while time.monotonic() < until:
            try:
                data, _ = rx.recvfrom(65536)
            except socket.timeout:
                continue
            p = parse_datagram(data)
            if p is None:
                continue
            ch, payload = p
            if not ch.startswith(a.prefix):
                continue
            captured.setdefault(ch, []).append((time.monotonic(), payload))
            senders.setdefault(ch, header(payload)[2])
            if payload.endswith(TRAILER_MAGIC):
                key_id = payload[-TRAILER:-TRAILER + 4]
            if ch == a.prefix + "PROGRAM_CMD" and start_seen is None:
                m = lcmt_program_command.decode(payload)
                if m.command == lcmt_program_command.START:
                    start_seen = time.monotonic()
            if start_seen is not None and time.monotonic() > start_seen + 0.3:
                return True
        return False

    if not sniff(deadline):
        sys.exit("stranger: saw no START on %sPROGRAM_CMD within %.0f s" % (a.prefix, a.timeout))
    if key_id is None:
        sys.exit("stranger: the cell's datagrams carry no signature trailer")
    unknown_id = bytes(b ^ 0x5A for b in key_id)

    sent = {}  # channel -> kind -> count
    seqno = random.randrange(1 << 30)

    def send(ch, payload, kind):
        nonlocal seqno
        seqno += 1
        tx.sendto(lcm_datagram(seqno, ch, payload), (a.group, a.port))
        sent.setdefault(ch, {}).setdefault(kind, 0)
        sent[ch][kind] += 1
        time.sleep(0.002)

    def stamp(m, ch, i):
        m.utime = int(time.time() * 1e6)
        m.sender = senders.get(ch, 4242)  # masquerade as the channel's real sender
        m.seq = 10_000_000 + i           # "newer" than anything the real sender sent
        return m

    cmd_ch, sp_ch, dc_ch = a.prefix + "PROGRAM_CMD", a.prefix + "SETPOINTS", a.prefix + "DRIVE_CMD"

    def made_up(i):
        out = []
        for c, path, ov in ((lcmt_program_command.STOP, "", 0.0), (lcmt_program_command.HOLD, "", 0.0),
                            (lcmt_program_command.OVERRIDE, "", 1.5),
                            (lcmt_program_command.LOAD, "/etc/shadow", 0.0)):
            m = lcmt_program_command()
            m.command, m.program_path, m.feed_override, m.num_axes, m.position_mm = c, path, ov, 0, []
            out.append((cmd_ch, stamp(m, cmd_ch, i).encode()))
        sp = lcmt_setpoint.decode(captured[sp_ch][-1][1]) if sp_ch in captured else lcmt_setpoint()
        sp.cycle += 100
        sp.position_mm = [sp.position_mm[0] + 100.0, sp.position_mm[1] + 100.0] + list(sp.position_mm[2:])
        out.append((sp_ch, stamp(sp, sp_ch, i).encode()))
        d = lcmt_drive_command()
        d.command = lcmt_drive_command.DISABLE
        out.append((dc_ch, stamp(d, dc_ch, i).encode()))
        return out

    for i in range(N):
        for ch, payload in made_up(i):
            send(ch, payload, "unsigned")
            send(ch, payload + key_id + os.urandom(32) + TRAILER_MAGIC, "forged")
            send(ch, payload + unknown_id + os.urandom(32) + TRAILER_MAGIC, "unknown_key")
    # Replays and corruptions of what the cell itself sent (captured >= 50 ms ago).
    sniff(time.monotonic() + 0.2)
    cutoff = time.monotonic() - 0.05
    for base in ("PROGRAM_CMD", "SETPOINTS", "PROGRAM_BLOCKS", "BLOCK_REQUEST", "INTERP_INPUT"):
        ch = a.prefix + base
        old = [p for (t, p) in captured.get(ch, []) if t < cutoff and p.endswith(TRAILER_MAGIC)]
        for payload in old[-N:]:
            send(ch, payload, "replayed")
            bad = bytearray(payload)
            bad[40] ^= 0x10  # one bit of the payload: corruption
            send(ch, bytes(bad), "forged")
    # Delay: the first setpoints captured, sent again once they are 2.5 s old (more
    # than the cell's 2 s freshness window): dropped as stale.
    first = [(t, p) for (t, p) in captured.get(sp_ch, []) if p.endswith(TRAILER_MAGIC)][:N]
    if first:
        time.sleep(max(0.0, first[-1][0] + 2.5 - time.monotonic()))
        for _t, payload in first:
            send(sp_ch, payload, "delayed")
    json.dump({"sent": sent, "key_id": key_id.hex()}, open(a.out, "w"), indent=1)
    total = sum(sum(k.values()) for k in sent.values())
    print("stranger: sent %d datagrams: %s" % (total, json.dumps(sent, sort_keys=True)))


def check(a):
    sys.path.insert(0, a.py)
    from cnc import lcmt_heartbeat, lcmt_alarm, lcmt_interp_input, lcmt_program_state, lcmt_program_command  # noqa
    sent = json.load(open(a.sent))["sent"]
    hb, alarms, applied, states = {}, [], [], []
    for _ts, ch, payload in lcmlog.events(a.log):
        base = ch[len(a.prefix):]
        if base == "HEARTBEAT":
            m = lcmt_heartbeat.decode(payload)
            hb[m.service] = m
        elif base == "ALARM":
            alarms.append(lcmt_alarm.decode(payload))
        elif base == "INTERP_INPUT":
            m = lcmt_interp_input.decode(payload)
            if m.kind == lcmt_interp_input.COMMAND:
                applied.append(m.command.command)
        elif base == "PROGRAM_STATE":
            states.append(lcmt_program_state.decode(payload))
    failures = []
    C = lcmt_program_command
    for bad in (C.STOP, C.HOLD, C.OVERRIDE):
        if bad in applied:
            failures.append("the interpolator applied command %d" % bad)
    if applied.count(C.START) != 1:
        failures.append("the interpolator applied %d STARTs (expected 1)" % applied.count(C.START))
    if any("shadow" in (s.program_path + s.error) for s in states):
        failures.append("the program server acted on LOAD /etc/shadow")
    # Per receiver and attacked channel: drops by cause against what was sent.
    subscribed = {
        "cnc-logger": None,  # every channel
        "cnc-program-server": {"PROGRAM_CMD", "BLOCK_REQUEST"},
        "cnc-interpolator": {"PROGRAM_CMD", "PROGRAM_BLOCKS"},
        "cnc-drive-bridge": {"SETPOINTS", "DRIVE_CMD"},
        "cnc-monitor": {"SETPOINTS", "INTERP_INPUT"},
    }
    print("%-18s %-16s %8s %8s %8s %8s %8s   %s" % ("receiver", "channel", "unsigned", "forged", "unkn.key",
                                                     "replayed", "stale", "sent u/f/k/r/d  accepted-of-stranger"))
    for service, chans in subscribed.items():
        m = hb.get(service)
        if m is None:
            failures.append("no heartbeat from %s" % service)
            continue
        for ch, kinds in sorted(sent.items()):
            base = ch[len(a.prefix):]
            if chans is not None and base not in chans:
                continue
            i = m.channel.index(ch) if ch in m.channel else -1
            got = [0, 0, 0, 0, 0] if i < 0 else [m.rejected_unsigned[i], m.rejected_forged[i],
                                                  m.rejected_unknown_key[i], m.rejected_replayed[i],
                                                  m.rejected_stale[i]]
            want = [kinds.get("unsigned", 0), kinds.get("forged", 0), kinds.get("unknown_key", 0),
                    kinds.get("replayed", 0), kinds.get("delayed", 0)]
            print("%-18s %-16s %8d %8d %8d %8d %8d   %d/%d/%d/%d/%d  %d" % (service[4:], base, *got, *want,
                                                                         sum(want) - sum(got)))
            if got != want:
                failures.append("%s on %s counted %s dropped, the stranger sent %s" % (service, base, got, want))
    # Alarms: every cause raised, at most one a second per service and cause.
    by = {}
    for al in alarms:
        if al.code.startswith("bus_"):
            by.setdefault((al.source, al.code), []).append(al.utime)
    for cause in ("bus_unsigned", "bus_forged", "bus_unknown_key", "bus_replayed", "bus_stale"):
        n = sum(len(v) for (s, c), v in by.items() if c == cause)
        print("alarms %-16s %d (from %d services)" % (cause, n, sum(1 for (s, c) in by if c == cause)))
        if n == 0:
            failures.append("no %s alarm" % cause)
    for (s, c), times in by.items():
        times.sort()
        for t0, t1 in zip(times, times[1:]):
            if t1 - t0 < 990_000:
                failures.append("%s raised %s twice within %.3f s" % (s, c, (t1 - t0) / 1e6))
    print("alarms bus_* total %d" % sum(len(v) for v in by.values()))
    for f in failures:
        print("FAIL: " + f, file=sys.stderr)
    sys.exit(1 if failures else 0)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("mode", choices=["attack", "check"])
    p.add_argument("--group", default="239.255.76.67")
    p.add_argument("--port", type=int)
    p.add_argument("--prefix", required=True)
    p.add_argument("--py", required=True)
    p.add_argument("--out")
    p.add_argument("--timeout", type=float, default=30)
    p.add_argument("--log")
    p.add_argument("--sent")
    a = p.parse_args()
    attack(a) if a.mode == "attack" else check(a)


if __name__ == "__main__":
    main()
