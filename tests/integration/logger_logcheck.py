#!/usr/bin/python3
"""Checks one cnc-logger file byte by byte, independently of LCM's reader: whole
events only (no torn tail), event numbers 0..n-1, and the logger's stats
(lcmt_logger_stats on PREFIX + LOGGER_STATS, decoded by hand).

    logger_logcheck.py LOG --prefix P [--closing] [--kill-utime US --flush-period S]

--closing: the last event must be the closing LOGGER_STATS (SIGTERM / SIGINT).
--kill-utime: the file must hold what the logger received up to one flush period
(plus slack) before the SIGKILL, and at least what its last stats said it had written.
Prints the figures as `# key value` lines; exit 1 on a failed check.
"""
import argparse
import os
import struct
import sys

MAGIC = 0xEDA1DA01
# A flush every period, but the logger may run late on a loaded machine.
SLACK_S = 1.0


def events(data):
    off = 0
    while off < len(data):
        if len(data) - off < 28:
            raise ValueError(f"torn event header at byte {off} ({len(data) - off} bytes left)")
        magic, num, ts, clen, dlen = struct.unpack_from(">IqqII", data, off)
        if magic != MAGIC:
            raise ValueError(f"no event magic at byte {off}")
        end = off + 28 + clen + dlen
        if end > len(data):
            raise ValueError(f"torn event {num} at byte {off}: needs {end - off} bytes, {len(data) - off} left")
        yield num, ts, data[off + 28:off + 28 + clen].decode(), data[off + 28 + clen:end]
        off = end


def logger_stats(payload):
    """The head of lcmt_logger_stats: after the 8-byte fingerprint, utime, seq, sender,
    path, files, events, bytes, events_dropped, write_errors, socket_drops, max_io_s,
    max_loop_gap_s, closing."""
    off = 8
    utime, seq, sender = struct.unpack_from(">qqi", payload, off)
    off += 20
    (n,) = struct.unpack_from(">i", payload, off)
    path = payload[off + 4:off + 4 + n - 1].decode()
    off += 4 + n
    files, ev, nbytes, dropped, write_errors, socket_drops, max_io_s, max_gap_s, closing = struct.unpack_from(
        ">iqqqqqddb", payload, off)
    return dict(utime=utime, seq=seq, path=path, files=files, events=ev, bytes=nbytes, dropped=dropped,
                write_errors=write_errors, socket_drops=socket_drops, max_io_s=max_io_s, max_loop_gap_s=max_gap_s,
                closing=bool(closing))


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("log")
    ap.add_argument("--prefix", required=True)
    ap.add_argument("--closing", action="store_true")
    ap.add_argument("--kill-utime", type=int)
    ap.add_argument("--flush-period", type=float, default=0.5)
    a = ap.parse_args()

    data = open(a.log, "rb").read()
    failures = []
    evs = []
    try:
        evs = list(events(data))
    except ValueError as e:
        failures.append(str(e))
    for k, (num, _, _, _) in enumerate(evs):
        if num != k:
            failures.append(f"event {k} is numbered {num}")
            break
    stats_ch = a.prefix + "LOGGER_STATS"
    setpoints = [ts for _, ts, ch, _ in evs if ch == a.prefix + "SETPOINTS"]
    # This logger's own reports name this file (other loggers' reports are recorded too).
    own = os.path.realpath(a.log)
    stats = [(k, st) for k, st in ((k, logger_stats(d)) for k, (_, _, ch, d) in enumerate(evs) if ch == stats_ch)
             if os.path.realpath(st["path"]) == own]
    print(f"# events {len(evs)}")
    print(f"# bytes {len(data)}")
    print(f"# setpoints {len(setpoints)}")
    print(f"# logger_stats {len(stats)}")
    if not setpoints:
        failures.append("no setpoints in the log")
    if not stats:
        failures.append("no LOGGER_STATS of this logger in the log")
    else:
        k, last = stats[-1]
        print(f"# last_stats_events {last['events']} (the file holds {k} events before it)")
        print(f"# longest_io_s {last['max_io_s']:.4f} longest_loop_gap_s {last['max_loop_gap_s']:.4f}")
        if k < last["events"]:
            failures.append(f"the last stats say {last['events']} events were written, the file holds {k} before it")
        if last["dropped"] != 0 or last["write_errors"] != 0:
            failures.append(f"the logger reports {last['dropped']} dropped, {last['write_errors']} write errors")
    if a.closing:
        if not evs or evs[-1][2] != stats_ch or not stats[-1][1]["closing"]:
            failures.append("the last event is not the closing LOGGER_STATS")
    if a.kill_utime is not None and evs:
        first_ts = evs[0][1]
        last_ts = max(ts for _, ts, _, _ in evs)
        behind = (a.kill_utime - last_ts) / 1e6
        print(f"# recorded_s {(last_ts - first_ts) / 1e6:.3f}")
        print(f"# lost_window_s {behind:.3f} (flush period {a.flush_period} s)")
        if behind > a.flush_period + SLACK_S:
            failures.append(f"the last event is {behind:.3f} s older than the kill: more than a flush period lost")
        if stats and stats[-1][1]["closing"]:
            failures.append("a killed logger wrote a closing report")
    for f in failures:
        print("FAIL: " + f, file=sys.stderr)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
