#!/usr/bin/python3
"""A controlled stop of one axis in the drive bridge's tick trace (CNC_BRIDGE_DEBUG_TRACE),
checked against the bridge's configured stop (deceleration a, jerk j).

  stop_ticks.py LABEL TICKS CAUSE_BEFORE CAUSE_AFTER DECEL JERK SERVO_PERIOD MIN_V FE_LIMIT [AXIS] [ONSET_S]

CAUSE_BEFORE, CAUSE_AFTER: wall times (date +%s.%N) around the command that caused the
stop; the ticks carry monotonic times, and the two clocks' offset is taken at the check.

The stop is the bridge's, so it is measured on the bridge's clock: the ticks whose
command went to the drives (a tick held for a stalled link is not written, and a
missed timer deadline is no tick), one servo period each. On that clock the command
is exact whatever the PC does, while a stop read off the simulator's world in
seconds mixes in the stalls of a loaded PC: its world stands when the stream runs
dry and the bridge's playback catches up afterwards, so speeds read 4-5 % over F and
fitted decelerations 0.86-1.28 x the configured one (stop_trace.py, 1 run in 15-20
under two busy loops). The axis is checked beside it, by what the drive reports at
every tick: its following error, and where it comes to rest.

  * the onset: the first tick from which the commanded speed falls monotonically to
    rest and decelerates by more than 5 % of a (and more than the playback's rate slew
    could) somewhere in its first 5 ticks; on the
    wall clock (the tick's time) within ONSET_S of CAUSE_AFTER (default 0.1 s);
  * every tick's deceleration (second difference) within a, its jerk within j
    (1e-6 relative, and the trace's nanometres differenced), and no tick faster than the speed at the onset;
  * the distance from the onset to rest: at least v^2/(2a) (no stop is shorter than
    one at a throughout) and at most v^2/(2a) + v*a/j plus two ticks' travel: the
    S-curve's with its ramps at half the jerk limit (the limiter takes the deceleration
    back at its feedback's share of the jerk, j/2, and creeps onto the stop point);
  * the axis: the drive's following error within FE_LIMIT at every tick of the stop,
    and at rest (the command moving less than 1 um over 50 ticks) the actual position within
    0.05 mm of the command.
Exit 0 when all hold; the figures go to stderr either way.
"""
import csv
import sys
import time


def main():
    label, path = sys.argv[1], sys.argv[2]
    before, after, a, j, T, min_v, fe_limit = (float(v) for v in sys.argv[3:10])
    axis = int(sys.argv[10]) if len(sys.argv) > 10 else 0
    onset_bound = float(sys.argv[11]) if len(sys.argv) > 11 else 0.1
    # The causes are wall times (date +%s.%N), the ticks monotonic ones.
    wall_less_mono = time.time() - time.monotonic()
    before -= wall_less_mono
    after -= wall_less_mono
    rows = [r for r in csv.DictReader(open(path)) if r["held"] == "0"]
    mono = [float(r["mono"]) for r in rows]
    x = [float(r[f"cmd{axis}"]) for r in rows]
    fe = [float(r[f"fe{axis}"]) for r in rows]
    act = [float(r[f"act{axis}"]) for r in rows]
    v = [(x[k + 1] - x[k]) / T for k in range(len(x) - 1)]  # v[k]: from tick k to k+1
    k_cause = max(k for k in range(len(mono)) if mono[k] <= before)
    sign = 1.0 if v[k_cause] >= 0 else -1.0
    s = [sign * w for w in v]

    # Braking, not the playback's rate slewing down as its buffer drains (0.002 of the speed
    # per tick at most, drive_bridge.cc's kRateSlewPerTick: 0.42 mm/s a tick at 210 mm/s,
    # which a 5 %-of-a threshold took for the onset 21 ms before a link cut and so counted
    # 6 mm of slowing cruise as braking: 18.6 mm against 18.1, three_hosts in a fresh clone).
    def is_onset(k):
        return any(s[m] - s[m + 1] > max(0.05 * a * T, 1.5 * 0.002 * s[m]) for m in range(k, min(k + 5, len(s) - 1)))

    # Rest: the first tick from which the command moves less than 1 um in 50 ticks (the
    # limiter's last approach onto the stop point creeps).
    rest = next(k for k in range(k_cause, len(x) - 50) if all(abs(x[m] - x[k]) < 1e-3 for m in range(k, k + 50)))
    # The onset: the earliest tick from which the speed falls monotonically to rest, and
    # not before the cause (20 ticks for the two clocks' offset): a cruise whose speed the
    # playback's rate slewed down by hundredths of a mm/s is no stop, yet the search from
    # 200 ticks back walked into one and took a playback dip there for the onset (braking
    # "began -182 ms after the cause", distance 49.9 mm: fault_reset and three_hosts in a
    # fresh clone, each once, where the stop itself was 12.4 mm from 200 mm/s, as bound).
    onset = rest
    while onset > k_cause - 20 and s[onset - 1] >= s[onset] - 1e-9:
        onset -= 1
    while onset < rest and not is_onset(onset):
        onset += 1
    v0 = s[onset]
    dist = sign * (x[rest] - x[onset])
    lo = v0 ** 2 / (2 * a)
    hi = lo + (v0 * a / j if j > 0 else 0.0) + 2 * v0 * T
    acc = [(s[k + 1] - s[k]) / T for k in range(onset, rest)]
    jerk = [(acc[k + 1] - acc[k]) / T for k in range(len(acc) - 1)]
    worst_a = max((-w for w in acc), default=0.0)
    worst_j = max((abs(w) for w in jerk), default=0.0)
    fastest = max(s[onset:rest + 1])
    worst_fe = max(abs(w) for w in fe[onset:rest + 50])
    settle = abs(act[rest + 49] - x[rest + 49])
    latency = mono[onset] - after
    stop_s = (rest - onset) * T
    print(f"# {label} (the bridge's ticks): axis {axis} at {sign * v0:.1f} mm/s; braking began "
          f"{latency * 1e3:.0f} ms after the cause (bound {onset_bound * 1e3:.0f} ms; the cause took "
          f"{(after - before) * 1e3:.0f} ms); stopped in {rest - onset} ticks ({stop_s * 1e3:.0f} ms on the bridge's "
          f"clock, {(mono[rest] - mono[onset]) * 1e3:.0f} ms on the wall's); distance {dist:.3f} mm (within "
          f"[{lo:.3f}, {hi:.3f}]: v^2/2a .. + v*a/j + 2 ticks); largest deceleration {worst_a:.1f} mm/s^2 "
          f"(limit {a:g}), jerk {worst_j:.0f} mm/s^3 (limit {j:g}); the drive's following error up to "
          f"{worst_fe:.3f} mm (limit {fe_limit:g}), at rest {settle * 1e3:.1f} um from the command", file=sys.stderr)
    # Rounding: the trace's nanometres, differenced over 1 ms ticks.
    eps = 1e-6
    ok = (v0 > min_v and latency <= onset_bound and lo * (1 - eps) <= dist <= hi and worst_a <= a * (1 + eps) + 0.01
          and (j <= 0 or worst_j <= j * (1 + eps) + 5) and fastest <= v0 * (1 + eps) + 1e-9 and worst_fe <= fe_limit
          and settle <= 0.05)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
