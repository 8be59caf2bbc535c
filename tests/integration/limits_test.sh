#!/usr/bin/env bash
# Hard limits on the live cell (config/machines/sim3_guarded.yaml, X's max switch moved
# in to 150 mm so a program reaches it): normally closed switches on the I/O module's
# discrete inputs, opened by cnc-servo-sim as the simulated axis passes them, their
# wires cut by the control FIFO ("at X MM cut NAME", "mend NAME"). Each edge is logged
# by the simulator with its wall clock and the axes' position and speed.
#  1. G1 X200 at 100 mm/s runs into the switch at X 150: the program ends in a fault
#     naming the axis, end and input; the bridge brakes from the edge at
#     timing.stop_decel_mm_s2 within v*t + v^2/(2a) + 2*v*a/(2j) (and no harder than
#     v^2/(2a)); the drives are disabled at standstill; ENABLE is refused until the
#     operator's FAULT_RESET; nothing moves until fault-reset and reset. A jog towards the
#     switch is refused by the interlock (naming it). Then a move
#     further towards the switch is refused (a stop and a fault naming it, X moves
#     less than 2 um), and a move off it runs.
#  2. The switch's wire cut at X 80 while X moves away from it: the same trip; ENABLE
#     refused until the fault-reset (allowed on the cut switch); mended, a move runs.
# The figures (edge to braking, stop distance against the bounds, the drives' disable)
# are printed for each trip.
#   limits_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-limits.XXXXXX)"
trap 'cleanup $?' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3_guarded.yaml" "$WORK/guarded.yaml"
sed -e 's#limit_min_mm: -6, limit_max_mm: 401#limit_min_mm: -6, limit_max_mm: 150#' "$WORK/guarded.yaml" >"$M"
grep -q "limit_max_mm: 150" "$M" || fail "X's max switch not moved in"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")
prog() { printf 'G21 G90\n%s\nM30\n' "$2" >"$WORK/$1.ngc"; }
prog into "G1 X200 F6000"
prog toward "G1 X160 F600"
prog off "G1 X100 F6000"
prog back "G1 X0 F6000"
prog again "G1 X60 F3000"

mkfifo "$WORK/sim.ctl"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --control "$WORK/sim.ctl"
exec 7<>"$WORK/sim.ctl"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
start_cell
now_us() { date +%s%6N; }

# stopped_case NAME PROGRAM PATTERN: PROGRAM must end in a fault whose report matches PATTERN.
stopped_case() {
  local rc=0
  "${CTL[@]}" --do run --program "$2" --timeout 60 >"$WORK/$1.run.out" 2>&1 || rc=$?
  [ "$rc" -ne 0 ] || { cat "$WORK/$1.run.out" >&2; fail "$1: the program ran to its end through the hard limit"; }
  grep -q -- "$3" "$WORK/$1.run.out" || { cat "$WORK/$1.run.out" >&2; fail "$1: cnc-ctl does not report '$3'"; }
  note "$1: the program ended: $(grep -m1 -- "$3" "$WORK/$1.run.out")"
}

# ---- 1. X runs into its max switch ---------------------------------------------------
stopped_case hit "$WORK/into.ngc" "axis X's max switch (input x_max_ok on module io1) reads 0"
sleep 0.3
expect_refused enable_latched "the hard limit (axis X's max switch (input x_max_ok on module io1)) is latched" "${CTL[@]}" --do enable --timeout 5
echo "hit $(now_us)" >"$WORK/resets"
ok fault_reset1 "${CTL[@]}" --do fault-reset
ok reset1 "${CTL[@]}" --do reset --timeout 20
# On the switch: a jog towards it is refused by the interlock, before anything moves.
sleep 0.2
expect_refused jog_towards "jog towards the limit switch x_max_ok, which is open" "${CTL[@]}" --do jog --axis X --value 0.5 --timeout 5
echo "toward $(now_us)" >"$WORK/toward_from"
stopped_case toward "$WORK/toward.ngc" "moves the axis towards it"
echo "toward_end $(now_us)" >>"$WORK/toward_from"
ok fault_reset2 "${CTL[@]}" --do fault-reset
ok reset2 "${CTL[@]}" --do reset --timeout 20
ok off "${CTL[@]}" --do run --program "$WORK/off.ngc" --timeout 60

# ---- 2. its wire cut while X moves away from it ------------------------------------------
echo "at X 80 cut x_max_ok" >&7
stopped_case cut "$WORK/back.ngc" "axis X's max switch (input x_max_ok on module io1) reads 0"
sleep 0.3
expect_refused enable_cut "is latched: FAULT_RESET first" "${CTL[@]}" --do enable --timeout 5
echo "cut $(now_us)" >>"$WORK/resets"
ok fault_reset3 "${CTL[@]}" --do fault-reset
ok reset3 "${CTL[@]}" --do reset --timeout 20
echo "mend x_max_ok" >&7
ok again "${CTL[@]}" --do run --program "$WORK/again.ngc" --timeout 60

for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
exec 7>&-
grep -E "x_max_ok|hard limit|axis [XYZ]: (enabled|disabled)" "$WORK/servo-sim.log" "$WORK/drive-bridge.log" |
  sed 's#^.*/##' >&2 || true

/usr/bin/python3 - "$WORK/cell.lcmlog" "$TEST_PREFIX" "$(dirname "$0")" "$WORK/servo-sim.log" "$WORK/resets" "$M" \
  "$WORK/toward_from" <<'PY' || fail "the hard limits' reaction is not as it should be"
import re, sys
log, prefix, here, simlog, resets_file, machine, toward_file = sys.argv[1:8]
sys.path.insert(0, here)
from lcmlog import events, Fields
import safety_figures
from safety_figures import read_io_status, stop_figures
decel, accel, jerk = safety_figures.x_stop_limits(machine)
a = min(decel, accel)
edges, power = safety_figures.sim_edges(open(simlog), "x_max_ok")
resets = [int(l.split()[1]) for l in open(resets_file)]
axis, io = read_io_status(log, prefix)
from checks import Checks
check = Checks()
check(len(edges) == 2, f"two falling edges of x_max_ok in the simulator's log ({len(edges)})")
if not check.ok: sys.exit(1)
for (name, (t0, x0, _)), t_reset in zip((("hit", edges[0]), ("wire cut", edges[1])), resets):
    trips = sorted({s["limit_utime"] for s in io if t0 < s["limit_utime"] < t0 + 1e6})
    check(len(trips) == 1, f"{name}: the bridge's trip stamp follows the edge")
    if not trips: check.ok = False; continue
    trip = trips[0]
    stood_ms = next((s["limit_stop_ms"] for s in io if s["limit_utime"] == trip and s["limit_stop_ms"] > 0), float("nan"))
    check.ok = stop_figures(name, t0, x0, trip, stood_ms, t_reset, axis, power, a, jerk, check) and check.ok
# The refused move towards the switch: X moved less than 2 um towards it.
t_from, t_to = [int(l.split()[1]) for l in open(toward_file)]
xs = [s[2] for s in axis if t_from <= s[0] <= t_to]
check(bool(xs) and max(xs) - xs[0] < 2e-3,
      f"a move towards the switch refused: X went {1e3 * (max(xs) - xs[0]) if xs else float('nan'):.2f} um towards it")
sys.exit(0 if check.ok else 1)
PY
echo "PASS"
