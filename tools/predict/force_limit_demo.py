#!/usr/bin/python3
"""The force feed limit on a pocket with corners, side by side.

Plans config/programs/pocket_corner.ngc twice with cnc-plan (the dry run: the
interpolator core as it runs live) - on config/machines/sim3_cutting.yaml (no feed
limit) and sim3_cutting_limit.yaml (cutting.feed_limit: true, the planner keeps the
predicted tool-tip deflection within cutting.deflection_tolerance_mm) - then predicts
force, deflection and the walls' surface error along both setpoint streams with
`cnc-predict program` (stations every 0.05 mm, its own stock model: an independent
check of what the planner limited), prints the figures and plots feed and deflection
against time for both runs.

    /usr/bin/python3 tools/predict/force_limit_demo.py --build build --out /tmp/force_demo \
        [--png docs/img/force_limit_pocket.png]
"""
import argparse
import csv
import os
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PROGRAM = os.path.join(ROOT, "config/programs/pocket_corner.ngc")
TOOL = os.path.join(ROOT, "config/tools/hss_flat_4f_d6.yaml")
MATERIAL = os.path.join(ROOT, "config/materials/al_paper004.yaml")
FINISH_LINES = {18, 19, 20, 21, 22}  # the finishing contour of pocket_corner.ngc


def tolerance_of(machine):
    with open(machine) as f:
        for line in f:
            s = line.strip()
            if s.startswith("deflection_tolerance_mm:"):
                return float(s.split(":")[1].split("#")[0])
    raise SystemExit(machine + ": no cutting.deflection_tolerance_mm")


def run(build, machine, out):
    os.makedirs(out, exist_ok=True)
    sp = os.path.join(out, "setpoints.csv")
    plan = subprocess.run([os.path.join(build, "tools/cnc-plan"), "--machine", machine, "--program", PROGRAM,
                           "--csv", sp], check=True, capture_output=True, text=True).stdout
    subprocess.run([os.path.join(build, "tools/cnc-predict"), "program", "--csv", sp, "--program", PROGRAM,
                    "--out", out, "--tool", TOOL, "--material", MATERIAL, "--stock-top", "0"],
                   check=True, capture_output=True, text=True)
    with open(sp) as f:
        sps = list(csv.DictReader(f))
    with open(os.path.join(out, "predict.csv")) as f:
        pred = list(csv.DictReader(f))
    t_end = float(sps[-1]["t_s"])
    finish = [float(r["t_s"]) for r in sps if int(r["line"]) in FINISH_LINES]
    walls = [abs(float(r["surface_error_mm"])) for r in pred if r["final_wall"] == "1"]
    limits = {}
    for r in sps:
        limits[r["limit"]] = limits.get(r["limit"], 0) + 1
    return {
        "plan": plan.strip().splitlines()[0] if plan.strip() else "",
        "sps": sps,
        "pred": pred,
        "time_s": t_end,
        "finish_s": (max(finish) - min(finish)) if finish else 0.0,
        "max_deflection_mm": max(float(r["deflection_peak_mm"]) for r in pred),
        "max_surface_error_mm": max(walls) if walls else 0.0,
        "limits": limits,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--out", required=True)
    ap.add_argument("--png", default=os.path.join(ROOT, "docs/img/force_limit_pocket.png"))
    a = ap.parse_args()
    free_cfg = os.path.join(ROOT, "config/machines/sim3_cutting.yaml")
    limit_cfg = os.path.join(ROOT, "config/machines/sim3_cutting_limit.yaml")
    tol = tolerance_of(limit_cfg)
    runs = {"without the limit": run(a.build, free_cfg, os.path.join(a.out, "free")),
            "with the force limit": run(a.build, limit_cfg, os.path.join(a.out, "limited"))}
    print("pocket_corner.ngc, HSS 4-flute D6 in Al (paper 004), 3 mm deep, S1250 F100; "
          "deflection tolerance %.0f um" % (tol * 1e3))
    for name, r in runs.items():
        print("%-21s machining time %7.2f s (finishing contour %6.2f s), max tool-tip deflection %6.1f um, "
              "max surface error of the final walls %6.1f um, setpoints limited by force: %d"
              % (name, r["time_s"], r["finish_s"], r["max_deflection_mm"] * 1e3, r["max_surface_error_mm"] * 1e3,
                 r["limits"].get("force", 0)))

    fig = plt.figure(figsize=(11, 10))
    gs = fig.add_gridspec(3, 1, height_ratios=[1, 1, 1.1])
    ax = [fig.add_subplot(gs[0])]
    ax.append(fig.add_subplot(gs[1], sharex=ax[0]))
    zoom = fig.add_subplot(gs[2])
    colours = {"without the limit": "#d62728", "with the force limit": "#1f77b4"}
    for name, r in runs.items():
        t = [float(s["t_s"]) for s in r["sps"]]
        f = [float(s["feed_mm_min"]) for s in r["sps"]]
        ax[0].plot(t, f, color=colours[name], lw=0.9,
                   label="%s: %.1f s" % (name, r["time_s"]))
        tp = [float(s["t_s"]) for s in r["pred"]]
        d = [float(s["deflection_peak_mm"]) * 1e3 for s in r["pred"]]
        ax[1].plot(tp, d, color=colours[name], lw=0.9,
                   label="%s: max %.1f um, walls' max surface error %.1f um"
                   % (name, r["max_deflection_mm"] * 1e3, r["max_surface_error_mm"] * 1e3))
    ax[1].axhline(tol * 1e3, color="k", ls="--", lw=0.8, label="tolerance %.0f um" % (tol * 1e3))
    ax[0].set_ylim(0, 120)
    ax[0].set_ylabel("commanded feed, mm/min")
    ax[1].set_ylabel("tool-tip deflection (peak per tooth), um")
    ax[1].set_xlabel("time, s")
    ax[0].legend(loc="upper right", fontsize=8)
    ax[1].legend(loc="upper right", fontsize=8)
    ax[0].set_title("pocket_corner.ngc: roughing slots and a finishing contour with four inside corners "
                    "(cnc-plan, deflection by cnc-predict)", fontsize=9)
    # The finishing contour (four walls, four inside corners) from its start, both runs.
    zoom_d = zoom.twinx()
    for name, r in runs.items():
        fin = [s for s in r["sps"] if int(s["line"]) in FINISH_LINES]
        t0 = float(fin[0]["t_s"])
        zoom.plot([float(s["t_s"]) - t0 for s in fin], [float(s["feed_mm_min"]) for s in fin], color=colours[name],
                  lw=0.9, label="feed, " + name)
        pf = [s for s in r["pred"] if int(s["line"]) in FINISH_LINES]
        zoom_d.plot([float(s["t_s"]) - t0 for s in pf], [float(s["deflection_peak_mm"]) * 1e3 for s in pf],
                    color=colours[name], lw=0.9, ls=":", label="deflection, " + name)
    zoom_d.axhline(tol * 1e3, color="k", ls="--", lw=0.8)
    zoom.set_ylim(0, 120)
    zoom_d.set_ylim(0, 120)
    zoom.set_xlabel("time from the start of the finishing contour, s")
    zoom.set_ylabel("feed, mm/min (solid)")
    zoom_d.set_ylabel("deflection, um (dotted)")
    zoom.set_title("the finishing contour: the corners are taken slower, the walls at the programmed feed", fontsize=9)
    zoom.legend(loc="lower left", fontsize=8)
    zoom_d.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    os.makedirs(os.path.dirname(a.png), exist_ok=True)
    fig.savefig(a.png, dpi=110)
    print("wrote " + a.png)
    return 0


if __name__ == "__main__":
    sys.exit(main())
