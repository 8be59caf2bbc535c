#!/usr/bin/env python3
"""Compares two x,y,z CSV files point by point (same points, same order): how many
points each touched, and the largest |dz| over the points both touched."""
import sys


def read(path):
    with open(path) as f:
        next(f)
        return [line.rstrip("\n").split(",") for line in f]


def main():
    a, b = read(sys.argv[1]), read(sys.argv[2])
    if len(a) != len(b):
        sys.exit(f"{sys.argv[1]}: {len(a)} points, {sys.argv[2]}: {len(b)}")
    worst, where, only_a, only_b = 0.0, None, 0, 0
    for ra, rb in zip(a, b):
        if ra[:2] != rb[:2]:
            sys.exit(f"points differ: {ra[:2]} vs {rb[:2]}")
        if not ra[2] or not rb[2]:
            only_a += bool(ra[2]) and not rb[2]
            only_b += bool(rb[2]) and not ra[2]
            continue
        dz = abs(float(ra[2]) - float(rb[2]))
        if dz > worst:
            worst, where = dz, ra
    print(f"points={len(a)} max_abs_dz={worst:.3g} at={where[:2] if where else '-'} "
          f"touched_only_first={only_a} touched_only_second={only_b}")


if __name__ == "__main__":
    main()
