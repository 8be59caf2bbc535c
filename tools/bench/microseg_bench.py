#!/usr/bin/python3
"""Micro-segment bench: CAM-style programs of short G1 moves through the
dry run (cnc-plan) under G61, G64 P with corner blends only, G64 P with spline
fitting, and (the surface) the exact NURBS program they were sampled from.

For each: machining time, the programmed time (each move's length over its feed,
rapids at the least axis-velocity limit along them), their ratio, the largest
distance of a programmed point from the path the setpoints draw, the peak use of
the axis limits (cnc-plan's finite differences), and the wall time of the dry run.
A feed plot (matplotlib) per program. With --linuxcnc the raster also runs on
LinuxCNC 2.9's planner (../shared/tools/linuxcnc_sim/run.sh), side by side.

  microseg_bench.py --plan build/tools/cnc-plan --machine config/machines/sim3.yaml
                    --out runs/microseg [--tol 0.01] [--surface-moves 100000] [--linuxcnc DIR]
"""
import argparse
import csv
import math
import os
import re
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import microseg_programs  # noqa: E402


def program_points(path):
    """The programmed end points of G0/G1 moves in order (absolute X Y Z, mm), with the
    feed of each (None for G0); G6.2 curves are skipped (their points are controls)."""
    pos = [0.0, 0.0, 0.0]
    pts = []
    feed = None
    mode = None
    for line in open(path):
        line = line.split("(")[0].strip().upper()
        if not line or line.startswith("K") or line.startswith("G6.2"):
            continue
        words = dict(re.findall(r"([A-Z])([-+]?[0-9.]+)", line))
        for g in re.findall(r"G([0-9.]+)", line):
            if g in ("0", "00"):
                mode = 0
            elif g in ("1", "01"):
                mode = 1
        if "F" in words:
            feed = float(words["F"])
        moved = False
        for i, a in enumerate("XYZ"):
            if a in words:
                pos[i] = float(words[a])
                moved = True
        if moved and mode in (0, 1):
            pts.append((tuple(pos), None if mode == 0 else feed))
    return pts


def programmed_time(pts, vmax):
    t = 0.0
    prev = (0.0, 0.0, 0.0)
    for p, f in pts:
        d = [p[i] - prev[i] for i in range(3)]
        L = math.sqrt(sum(x * x for x in d))
        if L > 0:
            if f is None:
                v = min(vmax[i] / (abs(d[i]) / L) for i in range(3) if d[i] != 0)
            else:
                v = f / 60.0
            t += L / v
        prev = p
    return t



def read_csv(path):
    rows = list(csv.DictReader(open(path)))
    xyz = np.array([[float(r["x_mm"]), float(r["y_mm"]), float(r["z_mm"])] for r in rows])
    t = np.array([float(r["t_s"]) for r in rows])
    f = np.array([float(r["feed_mm_min"]) for r in rows])
    return t, xyz, f


def max_deviation(points, xyz):
    """Largest distance of a programmed point from the polyline through the setpoints
    (both in path order: a window search around the last match)."""
    P = np.vstack([np.zeros((1, 3)), xyz])
    A, B = P[:-1], P[1:]
    D = B - A
    DD = np.maximum((D * D).sum(axis=1), 1e-300)
    j = 0
    worst = 0.0
    n = len(A)
    for q in points:
        q = np.asarray(q)
        best, best_k = 1e300, j
        lo, hi = max(0, j - 20), min(n, j + 400)
        while True:
            W = q - A[lo:hi]
            t = np.clip((W * D[lo:hi]).sum(axis=1) / DD[lo:hi], 0, 1)
            E = W - t[:, None] * D[lo:hi]
            e = np.sqrt((E * E).sum(axis=1))
            k = int(np.argmin(e))
            if e[k] < best:
                best, best_k = float(e[k]), lo + k
            if best < 0.05 or hi >= n:
                break
            lo, hi = hi, min(n, hi + 4000)  # far from the window: search on
        worst = max(worst, best)
        j = best_k
    return worst


def plan(args, program, machine, csv_path):
    t0 = time.perf_counter()
    p = subprocess.run([args.plan, "--machine", machine, "--program", program, "--csv", csv_path],
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit("cnc-plan failed on %s: %s" % (program, p.stderr.strip()))
    use = re.search(r"peak use of the axis limits[^:]*: (.*)", p.stdout)
    blocks = re.search(r"(\d+) blocks", p.stdout)
    return wall, (use.group(1).strip() if use else ""), int(blocks.group(1)) if blocks else 0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--plan", required=True)
    ap.add_argument("--machine", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--tol", type=float, default=0.01)
    ap.add_argument("--surface-moves", type=int, default=100000)
    ap.add_argument("--linuxcnc", default="", help="run the raster on LinuxCNC too (the linuxcnc_sim folder)")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    import subprocess as sp  # noqa
    sp.run([sys.executable, os.path.join(HERE, "microseg_programs.py"), a.out, "--tol", str(a.tol),
            "--surface-moves", str(a.surface_moves)], check=True)
    # The same machine with the spline fit off: G64 P then only rounds corners.
    blend_cfg = os.path.join(a.out, "machine_blend_only.yaml")
    text = open(a.machine).read()
    base = os.path.dirname(os.path.abspath(a.machine))
    text = text.replace("\nprogram:\n", "\nprogram:\n  g64_fit: false\n") if "\nprogram:\n" in text \
        else text + "\nprogram:\n  g64_fit: false\n"
    with open(blend_cfg, "w") as f:
        f.write(text)
    # Relative paths in the machine file resolve from its folder: keep it there.
    blend_cfg_in_place = os.path.join(base, ".microseg_blend_only.yaml")
    with open(blend_cfg_in_place, "w") as f:
        f.write(text)
    vmax = [250.0, 250.0, 150.0]
    m = re.findall(r"max_velocity_mm_s:\s*([0-9.]+)", open(a.machine).read())
    if len(m) >= 3:
        vmax = [float(x) for x in m[:3]]

    cases = [
        ("raster", [("G61", "raster_g61.ngc", a.machine), ("G64 P blend", "raster_g64.ngc", blend_cfg_in_place),
                    ("G64 P fit", "raster_g64.ngc", a.machine)]),
        ("surface", [("exact NURBS", "surface_nurbs.ngc", a.machine), ("G61", "surface_g61.ngc", a.machine),
                     ("G64 P blend", "surface_g64.ngc", blend_cfg_in_place),
                     ("G64 P fit", "surface_g64.ngc", a.machine)]),
    ]
    results = {}
    try:
        for name, variants in cases:
            pts = program_points(os.path.join(a.out, variants[-1][1]))
            t_prog = programmed_time(pts, vmax)
            print("%s: %d programmed points, programmed time %.3f s (lengths over feeds)" % (name, len(pts), t_prog))
            for label, prog, machine in variants:
                csv_path = os.path.join(a.out, "%s_%s.csv" % (name, label.replace(" ", "_")))
                wall, use, blocks = plan(a, os.path.join(a.out, prog), machine, csv_path)
                t, xyz, f = read_csv(csv_path)
                T = t[-1] + (t[1] - t[0])
                dev = max_deviation([p for p, _ in pts], xyz) if label != "exact NURBS" else float("nan")
                results[(name, label)] = (t, f)
                print("  %-12s time %8.3f s  %6.1f %% of programmed  blocks %6d  largest point deviation %s  "
                      "dry run %.2f s wall  | %s" % (label, T, 100 * T / t_prog, blocks,
                                                      "%.4f mm" % dev if dev == dev else "   -    ", wall, use))
    finally:
        os.remove(blend_cfg_in_place)
    if a.linuxcnc:
        run_sh = os.path.join(a.linuxcnc, "run.sh")
        work = os.path.join(a.out, "linuxcnc")
        os.makedirs(work, exist_ok=True)
        p = sp.run([run_sh, work, os.path.join(a.out, "raster_g64.ngc"), os.path.join(a.out, "raster_g61.ngc")],
                   capture_output=True, text=True, timeout=600)
        print("LinuxCNC 2.9 (its planner, sim3's limits, wall time from AUTO_RUN to idle):")
        for line in p.stdout.splitlines():
            if line.strip():
                print("  " + line.strip())
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, axes = plt.subplots(2, 1, figsize=(11, 7.5))
    for ax, (name, window) in zip(axes, [("raster", None), ("surface", (20.0, 26.0))]):
        for (n, label), (t, f) in results.items():
            if n != name:
                continue
            sel = np.ones_like(t, dtype=bool) if window is None else (t >= window[0]) & (t <= window[1])
            ax.plot(t[sel], f[sel], lw=0.9, label=label)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("feed (mm/min)")
        ax.set_title("%s: feed along the path (G64 P%g)%s" % (name, a.tol, "" if window is None else
                                                            ", %g-%g s" % window))
        ax.legend(loc="lower right")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    png = os.path.join(a.out, "microseg_feed.png")
    fig.savefig(png, dpi=110)
    print("feed plot: %s" % png)


if __name__ == "__main__":
    main()
