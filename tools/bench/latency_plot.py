#!/usr/bin/python3
"""Cycle timing of the cell's services: reads the DIR/<service>.json files the services
write at the end of a run (--latency-dir / CNC_LATENCY_DIR; see common/util/realtime.h),
prints a table (min, mean, p99, p99.9, max in µs, cycles, overruns, scheduling) and plots
the histograms of wake-up latency and compute time, one row per service, one line per run.

    latency_plot.py --run idle=DIR1 --run loaded=DIR2 [--png OUT.png] [--table OUT.txt] [--title T]

make_report.py imports read_runs, text_table, html_table and plot from here.
"""
import argparse
import glob
import html
import json
import os
import sys

SERVICE_ORDER = ["cnc-drive-bridge", "cnc-interpolator", "cnc-servo-sim", "cnc-monitor"]
RUN_COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e"]


def read_dir(d):
    """{service: data} of the latency files in d ({} when there are none)."""
    out = {}
    for path in sorted(glob.glob(os.path.join(d, "*.json"))):
        try:
            with open(path) as f:
                data = json.load(f)
        except (OSError, ValueError) as e:
            print("latency_plot: skipping %s: %s" % (path, e), file=sys.stderr)
            continue
        if isinstance(data, dict) and "wake" in data and "compute" in data:
            out[data.get("service") or os.path.basename(path)[:-5]] = data
    return out


def read_runs(specs):
    """[(label, {service: data})] from ["label=DIR", ...] or [(label, DIR), ...]."""
    runs = []
    for s in specs:
        label, d = s if isinstance(s, tuple) else (s.split("=", 1) if "=" in s else (os.path.basename(s.rstrip("/")), s))
        runs.append((label, read_dir(d)))
    return runs


def services_of(runs):
    names = set()
    for _, data in runs:
        names.update(data)
    return sorted(names, key=lambda n: (SERVICE_ORDER.index(n) if n in SERVICE_ORDER else 99, n))


COLUMNS = ["service", "run", "what", "cycles", "overruns", "min", "mean", "p99", "p99.9", "max"]


def rows_of(runs):
    rows = []
    for svc in services_of(runs):
        for label, data in runs:
            d = data.get(svc)
            if d is None:
                continue
            for what, key in (("wake-up", "wake"), ("compute", "compute")):
                h = d[key]
                rows.append({
                    "service": svc, "run": label, "what": what, "cycles": d.get("cycles", h["count"]),
                    "overruns": d.get("overruns", 0), "min": h["min_us"], "mean": h["mean_us"], "p99": h["p99_us"],
                    "p99.9": h["p999_us"], "max": h["max_us"], "scheduling": d.get("scheduling", ""),
                    "period_us": d.get("period_us", 0), "overflow": h.get("overflow", 0)})
    return rows


def text_table(runs):
    rows = rows_of(runs)
    if not rows:
        return "(no latency files)"
    head = "%-17s %-8s %-8s %8s %8s %8s %8s %8s %8s %9s" % ("service", "run", "µs", "cycles", "overruns", "min",
                                                              "mean", "p99", "p99.9", "max")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append("%-17s %-8s %-8s %8d %8d %8.1f %8.1f %8.1f %8.1f %9.1f" % (
            r["service"], r["run"], r["what"], r["cycles"], r["overruns"], r["min"], r["mean"], r["p99"], r["p99.9"],
            r["max"]))
    sched = sorted({"%s (%s): %s" % (r["service"], r["run"], r["scheduling"]) for r in rows if r["scheduling"]})
    lines.append("")
    lines.extend("scheduling  " + s for s in sched)
    return "\n".join(lines)


def html_table(runs):
    rows = rows_of(runs)
    if not rows:
        return "<p>no latency files</p>"
    e = html.escape
    out = ["<table><tr><th>service</th><th>run</th><th>µs</th><th>cycles</th><th>overruns</th><th>min</th>"
           "<th>mean</th><th>p99</th><th>p99.9</th><th>max</th><th>scheduling</th></tr>"]
    for r in rows:
        late = r["what"] == "wake-up" and r["period_us"] and r["max"] >= r["period_us"]
        out.append("<tr><td>%s</td><td>%s</td><td>%s</td><td>%d</td><td class='%s'>%d</td><td>%.1f</td><td>%.1f</td>"
                   "<td>%.1f</td><td>%.1f</td><td class='%s'>%.1f</td><td>%s</td></tr>" % (
                       e(r["service"]), e(r["run"]), e(r["what"]), r["cycles"], "bad" if r["overruns"] else "",
                       r["overruns"], r["min"], r["mean"], r["p99"], r["p99.9"], "bad" if late else "", r["max"],
                       e(r["scheduling"])))
    out.append("</table>")
    return "\n".join(out)


def display_edges(hi_us):
    """Display bins: 1 µs wide to 10 µs, then 10 per decade, on the recording's bin edges."""
    edges = list(range(0, 11))
    k = 11
    while edges[-1] < hi_us:
        e = 10 ** (k / 10.0)
        step = 1 if e < 1000 else 10
        e = int(round(e / step) * step)
        if e > edges[-1]:
            edges.append(e)
        k += 1
    return edges


def rebin(h, edges):
    """Counts of the recorded bins in the display bins (by lower edge; overflow at its lower edge)."""
    counts = [0] * (len(edges) - 1)
    j = 0
    for lo, _hi, n in sorted(h["bins"], key=lambda b: b[0]):
        while j + 1 < len(edges) - 1 and lo >= edges[j + 1]:
            j += 1
        counts[j] += n
    return counts


def plot(runs, png, title=""):
    """One row per service, wake-up latency left, compute right: the share of cycles in
    log-spaced bins (log-log steps, cyclictest style), one line per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    services = services_of(runs)
    if not services:
        return False
    top = 20
    for _, data in runs:
        for d in data.values():
            top = max(top, d["wake"]["max_us"], d["compute"]["max_us"], d.get("period_us") or 0)
    edges = display_edges(top * 1.05)
    fig, axs = plt.subplots(len(services), 2, figsize=(12, 2.8 * len(services)), constrained_layout=True,
                            squeeze=False)
    for row, svc in enumerate(services):
        for col, key in enumerate(("wake", "compute")):
            ax = axs[row][col]
            what = None
            for i, (label, data) in enumerate(runs):
                d = data.get(svc)
                if d is None or not d[key]["count"]:
                    continue
                what = d.get(key + "_what", key)
                h = d[key]
                share = [c / float(h["count"]) for c in rebin(h, edges)]
                colour = RUN_COLOURS[i % len(RUN_COLOURS)]
                ax.stairs(share, [max(e, 0.5) for e in edges], color=colour, lw=1.0,
                          label="%s: n=%d, p99 %.0f, p99.9 %.0f, max %.0f µs" % (
                              label, h["count"], h["p99_us"], h["p999_us"], h["max_us"]))
                ax.axvline(max(h["p99_us"], 0.5), color=colour, ls=":", lw=0.9)
                ax.axvline(max(h["max_us"], 0.5), color=colour, ls="--", lw=0.9)
                if col == 0 and d.get("period_us"):
                    ax.axvline(d["period_us"], color="#333333", lw=0.9)
            ax.set_xscale("log")
            ax.set_yscale("log", nonpositive="clip")
            ax.set_xlim(0.5, edges[-1])
            ax.set_xlabel("µs  (dotted: p99, dashed: max%s)" % (", black: the period" if col == 0 else ""))
            ax.set_ylabel("share of cycles")
            ax.set_title("%s: %s" % (svc, "wake-up latency" if col == 0 else "compute"), fontsize=10)
            if what:
                ax.text(0.01, 0.02, what, transform=ax.transAxes, fontsize=6.5, color="#555555")
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=7, loc="upper right")
    if title:
        fig.suptitle(title)
    fig.savefig(png, dpi=100)
    plt.close(fig)
    return True


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", action="append", required=True, help="LABEL=DIR (DIR holds the services' *.json)")
    ap.add_argument("--png", help="write the histograms here")
    ap.add_argument("--table", help="write the table here too")
    ap.add_argument("--title", default="")
    a = ap.parse_args()
    runs = read_runs(a.run)
    if not services_of(runs):
        sys.exit("latency_plot: no latency files in %s" % ", ".join(a.run))
    table = text_table(runs)
    print(table)
    if a.table:
        with open(a.table, "w") as f:
            f.write(table + "\n")
    if a.png and plot(runs, a.png, a.title):
        print("wrote " + a.png)


if __name__ == "__main__":
    main()
