#!/usr/bin/python3
"""The levels of a cnc-cam rough plan (written by `cnc-cam rough --png`): left, the
paths of every level seen from above, coloured by height; right, the smallest slope of
the part on each contour against height, with the chosen levels.

  /usr/bin/python3 tools/cam/plot_rough.py LEVELS.csv OUT.png [TITLE]
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    src, out = sys.argv[1], sys.argv[2]
    title = sys.argv[3] if len(sys.argv) > 3 else ""
    paths, slope_z, slope_deg, levels = {}, [], [], []
    with open(src) as f:
        for row in csv.DictReader(f):
            kind, z = row["kind"], float(row["z"])
            if kind == "path":
                paths.setdefault((int(row["level"]), int(row["chain"])), (z, [], []))
                _, xs, ys = paths[(int(row["level"]), int(row["chain"]))]
                xs.append(float(row["x"]))
                ys.append(float(row["y"]))
            elif kind == "slope":
                slope_z.append(z)
                slope_deg.append(float(row["x"]))
            elif kind == "level":
                levels.append(z)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 6), gridspec_kw={"width_ratios": [1.2, 1]})
    zs = [v[0] for v in paths.values()] or [0.0]
    lo, hi = min(zs), max(zs)
    cmap = plt.get_cmap("viridis")
    for (lvl, _), (z, xs, ys) in sorted(paths.items()):
        ax.plot(xs, ys, lw=0.6, color=cmap((z - lo) / (hi - lo) if hi > lo else 0.5))
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(lo, hi))
    fig.colorbar(sm, ax=ax, label="level z (mm)")
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"{len(levels)} levels, tool paths from above")
    bx.plot(slope_deg, slope_z, lw=0.8, color="tab:blue", label="smallest slope on the contour")
    for z in levels:
        bx.axhline(z, color="tab:red", lw=0.8)
    bx.plot([], [], color="tab:red", lw=0.8, label="levels")
    bx.set_xlabel("slope (deg from horizontal)")
    bx.set_ylabel("z (mm)")
    bx.set_xlim(0, 90)
    bx.legend(loc="lower right")
    bx.set_title("slope profile and levels")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    main()
