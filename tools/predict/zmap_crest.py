#!/usr/bin/python3
"""Choi et al. 2005's Z-map check, independently of the Z-map's rasteriser: the height the rotating
edges leave at a point of simulate_inclined_plane's case (same set-up: r, 2 flutes, passes
f_p apart along +X, each starting r + 2 f_t before the window with the same spindle phase,
10000 rpm), from the moments each edge's plane passes over the point (sign changes on a
0.02 µm path step), and the crest of the surface around the highest cell of a map.

  cnc-predict zmap --alpha A --feed-per-tooth C --pitch 0.001 --window 1 --out DIR
  zmap_crest.py DIR/zmap_surface.csv --alpha A --feed-per-tooth C --pitch 0.001
      -> the map's highest cell, the same point recomputed, the crest within ±1.5 µm of it
"""
import argparse
import numpy as np

ap = argparse.ArgumentParser()
ap.add_argument("surface")
ap.add_argument("--alpha", type=float, required=True)
ap.add_argument("--feed-per-tooth", type=float, required=True)
ap.add_argument("--pick-feed", type=float, default=0.5)
ap.add_argument("--radius", type=float, default=5.0)
ap.add_argument("--pitch", type=float, required=True, help="the map's pitch given to cnc-predict zmap, mm")
a = ap.parse_args()
r, n, fp, ft = a.radius, 2, a.pick_feed, a.feed_per_tooth
alpha = np.radians(a.alpha)
sa, ca = np.sin(alpha), np.cos(alpha)
s0 = (-(r + 2 * ft) + r * sa) / ca
rot_per_mm = 2 * np.pi / (n * ft)


def deviation_um(px, py):
    best = np.inf
    for q in range(int(np.floor((py - r) / fp)), int(np.ceil((py + r) / fp)) + 1):
        yq = q * fp
        if abs(py - yq) >= r:
            continue
        s = np.arange((px - 1.05 * r) / ca + r * sa / ca, (px + 1.05 * r) / ca + r * sa / ca, 2e-5)
        cx, cz = s * ca - r * sa, s * sa + r * ca
        th = -rot_per_mm * (s - s0)
        dx, dy = px - cx, py - yq
        phi, rho = np.arctan2(dy, dx), np.hypot(dx, dy)
        for k in range(n):
            g = np.angle(np.exp(1j * (phi - th - 2 * np.pi * k / n)))
            i = np.nonzero(((g[:-1] <= 0) & (g[1:] > 0)) | ((g[:-1] >= 0) & (g[1:] < 0)))[0]
            i = i[np.abs(g[i] - g[i + 1]) < 1.0]  # not the ±π wrap
            l = g[i] / (g[i] - g[i + 1])
            rr = rho[i] + l * (rho[i + 1] - rho[i])
            zz = cz[i] + l * (cz[i + 1] - cz[i])
            ok = rr < r
            if ok.any():
                z = zz[ok] - np.sqrt(r * r - rr[ok] ** 2)
                best = min(best, float(np.min(-px * sa + z * ca)))
    return best * 1e3


m = np.loadtxt(a.surface, delimiter=",", comments="#")
file_pitch = float(open(a.surface).readline().split("pitch_mm=")[1])
every = int(round(file_pitch / a.pitch))  # the file keeps every `every`-th column and row
j, i = np.unravel_index(m.argmax(), m.shape)
x0, y0 = (i * every + 0.5) * a.pitch, (j * every + 0.5) * a.pitch
print(f"map: highest {m.max():.3f} um (R_max {m.max() - m.min():.3f}) at x={x0:.5f} y={y0:.5f} (every {every}. cell of {a.pitch * 1e3:g} um)")
print(f"recomputed there: {deviation_um(x0, y0):.3f} um")
best = max((deviation_um(x0 + dx, y0 + dy), x0 + dx, y0 + dy)
           for dx in np.linspace(-1.5e-3, 1.5e-3, 11) for dy in np.linspace(-1.5e-3, 1.5e-3, 7))
print(f"crest within +-1.5 um: {best[0]:.3f} um at x={best[1]:.5f} y={best[2]:.5f}; lowest cell {m.min():.3f} um")
