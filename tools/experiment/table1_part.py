#!/usr/bin/env python3
"""Choi et al. 2005, Table 1: the part and its finishing programs.

The surface is a cylindrical wave along X, z(x) = A cos(2 pi x / L), A = 3 mm, L = 50 mm:
its tops (x = 0, 50, ...) and valleys (x = 25, 75, ...) are where the feed inclination
along an X pass is below the critical angle (alpha_c = 4.4 deg at r 3, f_p 0.2, f_t 0.28:
a band about 3.2 mm wide, where the law slows the feed most), and its slopes reach
20.7 deg (region II). Along X it runs through every inclination the law tells apart; across
the passes (Y) it is straight, so every pass is the same curve and the pick feed is exactly
0.2 mm (a surface bent along Y too would shift a ball's contact point off the pass's
plane and the passes' spacing with it). Curvature radius 21.1 mm at a top, 18.1 mm on the
tool centre's path at a valley: far above r = 3 mm, and the centripetal acceleration at
F7000 stays at 0.75 m/s^2.

Finishing: raster passes along X, f_p = 0.2 mm apart in Y, back and forth, each one
cubic NURBS (G6.2) fitted to the ball's tool-tip path (the surface offset by r along its
normal, less r along Z) by least squares on uniform knots 1.25 mm apart (the fit's error
is printed: below 0.1 um); linked at the tops by a G1 step of 0.2 mm in Y. S12500 F7000;
the law's program carries the PROCESS line (r 3, 2 flutes, pick 0.2, R_max 3.3 um), the
fixed one not.

  table1_part.py --size tiny|reduced|full --out DIR
writes DIR/table1_fixed.ngc, DIR/table1_law.ngc and DIR/part.json (the surface, the
strip, the measured regions).
"""
import argparse
import json
import math
import os
import sys

import numpy as np
from scipy.interpolate import make_lsq_spline

A_MM, L_MM = 3.0, 50.0
Z_BASE_MM = -10.0  # the wave's middle: its tops 7 mm below the machine's Z travel end (+5)
SAFE_Z_MM = 0.0
R_MM, FLUTES, PICK_MM, RMAX_UM = 3.0, 2, 0.2, 3.3
RPM, FEED = 12500, 7000
KNOT_MM = 1.25
# x range (whole wavelengths or a valley-centred span: both ends at the same height) and passes.
SIZES = {
    # A valley, 5 passes of 12 mm: the suite's check (tests/integration/table1_test.sh).
    "tiny": {"x": (19.0, 31.0), "passes": 5},
    # Two wavelengths, 31 passes (6 mm): about half a minute of machining per run.
    "reduced": {"x": (0.0, 100.0), "passes": 31},
    # 150 x 100 mm, 501 passes: 12 min 46 s fixed, 16 min 4 s under the law (dry run).
    "full": {"x": (0.0, 150.0), "passes": 501},
}


def surface(x):
    return Z_BASE_MM + A_MM * np.cos(2 * np.pi * x / L_MM)


def slope(x):
    return -A_MM * 2 * np.pi / L_MM * np.sin(2 * np.pi * x / L_MM)


def tool_tip(x):
    """The ball's tip (program point) touching the surface at x: offset by r along the normal, less r."""
    fx = slope(x)
    n = np.sqrt(1 + fx * fx)
    return x - R_MM * fx / n, surface(x) + R_MM / n - R_MM


def critical_angle_deg(ft):
    a = PICK_MM ** 2 + (ft - PICK_MM / (2 * math.pi)) ** 2
    return math.degrees(math.asin(math.sqrt((a / (8 * R_MM)) ** 2 - a / 4 + ft * ft) / R_MM))


def flat_regions(x0, x1):
    """Tops and valleys inside [x0, x1]: where |alpha| < alpha_c at the programmed feed."""
    ac = math.radians(critical_angle_deg(FEED / (FLUTES * RPM)))
    # |slope| = A k |sin(k x)| < tan(alpha_c) -> |x - x_flat| < asin(tan(ac) / (A k)) / k
    k = 2 * math.pi / L_MM
    half = math.asin(math.tan(ac) / (A_MM * k)) / k
    out = []
    for m in range(int(math.floor(x0 / (L_MM / 2))) - 1, int(math.ceil(x1 / (L_MM / 2))) + 2):
        xc = m * L_MM / 2
        if x0 + R_MM <= xc - half and xc + half <= x1 - R_MM:
            out.append({"x_mm": xc, "kind": "top" if m % 2 == 0 else "valley", "half_width_mm": half})
    return out


def fit_pass(x0, x1):
    """Cubic B-spline control points (x, z) and knots of the tool-tip path from x0 to x1."""
    n_int = max(1, int(round((x1 - x0) / KNOT_MM)))
    u = np.linspace(x0, x1, 40 * n_int + 1)
    px, pz = tool_tip(u)
    inner = np.linspace(x0, x1, n_int + 1)
    t = np.r_[[x0] * 3, inner, [x1] * 3]
    sx, sz = make_lsq_spline(u, px, t, k=3), make_lsq_spline(u, pz, t, k=3)
    # The fit's error: the spline's tip against the exact tip path, in z at the same x
    # (the tip's x grows with the surface's: its path's curvature radius exceeds r).
    uu = np.linspace(x0, x1, 200 * n_int + 1)
    tx, tz = tool_tip(np.linspace(x0, x1, 4000 * n_int + 1))
    err = float(np.max(np.abs(sz(uu) - np.interp(sx(uu), tx, tz))))
    knots = (t - x0) / (x1 - x0)
    return list(zip(sx.c, sz.c)), list(knots), err


def program(size, law):
    cfg = SIZES[size]
    x0, x1 = cfg["x"]
    cps, knots, err = fit_pass(x0, x1)
    out = ["%",
           f"( Choi et al. 2005 Table 1: z = {A_MM:g} cos 2 pi x / {L_MM:g}, size {size}, "
           f"{'roughness law' if law else 'fixed feed'}; tools/experiment/table1_part.py )",
           "G21 G90 G17"]
    if law:
        out.append(f"(PROCESS, BALL_RADIUS={R_MM:g}, FLUTES={FLUTES}, PICK_FEED={PICK_MM:g}, RMAX_UM={RMAX_UM:g})")
    # The first pass starts on its first control point (a clamped spline's start).
    out += [f"S{RPM} M3", f"G0 Z{SAFE_Z_MM:g}", f"G0 X{cps[0][0]:.5f} Y0", f"G0 Z{cps[0][1] + 1:.5f}",
            f"G1 Z{cps[0][1]:.5f} F1000"]
    for p in range(cfg["passes"]):
        y = p * PICK_MM
        seq = cps if p % 2 == 0 else cps[::-1]
        ks = knots if p % 2 == 0 else [1 - k for k in knots[::-1]]
        if p > 0:
            out.append(f"G1 Y{y:.4f} F{FEED}")
        cx, cz = seq[0]
        out.append(f"G6.2 P4 K{ks[0]:.6f} X{cx:.5f} Y{y:.4f} Z{cz:.5f} R1 F{FEED}")
        for k, (cx, cz) in zip(ks[1:], seq[1:]):
            out.append(f"K{k:.6f} X{cx:.5f} Z{cz:.5f} R1")
        for k in ks[len(seq):]:
            out.append(f"K{k:.6f}")
    out += [f"G0 Z{SAFE_Z_MM:g}", "M5", "M30", "%"]
    return "\n".join(out) + "\n", err


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", choices=sorted(SIZES), default="reduced")
    ap.add_argument("--out", required=True, help="directory for the two programs and part.json")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    for law in (False, True):
        text, err = program(a.size, law)
        with open(os.path.join(a.out, f"table1_{'law' if law else 'fixed'}.ngc"), "w") as f:
            f.write(text)
    cfg = SIZES[a.size]
    x0, x1 = cfg["x"]
    ft = FEED / (FLUTES * RPM)
    part = {
        "size": a.size, "amplitude_mm": A_MM, "z_base_mm": Z_BASE_MM, "wavelength_mm": L_MM, "x_mm": [x0, x1],
        "y_mm": [0.0, (cfg["passes"] - 1) * PICK_MM], "passes": cfg["passes"],
        "ball_radius_mm": R_MM, "flutes": FLUTES, "pick_feed_mm": PICK_MM, "target_rmax_um": RMAX_UM,
        "spindle_rpm": RPM, "feed_mm_min": FEED, "feed_per_tooth_mm": ft,
        "critical_angle_deg": critical_angle_deg(ft), "flat_regions": flat_regions(x0, x1),
        "nurbs_fit_error_um": err * 1e3,
    }
    with open(os.path.join(a.out, "part.json"), "w") as f:
        json.dump(part, f, indent=1)
    print(f"table1_part: size {a.size}: x {x0:g}..{x1:g} mm, {cfg['passes']} passes, alpha_c "
          f"{part['critical_angle_deg']:.2f} deg, NURBS fit within {err * 1e3:.3f} um, "
          f"{len(part['flat_regions'])} flat regions", file=sys.stderr)


if __name__ == "__main__":
    main()
