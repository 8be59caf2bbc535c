#!/usr/bin/env python3
"""Samples the resident memory of a cell's processes and the size of its log.

    sample.py --out rss.csv --period 2 --log run.lcmlog NAME=PID [NAME=PID ...]

One row per period: wall time (s since start), the log's size (bytes), then VmRSS
(KiB) of each process (empty once it has ended), then each one's CPU time so far
(user + system, s). Ends when every process has ended,
or on SIGTERM.
"""
import argparse
import os
import signal
import sys
import time


def rss_kib(pid):
    try:
        with open("/proc/%d/status" % pid) as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def cpu_s(pid):
    try:
        with open("/proc/%d/stat" % pid) as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--period", type=float, default=2.0)
    ap.add_argument("--log", default="")
    ap.add_argument("procs", nargs="+", help="NAME=PID")
    a = ap.parse_args()
    procs = [(p.split("=")[0], int(p.split("=")[1])) for p in a.procs]
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    t0 = time.monotonic()
    with open(a.out, "w") as f:
        f.write("t_s,log_bytes," + ",".join(n for n, _ in procs) + "," + ",".join("cpu_" + n for n, _ in procs) + "\n")
        while not stop:
            values = [rss_kib(pid) for _, pid in procs]
            if all(v is None for v in values):
                break
            try:
                size = os.path.getsize(a.log) if a.log else 0
            except OSError:
                size = 0
            cpu = [cpu_s(pid) for _, pid in procs]
            f.write("%.1f,%d,%s,%s\n" % (time.monotonic() - t0, size, ",".join("" if v is None else str(v) for v in values),
                                         ",".join("" if c is None else "%.2f" % c for c in cpu)))
            f.flush()
            time.sleep(a.period)
    return 0


if __name__ == "__main__":
    sys.exit(main())
