#!/usr/bin/python3
"""Arcs whose end point is off the start radius, against LinuxCNC.

LinuxCNC 2.9 accepts an arc whose end radius differs from its start radius by up to
2*0.01*sqrt(2) mm (or 0.1 % of the radius), keeps the programmed centre, and draws a
spiral: its trajectory planner's circle (posemath's PmCircle) moves the radius
linearly with the angle turned, from the start radius to the end radius, and a helix's
axial coordinate linearly with the angle too.

For each case this runs LinuxCNC's own interpreter (/usr/bin/rs274) for the canonical
ARC_FEED call (centre, end, rotation, as LinuxCNC's planner receives it), builds
LinuxCNC's spiral from it, runs our dry run (cnc-plan) on the same program, and
measures every setpoint of the arc against LinuxCNC's spiral at the setpoint's own
angle: the radial and axial difference (an upper bound of the distance to the curve).
Beside it, what the arc did before (the start radius kept, then the whole mismatch in
the block's last cycle): a deviation from LinuxCNC's path of the whole mismatch. Cases
beyond the tolerance must be refused by both.

  arc_spiral_check.py --plan BUILD/tools/cnc-plan --machine config/machines/sim3.yaml
                      --out DIR [--rs274 /usr/bin/rs274] [--max-dev-mm 1e-6]
Exit 0 when every accepted case is within --max-dev-mm of LinuxCNC's path, ends on
its programmed end point (1e-9 mm) and both refuse the same cases; 1 otherwise.
"""
import argparse
import csv
import math
import os
import re
import subprocess
import sys
import tempfile

# name, plane, start (x, y, z), the arc's line, True when LinuxCNC refuses it.
# Numbers have at most 4 decimals: rs274 prints 4, so its canonical call is exact.
CASES = [
    ("g17_ccw_out_0.019", 17, (10, 0, 0), "G3 X-10.019 Y0 I-10 J0", False),
    ("g17_cw_in_0.019", 17, (10, 0, 0), "G2 X0 Y-9.981 I-10 J0", False),
    ("g17_ccw_out_0.028", 17, (20, 5, -3), "G3 X5 Y20.028 I-15 J0", False),
    ("g17_ccw_in_0.0275_three_quarters", 17, (20, 5, -3), "G3 X5 Y-9.9725 I-15 J0", False),
    ("g17_helix_0.015", 17, (10, 0, 0), "G3 X-10.015 Y0 Z-4 I-10 J0", False),
    ("g17_two_turns_0.02", 17, (10, 0, 0), "G3 X0 Y10.02 I-10 J0 P2", False),
    ("g18_cw_in_0.019", 18, (10, 0, 0), "G2 X-9.981 Z0 I-10 K0", False),
    ("g18_ccw_out_0.02", 18, (10, 0, -5), "G3 X30.02 Z-5 I10 K0", False),
    ("g19_ccw_out_0.019", 19, (0, 10, 0), "G3 Y-10.019 Z0 J-10 K0", False),
    ("g19_cw_in_0.025_helix", 19, (3, 10, 0), "G2 X8 Y-9.975 Z0 J-10 K0", False),
    ("g17_small_r2_0.0025", 17, (2, 0, 0), "G3 X-2.0025 Y0 I-2 J0", False),
    ("g17_refused_0.030", 17, (10, 0, 0), "G3 X-10.03 Y0 I-10 J0", True),
    ("g18_refused_0.05", 18, (10, 0, 0), "G2 X-10.05 Z0 I-10 K0", True),
]

PLANE_AXES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}  # first, second, normal (x=0, y=1, z=2)
PLANE_WORD = {17: "G17", 18: "G18", 19: "G19"}


# The cases are written about the origin; the programs run shifted into sim3's travel.
SHIFT = (100.0, 100.0, -50.0)


def shifted(start, line):
    """The start point and the arc's line moved by SHIFT (I, J, K are incremental)."""
    st = tuple(start[i] + SHIFT[i] for i in range(3))
    moved = re.sub(r"([XYZ])([-+]?[0-9.]+)",
                   lambda m: "%s%.4f" % (m.group(1), float(m.group(2)) + SHIFT["XYZ".index(m.group(1))]), line)
    return st, moved


def program(plane, start, line):
    """Line 4 is the arc."""
    return ("G21 G90 G94 %s\nG0 X%.4f Y%.4f Z%.4f\nF600\n%s\nM2\n" %
            (PLANE_WORD[plane], start[0], start[1], start[2], line))


def rs274_arc(rs274, path, home):
    out = path + ".canon"
    p = subprocess.run([rs274, "-g", path, out], stdin=subprocess.DEVNULL, capture_output=True, text=True,
                       env=dict(os.environ, HOME=home), timeout=60)
    text = open(out).read() if os.path.exists(out) else ""
    arcs = re.findall(r"ARC_FEED\(([^)]*)\)", text)
    refused = p.returncode != 0
    return refused, [float(v) for v in arcs[0].split(",")] if arcs else None, (p.stdout + p.stderr).strip()


def plan(cnc_plan, machine, path, csv_path):
    p = subprocess.run([cnc_plan, "--machine", machine, "--program", path, "--csv", csv_path],
                       capture_output=True, text=True, timeout=120)
    return p.returncode, (p.stdout + p.stderr).strip()


def linuxcnc_spiral(plane, start, call):
    """LinuxCNC's circle from ARC_FEED(first_end, second_end, first_axis, second_axis,
    rotation, axis_end, ...): centre in the plane, start and end radius, the angle
    turned (rotation > 0: counter-clockwise seen from the plane's normal, plus
    rotation-1 full turns; < 0: clockwise, plus -rotation-1), the axial end."""
    f, s, nrm = PLANE_AXES[plane]
    e1, e2, c1, c2, rot, axial_end = call[0], call[1], call[2], call[3], int(call[4]), call[5]
    s1, s2 = start[f] - c1, start[s] - c2
    t1, t2 = e1 - c1, e2 - c2
    r0 = math.hypot(s1, s2)
    r1 = math.hypot(t1, t2)
    a0 = math.atan2(s2, s1)
    a1 = math.atan2(t2, t1)
    ccw = rot > 0
    sweep = (a1 - a0) if ccw else (a0 - a1)
    while sweep <= 1e-12:
        sweep += 2 * math.pi
    sweep += 2 * math.pi * (abs(rot) - 1)
    return dict(f=f, s=s, n=nrm, c=(c1, c2), r0=r0, r1=r1, a0=a0, sweep=sweep, ccw=ccw, h0=start[nrm],
                h1=axial_end, end=(e1, e2))


def deviations(sp, xyz):
    """Per setpoint: the turned angle (unwrapped along the path), the radial and axial
    difference from LinuxCNC's spiral at that angle."""
    c1, c2 = sp["c"]
    out = []
    prev = sp["a0"]
    turned = 0.0
    for p in xyz:
        q1, q2 = p[sp["f"]] - c1, p[sp["s"]] - c2
        a = math.atan2(q2, q1)
        d = (a - prev) if sp["ccw"] else (prev - a)
        d = (d + math.pi) % (2 * math.pi) - math.pi  # the step's turn, small
        turned += d
        prev = a
        frac = min(max(turned / sp["sweep"], 0.0), 1.0)
        r_l = sp["r0"] + (sp["r1"] - sp["r0"]) * frac
        h_l = sp["h0"] + (sp["h1"] - sp["h0"]) * frac
        out.append((turned, math.hypot(q1, q2) - r_l, p[sp["n"]] - h_l, math.hypot(q1, q2)))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--plan", required=True)
    ap.add_argument("--machine", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--rs274", default="/usr/bin/rs274")
    ap.add_argument("--max-dev-mm", type=float, default=1e-6)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    home = tempfile.mkdtemp(prefix="rs274-home-")
    ok = True
    worst_all = 0.0
    curves = []
    print("%-34s %9s %9s %8s %11s %12s %13s" % ("case", "r0 mm", "r1 mm", "turn deg", "setpoints",
                                                  "largest dev", "before (jump)"))
    for name, plane, start, line, refuse in CASES:
        start, line = shifted(start, line)
        path = os.path.join(a.out, name + ".ngc")
        with open(path, "w") as f:
            f.write(program(plane, start, line))
        l_refused, call, l_msg = rs274_arc(a.rs274, path, home)
        csv_path = os.path.join(a.out, name + ".csv")
        rc, msg = plan(a.plan, a.machine, path, csv_path)
        o_refused = rc != 0
        if refuse or l_refused or o_refused:
            same = l_refused == o_refused == refuse
            print("%-34s refused by LinuxCNC: %s, by cnc-plan: %s%s" % (name, l_refused, o_refused,
                                                                         "" if same else "  MISMATCH"))
            if not same:
                print("    rs274: %s\n    cnc-plan: %s" % (l_msg[-300:], msg[-300:]))
                ok = False
            continue
        if call is None:
            print("%-34s rs274 printed no ARC_FEED" % name)
            ok = False
            continue
        sp = linuxcnc_spiral(plane, start, call)
        rows = list(csv.DictReader(open(csv_path)))
        xyz = [(float(r["x_mm"]), float(r["y_mm"]), float(r["z_mm"])) for r in rows if int(r["line"]) == 4]
        finite = all(math.isfinite(v) for p in xyz for v in p)
        dev = deviations(sp, xyz)
        worst = max(math.hypot(d[1], d[2]) for d in dev)
        end = [float(rows[-1][k]) for k in ("x_mm", "y_mm", "z_mm")]
        want = list(start)
        want[sp["f"]], want[sp["s"]], want[sp["n"]] = sp["end"][0], sp["end"][1], sp["h1"]
        end_err = max(abs(end[i] - want[i]) for i in range(3))
        turned_ok = abs(dev[-1][0] - sp["sweep"]) < 1e-6
        jump = abs(sp["r1"] - sp["r0"])
        print("%-34s %9.4f %9.4f %8.1f %11d %9.2e mm %10.4f mm" % (name, sp["r0"], sp["r1"],
                                                                  math.degrees(sp["sweep"]), len(xyz), worst, jump))
        if not (finite and worst <= a.max_dev_mm and end_err <= 1e-9 and turned_ok):
            print("    FAIL: finite %s, largest deviation %.3g mm (limit %.3g), end off by %.3g mm, "
                  "turned %.6f of %.6f rad" % (finite, worst, a.max_dev_mm, end_err, dev[-1][0], sp["sweep"]))
            ok = False
        worst_all = max(worst_all, worst)
        curves.append((name, sp, dev))
    print("largest deviation from LinuxCNC's spiral over all accepted cases: %.3g mm" % worst_all)
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 8))
        for name, sp, dev in curves:
            ax2.plot([d[0] / sp["sweep"] for d in dev], [math.hypot(d[1], d[2]) * 1e6 for d in dev], lw=0.8,
                     label=name)
        ax2.set_xlabel("angle turned / the arc's angle")
        ax2.set_ylabel("distance from LinuxCNC's spiral (nm)")
        ax2.set_title("Every accepted case: ours against LinuxCNC's spiral (the CSV's 1e-9 mm rounding)")
        ax2.grid(alpha=0.3)
        ax2.legend(fontsize=6, ncol=2, loc="upper right")
        for name, sp, dev in curves[:4]:
            th = [d[0] / sp["sweep"] for d in dev]
            ax.plot(th, [(d[3] - sp["r0"]) * 1000 for d in dev], lw=1.4, label="%s: ours" % name)
            ax.plot([0, 1], [0, (sp["r1"] - sp["r0"]) * 1000], "k:", lw=0.9)
            ax.plot(th[:-1] + [th[-1]], [0.0] * (len(th) - 1) + [(sp["r1"] - sp["r0"]) * 1000], lw=0.8, ls="--",
                    label="%s: before (jump at the end)" % name)
        ax.set_xlabel("angle turned / the arc's angle")
        ax.set_ylabel("radius - start radius (um)")
        ax.set_title("Arcs with the end off the start radius: ours (solid), LinuxCNC's spiral (dotted)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
        fig.tight_layout()
        png = os.path.join(a.out, "arc_spiral.png")
        fig.savefig(png, dpi=80)
        print("plot: %s" % png)
    except ImportError:
        pass
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
