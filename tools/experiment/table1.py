#!/usr/bin/env python3
"""Choi et al. 2005, Table 1, in the live cell: `./cnc experiment table1 [--size tiny|reduced|full]`.

1. tools/experiment/table1_part.py writes the part's two programs (fixed feed; the
   roughness law with the paper's target).
2. Each runs in a live cell on the simulated drives (the services of config/services.txt
   but the HMI and the OPC UA server, started here; the logger records every channel).
3. cnc-logexport turns each log into tables; the drives' actual positions (AXIS_STATUS,
   every T_ipo) become a setpoint table for cnc-predict, whose clock is stretched so that
   the Z-map's spindle angle is the one the spindle's measured speed (SPINDLE_STATUS'
   actual_rpm, integrated) gives.
4. cnc-predict's Z-map of the ball's rotating edges cuts the machined surface: in a window
   over each flat region (|alpha| < alpha_c: the tops and valleys) at 2.5 um, and over the
   whole strip at 10 um for its R_max map (not for the full size: too many cells).
5. R_max (peak to valley of the distance from the nominal surface along its normal) and
   the report: tools/experiment/table1_report.py.

  table1.py --build DIR --machine FILE --size SIZE --out DIR [--skip-runs]
Exit status 0 when both runs ran to their end and every figure was computed.
"""
import argparse
import csv
import json
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)
import table1_part as part  # noqa: E402


T0 = time.monotonic()


def say(msg):
    print(f"table1: [{time.monotonic() - T0:6.1f} s] {msg}", file=sys.stderr, flush=True)


def services(build):
    """(name, executable) of the cell's services in start order, without the HMI and OPC UA."""
    out = []
    with open(os.path.join(ROOT, "config", "services.txt")) as f:
        for row in f:
            row = row.split("#")[0].split()
            if len(row) >= 2 and row[0] not in ("hmi", "opcua"):
                out.append((row[0], os.path.join(build, row[1])))
    return out


def run_cell(build, machine, program, run_dir, timeout_s):
    """The program in a live cell; returns the wall time of cnc-ctl's run. The log: run_dir/cell.lcmlog."""
    os.makedirs(run_dir, exist_ok=True)
    procs = []
    try:
        for name, exe in services(build):
            args = [exe, "--machine", machine]
            if name == "logger":
                args += ["--out", os.path.join(run_dir, "cell")]
            log = open(os.path.join(run_dir, f"{name}.log"), "w")
            procs.append((name, subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT)))
            time.sleep(0.1)
        t0 = time.monotonic()
        ctl = subprocess.run([os.path.join(build, "tools", "cnc-ctl"), "--machine", machine, "--do", "run",
                              "--program", program, "--timeout", str(timeout_s)],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        wall = time.monotonic() - t0
        with open(os.path.join(run_dir, "ctl.out"), "w") as f:
            f.write(ctl.stdout)
        if ctl.returncode != 0:
            raise RuntimeError(f"{program}: cnc-ctl exited {ctl.returncode}:\n{ctl.stdout[-2000:]}")
        time.sleep(0.3)  # the last statuses into the log
        return wall
    finally:
        for name, p in reversed(procs):  # reverse start order, as ./cnc up stops them
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(10)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def actual_setpoints(export_dir, out_csv, rpm_nominal):
    """The drives' actual positions as a cnc-plan setpoint table, its clock stretched to the spindle's angle.

    Returns a dict of what it measured: the spindle's speed while cutting, the cutting time."""
    sp = {int(r["cycle"]): r for r in read_csv(os.path.join(export_dir, "setpoints.csv"))}
    ax = read_csv(os.path.join(export_dir, "axis_status.csv"))
    period = float(json.load(open(os.path.join(export_dir, "summary.json")))["period_s"])
    # The positions' time: the bridge's playback clock when the drives were read (the
    # simulated drives' world stands when the bridge's does); setpoint_cycle repeats and
    # skips with the setpoints' arrival (feeds from it jumped to 10,500 mm/min at F7000).
    # A status whose clock has not moved since the last one is left out.
    cycle0 = int(ax[0]["setpoint_cycle"]) - float(ax[0]["t_s"]) / period
    rows, last = [], -math.inf
    for r in ax:
        pc = float(r["playback_cycle"])
        if math.isfinite(pc) and pc > last + 0.2:
            rows.append(r)
            last = pc
    t = np.array([(float(r["playback_cycle"]) - cycle0) * period for r in rows])
    pos = np.array([[float(r["x_actual_mm"]), float(r["y_actual_mm"]), float(r["z_actual_mm"])] for r in rows])
    cyc = [int(r["setpoint_cycle"]) for r in rows]
    line = np.array([int(sp[c]["line"]) if c in sp else 0 for c in cyc])
    cmd_feed = np.array([float(sp[c]["feed_mm_min"]) if c in sp else 0.0 for c in cyc])
    # The actual feed: the positions' central differences.
    v = np.zeros(len(t))
    if len(t) > 2:
        d = np.linalg.norm(pos[2:] - pos[:-2], axis=1) / np.maximum(t[2:] - t[:-2], 1e-9)
        v[1:-1] = d * 60.0
    # The spindle's angle: its measured speed (SPINDLE_STATUS, every T_ipo) integrated
    # over the positions' clock. The VFD has no encoder: the angle's origin is arbitrary.
    spin = read_csv(os.path.join(export_dir, "spindle_status.csv"))
    ts = np.array([float(r["t_s"]) for r in spin])
    rpm = np.array([float(r["actual_rpm"]) for r in spin])
    order = np.argsort(ts)
    ts, rpm = ts[order], rpm[order]
    rpm_t = np.interp(t, ts, rpm)
    rev = np.r_[0.0, np.cumsum(0.5 * (rpm_t[1:] + rpm_t[:-1]) * np.diff(t) / 60.0)]
    t_warp = rev * 60.0 / rpm_nominal
    # The Z-map runs the centre straight between samples: over 4 ms at F7000 (0.47 mm) on
    # the tops' and valleys' 18-24 mm radii that is a chord 1.1-1.5 um off the arc, a third
    # of the target. A cubic through the samples (Catmull-Rom, uniform in time) puts
    # UPSAMPLE - 1 points between them: the chord then falls below 0.1 um.
    UPSAMPLE = 4
    with open(out_csv, "w") as f:
        f.write("cycle,t_s,x_mm,y_mm,z_mm,line,u,feed_mm_min\n")
        for k in range(len(t)):
            f.write(f"{cyc[k]},{t_warp[k]:.7f},{pos[k, 0]:.6f},{pos[k, 1]:.6f},{pos[k, 2]:.6f},{line[k]},0,{v[k]:.2f}\n")
            if k == 0 or k + 2 >= len(t):
                continue
            p0, p1, p2, p3 = pos[k - 1], pos[k], pos[k + 1], pos[k + 2]
            for j in range(1, UPSAMPLE):
                s = j / UPSAMPLE
                q = 0.5 * ((2 * p1) + (-p0 + p2) * s + (2 * p0 - 5 * p1 + 4 * p2 - p3) * s * s
                           + (-p0 + 3 * p1 - 3 * p2 + p3) * s ** 3)
                tq = t_warp[k] + s * (t_warp[k + 1] - t_warp[k])
                f.write(f"{cyc[k]},{tq:.7f},{q[0]:.6f},{q[1]:.6f},{q[2]:.6f},{line[k]},0,{v[k]:.2f}\n")
    moving = cmd_feed > 0
    rpm_at = rpm_t[moving] if moving.any() else np.array([math.nan])
    return {
        "spindle_rpm_mean": float(np.mean(rpm_at)), "spindle_rpm_min": float(np.min(rpm_at)),
        "spindle_rpm_max": float(np.max(rpm_at)),
        "t_s": t.tolist(), "feed_actual": v.tolist(), "feed_commanded": cmd_feed.tolist(),
        "x_mm": pos[:, 0].tolist(), "y_mm": pos[:, 1].tolist(), "z_mm": pos[:, 2].tolist(), "line": line.tolist(),
    }


def read_stock(path):
    with open(path) as f:
        head = f.readline()
    kv = dict(w.split("=") for w in head.replace(";", " ").split() if "=" in w)
    z = np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
    return float(kv["x0"]), float(kv["y0"]), float(kv["pitch_mm"]), z


def deviation(stock_csv):
    """The machined surface's distance from the nominal one along its normal (mm), on the stock's grid."""
    x0, y0, pitch, z = read_stock(stock_csv)
    x = x0 + pitch * np.arange(z.shape[1])
    y = y0 + pitch * np.arange(z.shape[0])
    cosa = 1.0 / np.sqrt(1.0 + part.slope(x) ** 2)
    return x, y, (z - part.surface(x)[None, :]) * cosa[None, :]


def predict(build, setpoints, program, out_dir, rpm, pitch, window=None, stock_cells=None, block=None):
    os.makedirs(out_dir, exist_ok=True)
    args = [os.path.join(build, "tools", "cnc-predict"), "program", "--csv", setpoints,
            "--tool", os.path.join(ROOT, "config", "tools", "ball_r3_2f.yaml"), "--program", program,
            "--out", out_dir, "--spindle-rpm", f"{rpm}", "--pitch", f"{pitch}",
            "--stock-top", f"{part.Z_BASE_MM + part.A_MM + 0.05}", "--threads", "2"]
    if window:
        args += ["--window", ",".join(f"{w:.4f}" for w in window), "--pick-feed", f"{part.PICK_MM}"]
    if stock_cells:
        args += ["--stock-cells", str(stock_cells)]
    if block:
        args += ["--block", f"{block}"]
    r = subprocess.run(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    with open(os.path.join(out_dir, "predict.out"), "w") as f:
        f.write(r.stdout + r.stderr)
    if r.returncode != 0:
        raise RuntimeError(f"cnc-predict failed ({r.returncode}): {r.stderr[-1500:]}")
    return r.stdout


def measure_window(build, setpoints, program, out_dir, rpm, region, ylo, yhi):
    """R_max in one flat region: areal (every cell) and along X (profiles, as a stylus reads them)."""
    x0, x1 = region["x_mm"] - region["half_width_mm"], region["x_mm"] + region["half_width_mm"]
    text = predict(build, setpoints, program, out_dir, rpm, 0.0025, window=(x0, ylo, x1, yhi), stock_cells=100000)
    # cnc-predict's own figures: R_max against the centre pass's path offset by r, and the model there.
    kv = dict(w.split("=", 1) for w in text.split() if "=" in w)
    x, y, dev = deviation(os.path.join(out_dir, "stock.csv"))
    inside = (x >= x0) & (x <= x1)
    d = dev[:, inside] * 1e3
    prof = d.max(axis=1) - d.min(axis=1)
    np.save(os.path.join(out_dir, "deviation_um.npy"), d)
    return {
        "x_mm": region["x_mm"], "kind": region["kind"], "window": [x0, ylo, x1, yhi],
        "rmax_um": float(d.max() - d.min()),
        "rmax_profile_x_mean_um": float(prof.mean()), "rmax_profile_x_max_um": float(prof.max()),
        "mean_deviation_um": float(d.mean()),
        "model_um": kv.get("model_um", ""),
        "feed_per_tooth_mm": kv.get("f_t", ""), "alpha_deg": kv.get("alpha_deg", ""),
    }


def main():
    # SIGTERM (./cnc's run_child hands it on) as an exception: run_cell's finally stops the cell.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build", required=True)
    ap.add_argument("--machine", required=True)
    ap.add_argument("--size", choices=sorted(part.SIZES), default="reduced")
    ap.add_argument("--out", required=True)
    ap.add_argument("--skip-runs", action="store_true", help="analyse the logs already in --out")
    ap.add_argument("--no-map", action="store_true", help="no whole-strip Z-map (the R_max windows only)")
    a = ap.parse_args()
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    prog_dir = os.path.join(out, "programs")
    subprocess.run([sys.executable, os.path.join(HERE, "table1_part.py"), "--size", a.size, "--out", prog_dir],
                   check=True)
    with open(os.path.join(prog_dir, "part.json")) as f:
        geo = json.load(f)
    results = {"size": a.size, "part": geo, "runs": {}}
    # The measured band across the passes: the middle 1 mm (the whole strip but its outer passes when narrower).
    ymid = 0.5 * (geo["y_mm"][0] + geo["y_mm"][1])
    half = min(0.5, 0.5 * (geo["y_mm"][1] - geo["y_mm"][0]) - part.PICK_MM)
    ylo, yhi = ymid - half, ymid + half
    whole_map = a.size != "full" and not a.no_map
    for run in ("fixed", "law"):
        program = os.path.join(prog_dir, f"table1_{run}.ngc")
        rd = os.path.join(out, run)
        if not a.skip_runs:
            say(f"{run}: running {program} in the live cell")
            wall = run_cell(a.build, os.path.abspath(a.machine), program, rd, 7200)
        else:
            wall = math.nan
        logs = sorted(f for f in os.listdir(rd) if f.startswith("cell") and ".lcmlog" in f)
        export = os.path.join(rd, "export")
        subprocess.run([os.path.join(a.build, "tools", "cnc-logexport"), "--log", os.path.join(rd, logs[0]),
                        "--out", export], check=True, stdout=subprocess.DEVNULL)
        with open(os.path.join(export, "summary.json")) as f:
            summary = json.load(f)
        act_csv = os.path.join(rd, "actual_setpoints.csv")
        act = actual_setpoints(export, act_csv, part.RPM)
        with open(os.path.join(rd, "trace.json"), "w") as f:
            json.dump({k: act[k] for k in ("t_s", "feed_actual", "feed_commanded", "x_mm", "y_mm", "z_mm", "line")}, f)
        # The finishing passes' time: from the first G6.2 to the end of the last pass (the
        # program time also holds the spindle's run-up, the approach and the retract).
        with open(program) as f:
            text = f.read().splitlines()
        first = next(i for i, row in enumerate(text) if row.startswith("G6.2")) + 1
        last = max(i for i, row in enumerate(text) if row.startswith("K")) + 1
        tl = [t for t, ln in zip(act["t_s"], act["line"]) if first <= ln <= last]
        passes_s = tl[-1] - tl[0] + 0.004 if tl else math.nan
        say(f"{run}: program time {summary.get('program_time_s', math.nan):.3f} s, passes {passes_s:.3f} s, spindle {act['spindle_rpm_mean']:.1f} rpm "
            f"({act['spindle_rpm_min']:.1f}..{act['spindle_rpm_max']:.1f}) while moving")
        res = {"wall_s": wall, "program_time_s": summary.get("program_time_s"), "passes_time_s": passes_s,
               "spindle_rpm_mean": act["spindle_rpm_mean"], "spindle_rpm_min": act["spindle_rpm_min"],
               "spindle_rpm_max": act["spindle_rpm_max"], "summary": summary, "regions": []}
        for reg in geo["flat_regions"]:
            say(f"{run}: Z-map of the {reg['kind']} at x {reg['x_mm']:g} mm")
            w = measure_window(a.build, act_csv, program, os.path.join(rd, f"window_{reg['x_mm']:g}"),
                               part.RPM, reg, ylo, yhi)
            say(f"{run}: {reg['kind']} at x {reg['x_mm']:g}: R_max {w['rmax_um']:.2f} um (along X: mean "
                f"{w['rmax_profile_x_mean_um']:.2f}, max {w['rmax_profile_x_max_um']:.2f} um)")
            res["regions"].append(w)
        if whole_map:
            say(f"{run}: Z-map of the whole strip")
            predict(a.build, act_csv, program, os.path.join(rd, "whole"), part.RPM, 0.01, block=0.25,
                    stock_cells=1000)
        results["runs"][run] = res
    with open(os.path.join(out, "results.json"), "w") as f:
        json.dump(results, f, indent=1)
    subprocess.run([sys.executable, os.path.join(HERE, "table1_report.py"), out], check=True)
    say(f"report: {out}/table1.md")


if __name__ == "__main__":
    main()
