#!/usr/bin/python3
"""Report of a recorded run, for a browser: reads the tables cnc-logexport wrote into
DIR and writes DIR/index.html with PNG plots (matplotlib) and a summary table:

  (a) feed against time, coloured by the constraint that limited each setpoint
  (b) chord error against time with the tolerance
  (c) predicted R_max against time with the target
  (d) following error per axis against time
  (e) the path, XY and XZ projections, coloured by feed
  (f) the alarms
  (g) the cycle timing of the services (wake-up latency and compute histograms, and
      their table), when the run has latency files: --latency-dir, else the folder
      `latency` beside the log (./cnc demo writes it there)

    make_report.py DIR [--tolerance-um UM] [--target-rmax-um UM] [--title T] [--latency-dir D]

The tolerance and the target come from the log when it has them (the recorded
config, the monitor's reports, the program's process parameters); the options are
the fallback. A panel whose data is missing or all NaN says "no data".
"""
import argparse
import csv
import html
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from plot_plan import COLOURS  # noqa: E402  (one colour per limit across the project's plots)

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "bench"))
import latency_plot  # noqa: E402  (the latency files, their table and plot: tools/bench/latency_plot.py)

RUNNING_STATES = {"running", "held", "starved"}
DPI = 100


def read_csv(path):
    if not os.path.exists(path):
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def column(rows, name):
    out = []
    for r in rows:
        try:
            out.append(float(r.get(name, "nan")))
        except (TypeError, ValueError):
            out.append(float("nan"))
    return out


def finite(values):
    return [v for v in values if math.isfinite(v)]


def program_window(setpoints):
    """The span of the program: first to last running setpoint, or everything."""
    t = column(setpoints, "t_s")
    running = [t[i] for i, r in enumerate(setpoints) if r["state"] in RUNNING_STATES]
    if not running:
        return (min(t), max(t)) if t else (0.0, 0.0)
    margin = 0.02 * max(running[-1] - running[0], 0.1)
    return running[0] - margin, running[-1] + margin


def in_window(rows, window):
    lo, hi = window
    return [r for r in rows if lo <= float(r["t_s"]) <= hi]


class Report:
    def __init__(self, out_dir):
        self.out_dir = out_dir
        self.panels = []  # (file, caption, empty)

    def save(self, fig, name, caption, empty=False):
        fig.savefig(os.path.join(self.out_dir, name), dpi=DPI)
        plt.close(fig)
        self.panels.append((name, caption, empty))

    def no_data(self, name, title, why):
        fig, ax = plt.subplots(figsize=(11, 2.2), constrained_layout=True)
        ax.set_axis_off()
        ax.set_title(title)
        ax.text(0.5, 0.5, "no data: " + why, ha="center", va="center", fontsize=14, color="#7f7f7f",
                transform=ax.transAxes)
        self.save(fig, name, title + " — no data: " + why, empty=True)


def plot_feed(rep, sp, mon):
    title = "(a) feed against time, coloured by the limiting constraint"
    t, f = column(sp, "t_s"), column(sp, "feed_mm_min")
    if not finite(f):
        return rep.no_data("feed.png", title, "no setpoints in the program's span")
    fig, ax = plt.subplots(figsize=(11, 4), constrained_layout=True)
    limits = [r["limit"] for r in sp]
    for name, colour in COLOURS.items():
        idx = [i for i in range(len(sp)) if limits[i] == name]
        if idx:
            ax.scatter([t[i] for i in idx], [f[i] for i in idx], s=4, color=colour, label=name)
    tm, fa = column(mon, "t_s"), column(mon, "actual_feed_mm_min")
    if finite(fa):
        ax.plot(tm, fa, color="#000000", lw=0.6, alpha=0.6, label="actual (monitor)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("feed [mm/min]")
    ax.set_title(title)
    ax.legend(markerscale=3, fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    rep.save(fig, "feed.png", title)


def plot_chord(rep, mon, tolerance_um, tolerance_note):
    title = "(b) chord error against time"
    t, e = column(mon, "t_s"), [v * 1000 for v in column(mon, "chord_error_mm")]
    if not finite(e):
        return rep.no_data("chord_error.png", title, "the monitor reported no chord error (all NaN)")
    fig, ax = plt.subplots(figsize=(11, 3.5), constrained_layout=True)
    ax.plot(t, e, ".", ms=2, color="#d62728", label="chord error")
    if tolerance_um is not None:
        ax.axhline(tolerance_um, color="#333333", ls="--", label="tolerance %.3g µm (%s)" % (tolerance_um, tolerance_note))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("chord error [µm]")
    ax.set_title(title)
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    rep.save(fig, "chord_error.png", title)


def plot_rmax(rep, mon, target_um, target_note):
    title = "(c) predicted R_max against time"
    t, r = column(mon, "t_s"), column(mon, "predicted_rmax_um")
    if not finite(r):
        return rep.no_data("rmax.png", title, "the monitor predicted no R_max (all NaN: no process parameters?)")
    fig, ax = plt.subplots(figsize=(11, 3.5), constrained_layout=True)
    ax.plot(t, r, ".", ms=2, color="#2ca02c", label="predicted R_max")
    per_row = column(mon, "target_rmax_um")
    if target_note == "MONITOR" and finite(per_row):
        ax.step(t, per_row, where="post", color="#333333", ls="--", label="target (monitor)")
    elif target_um is not None:
        ax.axhline(target_um, color="#333333", ls="--", label="target %.4g µm (%s)" % (target_um, target_note))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("R_max [µm]")
    ax.set_title(title)
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    rep.save(fig, "rmax.png", title)


def plot_deflection(rep, mon):
    """VMCS 1999 live: only when the monitor predicted a deflection (machine config `cutting:`)."""
    t, d = column(mon, "t_s"), [v * 1000 for v in column(mon, "deflection_mm")]
    if not finite(d):
        return
    title = "(c2) predicted tool-tip deflection against time (VMCS 1999, from the stock)"
    fig, ax = plt.subplots(figsize=(11, 3.5), constrained_layout=True)
    ax.plot(t, d, ".", ms=2, color="#8c564b", label="predicted deflection (peak per tooth period)")
    tol = [v * 1000 for v in column(mon, "deflection_tolerance_mm")]
    if finite(tol):
        ax.step(t, tol, where="post", color="#333333", ls="--", label="tolerance (monitor)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("deflection [µm]")
    ax.set_title(title)
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    rep.save(fig, "deflection.png", title)


def plot_following_error(rep, axis_rows, mon, axes):
    title = "(d) following error per axis"
    source, rows, key = "axis status", axis_rows, "{}_following_error_mm"
    if not any(finite(column(rows, key.format(a))) for a in axes):
        source, rows, key = "monitor", mon, "fe_{}_mm"
    series = [(a, column(rows, key.format(a))) for a in axes]
    if not any(finite(v) for _, v in series):
        return rep.no_data("following_error.png", title, "no axis status or monitor reports")
    fig, ax = plt.subplots(figsize=(11, 3.5), constrained_layout=True)
    t = column(rows, "t_s")
    for a, v in series:
        ax.plot(t, [x * 1000 for x in v], lw=0.8, label=a.upper())
    ax.set_xlabel("time [s]")
    ax.set_ylabel("following error [µm]")
    ax.set_title("%s (from the %s)" % (title, source))
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    rep.save(fig, "following_error.png", title)


def plot_path(rep, sp, axes):
    title = "(e) the path, coloured by feed"
    if len(axes) < 3 or not sp:
        return rep.no_data("path.png", title, "fewer than three axes or no setpoints")
    x, y, z = (column(sp, a + "_mm") for a in axes[:3])
    f = column(sp, "feed_mm_min")
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5), constrained_layout=True)
    for ax, v, name in ((ax1, y, axes[1]), (ax2, z, axes[2])):
        sc = ax.scatter(x, v, c=f, s=3, cmap="viridis")
        ax.set_xlabel(axes[0].upper() + " [mm]")
        ax.set_ylabel(name.upper() + " [mm]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title("%s%s projection" % (axes[0].upper(), name.upper()))
        ax.grid(alpha=0.3)
    fig.colorbar(sc, ax=[ax1, ax2], label="feed [mm/min]")
    fig.suptitle(title)
    rep.save(fig, "path.png", title)


def scaled(v, factor):
    return None if v is None else v * factor


def fmt(v, spec="%.4g", unit=""):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    return (spec % v) + unit


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir", help="the directory cnc-logexport wrote; index.html goes there")
    ap.add_argument("--tolerance-um", type=float, default=None, help="chord tolerance when the log has none (1)")
    ap.add_argument("--target-rmax-um", type=float, default=None, help="R_max target when the log has none")
    ap.add_argument("--title", default="")
    ap.add_argument("--latency-dir", default=None,
                    help="the services' cycle timing files (default: the folder 'latency' beside the log)")
    a = ap.parse_args()

    d = a.dir
    summary_path = os.path.join(d, "summary.json")
    if not os.path.exists(summary_path):
        sys.exit("make_report: no summary.json in %s (run cnc-logexport first)" % d)
    summary = json.load(open(summary_path))
    axes = summary.get("axes") or ["x", "y", "z"]
    setpoints = read_csv(os.path.join(d, "setpoints.csv"))
    if not setpoints:
        sys.exit("make_report: no setpoints in %s" % d)
    window = program_window(setpoints)
    sp = in_window(setpoints, window)
    mon = in_window(read_csv(os.path.join(d, "monitor.csv")), window)
    axis_rows = in_window(read_csv(os.path.join(d, "axis_status.csv")), window)
    alarms = read_csv(os.path.join(d, "alarms.csv"))

    notes = []
    if summary.get("chord_tolerance_mm") is not None:
        tolerance_um, tolerance_note = summary["chord_tolerance_mm"] * 1000, "from " + summary["chord_tolerance_source"]
        if a.tolerance_um is not None and abs(a.tolerance_um - tolerance_um) > 1e-12:
            notes.append("--tolerance-um %g not used: the log records %g µm" % (a.tolerance_um, tolerance_um))
    else:
        tolerance_um = a.tolerance_um if a.tolerance_um is not None else 1.0
        tolerance_note = "--tolerance-um" if a.tolerance_um is not None else "default, the log has none"
    if summary.get("target_rmax_um") is not None:
        target_um, target_note = summary["target_rmax_um"], summary["target_rmax_source"]
        if a.target_rmax_um is not None and abs(a.target_rmax_um - target_um) > 1e-12:
            notes.append("--target-rmax-um %g not used: the log records %g µm" % (a.target_rmax_um, target_um))
    else:
        target_um, target_note = a.target_rmax_um, "--target-rmax-um"

    rep = Report(d)
    plot_feed(rep, sp, mon)
    plot_chord(rep, mon, tolerance_um, tolerance_note)
    plot_rmax(rep, mon, target_um, target_note)
    plot_deflection(rep, mon)
    plot_following_error(rep, axis_rows, mon, axes)
    plot_path(rep, sp, axes)

    latency_dir = a.latency_dir
    if latency_dir is None and summary.get("log_files"):
        latency_dir = os.path.join(os.path.dirname(summary["log_files"][0]), "latency")
    latency_runs = latency_plot.read_runs([("this run", latency_dir)]) if latency_dir and os.path.isdir(
        latency_dir) else []
    if latency_runs and latency_plot.services_of(latency_runs):
        latency_plot.plot(latency_runs, os.path.join(d, "latency.png"))
        latency_html = ("<p>From %s: per cycle, the wake-up latency (wake time minus the deadline; for the "
                        "monitor, the delivery latency of AXIS_STATUS) and the compute time, in µs.</p>\n%s\n"
                        "<figure class='plot' data-empty='false'><img src='latency.png' alt='cycle timing'>"
                        "<figcaption>(g) cycle timing: histograms per service (log-log; dotted p99, dashed max, "
                        "solid the period)</figcaption></figure>" % (
                            html.escape(latency_dir), latency_plot.html_table(latency_runs)))
    else:
        latency_html = "<p>no latency files%s</p>" % (" in " + html.escape(latency_dir) if latency_dir else "")

    title = a.title or "run report: %s" % os.path.basename(summary.get("program") or "(no program)")
    e = html.escape
    logger = summary.get("logger") or {}
    rows = [
        ("program", e(summary.get("program") or "—") + " (program server: %s, interpolator: %s)" % (
            e(summary.get("program_state") or "—"), e(summary.get("interpolator_state") or "—"))),
        ("program time", fmt(summary.get("program_time_s"), "%.3f", " s")),
        ("blocks", "%s of %s done, %s re-sent" % (summary.get("blocks_done"), summary.get("blocks_total"),
                                                  summary.get("blocks_resent"))),
        ("setpoints", "%d in the log, %d running (T_ipo %s)" % (summary["setpoints"], summary["running_setpoints"],
                                                                fmt(summary.get("period_s"), "%.4g", " s"))),
        ("largest following error", fmt(summary.get("largest_following_error_mm"), "%.4f", " mm")
         + " (axis %s)" % e(summary.get("largest_following_error_axis") or "—")),
        ("largest chord error", fmt(scaled(summary.get("max_chord_error_mm"), 1000), "%.4g", " µm")
         + " (tolerance %s, %s)" % (fmt(tolerance_um, "%.4g", " µm"), e(tolerance_note))),
        ("largest predicted R_max", fmt(summary.get("max_predicted_rmax_um"), "%.4g", " µm")
         + " (target %s, %s)" % (fmt(target_um, "%.4g", " µm"), e(target_note))),
        ("alarms", str(summary.get("alarms", 0))),
        ("log", "<br>".join(e(p) for p in summary.get("log_files", []))),
    ]
    if logger:
        rows.append(("logger", "%d events, %.1f MB in %d file(s); %d dropped, %d write errors, %d socket drops; "
                     "longest write %s, longest loop pass %s%s" % (
                         logger["events"], logger["bytes"] / 1e6, logger["files"], logger["events_dropped"],
                         logger["write_errors"], logger["socket_drops"], fmt(logger.get("max_io_s"), "%.3f", " s"),
                         fmt(logger.get("max_loop_gap_s"), "%.3f", " s"),
                         "" if logger["closing"] else " (no closing report: killed?)")))
    summary_html = "\n".join("<tr><th>%s</th><td>%s</td></tr>" % (k, v) for k, v in rows)

    lstats = logger.get("channels", {}) if logger else {}
    channel_rows = []
    for ch, c in sorted(summary.get("channels", {}).items()):
        ls = lstats.get(ch, {})
        channel_rows.append("<tr><td>%s</td><td>%d</td><td>%d</td><td class='%s'>%d</td><td>%s</td><td>%s</td><td>%s</td></tr>" % (
            e(ch), c["events"], c["senders"], "bad" if c["seq_gaps"] else "", c["seq_gaps"],
            ls.get("received", "—"), ls.get("seq_gaps", "—"), ls.get("dropped", "—")))

    alarm_rows = "\n".join("<tr><td>%s</td><td>%s</td><td class='%s'>%s</td><td>%s</td><td>%s</td></tr>" % (
        fmt(float(r["t_s"]), "%.3f"), e(r["source"]), e(r["severity"]), e(r["severity"]), e(r["code"]), e(r["text"]))
        for r in alarms) or "<tr><td colspan='5'>no alarms</td></tr>"

    figures = "\n".join(
        "<figure class='%s' data-empty='%s'><img src='%s' alt='%s'><figcaption>%s</figcaption></figure>" % (
            "nodata" if empty else "plot", "true" if empty else "false", e(name), e(caption), e(caption))
        for name, caption, empty in rep.panels)

    page = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
 body {{ font-family: sans-serif; margin: 1.5em auto; max-width: 1150px; color: #222; }}
 table {{ border-collapse: collapse; margin: 0.5em 0 1.5em; }}
 th, td {{ border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; font-size: 0.92em; }}
 th {{ background: #f3f3f3; }}
 td.bad, td.fault {{ color: #b00; font-weight: bold; }}
 td.warning {{ color: #a60; }}
 figure {{ margin: 1em 0; }}
 figure img {{ max-width: 100%; border: 1px solid #ddd; }}
 figcaption {{ font-size: 0.85em; color: #555; }}
 .note {{ color: #a60; }}
</style>
</head>
<body>
<h1>{title}</h1>
{notes}
<h2>Summary</h2>
<table>{summary}</table>
<h2>Plots</h2>
{figures}
<h2>(f) Alarms</h2>
<table><tr><th>t [s]</th><th>source</th><th>severity</th><th>code</th><th>text</th></tr>
{alarms}
</table>
<h2>(g) Cycle timing</h2>
{latency}
<h2>Channels</h2>
<table><tr><th>channel</th><th>events in the log</th><th>senders</th><th>gaps in the log</th>
<th>logger: received</th><th>logger: seq gaps</th><th>logger: dropped</th></tr>
{channels}
</table>
</body>
</html>
""".format(title=e(title), notes="".join("<p class='note'>%s</p>" % e(n) for n in notes), summary=summary_html,
           figures=figures, alarms=alarm_rows, channels="\n".join(channel_rows), latency=latency_html)
    out = os.path.join(d, "index.html")
    with open(out, "w") as f:
        f.write(page)
    print("wrote " + out)


if __name__ == "__main__":
    main()
