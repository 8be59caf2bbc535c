#!/usr/bin/env python3
"""Pictures of cnc-cam output (matplotlib).

    plot_cam.py --xyz XYZ.csv [--ngc PART.ngc | --paths CUTS.csv] --out PICTURE.png [--title T]

--xyz: `cnc-cam drop` output: on a regular grid of points, the CL surface as a shaded
height map (points the cutter does not touch left blank); other points as dots
coloured by height. --ngc: a cnc-cam program drawn over it, G1 moves as lines, in the
program's coordinates (pass the same --origin mesh to cnc-cam raster for the two to
line up). --paths: CL points as `cut,x,y,z` lines (cnc-cam raster --png writes them),
each cut a line with its points as dots.

`cnc-cam drop --png` and `cnc-cam raster --png` run this with Debian's /usr/bin/python3."""
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
    if len(ux) * len(uy) != len(xs) or len(ux) < 2 or len(uy) < 2:
        return None, (np.array(xs), np.array(ys)), np.array(zs)  # not a grid
    grid = np.full((len(uy), len(ux)), np.nan)
    ix, iy = np.searchsorted(ux, xs), np.searchsorted(uy, ys)
    grid[iy, ix] = zs
    return ux, uy, grid


def read_cuts(path):
    cuts = {}
    with open(path) as f:
        next(f)
        for line in f:
            k, x, y, _ = line.rstrip("\n").split(",")
            cuts.setdefault(int(k), []).append((float(x), float(y)))
    return [np.array(c) for _, c in sorted(cuts.items())]


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
    ap.add_argument("--paths")
    ap.add_argument("--out", required=True)
    ap.add_argument("--title", default="")
    a = ap.parse_args()
    ux, uy, z = read_xyz(a.xyz)
    if ux is None:  # scattered points
        (px, py), span = uy, (1.0, 1.0)
        if len(px) > 0:
            span = (max(np.ptp(px), 1e-9), max(np.ptp(py), 1e-9))
        fig, ax = plt.subplots(figsize=(9, min(9 * span[1] / span[0] + 1, 16)))
        on = ~np.isnan(z)
        ax.scatter(px[~on], py[~on], s=2, color="0.7", label="touches nothing")
        sc = ax.scatter(px[on], py[on], c=z[on], s=4, cmap=plt.cm.terrain)
        fig.colorbar(sc, ax=ax, label="CL z, mm", shrink=0.8)
        ax.set_aspect("equal")
    else:
        fig, ax = plt.subplots(figsize=(9, min(9 * len(uy) / max(len(ux), 1) + 1, 16)))
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
    if a.paths:
        cuts = read_cuts(a.paths)
        n = sum(len(c) for c in cuts)
        for c in cuts:
            ax.plot(c[:, 0], c[:, 1], lw=0.5, color="k")
            if n <= 20000:
                ax.plot(c[:, 0], c[:, 1], ".", ms=1.5, color="tab:red")
        ax.plot([], [], lw=0.5, color="k", label=f"{len(cuts)} cuts")
        if n <= 20000:
            ax.plot([], [], ".", color="tab:red", label=f"{n} CL points")
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_title(a.title or a.xyz)
    fig.tight_layout()
    fig.savefig(a.out, dpi=120)


if __name__ == "__main__":
    main()
