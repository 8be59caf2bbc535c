#!/usr/bin/env python3
"""A 3D finishing program of N lines, as a CAM post writes one: a zig-zag raster
of short G1 segments over a smooth surface, one line per segment.

    finishing_program.py --lines 10000000 --out /tmp/finish10m.ngc

The surface is z = -3 + 1.5 sin(x / 25) cos(y / 40) (mm): its curvature is small
(under 2.4e-3 /mm), so consecutive segments of --step mm turn by under 1e-3 rad and
the planner runs them at the programmed feed; the rows run along X over --width mm,
--pick mm apart, each joined to the next by one G1 along Y. Coordinates are written
with 4 decimals, as posts do; a line `G1 X.. Y.. Z..` each (the Y of a row repeated:
the words a post writes when it does not drop unchanged ones). The feed is set once.
The program is G21 G90 G17 G94 G61 (exact path) from X0 Y0 at Z5, ends with M2 and
stays inside sim3's travel for --width up to 390 and rows * --pick up to 290 (10 M
lines by default: 2,564 rows of 3,900 segments over 390 x 128 mm, 1,000 m at 600 mm/s).
"""
import argparse
import math
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lines", type=int, default=10_000_000, help="lines of the program (default 10,000,000)")
    ap.add_argument("--step", type=float, default=0.1, help="segment length along X, mm (default 0.1)")
    ap.add_argument("--width", type=float, default=390.0, help="length of a row along X, mm (default 390)")
    ap.add_argument("--pick", type=float, default=0.05, help="distance between rows along Y, mm (default 0.05)")
    ap.add_argument("--feed", type=float, default=36000.0, help="F, mm/min (default 36000)")
    ap.add_argument("--out", required=True, help="the program's path")
    a = ap.parse_args()
    per_row = int(round(a.width / a.step))
    header = ["(finishing_program.py: %d lines, raster %g mm x %g mm steps, pick %g mm, F%g)" %
              (a.lines, a.width, a.step, a.pick, a.feed),
              "G21 G90 G17 G94 G61", "G0 X0.0000 Y0.0000 Z5.0000"]
    moves = a.lines - len(header) - 2  # the first G1 (with F) and M2
    if moves < 1:
        sys.exit("finishing_program.py: --lines %d is too few" % a.lines)

    def z(x, y):
        return -3.0 + 1.5 * math.sin(x / 25.0) * math.cos(y / 40.0)

    with open(a.out, "w", buffering=1 << 22) as f:
        f.write("\n".join(header) + "\n")
        f.write("G1 X0.0000 Y0.0000 Z%.4f F%g\n" % (z(0.0, 0.0), a.feed))
        xs = [a.step * k for k in range(per_row + 1)]
        sin_x = [1.5 * math.sin(x / 25.0) for x in xs]
        row, k, forward = 0, 0, True  # at (xs[k], row * pick)
        out = []
        written = 0
        while written < moves:
            y = row * a.pick
            if (forward and k == per_row) or (not forward and k == 0):
                row += 1  # the link to the next row, along Y
                forward = not forward
                y = row * a.pick
            else:
                k += 1 if forward else -1
            out.append("G1 X%.4f Y%.4f Z%.4f\n" % (xs[k], y, -3.0 + sin_x[k] * math.cos(y / 40.0)))
            written += 1
            if len(out) >= 65536:
                f.write("".join(out))
                out.clear()
        f.write("".join(out))
        f.write("M2\n")


if __name__ == "__main__":
    main()
