"""The safety chain's live figures, shared by the hard-limit and guard-door tests:
AXIS_STATUS and IO_STATUS read from a cell's log, and a stop measured from an input's
edge (the simulator's wall-clock stamp) against the bounds of a stop at deceleration a
and jerk j."""
import re

from lcmlog import events, Fields


def x_stop_limits(machine_file):
    """(stop deceleration, X's acceleration, X's jerk) of a machine file."""
    text = open(machine_file).read()
    decel = float(re.search(r"stop_decel_mm_s2:\s*([0-9.]+)", text).group(1))
    x_axis = text[text.index("- name: X"):text.index("- name: Y")]
    accel = float(re.search(r"max_accel_mm_s2:\s*([0-9.]+)", x_axis).group(1))
    jerk = float(re.search(r"max_jerk_mm_s3:\s*([0-9.]+)", x_axis).group(1))
    return decel, accel, jerk


def sim_edges(lines, point):
    """From the simulator's log lines: the falling edges of I/O point `point` (wall us, X mm,
    X mm/s) and each drive's enable and disable (wall us, axis, what, mm, mm/s)."""
    edges, power = [], []
    edge = re.compile(r"io io1: %s set to 0 at utime (\d+) with X (-?[0-9.]+) mm (-?[0-9.]+) mm/s" % re.escape(point))
    for line in lines:
        m = edge.search(line)
        if m: edges.append((int(m.group(1)), float(m.group(2)), float(m.group(3))))
        m = re.search(r"axis ([XYZ]): (enabled|disabled) at (-?[0-9.]+) mm, (-?[0-9.]+) mm/s, utime (\d+)", line)
        if m: power.append((int(m.group(5)), m.group(1), m.group(2), float(m.group(3)), float(m.group(4))))
    return edges, power


def read_io_status(log, prefix):
    """([(utime, X commanded, X actual)], [IO_STATUS as dicts]) of the log."""
    axis, io = [], []
    for ts, ch, b in events(log):
        if ch == prefix + "AXIS_STATUS":
            f = Fields(b)
            utime, _, _, _ = f.get("qqiq")
            n = f.get("i")
            for _ in range(n): f.str()
            cmd = f.get("%dd" % n)
            act = f.get("%dd" % n)
            axis.append((utime, cmd[0], act[0]))
        elif ch == prefix + "IO_STATUS":
            f = Fields(b)
            f.get("qqiqbq")
            n = f.get("i")
            for _ in range(n): f.str()
            f.get("%db" % n); f.get("%dd" % n); f.get("%db" % n)
            m = f.get("i")
            for _ in range(m): f.str()
            f.get("%db" % m); f.get("%dq" % m); f.get("%dq" % m); f.get("%dq" % m)
            for _ in range(m): f.str()
            s = {"ts": ts}
            s["estop"] = f.get("b"); f.str(); s["estop_utime"] = f.get("q"); s["estop_stop_ms"] = f.get("d")
            s["limit"] = f.get("b"); s["limit_input"] = f.str(); s["limit_utime"] = f.get("q")
            s["limit_stop_ms"] = f.get("d")
            s["door"] = f.get("b"); s["door_input"] = f.str(); s["door_utime"] = f.get("q")
            io.append(s)
    return axis, io


def interp(axis, t, k):
    """AXIS_STATUS field k (1 commanded, 2 actual) of X at wall time t, linearly between statuses."""
    for p, q in zip(axis, axis[1:]):
        if p[0] <= t <= q[0]:
            return p[k] + (q[k] - p[k]) * (t - p[0]) / (q[0] - p[0])
    return float("nan")


def speed_at(axis, t0):
    """X's commanded speed at t0: the fastest of the five status periods before it (a
    period in which the bridge held for a stalled link advanced less)."""
    k = max(i for i, st in enumerate(axis) if st[0] <= t0)
    return max(abs(axis[i][1] - axis[i - 1][1]) / 0.004 for i in range(k - 4, k + 1))


def stop_figures(name, t0, x0, t_brake, stood_ms, t_reset, axis, power, a, jerk, check, disabled=True, lead_s=0.0):
    """Prints and checks one stop: from the edge t0 (X at x0) the reaction t_brake (wall
    clock, us), the command's stop distance within v*t + the time-optimal brake at a and
    j/2 (v^2/(2a) + v*a/j: the limiter ends a stop on a curve at half the jerk limit)
    and no shorter than v^2/(2a),
    X at rest until t_reset, the drives disabled at standstill (or, disabled=False,
    enabled throughout). lead_s: how long after t_brake the drives' command begins
    braking (the bridge's playback behind a path the interpolator brakes)."""
    import sys
    ok = True
    v = speed_at(axis, t0)
    t_react = (t_brake - t0) * 1e-6
    before = [s for s in axis if t0 <= s[0] < t_reset]
    cmd_rest, act_rest = before[-1][1], before[-1][2]
    cmd0 = interp(axis, t0, 1)
    d_cmd, d_act = abs(cmd_rest - cmd0), abs(act_rest - x0)
    def brake(j):
        """The time-optimal stop from v at a and j (a never reached below v = a^2/j)."""
        return v * v / (2 * a) + v * a / (2 * j) if v >= a * a / j else v * (v / j) ** 0.5
    low = v * v / (2 * a)
    ideal = v * (t_react + lead_s) + brake(jerk)
    bound = v * (t_react + lead_s) + brake(jerk / 2)
    lag = abs(cmd0 - x0)
    still = next((s for s in before if all(abs(r[2] - act_rest) <= 1e-3 for r in before if r[0] >= s[0])), None)
    t_still = (still[0] - t0) * 1e-3 if still else float("nan")
    off = [p for p in power if p[2] == "disabled" and t0 < p[0] < t_reset]
    on_early = [p for p in power if p[2] == "enabled" and t0 < p[0] < t_reset]
    print(f"# {name} at X {x0:.3f} mm, {v:.2f} mm/s: edge to braking {t_react * 1e3:.2f} ms"
          f"{f' (+ the playback lead {lead_s * 1e3:.0f} ms)' if lead_s else ''}; the command at rest "
          f"{stood_ms:.1f} ms after it; X within 1 um of its rest {t_still:.1f} ms after the edge", file=sys.stderr)
    print(f"# {name}: stop distance of the command {d_cmd:.4f} mm; v^2/(2a) {low:.4f} mm; time-optimal "
          f"(reaction and brake) {ideal:.4f} mm ({d_cmd / ideal:.3f} of it); bound (the brake at j/2) {bound:.4f} mm "
          f"(a {a:g} mm/s^2, j {jerk:g} mm/s^3); of X itself {d_act:.4f} mm (its lag at the edge {lag:.4f} mm)",
          file=sys.stderr)
    for p in off:
        print(f"# {name}: drive {p[1]} disabled {(p[0] - t0) * 1e-3:.1f} ms after the edge at {p[3]:.4f} mm, "
              f"{p[4]:.4f} mm/s", file=sys.stderr)
    def c(cond, what):
        nonlocal ok
        check(cond, what)
        ok = ok and cond
    c(95 < v < 106, f"{name}: X moved at the programmed 100 mm/s at the edge")
    c(0 <= t_react < (0.010 if disabled else 0.030), f"{name}: braking began within {10 if disabled else 30} ms of the edge")
    c(low - 1e-3 <= d_cmd <= bound + 1e-3, f"{name}: the command's stop distance between v^2/(2a) and the bound")
    c(d_act <= bound + lag + 0.01, f"{name}: X's stop distance within the bound and its lag at the edge")
    if disabled:
        c(sorted(p[1] for p in off) == ["X", "Y", "Z"], f"{name}: every drive disabled")
        c(all(abs(p[4]) < 0.05 for p in off), f"{name}: at standstill (under 0.05 mm/s)")
    else:
        c(not off, f"{name}: no drive disabled")
    c(not on_early, f"{name}: no drive enabled again before the operator's reset")
    moved = max(abs(s[2] - act_rest) for s in before if still and s[0] >= still[0]) if still else float("nan")
    c(moved <= 1e-3, f"{name}: X stood still ({moved * 1e3:.2f} um) until the operator")
    return ok
