#!/usr/bin/python3
"""Machining-time bench (issue 31, item 4): real CAM programs through the project's
planner (the dry run, cnc-plan) and through LinuxCNC 2.9's (headless, linuxcnc_sim/),
at the same blend tolerance, each time against the program's length/F bound.

Per program it prints:
  bound     length/F: each move's length over its feed, the feed capped along the move
            by the axes' velocity limits (rapids at that cap), plus the dwells (s)
  ours      the project's machining time (first to last moving setpoint, 4 ms) and its
            ratio to the bound
  lcnc      LinuxCNC's (first to last moving servo sample, 1 ms, in servo time) and ratio
  o/l       ours / LinuxCNC
  stops     times the path stands still between its first and last motion, on each side
            (the dwells' own stops taken off: every dwell with motion on both sides of it
            forces one on both planners; see STOPS below)
  dev       the largest distance of the commanded path (samples joined by straight lines)
            from the programmed lines and arcs, on each side (mm; cnc-path-deviation)
  jerk      the project's largest per-axis jerk from finite differences of its 4 ms
            setpoints, as a share of that axis's limit (cnc-plan's own figure)
  sp/s      the dry run's setpoints per second (cnc-plan without --csv; interpolator core
            with the G64 P fit, planner inline)
  j*100     the project's program time with every jerk limit (axes', path's) 100 times
            as high, and its ratio to LinuxCNC's: what the jerk limit costs on the same
            path, which LinuxCNC 2.9 (no jerk limit) does not pay
and the geometric mean of the ratio ours/LinuxCNC, against the goal (<= 1.0, no program
above 1.10). Also: the project's time with the roughness law of the machine file on
(its process: section; the main table is with it off, as LinuxCNC has none), LinuxCNC's
servo clock against the wall, and a plot of the ratios (matplotlib).

Programs: tools/bench/programs/cam/*.ngc (sources and licences in its README.md) and the
micro-segment bench's raster and surface (microseg_programs.py), each adapted the same
way for both planners (adapt() below: no tool changes, no operator stops, no '%' lines).
Tolerance: "main" inserts G64 P0.0254 (mm) where a program gives none (a G64 without P
gets P0.0254); "asis" runs the programs as they are (after the adaptations).

Machines: a copy of the machine file with every axis's travel at +-2000 mm (the
programs' own origins are kept), in OUT/machines/; LinuxCNC gets the same travel and
sim3's axis limits (linuxcnc_sim/sim3.ini). Every LinuxCNC program runs in a fresh
session (linuxcnc_sim/run.sh --record: the commanded joint positions at the servo rate).

STOPS: a stop is a run of sample intervals whose mean path speed (|p[k+1]-p[k]| / T) is
below V_STOP + the most a sample interval touching a true stop can show at that
planner's period and limits: LinuxCNC limits acceleration (its 1 ms samples next to a
stop move up to a T / 2 on average: a = the path's acceleration bound, |(3000, 3000,
2000)| mm/s^2, 2.3 mm/s), the project limits jerk (its 4 ms setpoints: j T^2 / 6 with
j = |(60000, 60000, 40000)| mm/s^3, 0.25 mm/s). V_STOP = 0.5 mm/s.

  machining_time.py [--out DIR] [--modes main,asis] [--only NAME,...] [--no-linuxcnc]
                    [--reuse] [--plan PATH] [--deviation PATH] [--machine FILE]
"""
import argparse
import copy
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)
import microseg_programs  # noqa: E402

TOL_MM = 0.0254
TRAVEL_MM = 2000
JERK_FREE = 100  # the j*100 column: every jerk limit this many times as high
V_STOP = 0.5  # mm/s
LCNC_T = 0.001
GOAL_GEOMEAN, GOAL_MAX = 1.0, 1.10

# ---- programs ------------------------------------------------------------------------

WORD_DROP = [
    # tool changes and operator stops: a 3-axis bench machine has no changer and no operator
    re.compile(r"(?<![A-Z#<\[])M0*(?:0|1|6|60)(?![0-9.])", re.I),
    re.compile(r"(?<![A-Z#<\[])T\s*(?:#<[^>]*>|#[0-9]+|\[[^\]]*\]|[0-9.]+)", re.I),
]


def split_comments(line):
    """(code, comments): the parts of a line outside and inside (...) and after ';'."""
    code, comments, depth = [], [], 0
    i = 0
    while i < len(line):
        c = line[i]
        if depth == 0 and c == ";":
            comments.append(line[i:])
            break
        if c == "(":
            depth += 1
        if depth:
            comments.append(c)
        else:
            code.append(c)
        if c == ")" and depth:
            depth -= 1
        i += 1
    return "".join(code), "".join(comments)


def adapt(text, mode):
    """The program as both planners run it: '%' lines dropped (program delimiters, and
    the remarks some posts write after one; M2 added where they were the only end),
    tool changes (M6, T words) and operator stops (M0, M1, M60) taken out of the code
    (comments kept). mode 'main': G64 P0.0254 where the program sets no tolerance
    (first line; a G64 without P gets one)."""
    out = []
    has_p = False
    for line in text.splitlines():
        if line.lstrip().startswith("%"):
            continue
        code, comments = split_comments(line)
        for rx in WORD_DROP:
            code = rx.sub("", code)
        if re.search(r"G0*64(?![0-9.])", code, re.I):
            if re.search(r"G0*64(?![0-9.])\s*P", code, re.I):
                has_p = True
            elif mode == "main":
                code = re.sub(r"(G0*64)(?![0-9.])", r"\1 P%g" % TOL_MM, code, count=1, flags=re.I)
        out.append((code.rstrip() + (" " + comments if comments else "")).rstrip())
    if mode == "main" and not has_p:
        out.insert(0, "G64 P%g (machining-time bench: the blend tolerance, mm)" % TOL_MM)
    if not any(re.search(r"(?<![A-Z#<\[])M0*(?:2|30)(?![0-9.])", split_comments(l)[0], re.I) for l in out):
        out.append("M2 (machining-time bench: the end the '%' lines gave)")
    return "\n".join(out) + "\n"


def tolerance_of(text):
    """The first G64 P of a program in mm (its units at that line), or None."""
    inch = False
    for line in text.splitlines():
        code, _ = split_comments(line)
        if re.search(r"G0*20(?![0-9.])", code, re.I):
            inch = True
        if re.search(r"G0*21(?![0-9.])", code, re.I):
            inch = False
        m = re.search(r"G0*64(?![0-9.])\s*P\s*([0-9.]+)", code, re.I)
        if m:
            return float(m.group(1)) * (25.4 if inch else 1.0)
    return None


def sources(out_dir):
    """(name, original text) of every program: the CAM folder, then raster and surface."""
    progs = []
    cam = os.path.join(HERE, "programs", "cam")
    for f in sorted(os.listdir(cam)):
        if f.endswith(".ngc"):
            progs.append((f[:-4], open(os.path.join(cam, f)).read()))
    # The micro-segment bench's programs, written as that bench writes them but with no
    # path mode of their own (the mode is the bench's).
    r = microseg_programs.raster()
    _, sampled = microseg_programs.surface(100000)
    for name, body in (("ms_raster", r), ("ms_surface", sampled)):
        text = "(%s: tools/bench/microseg_programs.py)\nG21 G17 G90 G54 G40 G49 G80\n%sG0 Z5\nM2\n" % (name, body)
        progs.append((name, text))
    return progs


# ---- machines --------------------------------------------------------------------------

def machines(base, out_dir):
    """Copies of the machine file with +-TRAVEL_MM of travel and a tool table with tool 1
    (LinuxCNC's sim.tbl has it too): {'law_on': path, 'law_off': path}, the second
    without the process: section (no roughness law)."""
    import yaml
    d = os.path.join(out_dir, "machines")
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, "tools.tbl"), "w") as f:
        f.write("T1 P1 D6 ;\n")
    cfg = yaml.safe_load(open(base))
    for a in cfg["axes"]:
        a["min_mm"], a["max_mm"] = -TRAVEL_MM, TRAVEL_MM
    cfg.setdefault("program", {})["tool_table"] = "tools.tbl"
    out = {}
    for law in ("law_on", "law_off", "jerk_free"):
        c = copy.deepcopy(cfg)
        if law != "law_on":
            c.pop("process", None)
        note = {"law_on": "", "law_off": ", no process: section",
                "jerk_free": ", no process: section, every jerk limit x%g" % JERK_FREE}[law]
        if law == "jerk_free":
            for a in c["axes"]:
                a["max_jerk_mm_s3"] *= JERK_FREE
            if "path_jerk_mm_s3" in c.get("motion", {}):
                c["motion"]["path_jerk_mm_s3"] *= JERK_FREE
        path = os.path.join(d, "wide_%s.yaml" % law)
        with open(path, "w") as f:
            f.write("# %s with every axis's travel at +-%d mm%s (machining_time.py)\n"
                    % (os.path.relpath(base, ROOT), TRAVEL_MM, note))
            yaml.safe_dump(c, f, sort_keys=False)
        out[law] = path
    return out


def machine_limits(path):
    import yaml
    cfg = yaml.safe_load(open(path))
    axes = cfg["axes"][:3]
    return {
        "T": cfg["timing"]["ipo_period_s"],
        "a": [a["max_accel_mm_s2"] for a in axes],
        "j": [a["max_jerk_mm_s3"] for a in axes],
    }


# ---- runs ------------------------------------------------------------------------------

def run(cmd, timeout=None):
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    return r.returncode, r.stdout, r.stderr


def kv(line):
    return dict(w.split("=", 1) for w in line.split()[1:] if "=" in w)


def geometry(dev, program, machine):
    dump = os.path.splitext(program)[0] + ".moves.csv"
    rc, out, err = run([dev, "--program", program, "--machine", machine, "--dump", dump])
    if rc != 0:
        raise RuntimeError("cnc-path-deviation refused %s: %s" % (program, err.strip()))
    g = kv(out.splitlines()[0])
    g = {k: float(v) for k, v in g.items()}
    g.update(against_rs274(program, dump, os.path.join(os.path.dirname(machine), "tools.tbl")))
    return g


def against_rs274(program, dump, tools):
    """The moves the geometry is made of (the project's interpreter) against LinuxCNC's
    own interpreter, rs274 (with the bench's tool table: rs274's own has lengths): the same
    count of moves and their end points (rs274 prints 4 decimals of the program's units:
    0.00005 in = 0.0013 mm)."""
    if not shutil.which("rs274"):
        return {}
    out = program + ".rs274"
    with open(os.devnull) as null:
        subprocess.run(["rs274", "-t", tools, "-g", program, out], stdin=null, capture_output=True, timeout=600)
    if not os.path.exists(out):
        return {"rs274_moves": -1}
    theirs, scale, plane = [], 1.0, "XY"
    for line in open(out):
        m = re.search(r"([A-Z_]+)\((.*)\)\s*$", line)
        if not m:
            continue
        call, a = m.group(1), m.group(2)
        if call == "USE_LENGTH_UNITS":
            scale = 25.4 if "INCHES" in a else 1.0
        elif call == "SELECT_PLANE":
            plane = a.split("_")[-1]
        elif call in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            v = [float(x) for x in a.split(",")[:3]]
            theirs.append([x * scale for x in v])
        elif call == "ARC_FEED":
            v = [float(x) for x in a.split(",")]
            first, second, axis = v[0], v[1], v[5]
            xyz = {"XY": (first, second, axis), "XZ": (second, axis, first), "YZ": (axis, first, second)}[plane]
            theirs.append([x * scale for x in xyz])
    ours = np.loadtxt(dump, delimiter=",", skiprows=1, usecols=(5, 6, 7), ndmin=2)
    r = {"rs274_moves": len(theirs), "moves_dumped": len(ours)}
    if len(theirs) == len(ours) and len(ours):
        r["rs274_max_mm"] = float(np.abs(np.array(theirs) - ours).max())
    return r


def deviation(dev, program, machine, csv):
    rc, out, err = run([dev, "--program", program, "--machine", machine, "--path", csv])
    if rc != 0:
        raise RuntimeError("cnc-path-deviation: %s" % err.strip())
    p = kv([l for l in out.splitlines() if l.startswith("path ")][0])
    return {"max_mm": float(p["max_mm"]), "lo_mm": float(p["lo_mm"]), "line": int(p["line"]),
            "at": [float(p["x"]), float(p["y"]), float(p["z"])]}


def plan(plan_bin, program, machine, csv):
    """cnc-plan: its printed figures (program time, setpoints/s, peak use of the limits)."""
    cmd = [plan_bin, "--machine", machine, "--program", program] + (["--csv", csv] if csv else [])
    t0 = time.monotonic()
    rc, out, err = run(cmd)
    wall = time.monotonic() - t0
    if rc != 0:
        return {"error": (err or out).strip().splitlines()[-1] if (err or out).strip() else "exit %d" % rc}
    m = re.search(r"program time ([0-9.]+) s \(([0-9]+) cycles.*?([0-9.]+) setpoints/s", out)
    use = {}
    for ax, v, a, j in re.findall(r"([A-Z]) v ([0-9.]+) a ([0-9.]+) j ([0-9.]+);", out):
        use[ax] = {"v": float(v), "a": float(a), "j": float(j)}
    return {"program_time_s": float(m.group(1)), "cycles": int(m.group(2)), "setpoints_per_s": float(m.group(3)),
            "use": use, "wall_s": wall}


def motion(P, T, eps):
    """From positions P (rows, the first at the start) sampled every T: the first and
    last moving interval and the mean speed of every interval."""
    d = np.linalg.norm(np.diff(P, axis=0), axis=1)
    moving = np.nonzero(d > eps)[0]
    if len(moving) == 0:
        return None
    return moving[0], moving[-1], d / T


def stops(v, first, last, threshold):
    """Runs of intervals in [first, last] whose mean speed is below threshold."""
    below = v[first:last + 1] < threshold
    if not below.any():
        return 0
    edges = np.diff(below.astype(np.int8))
    return int(below[0]) + int(np.count_nonzero(edges == 1))


def stop_thresholds(lim):
    """Both planners' stop thresholds (the project's, LinuxCNC's): each side is also
    counted at the other's, to show how much the count depends on it."""
    j_path = math.sqrt(sum(x * x for x in lim["j"]))
    a_path = math.sqrt(sum(x * x for x in lim["a"]))
    return (V_STOP + j_path * lim["T"] ** 2 / 6, V_STOP + a_path * LCNC_T / 2)


def ours(args, name, program, machine, lim, work, dev):
    csv = os.path.join(work, "ours.csv")
    if not (args.reuse and os.path.exists(csv) and os.path.exists(csv + ".json")):
        r = plan(args.plan, program, machine, csv)
        json.dump(r, open(csv + ".json", "w"))
    r = json.load(open(csv + ".json"))
    if "error" in r:
        return r
    data = np.loadtxt(csv, delimiter=",", skiprows=1, usecols=(2, 3, 4), ndmin=2)
    P = np.vstack([np.zeros((1, 3)), data])  # the dry run starts at the machine's home, 0 0 0
    T = lim["T"]
    m = motion(P, T, 1e-7)
    first, last, v = m
    j_path = math.sqrt(sum(x * x for x in lim["j"]))
    r["thr"] = V_STOP + j_path * T * T / 6
    r["time_s"] = (last - first + 1) * T
    r["stops_raw"] = stops(v, first, last, r["thr"])
    r["stops_at"] = {"%.2f" % x: stops(v, first, last, x) for x in stop_thresholds(lim)}
    r["dev"] = deviation(dev, program, machine, csv)
    r["jerk_use"] = max(u["j"] for u in r["use"].values()) if r["use"] else float("nan")
    r["jerk_axis"] = max(r["use"], key=lambda k: r["use"][k]["j"]) if r["use"] else "-"
    return r


def cpu_hz():
    for line in open("/proc/cpuinfo"):
        if line.startswith("cpu MHz"):
            return float(line.split(":")[1]) * 1e6
    return float("nan")


def lcnc(args, name, program, machine, lim, work, dev, timeout):
    d = os.path.join(work, "lcnc")
    res = os.path.join(d, "results.txt")
    if not (args.reuse and os.path.exists(res) and "ok=True" in open(res).read()):
        if os.path.isdir(d):
            shutil.rmtree(d)
        load0 = open("/proc/loadavg").read().split()[0]
        rc, out, err = run([args.linuxcnc, "--record", "--travel", str(TRAVEL_MM), "--timeout", str(int(timeout)),
                            d, program], timeout=timeout + 120)
        load1 = open("/proc/loadavg").read().split()[0]
        with open(os.path.join(d, "load.txt"), "w") as f:
            f.write("%s %s\n" % (load0, load1))
    lines = [l for l in open(res).read().splitlines() if l.strip()] if os.path.exists(res) else []
    if not lines or "ok=True" not in lines[0]:
        return {"error": "LinuxCNC: " + (lines[0] if lines else "no result (tty.log in %s)" % d)}
    head = lines[0].split()
    r = {"wall_s": float(head[1])}
    r.update({k: v for k, v in kv(lines[0]).items() if k in ("overruns", "span_min", "span_max", "err", "stalled")})
    r["load"] = open(os.path.join(d, "load.txt")).read().split() if os.path.exists(os.path.join(d, "load.txt")) else []
    samples = os.path.join(d, kv(lines[0])["samples"])
    raw = [l for l in open(samples) if l.strip()]
    r["gaps"] = sum(1 for l in raw if l.startswith("overrun"))
    S = np.array([[float(x) for x in l.split()] for l in raw if not l.startswith("overrun")])
    r["samples"] = len(S)
    P = S[:, 1:4]
    m = motion(P, LCNC_T, 5e-7)
    first, last, v = m
    a_path = math.sqrt(sum(x * x for x in lim["a"]))
    r["thr"] = V_STOP + a_path * LCNC_T / 2
    r["time_s"] = (last - first + 1) * LCNC_T
    r["stops_raw"] = stops(v, first, last, r["thr"])
    r["stops_at"] = {"%.2f" % x: stops(v, first, last, x) for x in stop_thresholds(lim)}
    # The servo clock against the wall: this LinuxCNC reports motion.servo.last-period in
    # CPU clocks (TSC) or in ns; the samples' count is servo time.
    per = S[:, 6]
    scale = cpu_hz() if np.median(per) > 1.5e6 else 1e9
    r["servo_s"] = len(S) * LCNC_T
    r["servo_wall_s"] = float(per[1:].sum() / scale)
    r["servo_max_gap_ms"] = float(per[1:].max() / scale * 1e3)
    csv = os.path.join(d, "path.csv")
    lo, hi = max(0, first - 1), min(len(P), last + 2)
    np.savetxt(csv, P[lo:hi], fmt="%.6f", delimiter=",", header="x_mm,y_mm,z_mm", comments="")
    r["dev"] = deviation(dev, program, machine, csv)
    return r


# ---- the bench -------------------------------------------------------------------------

def geomean(xs):
    xs = [x for x in xs if x and x > 0 and math.isfinite(x)]
    return math.exp(sum(math.log(x) for x in xs) / len(xs)) if xs else float("nan")


def fmt(x, f="%.2f"):
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f % x


def table(rows, mode, law_on):
    out = []
    out.append("mode %s: G64 P %s; times in s (motion: first to last moving sample), dev in mm" %
               (mode, "0.0254 where the program gives none" if mode == "main" else "as the program gives"))
    hdr = ("%-16s %6s %7s | %8s %5s | %8s %5s | %5s | %5s %5s | %7s %7s | %5s | %9s | %8s | %8s %5s"
           % ("program", "P mm", "bound", "ours", "/bnd", "lcnc", "/bnd", "o/l", "st.o", "st.l", "dev.o", "dev.l",
              "jerk", "sp/s", "law on", "j*100", "/l"))
    out.append(hdr)
    out.append("-" * len(hdr))
    for r in rows:
        o, l, g = r["ours"], r.get("lcnc", {}), r["geo"]
        if "error" in o:
            out.append("%-16s ours: %s" % (r["name"], o["error"]))
            continue
        lt = l.get("time_s") if l and "error" not in l else None
        dw = int(g["dwell_stops"])
        jf = r.get("jerk_free_s")
        out.append("%-16s %6s %7.2f | %8.2f %5.2f | %8s %5s | %5s | %5d %5s | %7.4f %7s | %5.2f | %9.0f | %8s | %8s %5s" % (
            r["name"], fmt(r["tol_mm"], "%.4f"), g["bound_s"], o["time_s"], o["time_s"] / g["bound_s"],
            fmt(lt), fmt(lt / g["bound_s"] if lt else None), fmt(o["time_s"] / lt if lt else None),
            max(0, o["stops_raw"] - dw), "-" if lt is None else "%d" % max(0, l["stops_raw"] - dw),
            o["dev"]["max_mm"], fmt(l["dev"]["max_mm"], "%.4f") if lt else "-", o["jerk_use"],
            r.get("sps", float("nan")), fmt(law_on.get(r["name"]), "%.2f"), fmt(jf),
            fmt(jf / lt if jf and lt else None)))
        if l and "error" in l:
            out.append("%-16s lcnc: %s" % ("", l["error"]))
    ratios = [r["ours"]["time_s"] / r["lcnc"]["time_s"] for r in rows
              if "error" not in r["ours"] and r.get("lcnc") and "error" not in r["lcnc"]]
    free = [r["jerk_free_s"] / r["lcnc"]["time_s"] for r in rows
            if r.get("jerk_free_s") and r.get("lcnc") and "error" not in r["lcnc"]]
    if ratios:
        gm = geomean(ratios)
        worst = max(ratios)
        out.append("geometric mean of ours/LinuxCNC over %d programs: %.3f (goal <= %.2f: %s); largest %.3f "
                   "(goal <= %.2f: %s)" % (len(ratios), gm, GOAL_GEOMEAN, "met" if gm <= GOAL_GEOMEAN else "NOT met",
                                           worst, GOAL_MAX, "met" if worst <= GOAL_MAX else "NOT met"))
    if free:
        out.append("the same with every jerk limit x%g (j*100/l): geometric mean %.3f, largest %.3f"
                   % (JERK_FREE, geomean(free), max(free)))
    chk = [(r["name"], r["geo"].get("rs274_moves"), r["geo"].get("moves_dumped"), r["geo"].get("rs274_max_mm"))
           for r in rows]
    bad = [c for c in chk if c[1] is not None and (c[1] != c[2] or c[3] is None or c[3] > 0.0015)]
    if any(c[1] is not None for c in chk):
        out.append("geometry against LinuxCNC's rs274: %s" % (
            "every move's end point within %.4f mm (%d moves)" % (max(c[3] for c in chk if c[3] is not None),
                                                                 sum(c[2] for c in chk if c[2]))
            if not bad else "DIFFERS: " + ", ".join("%s %s/%s moves, %s mm" % c for c in bad)))
    out.append("st.o/st.l: stops, the dwells' own (%s) taken off; jerk: the project's largest per-axis jerk "
               "(finite differences of its 4 ms setpoints) / that axis's limit; sp/s: the dry run's setpoints per "
               "second (no CSV); law on: the project's time with the machine file's roughness law (process:)"
               % ", ".join("%s %d" % (r["name"], r["geo"]["dwell_stops"]) for r in rows if r["geo"]["dwell_stops"]))
    return "\n".join(out)


def clock_table(rows):
    out = ["LinuxCNC's servo clock against the wall (samples x 1 ms; the sum of motion.servo.last-period; "
           "the driver's enable-to-disable span; the longest servo gap; load average before/after):"]
    for r in rows:
        l = r.get("lcnc")
        if not l or "error" in l:
            continue
        out.append("  %-16s servo %8.3f s  periods %8.3f s (x%.4f)  span %8.3f..%8.3f s  longest gap %6.1f ms  "
                   "wall %8.3f s  load %s  gaps in the record %d" % (
                       r["name"], l["servo_s"], l["servo_wall_s"], l["servo_wall_s"] / l["servo_s"],
                       float(l.get("span_min", "nan")), float(l.get("span_max", "nan")), l["servo_max_gap_ms"],
                       l["wall_s"], "/".join(l["load"]), l["gaps"] + int(l.get("overruns", "0") or 0))
                   + ("  (its interpreter stayed out of idle after the last motion: %s)" % l["stalled"]
                      if l.get("stalled") else ""))
    return "\n".join(out)


def plot(rows, mode, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ok = [r for r in rows if "error" not in r["ours"] and r.get("lcnc") and "error" not in r["lcnc"]]
    if not ok:
        return
    names = [r["name"] for r in ok]
    x = np.arange(len(ok))
    ob = [r["ours"]["time_s"] / r["geo"]["bound_s"] for r in ok]
    lb = [r["lcnc"]["time_s"] / r["geo"]["bound_s"] for r in ok]
    ol = [r["ours"]["time_s"] / r["lcnc"]["time_s"] for r in ok]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(max(8, 0.8 * len(ok) + 3), 8), sharex=True)
    a1.bar(x - 0.2, ob, 0.4, label="project / bound")
    a1.bar(x + 0.2, lb, 0.4, label="LinuxCNC 2.9 / bound")
    a1.axhline(1.0, color="k", lw=0.8)
    a1.set_ylabel("machining time / (length/F bound)")
    a1.legend()
    a1.set_title("machining time, mode %s (%s)" % (
        mode, "G64 P0.0254 where the program gives none" if mode == "main" else "path modes as the programs give them"))
    a2.bar(x, ol, 0.6, color=["tab:green" if v <= GOAL_MAX else "tab:red" for v in ol])
    gm = geomean(ol)
    a2.axhline(1.0, color="k", lw=0.8)
    a2.axhline(GOAL_MAX, color="tab:red", lw=0.8, ls="--", label="1.10: no program above")
    a2.axhline(gm, color="tab:blue", lw=1.2, label="geometric mean %.3f" % gm)
    a2.set_ylabel("project / LinuxCNC")
    a2.set_xticks(x)
    a2.set_xticklabels(names, rotation=30, ha="right")
    a2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(ROOT, "runs", "machining-time"))
    ap.add_argument("--modes", default="main", help="main, asis (comma-separated)")
    ap.add_argument("--only", default="", help="program names (comma-separated)")
    ap.add_argument("--no-linuxcnc", action="store_true", help="the project's side only")
    ap.add_argument("--reuse", action="store_true", help="keep the runs already in OUT (LinuxCNC's take wall time)")
    ap.add_argument("--build", default=os.environ.get("CNC_BUILD_DIR", os.path.join(ROOT, "build")))
    ap.add_argument("--plan", default=None, help="cnc-plan (default: BUILD/tools/cnc-plan)")
    ap.add_argument("--deviation", default=None, help="cnc-path-deviation (default: BUILD/tools/bench/...)")
    ap.add_argument("--linuxcnc", default=os.path.join(HERE, "linuxcnc_sim", "run.sh"))
    ap.add_argument("--machine", default=os.path.join(ROOT, "config", "machines", "sim3.yaml"))
    args = ap.parse_args()
    args.plan = args.plan or os.path.join(args.build, "tools", "cnc-plan")
    args.deviation = args.deviation or os.path.join(args.build, "tools", "bench", "cnc-path-deviation")
    for b in (args.plan, args.deviation):
        if not os.access(b, os.X_OK):
            sys.exit("machining_time.py: no %s (build first: ./cnc build)" % b)
    os.makedirs(args.out, exist_ok=True)
    mach = machines(args.machine, args.out)
    lim = machine_limits(mach["law_off"])
    only = set(filter(None, args.only.split(",")))
    progs = [(n, t) for n, t in sources(args.out) if not only or n in only]
    report = ["machining-time bench, %s; %s; load average at the start %s" % (
        time.strftime("%Y-%m-%d %H:%M:%S"), subprocess.run(["git", "-C", ROOT, "describe", "--always", "--dirty"],
                                                           capture_output=True, text=True).stdout.strip(),
        open("/proc/loadavg").read().split()[0])]
    results = {}
    for mode in args.modes.split(","):
        rows, law_on = [], {}
        for name, text in progs:
            work = os.path.join(args.out, mode, name)
            os.makedirs(work, exist_ok=True)
            program = os.path.join(work, name + ".ngc")
            adapted = adapt(text, mode)
            if not (args.reuse and os.path.exists(program) and open(program).read() == adapted):
                open(program, "w").write(adapted)
            row = {"name": name, "tol_mm": tolerance_of(adapted)}
            row["geo"] = geometry(args.deviation, program, mach["law_off"])
            print("%s %s: bound %.2f s ..." % (mode, name, row["geo"]["bound_s"]), file=sys.stderr, flush=True)
            row["ours"] = ours(args, name, program, mach["law_off"], lim, work, args.deviation)
            if "error" not in row["ours"]:
                sps = plan(args.plan, program, mach["law_off"], None)
                row["sps"] = sps.get("setpoints_per_s", float("nan"))
                on = plan(args.plan, program, mach["law_on"], None)
                law_on[name] = on.get("program_time_s", float("nan"))
                row["jerk_free_s"] = plan(args.plan, program, mach["jerk_free"], None).get("program_time_s")
                row["law_on_program_time_s"] = law_on[name]
            if not args.no_linuxcnc:
                row["lcnc"] = lcnc(args, name, program, mach["law_off"], lim, work, args.deviation,
                                   timeout=10 * row["geo"]["bound_s"] + 300)
            rows.append(row)
            o, l = row["ours"], row.get("lcnc", {})
            print("  ours %s  lcnc %s" % (fmt(o.get("time_s")), fmt(l.get("time_s")) if l else "-"),
                  l.get("error", "") if l else "", file=sys.stderr, flush=True)
        # law on: as the time printed by cnc-plan; the ratio to the law-off program time
        for r in rows:
            if r["name"] in law_on and "error" not in r["ours"]:
                law_on[r["name"]] = law_on[r["name"]] / r["ours"]["program_time_s"]
        report.append(table(rows, mode, law_on).replace("law on: the project's time",
                                                        "law on: the project's time (its ratio to law off)"))
        if not args.no_linuxcnc:
            report.append(clock_table(rows))
            plot(rows, mode, os.path.join(args.out, "ratios-%s.png" % mode))
        results[mode] = rows
    text = "\n\n".join(report)
    print(text)
    open(os.path.join(args.out, "table.txt"), "w").write(text + "\n")
    json.dump(results, open(os.path.join(args.out, "results.json"), "w"), indent=1, default=float)
    print("\n(%s: table.txt, results.json%s)" % (args.out, ", ratios-*.png" if not args.no_linuxcnc else ""))


if __name__ == "__main__":
    main()
