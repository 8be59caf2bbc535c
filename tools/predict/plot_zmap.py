#!/usr/bin/env python3
"""Plots of `cnc-predict zmap-check --out DIR` (Choi et al. 2005's Z-map check).

  plot_zmap.py DIR   ->  DIR/zmap_vs_model.png   R_max over α: Z-map points, extended model lines,
                                                 the difference map over (α, f_t), and (when
                                                 DIR/converge.txt holds `cnc-predict-bench
                                                 zmap-converge`'s output) the α_c case's
                                                 difference against the grid pitch
                         DIR/zmap_surfaces.png   the simulated surfaces at α = 0°, α_c and 10° (f_t = f_p)
"""
import csv
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def critical_angle(r, ft, fp):
    q = ft - fp / (2 * math.pi)
    a = fp * fp + q * q
    rad = (a / (8 * r)) ** 2 - a / 4 + ft * ft
    return math.asin(min(1.0, math.sqrt(rad) / r)) if rad > 0 else 0.0


def rmax_extended(r, ft, fp, alpha):
    """roughness.h's rmax_extended (eqs. 2-4, p = f_p/2π), for drawing the model finely."""
    if abs(alpha) < critical_angle(r, ft, fp):
        x = (ft / r) ** 2 - math.sin(alpha) ** 2
        return r * x / (1 + math.sqrt(max(0.0, 1 - x)))
    q = (ft - fp / (2 * math.pi)) / fp
    return fp * fp / (8 * r) * (1 + q * q)


def read_grid(path):
    rows = list(csv.DictReader(open(path)))
    return [{k: float(v) for k, v in r.items()} for r in rows]


def read_matrix(path):
    out = []
    pitch = 1.0
    for line in open(path):
        if line.startswith("#"):
            if "pitch_mm=" in line:
                pitch = float(line.split("pitch_mm=")[1])
            continue
        out.append([float(v) for v in line.split(",")])
    return out, pitch


def main():
    d = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
    grid = read_grid(d / "rmax_grid.csv")
    cases = list(csv.DictReader(open(d / "rmax_cases.csv")))
    fts = sorted({r["ft_mm"] for r in grid})
    conv = d / "converge.txt"
    conv_rows = []
    if conv.exists():
        for line in open(conv):
            if "step_deg=0.50 pitch_um=" in line:
                kv = dict(w.split("=") for w in line.split() if "=" in w)
                conv_rows.append((float(kv["pitch_um"]), float(kv["diff_um"])))
    if conv_rows:
        fig, (ax, ax2, ax3) = plt.subplots(1, 3, figsize=(19, 5.5), gridspec_kw={"width_ratios": [1.2, 1.2, 0.8]})
    else:
        fig, (ax, ax2) = plt.subplots(1, 2, figsize=(14, 5.5))
    cmap = plt.get_cmap("viridis")
    for n, ft in enumerate(fts):
        pts = sorted((r["alpha_deg"], r["zmap_um"], r["model_um"]) for r in grid if r["ft_mm"] == ft)
        c = cmap(n / max(1, len(fts) - 1))
        fine = [i * 0.05 for i in range(int(max(p[0] for p in pts) / 0.05) + 1)]
        ax.plot(fine, [1e3 * rmax_extended(5.0, ft, 0.5, math.radians(a)) for a in fine], "-", color=c, lw=1.2)
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o", color=c, ms=3.5, label=f"f_t={ft:.3f}")
    for cs in cases:
        ax.plot(float(cs["alpha_deg"]), float(cs["zmap_um"]), "kx", ms=8)
    ax.set_xlabel("feed inclination α [deg]")
    ax.set_ylabel("R_max [µm]")
    ax.set_title("Z-map of the rotating edges (dots, x: digest cases) vs extended model (lines)\n"
                 "r = 5 mm, f_p = 0.5 mm, 2 flutes")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    alphas = sorted({r["alpha_deg"] for r in grid})
    z = [[next(r["diff_um"] for r in grid if r["alpha_deg"] == a and r["ft_mm"] == ft) for a in alphas] for ft in fts]
    vmax = max(abs(v) for row in z for v in row)
    im = ax2.pcolormesh(alphas, fts, z, cmap="RdBu_r", vmin=-vmax, vmax=vmax, shading="nearest")
    fig.colorbar(im, ax=ax2, label="Z-map − model [µm]")
    # the model's region boundary α_c(f_t) (eq. 4)
    r, fp = 5.0, 0.5
    ac = [math.degrees(critical_angle(r, ft, fp)) for ft in fts]
    ax2.plot(ac, fts, "k--", lw=1, label="α_c (eq. 4)")
    ax2.legend(fontsize=8)
    ax2.set_xlabel("α [deg]")
    ax2.set_ylabel("f_t [mm]")
    ax2.set_title(f"difference map, largest |Δ| = {vmax:.2f} µm (paper: 1.8 µm)")
    if conv_rows:
        conv_rows.sort()
        ax3.semilogx([p for p, _ in conv_rows], [v for _, v in conv_rows], "o-", color="C3")
        ax3.axhline(1.8, color="k", ls="--", lw=1, label="paper's largest error, 1.8 µm")
        ax3.set_xlabel("Z-map pitch [µm]")
        ax3.set_ylabel("Z-map − model at α = 4.34° ≈ α_c, f_t = f_p [µm]")
        ax3.set_title("the α_c case against the grid pitch\n(edge rotation step 0.1–2°: same to 0.001 µm)")
        ax3.grid(alpha=0.3, which="both")
        ax3.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(d / "zmap_vs_model.png", dpi=110)

    fig, axes = plt.subplots(1, 3, figsize=(19, 5.5))
    for ax, name, title in ((axes[0], "surface_alpha0.csv", "α = 0°, f_t = f_p (tip's cutting remains)"),
                            (axes[1], "surface_alphac.csv", "α = α_c = 4.34°, f_t = f_p (model 10.7 µm)"),
                            (axes[2], "surface_alpha10.csv", "α = 10°, f_t = f_p (feed marks and cusps)")):
        p = d / name
        if not p.exists():
            continue
        m, pitch = read_matrix(p)
        ny, nx = len(m), len(m[0])
        im = ax.imshow(m, origin="lower", extent=(0, nx * pitch, 0, ny * pitch), cmap="terrain", aspect="equal")
        fig.colorbar(im, ax=ax, label="deviation from the nominal plane [µm]")
        flat = [v for row in m for v in row]
        ax.set_title(f"{title}\nR_max = {max(flat) - min(flat):.2f} µm")
        hi = max(range(len(flat)), key=flat.__getitem__)
        ax.plot((hi % nx + 0.5) * pitch, (hi // nx + 0.5) * pitch, "r^", ms=9, label="highest point")
        for yp in (0.0, 0.5, 1.0):
            ax.axhline(yp, color="w", lw=0.6, ls=":")
        ax.legend(fontsize=7, loc="upper right")
        ax.set_xlabel("x (feed) [mm]")
        ax.set_ylabel("y (pick) [mm]")
    fig.tight_layout()
    fig.savefig(d / "zmap_surfaces.png", dpi=110)
    print(d / "zmap_vs_model.png", d / "zmap_surfaces.png")


if __name__ == "__main__":
    main()
