#!/usr/bin/env python3
"""Pictures of cnc-cam output (matplotlib).

    plot_cam.py --xyz XYZ.csv [--ngc PART.ngc] --out PICTURE.png [--title T]

--xyz: `cnc-cam drop` output on a regular grid of points: the CL surface as a shaded
height map (points the cutter does not touch left blank). --ngc: a cnc-cam program
drawn over it, G1 moves as lines, in the program's coordinates (pass the same --origin
mesh to cnc-cam raster for the two to line up)."""
import argparse
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LightSource  # noqa: E402


def read_xyz(path):
    xs, ys, zs = [], [], []
    with open(path) as f:
        next(f)
        for line in f:
            x, y, z = line.rstrip("\n").split(",")
            xs.append(float(x))
            ys.append(float(y))
            zs.append(float(z) if z else np.nan)
    ux, uy = np.unique(xs), np.unique(ys)
    grid = np.full((len(uy), len(ux)), np.nan)
    ix, iy = np.searchsorted(ux, xs), np.searchsorted(uy, ys)
    grid[iy, ix] = zs
    return ux, uy, grid


def read_moves(path):
    """G1 polylines of a cnc-cam program: lists of (x, y), split at every G0."""
    pos = {"X": 0.0, "Y": 0.0}
    modal, runs, run = 0, [], []
    with open(path) as f:
        for raw in f:
            line = re.sub(r"\(.*?\)", "", raw).upper()
            for g in re.findall(r"G\s*0*([01])(?![0-9.])", line):
                modal = int(g)
            words = dict((a, float(v)) for a, v in re.findall(r"([XYZ])\s*([-+]?[0-9.]+)", line))
            if not words:
                continue
            start = (pos["X"], pos["Y"])
            pos.update({k: v for k, v in words.items() if k in pos})
            if modal == 1:
                if not run:
                    run.append(start)
                run.append((pos["X"], pos["Y"]))
            elif run:
                runs.append(run)
                run = []
    if run:
        runs.append(run)
    return runs


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--xyz", required=True)
    ap.add_argument("--ngc")
    ap.add_argument("--out", required=True)
    ap.add_argument("--title", default="")
    a = ap.parse_args()
    ux, uy, z = read_xyz(a.xyz)
    fig, ax = plt.subplots(figsize=(9, 9 * len(uy) / max(len(ux), 1) + 1))
    ls = LightSource(azdeg=315, altdeg=45)
    zf = np.where(np.isnan(z), np.nanmin(z), z)
    dx = (ux[-1] - ux[0]) / max(len(ux) - 1, 1)
    rgb = ls.shade(zf, cmap=plt.cm.terrain, vert_exag=1.0, dx=dx, dy=dx, blend_mode="soft")
    rgb[np.isnan(z)] = 1.0
    ax.imshow(rgb, origin="lower", extent=(ux[0], ux[-1], uy[0], uy[-1]))
    sm = plt.cm.ScalarMappable(cmap=plt.cm.terrain, norm=plt.Normalize(np.nanmin(z), np.nanmax(z)))
    fig.colorbar(sm, ax=ax, label="CL z, mm", shrink=0.8)
    if a.ngc:
        for run in read_moves(a.ngc):
            r = np.array(run)
            ax.plot(r[:, 0], r[:, 1], lw=0.5, color="k")
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_title(a.title or a.xyz)
    fig.tight_layout()
    fig.savefig(a.out, dpi=120)


if __name__ == "__main__":
    main()
