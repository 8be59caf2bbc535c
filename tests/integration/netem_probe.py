#!/usr/bin/python3
"""Probe datagrams for cnc-netem's test: numbered, stamped with CLOCK_MONOTONIC
(one clock for every network namespace of this machine).

  netem_probe.py send GROUP PORT COUNT RATE_HZ          one datagram every 1/RATE_HZ s
  netem_probe.py recv GROUP PORT OUT.csv READY_FILE [--first-timeout S]
                                 until 1.5 s without a datagram (the first: S, 20 s; at most
                                 60 s in all); READY_FILE written once joined
  netem_probe.py check OUT.csv COUNT --loss PCT --delay MS --jitter MS [--ordered] [--forwarder-log F]
"""
import argparse
import socket
import struct
import sys
import time

FMT = "!IQ"  # number, send time (ns)
PAD = 100    # a setpoint's size, about


def send(a):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
    period = 1.0 / a.rate
    t0 = time.monotonic()
    for i in range(a.count):
        due = t0 + i * period
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        s.sendto(struct.pack(FMT, i, time.monotonic_ns()).ljust(PAD, b"\0"), (a.group, a.port))


def recv(a):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    s.bind((a.group, a.port))
    mreq = struct.pack("4s4s", socket.inet_aton(a.group), socket.inet_aton("0.0.0.0"))
    s.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, mreq)
    open(a.ready, "w").write("joined\n")
    rows = []
    end = time.monotonic() + 60
    s.settimeout(a.first_timeout)  # the first datagram
    while time.monotonic() < end:
        try:
            data = s.recv(2048)
        except socket.timeout:
            break
        t = time.monotonic_ns()
        n, sent = struct.unpack_from(FMT, data)
        rows.append((n, t - sent))
        s.settimeout(1.5)
    with open(a.out, "w") as f:
        f.write("number,delay_ns\n")
        for n, d in rows:
            f.write(f"{n},{d}\n")


def check(a):
    rows = [tuple(map(int, l.split(","))) for l in open(a.out).read().split("\n")[1:] if l]
    numbers = [n for n, _ in rows]
    got = len(set(numbers))
    dups = len(numbers) - got
    lost = a.count - got
    loss_pct = 100.0 * lost / a.count
    top = -1
    reordered = 0
    for n in numbers:
        if n < top:
            reordered += 1
        top = max(top, n)
    d = sorted(x / 1e6 for _, x in rows)
    q = lambda p: d[min(len(d) - 1, int(p * len(d)))] if d else float("nan")
    lo, hi = a.delay - a.jitter, a.delay + a.jitter
    inside = sum(1 for x in d if lo <= x <= hi + 0.5) / max(1, len(d))
    print(f"# probe: {a.count} sent, {got} received ({dups} duplicates), lost {lost} = {loss_pct:.2f} % "
          f"(set {a.loss:g} %), reordered {reordered}", file=sys.stderr)
    print(f"# delay ms: min {d[0] if d else 0:.3f} p10 {q(0.1):.3f} p25 {q(0.25):.3f} median {q(0.5):.3f} "
          f"p75 {q(0.75):.3f} p90 {q(0.9):.3f} p99 {q(0.99):.3f} max {d[-1] if d else 0:.3f} "
          f"(set {a.delay:g} ± {a.jitter:g}); within [{lo:g}, {hi + 0.5:g}] ms: {100 * inside:.1f} %", file=sys.stderr)
    bad = []
    if dups:
        bad.append(f"{dups} duplicates")
    # The loss: a fixed seed draws a fixed pattern; the tolerance covers the draws'
    # spread (4 sd of a binomial share) and a datagram lost by the kernel under load.
    tol = 4 * (a.loss / 100 * (1 - a.loss / 100) / a.count) ** 0.5 * 100 + 0.3
    if abs(loss_pct - a.loss) > tol:
        bad.append(f"loss {loss_pct:.2f} % outside {a.loss:g} ± {tol:.2f} %")
    if a.forwarder_log:
        # The forwarder's own count of what it dropped against what the probe missed.
        import re
        m = re.search(r"received (\d+), lost (\d+) .*?queue full (\d+), too large (\d+), sent (\d+)", open(a.forwarder_log).read())
        if not m:
            bad.append("no counters in the forwarder's log")
        else:
            frx, flost, ffull, fbig, fsent = map(int, m.groups())
            print(f"# forwarder: received {frx}, lost {flost}, queue full {ffull}, sent {fsent}", file=sys.stderr)
            if fsent != got or frx - flost - ffull - fbig != fsent:
                bad.append(f"forwarder sent {fsent}, probe received {got}")
            if a.count - frx > 0.003 * a.count:
                bad.append(f"{a.count - frx} datagrams never reached the forwarder")
    if d:
        # Never early (each is held at least delay - jitter after the forwarder took it,
        # which is after it was sent); most within the set range (+0.5 ms for the path
        # and the scheduler); the spread really spread (quartiles ~jitter apart).
        if d[0] < lo - 0.01:
            bad.append(f"a datagram arrived after {d[0]:.3f} ms, before delay - jitter = {lo:g} ms")
        if inside < 0.9:
            bad.append(f"only {100 * inside:.1f} % of delays within [{lo:g}, {hi + 0.5:g}] ms")
        if not (a.delay - a.jitter / 2 <= q(0.5) <= a.delay + a.jitter / 2 + 0.5):
            bad.append(f"median delay {q(0.5):.3f} ms not within {a.delay:g} -{a.jitter / 2:g} / +{a.jitter / 2 + 0.5:g} ms")
        if a.jitter > 0 and not (0.6 * a.jitter <= q(0.75) - q(0.25) <= 1.6 * a.jitter):
            bad.append(f"interquartile range {q(0.75) - q(0.25):.3f} ms, expected ~{a.jitter:g} ms (uniform)")
    if a.ordered and reordered:
        bad.append(f"{reordered} datagrams out of order with --keep-order")
    if bad:
        print("FAIL: " + "; ".join(bad), file=sys.stderr)
        sys.exit(1)


def main():
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("send")
    s.add_argument("group"); s.add_argument("port", type=int); s.add_argument("count", type=int)
    s.add_argument("rate", type=float)
    r = sub.add_parser("recv")
    r.add_argument("group"); r.add_argument("port", type=int); r.add_argument("out"); r.add_argument("ready")
    r.add_argument("--first-timeout", type=float, default=20.0)
    c = sub.add_parser("check")
    c.add_argument("out"); c.add_argument("count", type=int)
    c.add_argument("--loss", type=float, default=0); c.add_argument("--delay", type=float, default=0)
    c.add_argument("--jitter", type=float, default=0); c.add_argument("--ordered", action="store_true")
    c.add_argument("--forwarder-log")
    a = p.parse_args()
    {"send": send, "recv": recv, "check": check}[a.cmd](a)


if __name__ == "__main__":
    main()
