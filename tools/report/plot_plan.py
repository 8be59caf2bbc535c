#!/usr/bin/python3
"""Feed profile of a dry run (cnc-plan --csv): feed against time coloured by the
constraint that set it, the path, and the feed inclination angle with the critical
angle of Choi et al. 2005 when asked.

    plot_plan.py PLAN.csv --out FEED.png [--title T] [--alpha-c DEG] [--only-line N]
"""
import argparse
import csv
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLOURS = {
    "program": "#1f77b4",
    "chord": "#d62728",
    "roughness": "#2ca02c",
    "axis_velocity": "#9467bd",
    "curvature_accel": "#ff7f0e",
    "lookahead": "#7f7f7f",
    "force": "#8c564b",
    "none": "#cccccc",
}


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("csv")
    ap.add_argument("--out", required=True)
    ap.add_argument("--title", default="")
    ap.add_argument("--alpha-c", type=float, default=None, help="critical inclination angle in degrees")
    ap.add_argument("--only-line", type=int, default=None, help="plot only setpoints of this source line")
    a = ap.parse_args()

    rows = list(csv.DictReader(open(a.csv)))
    if not rows:
        sys.exit("plot_plan: no setpoints in " + a.csv)
    t = [float(r["t_s"]) for r in rows]
    x = [float(r["x_mm"]) for r in rows]
    y = [float(r["y_mm"]) for r in rows]
    z = [float(r["z_mm"]) for r in rows]
    f = [float(r["feed_mm_min"]) for r in rows]
    lim = [r["limit"] for r in rows]
    line = [int(r["line"]) for r in rows]
    keep = [i for i in range(len(rows)) if a.only_line is None or line[i] == a.only_line]

    # Inclination of each step: asin(|dz| / |d|).
    alpha = [float("nan")]
    for i in range(1, len(rows)):
        d = math.dist((x[i], y[i], z[i]), (x[i - 1], y[i - 1], z[i - 1]))
        alpha.append(math.degrees(math.asin(min(1.0, abs(z[i] - z[i - 1]) / d))) if d > 0 else float("nan"))

    panels = 3 if a.alpha_c is not None else 2
    fig, axes = plt.subplots(panels, 1, figsize=(10, 3.2 * panels), constrained_layout=True)
    ax = axes[0]
    for name, colour in COLOURS.items():
        idx = [i for i in keep if lim[i] == name]
        if idx:
            ax.scatter([t[i] for i in idx], [f[i] for i in idx], s=4, color=colour, label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("feed [mm/min]")
    ax.set_title(a.title or "feed profile")
    ax.legend(markerscale=3, fontsize=8, loc="best")
    ax.grid(alpha=0.3)

    # The path in the plane of its two largest extents.
    spans = {"X": (x, max(x) - min(x)), "Y": (y, max(y) - min(y)), "Z": (z, max(z) - min(z))}
    (h_name, (h, _)), (v_name, (v, _)) = sorted(spans.items(), key=lambda kv: -kv[1][1])[:2]
    if "X" in (h_name, v_name) and h_name != "X":
        h_name, v_name, h, v = v_name, h_name, v, h
    ax = axes[1]
    sc = ax.scatter([h[i] for i in keep], [v[i] for i in keep], c=[f[i] for i in keep], s=3, cmap="viridis")
    fig.colorbar(sc, ax=ax, label="feed [mm/min]")
    ax.set_xlabel(h_name + " [mm]")
    ax.set_ylabel(v_name + " [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("path, coloured by feed")
    ax.grid(alpha=0.3)

    if a.alpha_c is not None:
        ax = axes[2]
        ax.plot([x[i] for i in keep], [alpha[i] for i in keep], ".", ms=2, color="#333333", label="|alpha|")
        ax.axhline(a.alpha_c, color="#2ca02c", ls="--", label="alpha_c = %.2f deg" % a.alpha_c)
        ax2 = ax.twinx()
        ax2.plot([x[i] for i in keep], [f[i] for i in keep], color="#1f77b4", lw=1, label="feed")
        ax2.set_ylabel("feed [mm/min]")
        ax.set_xlabel("X [mm]")
        ax.set_ylabel("feed inclination |alpha| [deg]")
        ax.set_yscale("symlog", linthresh=1.0)
        ax.set_ylim(0, 90)
        ax.set_title("feed against the feed inclination angle (Choi et al. 2005, Fig. 12)")
        ax.legend(loc="upper left", fontsize=8)
        ax.grid(alpha=0.3)
    fig.savefig(a.out, dpi=110)
    print("wrote " + a.out)


if __name__ == "__main__":
    main()
