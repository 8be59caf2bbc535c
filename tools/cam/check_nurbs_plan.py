#!/usr/bin/python3
"""How far the dry run of a cnc-cam program written as G6.2 NURBS strays from its CL points.

    check_nurbs_plan.py LINES.ngc NURBS.ngc PLAN.csv

LINES.ngc: the same cnc-cam program written with G1 lines (its G1 end points are the CL
points; its G1 segments the CL polyline); NURBS.ngc: the one written with --nurbs;
PLAN.csv: `./cnc plan NURBS.ngc --csv PLAN.csv`. Prints
  cl_points, max_cl_to_plan_mm: every CL point's distance to the dry run's path along
      the curves (the polyline through their setpoints);
  setpoints, max_plan_to_cl_mm: every setpoint of a G6.2 curve's distance to the CL
      polyline.
Needs numpy (Debian's python3-numpy, which python3-matplotlib brings)."""
import csv
import re
import sys

import numpy as np


def g1_moves(path):
    """(start, end) of every G1 move, in order."""
    pos = {"X": None, "Y": None, "Z": None}
    modal, out = None, []
    for raw in open(path):
        line = re.sub(r"\(.*?\)", "", raw).strip().upper()
        for g in re.findall(r"G\s*([0-9.]+)", line):
            modal = {"0": 0, "1": 1}.get(g, -1)
        words = dict((m.group(1), float(m.group(2))) for m in re.finditer(r"([XYZ])\s*([-+]?[0-9.]+)", line))
        if not words:
            continue
        start = dict(pos)
        pos.update(words)
        if modal == 1 and None not in start.values():
            out.append(((start["X"], start["Y"], start["Z"]), (pos["X"], pos["Y"], pos["Z"])))
    return out


def curve_lines(path):
    """Line numbers (from 1) of the G6.2 curves: the G6.2 line and its K lines after it."""
    out, inside = set(), False
    for no, raw in enumerate(open(path), start=1):
        line = raw.strip().upper()
        inside = line.startswith("G6.2") or (inside and line.startswith("K"))
        if inside:
            out.add(no)
    return out


def dist_to_polyline(points, a, b, chunk=128):
    """Distance of each point to the nearest of segments a[i]-b[i] (all of them, in chunks)."""
    ab = b - a
    n = np.einsum("ij,ij->i", ab, ab)
    safe = np.where(n > 0, n, 1)
    out = np.empty(len(points))
    for lo in range(0, len(points), chunk):
        p = points[lo:lo + chunk, None, :]                       # (c, 1, 3)
        t = np.clip(np.einsum("cij,ij->ci", p - a[None], ab) / safe, 0, 1)
        t = np.where(n > 0, t, 0)
        d = np.linalg.norm(a[None] + t[..., None] * ab[None] - p, axis=2)
        out[lo:lo + chunk] = d.min(axis=1)
    return out


def main():
    moves = g1_moves(sys.argv[1])
    a = np.array([m[0] for m in moves])
    b = np.array([m[1] for m in moves])
    cl = b
    rows = list(csv.DictReader(open(sys.argv[3])))
    sp = np.array([[float(r["x_mm"]), float(r["y_mm"]), float(r["z_mm"])] for r in rows])
    curves = curve_lines(sys.argv[2])
    on_curve = np.array([int(r["line"]) in curves for r in rows])
    # The dry run's path along the curves: segments between consecutive setpoints both on
    # G6.2 lines (the CL points all lie on the curves; rapids and plunges are left out).
    both = on_curve[:-1] & on_curve[1:]
    d_cl = dist_to_polyline(cl, sp[:-1][both], sp[1:][both])
    d_sp = dist_to_polyline(sp[on_curve], a, b)
    print(f"cl_points={len(cl)} max_cl_to_plan_mm={d_cl.max():.3g} setpoints={int(on_curve.sum())} "
          f"max_plan_to_cl_mm={d_sp.max():.3g}")


if __name__ == "__main__":
    main()
