#!/usr/bin/env python3
"""How far the dry run of a cnc-cam program strays from its CL path.

    check_plan.py PROGRAM.ngc PLAN.csv

PROGRAM.ngc: G-code as cnc-cam writes it (G0/G1 with X Y Z words, one move a line);
PLAN.csv: `./cnc plan PROGRAM --csv PLAN.csv` (cnc-plan's setpoints, with the program
line of each). For every setpoint of a G1 line, the distance to that line's segment
(from the previous programmed point to its own); prints the largest, where it is,
and the count of setpoints checked. The writer rounds to 1e-4 mm, so a path that
follows its lines stays within about 1e-4 mm."""
import csv
import math
import re
import sys


def segments(path):
    pos = {"X": None, "Y": None, "Z": None}
    modal = None
    seg = {}
    with open(path) as f:
        for no, raw in enumerate(f, start=1):
            line = re.sub(r"\(.*?\)", "", raw).strip().upper()
            words = dict((m.group(1), m.group(2)) for m in re.finditer(r"([A-Z])\s*([-+]?[0-9.]+)", line))
            if "G" in words and words["G"] in ("0", "1"):
                modal = int(words["G"])
            for g in re.findall(r"G\s*([0-9.]+)", line):
                if g in ("0", "1"):
                    modal = int(g)
            if not any(a in words for a in "XYZ"):
                continue
            start = dict(pos)
            for a in "XYZ":
                if a in words:
                    pos[a] = float(words[a])
            if modal == 1 and None not in start.values():
                seg[no] = ((start["X"], start["Y"], start["Z"]), (pos["X"], pos["Y"], pos["Z"]))
    return seg


def dist(p, a, b):
    ab = [b[i] - a[i] for i in range(3)]
    ap = [p[i] - a[i] for i in range(3)]
    n = sum(c * c for c in ab)
    t = 0.0 if n == 0 else max(0.0, min(1.0, sum(ab[i] * ap[i] for i in range(3)) / n))
    return math.dist(p, [a[i] + t * ab[i] for i in range(3)])


def main():
    seg = segments(sys.argv[1])
    worst, where, checked = 0.0, None, 0
    with open(sys.argv[2]) as f:
        for row in csv.DictReader(f):
            line = int(row["line"])
            if line not in seg:
                continue
            p = (float(row["x_mm"]), float(row["y_mm"]), float(row["z_mm"]))
            d = dist(p, *seg[line])
            checked += 1
            if d > worst:
                worst, where = d, (line, p)
    print(f"setpoints_checked={checked} max_distance_mm={worst:.3g} at_line={where[0] if where else '-'}")


if __name__ == "__main__":
    main()
