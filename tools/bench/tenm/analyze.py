#!/usr/bin/env python3
"""The figures of a run of tools/bench/tenm/run.sh, from its folder.

    analyze.py --work DIR --prefix T12340.

Reads DIR/rss.csv (sample.py) and DIR/run.lcmlog (the cell's log, read event by
event: the headers of all, the data of PROGRAM_BLOCKS and INTERP_STATE only), prints
per service the resident memory at the start of the motion, at its end and its peak;
per stage the throughput (blocks served by the program server, blocks the
interpolator has done, setpoints published) over the run and in its 10-s windows; the
log's size and write rate; and plots rss.png: memory per service and each stage's
rate over the run.
"""
import argparse
import os
import struct
import sys

MAGIC = 0xEDA1DA01


def read_log(path, prefix):
    """Per 1-s bin of the log's time: events by channel; INTERP_STATE's blocks_done and
    setpoints_published (the last of the bin) and starved_cycles."""
    blocks_ch = prefix + "PROGRAM_BLOCKS"
    state_ch = prefix + "INTERP_STATE"
    served = {}
    done = {}
    published = {}
    starved = {}
    first = last = None
    events = 0
    with open(path, "rb", buffering=1 << 20) as f:
        while True:
            head = f.read(28)
            if len(head) < 28:
                break
            magic, _num, ts, clen, dlen = struct.unpack(">IqqII", head)
            if magic != MAGIC:
                raise ValueError("%s: no event magic" % path)
            ch = f.read(clen).decode()
            events += 1
            if first is None:
                first = ts
            last = ts
            sec = (ts - first) // 1_000_000
            if ch == blocks_ch:
                served[sec] = served.get(sec, 0) + 1
                f.seek(dlen, 1)
            elif ch == state_ch:
                data = f.read(dlen)
                # fingerprint, utime, seq, sender, cycle, state, token, blocks_done, buffered,
                # setpoints_published, starved_cycles
                v = struct.unpack_from(">qqqiqbqqqqq", data, 0)
                done[sec] = v[7]
                published[sec] = v[9]
                starved[sec] = v[10]
            else:
                f.seek(dlen, 1)
    return first, last, events, served, done, published, starved


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", required=True)
    ap.add_argument("--prefix", required=True)
    ap.add_argument("--plot", default="", help="the PNG (default WORK/rss.png)")
    a = ap.parse_args()
    log = os.path.join(a.work, "run.lcmlog")
    first, last, events, served, done, published, starved = read_log(log, a.prefix)
    span = (last - first) / 1e6
    size = os.path.getsize(log)

    # The motion: from the first second with a block done to the last second it grew.
    secs = sorted(done)
    moving = [s for i, s in enumerate(secs) if i > 0 and done[s] > done[secs[i - 1]]]
    t_start, t_stop = (moving[0] - 1, moving[-1]) if moving else (0, 0)
    dur = max(1, t_stop - t_start)
    n_served = sum(served.values())
    n_done = done[t_stop] - done.get(t_start, 0) if moving else 0
    n_sp = published[t_stop] - published.get(t_start, 0) if moving else 0
    print("log: %d events over %.1f s, %.1f MB, %.2f MB/s over the log's span" % (events, span, size / 1e6, size / 1e6 / span))
    print("motion: %d s (log seconds %d..%d); starved cycles at its end %d" % (dur, t_start, t_stop, starved.get(t_stop, 0)))
    print("blocks served (PROGRAM_BLOCKS events): %d; %.0f /s over the motion" % (n_served, n_served / dur))
    print("blocks done by the interpolator: %d; %.0f /s" % (n_done, n_done / dur))
    print("setpoints published: %d; %.1f /s" % (n_sp, n_sp / dur))
    # 10-s windows of the motion: the slowest and fastest stage rates.
    win = []
    for w0 in range(t_start, t_stop - 9, 10):
        s = sum(served.get(k, 0) for k in range(w0 + 1, w0 + 11))
        d = done.get(w0 + 10, 0) - done.get(w0, 0)
        p = published.get(w0 + 10, 0) - published.get(w0, 0)
        win.append((w0, s / 10, d / 10, p / 10))
    if win:
        print("10-s windows (%d): served %.0f..%.0f /s, done %.0f..%.0f /s, setpoints %.1f..%.1f /s" % (
            len(win), min(w[1] for w in win), max(w[1] for w in win), min(w[2] for w in win), max(w[2] for w in win),
            min(w[3] for w in win), max(w[3] for w in win)))

    # Memory.
    rows = [l.rstrip("\n").split(",") for l in open(os.path.join(a.work, "rss.csv"))]
    names = [n for n in rows[0][2:] if not n.startswith("cpu_")]
    data = rows[1:]
    t = [float(r[0]) for r in data]
    print("resident memory (MiB) at the first sample / after 10 % of the run / at the last / peak; growth from 10 % to the end:")
    series = {}
    for k, n in enumerate(names):
        vals = [(float(r[0]), int(r[2 + k]) / 1024.0) for r in data if r[2 + k]]
        if not vals:
            continue
        series[n] = vals
        ten = vals[len(vals) // 10][1]
        print("  %-15s %8.1f %8.1f %8.1f %8.1f  %+.1f" % (n, vals[0][1], ten, vals[-1][1], max(v for _, v in vals),
                                                       vals[-1][1] - ten))
    header = rows[0]
    if "cpu_" + names[0] in header and len(data) > 1:
        print("CPU time over the run (s) and its share of one core:")
        for n in names:
            k = header.index("cpu_" + n)
            c = [(float(r[0]), float(r[k])) for r in data if r[k]]
            if len(c) > 1:
                print("  %-15s %8.1f  %5.1f %%" % (n, c[-1][1] - c[0][1], 100 * (c[-1][1] - c[0][1]) / (c[-1][0] - c[0][0])))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("(no matplotlib: no plot)")
        return 0
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7), sharex=False)
    for n, vals in series.items():
        ax1.plot([v[0] / 60 for v in vals], [v[1] for v in vals], label=n)
    ax1.set_xlabel("wall time, min")
    ax1.set_ylabel("resident memory, MiB")
    ax1.set_yscale("log")
    ax1.set_title("%s: RSS of every service" % os.path.basename(os.path.normpath(a.work)))
    ax1.legend(fontsize=8, ncol=3)
    ax1.grid(True, which="both", alpha=0.3)
    if win:
        ax2.plot([(w[0] + 5) / 60 for w in win], [w[1] for w in win], label="blocks served /s")
        ax2.plot([(w[0] + 5) / 60 for w in win], [w[2] for w in win], label="blocks done /s")
        ax2.plot([(w[0] + 5) / 60 for w in win], [w[3] * 10 for w in win], label="setpoints /s x 10")
    ax2.set_xlabel("log time, min (10-s windows)")
    ax2.set_ylabel("rate")
    ax2.legend(fontsize=8)
    ax2.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(a.plot or os.path.join(a.work, "rss.png"), dpi=90)
    return 0


if __name__ == "__main__":
    sys.exit(main())
