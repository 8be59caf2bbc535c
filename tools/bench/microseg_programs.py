#!/usr/bin/python3
"""Part programs for the micro-segment bench: CAM-style runs of short G1
moves, and the exact NURBS program they were sampled from.

  raster   a raster over a gently curved surface: 10 rows of 200 moves of 0.3 mm,
           1-mm step-overs, coordinates to 3 decimals, F3000 (as a CAM post writes it)
  surface  a 3-D surface path: 40 rows, 1 mm apart, that are cubic B-splines in X Y Z
           (G6.2, order 4, a control point every 2 mm), and the same rows sampled every
           0.1 mm of arc length as G1 moves (3 decimals)

Each program is written in the path-control modes the bench compares: G61 (exact
path), G64 P<tol>; the surface also as the exact G6.2 program.

  microseg_programs.py OUTDIR [--tol 0.01] [--surface-moves 100000]
"""
import argparse
import math
import os


def surface_z(x, y):
    # Gently curved: radii of curvature of about 75 mm and more (the raster's surface).
    return -10.0 + 3.0 * math.sin(x / 15.0) * math.cos(y / 25.0)


def wavy_z(x, y):
    # The surface path's: radii of curvature down to about 9 mm along X.
    return -10.0 + 4.0 * math.sin(x / 6.0) * math.cos(y / 25.0)


def write(path, header, body):
    with open(path, "w") as f:
        f.write("(%s)\n" % os.path.basename(path))
        f.write("G21 G17 G90 G54 G40 G49 G80\n")
        f.write(header + "\n")
        f.write(body)
        f.write("G0 Z5\nM2\n")


def raster(fmt="%.3f"):
    lines = []
    x0, y0 = 10.0, 10.0
    lines.append("G0 X%s Y%s Z2" % (fmt % x0, fmt % y0))
    lines.append("G1 Z%s F1000" % (fmt % surface_z(x0, y0)))
    lines.append("F3000")
    for row in range(10):
        y = y0 + row * 1.0
        xs = [x0 + i * 0.3 for i in range(201)]
        if row % 2:
            xs.reverse()
        if row > 0:
            lines.append("G1 X%s Y%s Z%s" % (fmt % xs[0], fmt % y, fmt % surface_z(xs[0], y)))
        for x in xs[1:]:
            lines.append("G1 X%s Y%s Z%s" % (fmt % x, fmt % y, fmt % surface_z(x, y)))
    return "\n".join(lines) + "\n"


# --- the surface path: each row a clamped cubic B-spline in X Y Z -----------------

def row_curve(row, length, n_ctrl):
    """Control points and knots of row `row`: X from 10 to 10+length, Y fixed, Z on the
    surface at the control points' X (a smooth curve near the surface)."""
    y = 10.0 + row * 1.0
    ctrl = []
    for i in range(n_ctrl):
        x = 10.0 + length * i / (n_ctrl - 1)
        ctrl.append((x, y, wavy_z(x, y)))
    if row % 2:
        ctrl.reverse()
    spans = n_ctrl - 3
    knots = [0.0] * 4 + [k / spans for k in range(1, spans)] + [1.0] * 4
    return ctrl, knots


def basis_point(ctrl, knots, u):
    p = 3
    n = len(ctrl)
    if u >= knots[n]:
        k = n - 1
    else:
        k = p
        while knots[k + 1] <= u:
            k += 1
    # de Boor
    d = [list(ctrl[j + k - p]) for j in range(p + 1)]
    for r in range(1, p + 1):
        for j in range(p, r - 1, -1):
            i = j + k - p
            den = knots[i + p - r + 1] - knots[i]
            a = (u - knots[i]) / den if den else 0.0
            d[j] = [(1 - a) * d[j - 1][c] + a * d[j][c] for c in range(3)]
    return d[p]


def sample_by_length(ctrl, knots, step):
    # Dense polyline, then points every `step` of arc length along it.
    dense = [basis_point(ctrl, knots, i / 20000.0) for i in range(20001)]
    out = [dense[0]]
    acc = 0.0
    for a, b in zip(dense, dense[1:]):
        seg = math.dist(a, b)
        while acc + seg >= step:
            t = (step - acc) / seg
            p = [a[c] + t * (b[c] - a[c]) for c in range(3)]
            out.append(p)
            a = p
            seg = math.dist(a, b)
            acc = 0.0
        acc += seg
    if math.dist(out[-1], dense[-1]) > 1e-9:
        out.append(dense[-1])
    return out


def surface(moves, fmt="%.3f"):
    rows = 40
    length = moves * 0.1 / rows
    n_ctrl = max(6, int(length / 2))
    exact, sampled = [], []
    for r in range(rows):
        ctrl, knots = row_curve(r, length, n_ctrl)
        x, y, z = ctrl[0]
        # Both programs reach the row's start exactly (G6.2 starts where the tool is).
        move = ("G0 X%.6f Y%.6f Z2\nG1 Z%.6f F1000\n" % (x, y, z)) if r == 0 else \
               ("G1 X%.6f Y%.6f Z%.6f\n" % (x, y, z))
        exact.append(move)
        sampled.append(move)
        # G6.2: the first control point is where the tool stands.
        e = ["G6.2 P4 K%.6f X%.6f Y%.6f Z%.6f R1 F3000" % (knots[0], *ctrl[0])]
        for i in range(1, len(ctrl)):
            e.append("K%.6f X%.6f Y%.6f Z%.6f R1" % (knots[i], *ctrl[i]))
        for k in knots[len(ctrl):]:
            e.append("K%.6f" % k)
        exact.append("\n".join(e) + "\n")
        pts = sample_by_length(ctrl, knots, 0.1)
        s = ["F3000"]
        for p in pts[1:]:
            s.append("G1 X%s Y%s Z%s" % (fmt % p[0], fmt % p[1], fmt % p[2]))
        sampled.append("\n".join(s) + "\n")
    return "".join(exact), "".join(sampled)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("outdir")
    ap.add_argument("--tol", type=float, default=0.01)
    ap.add_argument("--surface-moves", type=int, default=100000)
    a = ap.parse_args()
    os.makedirs(a.outdir, exist_ok=True)
    r = raster()
    write(os.path.join(a.outdir, "raster_g61.ngc"), "G61", r)
    write(os.path.join(a.outdir, "raster_g64.ngc"), "G64 P%g" % a.tol, r)
    exact, sampled = surface(a.surface_moves)
    write(os.path.join(a.outdir, "surface_nurbs.ngc"), "G61", exact)
    write(os.path.join(a.outdir, "surface_g61.ngc"), "G61", sampled)
    write(os.path.join(a.outdir, "surface_g64.ngc"), "G64 P%g" % a.tol, sampled)


if __name__ == "__main__":
    main()
