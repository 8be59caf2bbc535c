#!/usr/bin/env bash
# The E-stop on the live cell (config/machines/sim3_safety.yaml): a normally closed
# button on the I/O module's discrete input estop_ok, simulated by cnc-servo-sim on
# the axes' Modbus TCP link. The simulator's control FIFO presses it when X passes a
# position ("at X MM input estop_ok 0") and logs the edge with its wall clock and
# the axes' position and speed; it logs each drive's disable and enable the same way.
#  1. Pressed at X 100 in a G1 X200 at 100 mm/s, spindle and flood on: the program
#     ends in a fault naming the E-stop; the bridge brakes from the edge (IO_STATUS's
#     trip stamp) at timing.stop_decel_mm_s2 to a standstill within v*t + v^2/(2a) +
#     v*a/(2j) (t: edge to braking), the spindle and coolant stop, the drives are
#     disabled at standstill; ENABLE and FAULT_RESET are refused while it reads 0;
#     released, ENABLE is still refused until FAULT_RESET; nothing moves until the
#     operator's fault-reset and reset.
#  2. Its wire cut at X 50 on the way back (the input stays 0 for a second): the
#     same stop, the same refusals, nothing moves; mended, reset and a move runs.
# The figures (edge to braking, to standstill, stop distance against the bound, the
# drives' disable) are printed for each.
#   estop_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-estop.XXXXXX)"
trap 'cleanup $?' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3_safety.yaml" "$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")

cat >"$WORK/out.ngc" <<'NGC'
G21 G90
M3 S3000
M8
G1 X200 F6000
M30
NGC
cat >"$WORK/back.ngc" <<'NGC'
G21 G90
G1 X0 F6000
M30
NGC
cat >"$WORK/again.ngc" <<'NGC'
G21 G90
G1 X20 F3000
M30
NGC

mkfifo "$WORK/sim.ctl"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --control "$WORK/sim.ctl"
exec 7<>"$WORK/sim.ctl"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
start_cell
now_us() { date +%s%6N; }

# stopped_case NAME PROGRAM: runs PROGRAM, which the E-stop armed before must end in a fault.
stopped_case() {
  local rc=0
  "${CTL[@]}" --do run --program "$2" --timeout 60 >"$WORK/$1.run.out" 2>&1 || rc=$?
  [ "$rc" -ne 0 ] || { cat "$WORK/$1.run.out" >&2; fail "$1: the program ran to its end through the E-stop"; }
  grep -q "E-stop" "$WORK/$1.run.out" || { cat "$WORK/$1.run.out" >&2; fail "$1: cnc-ctl does not name the E-stop"; }
  note "$1: the program ended: $(grep -m1 "E-stop" "$WORK/$1.run.out")"
}

# ---- 1. pressed mid-move --------------------------------------------------------------
echo "at X 100 input estop_ok 0" >&7
stopped_case press "$WORK/out.ngc"
sleep 0.3
expect_refused enable_pressed "E-stop input estop_ok on module io1 reads 0" "${CTL[@]}" --do enable --timeout 5
expect_refused reset_pressed "E-stop input estop_ok on module io1 still reads 0" "${CTL[@]}" --do fault-reset
# The operator's view of the chain (listening 0.5 s: the pause the release waits anyway).
"${CTL[@]}" --do status --timeout 0.5 >"$WORK/status.out" 2>&1 || { cat "$WORK/status.out" >&2; fail "cnc-ctl --do status failed"; }
grep -E "^(E-stop|io estop_ok)" "$WORK/status.out" >&2 || true
grep -qE "^E-stop: TRIPPED, drives disabled, input estop_ok reads 0, last trip stood in [0-9]+\.[0-9] ms\$" "$WORK/status.out" &&
  grep -qE "^io estop_ok +digital in +0 +io1 \(E-stop\)\$" "$WORK/status.out" ||
  { cat "$WORK/status.out" >&2; fail "cnc-ctl --do status does not show the E-stop tripped with its input"; }
echo "input estop_ok 1" >&7
sleep 0.3
expect_refused enable_released "is latched: FAULT_RESET first" "${CTL[@]}" --do enable --timeout 5
echo "press $(now_us)" >"$WORK/resets"
ok fault_reset1 "${CTL[@]}" --do fault-reset
ok reset1 "${CTL[@]}" --do reset --timeout 20

# ---- 2. the wire cut mid-move -----------------------------------------------------------
echo "at X 50 input estop_ok 0" >&7
stopped_case cut "$WORK/back.ngc"
expect_refused enable_cut "E-stop input estop_ok on module io1 reads 0" "${CTL[@]}" --do enable --timeout 5
sleep 1
expect_refused reset_cut "E-stop input estop_ok on module io1 still reads 0" "${CTL[@]}" --do fault-reset
expect_refused cnc_reset_cut "E-stop input estop_ok on module io1 reads 0" "${CTL[@]}" --do reset --timeout 5
echo "input estop_ok 1" >&7
sleep 0.3
echo "cut $(now_us)" >>"$WORK/resets"
ok fault_reset2 "${CTL[@]}" --do fault-reset
ok reset2 "${CTL[@]}" --do reset --timeout 20
ok again "${CTL[@]}" --do run --program "$WORK/again.ngc" --timeout 60

for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
exec 7>&-
grep -E "E-stop|estop|axis [XYZ]: (enabled|disabled)|spindle: stop|coolant_flood off" "$WORK/servo-sim.log" "$WORK/drive-bridge.log" |
  sed 's#^.*/##' >&2 || true

/usr/bin/python3 - "$WORK/cell.lcmlog" "$TEST_PREFIX" "$(dirname "$0")" "$WORK/servo-sim.log" "$WORK/resets" "$M" <<'PY' || fail "the E-stop's reaction is not as it should be"
import re, sys
log, prefix, here, simlog, resets_file, machine = sys.argv[1:7]
sys.path.insert(0, here)
import safety_figures
decel, accel, jerk = safety_figures.x_stop_limits(machine)
a = min(decel, accel)

# The simulator's view: the edges (wall clock, X and its speed) and each drive's disable/enable.
edges, power = safety_figures.sim_edges(open(simlog), "estop_ok")
resets = [int(l.split()[1]) for l in open(resets_file)]
axis, statuses = safety_figures.read_io_status(log, prefix)
io = [(s["ts"], s["estop"], s["estop_utime"], s["estop_stop_ms"]) for s in statuses]
from checks import Checks
check = Checks()
check(len(edges) == 2, f"two E-stop edges in the simulator's log ({len(edges)})")
if not check.ok: sys.exit(1)
def interp(t, k):
    return safety_figures.interp(axis, t, k)
for (name, (t0, x0, _)), t_reset in zip((("pressed", edges[0]), ("wire cut", edges[1])), resets):
    # X's speed at the edge: its command's over the status periods before (one every
    # T_ipo of servo ticks; their wall stamps jitter with the publish, the simulator's
    # own figure with its world's steps), the fastest of the last five: a period in
    # which the bridge held for a stalled link advanced less.
    k = max(i for i, st in enumerate(axis) if st[0] <= t0)
    v = max(abs(axis[i][1] - axis[i - 1][1]) / 0.004 for i in range(k - 4, k + 1))
    trips = sorted({s[2] for s in io if s[2] > t0 and s[2] < t0 + 1e6})
    check(len(trips) == 1, f"{name}: the bridge's trip stamp follows the edge")
    if not trips: check.ok = False; continue
    trip = trips[0]
    stood_ms = next((s[3] for s in io if s[2] == trip and s[3] > 0), float("nan"))
    t_react = (trip - t0) * 1e-6
    # Where X comes to rest: the last status before the operator's reset.
    before = [s for s in axis if t0 <= s[0] < t_reset]
    cmd_rest, act_rest = before[-1][1], before[-1][2]
    cmd0, act0 = interp(t0, 1), interp(t0, 2)
    d_cmd, d_act = abs(cmd_rest - cmd0), abs(act_rest - x0)
    # The time-optimal stop from v at a with jerk j: v^2/(2a) + v*a/(2j). The bridge's
    # limiter ends its stop on a curve at half the jerk limit: the ramp's allowance is
    # doubled in the bound.
    ramp = v * a / (2 * jerk)
    ideal = v * t_react + v * v / (2 * a) + ramp
    bound = v * t_react + v * v / (2 * a) + 2 * ramp
    lag = abs(cmd0 - x0)  # the simulated servo's lag behind its command at the edge
    # The actual at rest: within 1 um, the first status from which it stays there.
    still = next((s for s in before if all(abs(r[2] - act_rest) <= 1e-3 for r in before if r[0] >= s[0])), None)
    t_still = (still[0] - t0) * 1e-3 if still else float("nan")
    off = [p for p in power if p[2] == "disabled" and t0 < p[0] < t_reset]
    on_early = [p for p in power if p[2] == "enabled" and t0 < p[0] < t_reset]
    print(f"# {name} at X {x0:.3f} mm, {v:.2f} mm/s: edge to braking (the bridge's trip) {t_react * 1e3:.2f} ms; "
          f"the command at rest {stood_ms:.1f} ms after the trip; X within 1 um of its rest {t_still:.1f} ms after "
          f"the edge", file=sys.stderr)
    print(f"# {name}: stop distance of the command {d_cmd:.4f} mm; time-optimal v*t + v^2/(2a) + v*a/(2j) = "
          f"{v * t_react:.4f} + {v * v / (2 * a):.4f} + {ramp:.4f} = {ideal:.4f} mm (a {a:g} mm/s^2, j {jerk:g} "
          f"mm/s^3; {d_cmd / ideal:.3f} of it), bound {bound:.4f} mm; of X itself {d_act:.4f} mm (its lag at the edge "
          f"{lag:.4f} mm)", file=sys.stderr)
    for p in off:
        print(f"# {name}: drive {p[1]} disabled {(p[0] - t0) * 1e-3:.1f} ms after the edge at {p[3]:.4f} mm, "
              f"{p[4]:.4f} mm/s", file=sys.stderr)
    # (the bridge's playback runs up to 5 % fast while it makes up a late setpoint's lag)
    check(95 < v < 106, f"{name}: X moved at the programmed 100 mm/s when the input fell")
    check(0 <= t_react < 0.010, f"{name}: braking began within 10 ms of the edge")
    check(d_cmd <= bound + 1e-3, f"{name}: the command's stop distance within the bound")
    check(d_act <= bound + lag + 0.01, f"{name}: X's stop distance within the bound and its lag at the edge")
    check(sorted(p[1] for p in off) == ["X", "Y", "Z"], f"{name}: every drive disabled")
    check(all(abs(p[4]) < 0.05 for p in off), f"{name}: at standstill (under 0.05 mm/s)")
    check(not on_early, f"{name}: no drive enabled again before the operator's reset")
    moved = max(abs(s[2] - act_rest) for s in before if still and s[0] >= still[0])
    check(moved <= 1e-3, f"{name}: X stood still ({moved * 1e3:.2f} um) until the reset")
sys.exit(0 if check.ok else 1)
PY
grep -q "spindle: stop" "$WORK/servo-sim.log" || fail "the spindle did not stop"
grep -q "io io1: coolant_flood off" "$WORK/servo-sim.log" || fail "the coolant did not go off"
echo "PASS"
