#!/usr/bin/env python3
"""The report of `./cnc experiment table1`: DIR/table1.md and its pictures (DIR/img/*.png)
from DIR/results.json and the runs' tables (tools/experiment/table1.py writes them).

  table1_report.py DIR
"""
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import table1_part as part  # noqa: E402

PAPER = {"fixed": {"time_s": 37 * 60 + 23, "rmax_um": 5.4}, "law": {"time_s": 38 * 60 + 10, "rmax_um": 4.1}}
RUNS = (("fixed", "fixed feed"), ("law", "roughness law"))


def mmss(s):
    if s is None or not math.isfinite(s):
        return "–"
    return f"{int(s // 60)} min {s - 60 * (s // 60):04.1f} s" if s >= 60 else f"{s:.2f} s"


def read_map(path):
    with open(path) as f:
        head = f.readline()
        rows = [[float(v) for v in line.split(",")] for line in f if line.strip()]
    kv = dict(w.split("=") for w in head.replace(";", " ").split() if "=" in w)
    return float(kv["x0"]), float(kv["y0"]), np.array(rows)


def model_rmax_um(ft, alpha_deg):
    """The extended model (the digest's eqs. 2-4), for the table's model column."""
    r, fp = part.R_MM, part.PICK_MM
    a = math.radians(abs(alpha_deg))
    ac = math.radians(part.critical_angle_deg(ft))
    if a < ac:
        return r * (1 - math.sqrt(1 - (ft / r) ** 2 + math.sin(a) ** 2)) * 1e3
    p = fp / (2 * math.pi)
    return fp * fp / (8 * r) * (1 + ((ft - p) / fp) ** 2) * 1e3


def main():
    out = sys.argv[1]
    img = os.path.join(out, "img")
    os.makedirs(img, exist_ok=True)
    res = json.load(open(os.path.join(out, "results.json")))
    geo = res["part"]
    traces = {k: json.load(open(os.path.join(out, k, "trace.json"))) for k, _ in RUNS}

    # 1. The feed along the path (Fig. 17): the drives' actual feed over the run, and over one pass against x.
    fig, ax = plt.subplots(3, 1, figsize=(10, 9))
    for i, (k, name) in enumerate(RUNS):
        tr = traces[k]
        ax[i].plot(tr["t_s"], tr["feed_actual"], lw=0.6, label="actual (drives)")
        ax[i].plot(tr["t_s"], tr["feed_commanded"], lw=0.6, alpha=0.7, label="commanded (setpoints)")
        ax[i].axhline(part.FEED, color="k", lw=0.5, ls=":")
        ax[i].set_ylim(0, 8000)
        ax[i].set_ylabel("feed, mm/min")
        ax[i].set_title(f"({'ab'[i]}) {name}")
        ax[i].legend(loc="lower right", fontsize=8)
    ax[1].set_xlabel("time, s")
    # One pass in the middle of the strip, against x, with the surface's inclination.
    # The middle pass: its samples at its y, the axes moving.
    y_mid = (geo["passes"] // 2) * part.PICK_MM
    for k, name in RUNS:
        tr = traces[k]
        x, y, v = (np.array(tr[c]) for c in ("x_mm", "y_mm", "feed_actual"))
        on = (np.abs(y - y_mid) < 1e-3) & (np.array(tr["feed_commanded"]) > 0)
        ax[2].plot(x[on], v[on], ".", ms=1.5, label=name)
    xs = np.linspace(geo["x_mm"][0], geo["x_mm"][1], 2000)
    alpha = np.degrees(np.arctan(np.abs(part.slope(xs))))
    for reg in geo["flat_regions"]:
        ax[2].axvspan(reg["x_mm"] - reg["half_width_mm"], reg["x_mm"] + reg["half_width_mm"], color="0.85")
    ax2 = ax[2].twinx()
    ax2.plot(xs, alpha, color="0.5", lw=0.6, ls="--")
    ax2.set_ylabel("|alpha|, deg (dashed)")
    ax[2].set_ylim(0, 8000)
    ax[2].set_xlabel(f"x, mm (the pass at y {y_mid:.1f} mm; grey: |alpha| < alpha_c, the measured regions)")
    ax[2].set_ylabel("actual feed, mm/min")
    ax[2].legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(img, "table1_feed.png"), dpi=90)
    plt.close(fig)

    # 2. Both surfaces: the Z-map's distance from the nominal surface in the first measured region.
    regs = geo["flat_regions"]
    if regs:
        fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
        reg0 = res["runs"]["fixed"]["regions"][0]
        lim = None
        devs = {}
        for k, _ in RUNS:
            d = np.load(os.path.join(out, k, f"window_{reg0['x_mm']:g}", "deviation_um.npy"))
            devs[k] = d - np.median(d)
        lim = max(np.percentile(np.abs(devs[k]), 99.9) for k in devs)
        for i, (k, name) in enumerate(RUNS):
            w = res["runs"][k]["regions"][0]["window"]
            im = ax[i].imshow(devs[k], origin="lower", extent=(w[0], w[2], w[1], w[3]), cmap="viridis",
                              vmin=-lim, vmax=lim, aspect="auto")
            ax[i].set_title(f"{name}: {reg0['kind']} at x {reg0['x_mm']:g} mm, "
                            f"R_max {res['runs'][k]['regions'][0]['rmax_um']:.2f} um")
            ax[i].set_xlabel("x, mm (feed)")
            ax[i].set_ylabel("y, mm (pick feed)")
            fig.colorbar(im, ax=ax[i], label="distance from nominal, um (median removed)")
        fig.tight_layout()
        fig.savefig(os.path.join(img, "table1_surfaces.png"), dpi=90)
        plt.close(fig)
        # A profile along X through each (as a stylus reads it).
        fig, ax = plt.subplots(1, 1, figsize=(10, 3.4))
        for k, name in RUNS:
            d = devs[k]
            w = res["runs"][k]["regions"][0]["window"]
            xx = np.linspace(w[0], w[2], d.shape[1])
            ax.plot(xx, d[d.shape[0] // 2], lw=0.7, label=name)
        ax.set_xlabel("x, mm")
        ax.set_ylabel("um")
        ax.set_title("profile along X through the middle of the measured band")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(os.path.join(img, "table1_profiles.png"), dpi=110)
        plt.close(fig)

    # 3. The whole strip: surface (distance from nominal) and the R_max map, both runs.
    have_whole = all(os.path.exists(os.path.join(out, k, "whole", "rmax_map.csv")) for k, _ in RUNS)
    if have_whole:
        fig, ax = plt.subplots(2, 2, figsize=(13, 6.5))
        for i, (k, name) in enumerate(RUNS):
            x0, y0, z = read_map(os.path.join(out, k, "whole", "stock.csv"))
            with open(os.path.join(out, k, "whole", "stock.csv")) as f:
                pitch = float(f.readline().split("pitch_mm=")[1])
            xx = x0 + pitch * np.arange(z.shape[1])
            dev = (z - part.surface(xx)[None, :]) / np.sqrt(1 + part.slope(xx) ** 2)[None, :] * 1e3
            yy = y0 + pitch * np.arange(z.shape[0])
            # The strip but its ends, where the ball comes in and leaves (hundreds of um off).
            inside = (yy >= geo["y_mm"][0]) & (yy <= geo["y_mm"][1])
            cols = (xx >= geo["x_mm"][0] + part.R_MM) & (xx <= geo["x_mm"][1] - part.R_MM)
            dv = dev[inside][:, cols]
            im = ax[0, i].imshow(dv, origin="lower", aspect="auto", cmap="viridis",
                                 extent=(xx[cols][0], xx[cols][-1], yy[inside][0], yy[inside][-1]),
                                 vmin=np.percentile(dv, 0.5), vmax=np.percentile(dv, 99.5))
            ax[0, i].set_title(f"{name}: distance from the nominal surface")
            fig.colorbar(im, ax=ax[0, i], label="um")
            mx0, my0, m = read_map(os.path.join(out, k, "whole", "rmax_map.csv"))
            block = 0.25
            m = np.where(m < 0, np.nan, m)
            ny, nx = m.shape
            im = ax[1, i].imshow(m, origin="lower", aspect="auto", cmap="magma", vmin=0, vmax=15,
                                 extent=(mx0, mx0 + nx * block, my0, my0 + ny * block))
            ax[1, i].set_ylim(geo["y_mm"][0], geo["y_mm"][1])
            ax[1, i].set_title(f"{name}: R_max per {block} mm block (plane removed)")
            fig.colorbar(im, ax=ax[1, i], label="R_max, um")
            for a in (ax[0, i], ax[1, i]):
                a.set_xlabel("x, mm")
                a.set_ylabel("y, mm")
        fig.tight_layout()
        fig.savefig(os.path.join(img, "table1_maps.png"), dpi=75)
        plt.close(fig)

    # 4. The table.
    tf, tl = (res["runs"][k]["program_time_s"] for k in ("fixed", "law"))
    ratio = (tl / tf - 1) * 100 if tf and tl else math.nan
    pf, pl = (res["runs"][k]["passes_time_s"] for k in ("fixed", "law"))
    pratio = (pl / pf - 1) * 100 if pf and pl else math.nan
    paper_ratio = (PAPER["law"]["time_s"] / PAPER["fixed"]["time_s"] - 1) * 100

    def mean_over(k, key):
        v = [r[key] for r in res["runs"][k]["regions"]]
        return sum(v) / len(v) if v else math.nan

    ft_fixed = part.FEED / (part.FLUTES * part.RPM)
    lines = [f"# Choi et al. 2005, Table 1, in the live cell (size {res['size']})", "",
             f"Part: z = {geo['z_base_mm']:g} + {geo['amplitude_mm']:g} cos(2 pi x / {geo['wavelength_mm']:g}) mm, "
             f"x {geo['x_mm'][0]:g}..{geo['x_mm'][1]:g} mm, {geo['passes']} passes along X "
             f"(y {geo['y_mm'][0]:g}..{geo['y_mm'][1]:g} mm), f_p {part.PICK_MM} mm, ball r {part.R_MM:g} mm, "
             f"{part.FLUTES} flutes, S{part.RPM} F{part.FEED}; alpha_c {geo['critical_angle_deg']:.2f} deg at "
             f"f_t {ft_fixed:.2f} mm. The NURBS passes fit the tool-tip path within {geo['nurbs_fit_error_um']:.3f} um.",
             "",
             "| | paper (a) fixed | paper (b) law | cell, fixed | cell, law |",
             "|---|---|---|---|---|",
             f"| machining time | 37 min 23 s | 38 min 10 s | {mmss(tf)} | {mmss(tl)} |",
             f"| law against fixed | | +{paper_ratio:.1f} % | | {ratio:+.1f} % |",
             f"| the finishing passes alone (first G6.2 to the last pass's end) | | | {mmss(pf)} | {mmss(pl)} ({pratio:+.1f} %) |",
             f"| R_max where \\|alpha\\| < alpha_c, along X (mean of the profiles) | 5.4 um | 4.1 um | "
             f"{mean_over('fixed', 'rmax_profile_x_mean_um'):.2f} um | {mean_over('law', 'rmax_profile_x_mean_um'):.2f} um |",
             f"| the same, areal (every cell of the band) | | | {mean_over('fixed', 'rmax_um'):.2f} um | "
             f"{mean_over('law', 'rmax_um'):.2f} um |",
             "| target R_max f_p^2/(4r) | 3.3 um | 3.3 um | 3.3 um | 3.3 um |",
             f"| the extended model at alpha = 0 | | | {model_rmax_um(ft_fixed, 0):.2f} um (f_t {ft_fixed:.2f}) | 3.30 um |",
             "",
             "Per measured region (band y "
             f"{res['runs']['fixed']['regions'][0]['window'][1]:.2f}..{res['runs']['fixed']['regions'][0]['window'][3]:.2f} mm):"
             if regs else "", "",
             "| run | region | x, mm | R_max areal, um | along X mean / max, um | model at the middle pass, um | actual f_t there, mm |",
             "|---|---|---|---|---|---|---|"]
    for k, name in RUNS:
        for r in res["runs"][k]["regions"]:
            lines.append(f"| {name} | {r['kind']} | {r['window'][0]:.2f}..{r['window'][2]:.2f} | {r['rmax_um']:.2f} | "
                         f"{r['rmax_profile_x_mean_um']:.2f} / {r['rmax_profile_x_max_um']:.2f} | "
                         f"{r['model_um']} | {r['feed_per_tooth_mm']} |")
    lines += ["", "| run | spindle while moving, rpm (mean, min..max) | largest following error | cnc-ctl wall time |",
              "|---|---|---|---|"]
    for k, name in RUNS:
        r = res["runs"][k]
        fe = r["summary"].get("largest_following_error_mm")
        lines.append(f"| {name} | {r['spindle_rpm_mean']:.1f} ({r['spindle_rpm_min']:.1f}..{r['spindle_rpm_max']:.1f}) | "
                     f"{fe * 1e3 if fe is not None else math.nan:.1f} um ({r['summary'].get('largest_following_error_axis', '')}) | "
                     f"{mmss(r['wall_s'])} |")
    lines += ["", "![feed along the path](img/table1_feed.png)", ""]
    if regs:
        lines += ["![both surfaces in the first measured region](img/table1_surfaces.png)", "",
                  "![profiles along X](img/table1_profiles.png)", ""]
    if have_whole:
        lines += ["![the whole strip: surfaces and R_max maps](img/table1_maps.png)", ""]
    with open(os.path.join(out, "table1.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines[:16]))


if __name__ == "__main__":
    main()
