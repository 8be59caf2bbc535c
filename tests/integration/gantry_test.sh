#!/usr/bin/env bash
# A gantry on the live cell (config/machines/sim3_gantry.yaml: Y driven by the drives Y
# and Y2, each with its own home switch; the simulated Y2's switch 0.8 mm nearer than
# Y's, so the gantry starts out of square):
#  1. HOME Y: both sides search together, each latches its own switch, each goes to its
#     own home position. The skew (Y2's position less its switch's, minus Y's less its
#     switch's, from the simulator's trace) before and after: -0.8 mm, then within 10 um.
#  2. A short program: the largest skew while it runs (trace rows, 10 ms apart).
#  3. Y2 jammed (the simulator's control FIFO, `jam Y2`) while Y moves at 50 mm/s: the
#     skew crosses axes[].gantry.skew_limit_mm (0.5 mm): a fault naming the axis, both
#     drives and the skew; nothing moves for 1 s after; ENABLE refused until FAULT_RESET.
#     Freed, fault-reset and reset: the bridge squares the gantry again.
#  4. The bridge's and the monitor's largest skew (as read from the drives, JOINT_STATUS:
#     the monitor's includes the jam's); the log replays bit for bit (cnc-replay).
#   gantry_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-gantry-test.XXXXXX)"
trap 'cleanup $?' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3_gantry.yaml" "$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")
prog() { printf 'G21 G90\n%s\nM30\n' "$2" >"$WORK/$1.ngc"; }
prog short "G1 X40 Y30 F6000
G1 X0 Y0"
prog long "G1 Y60 F3000"

mkfifo "$WORK/sim.ctl"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --control "$WORK/sim.ctl" --trace "$WORK/trace.csv"
exec 7<>"$WORK/sim.ctl"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start_cell

# skew FROM [TO]: the simulated gantry's skew over the trace's rows in [FROM, TO] (wall
# clock): first, last, largest magnitude; and the largest motion of any drive, and
# whether any was on. Y2's switch at -3.2 mm, Y's at -4 mm (the simulator's config).
skew() {
  /usr/bin/python3 - "$WORK/trace.csv" "$@" <<'PY'
import csv, sys
lo = float(sys.argv[2]); hi = float(sys.argv[3]) if len(sys.argv) > 3 else 1e300
rows = [r for r in csv.DictReader(open(sys.argv[1])) if None not in r.values() and "" not in r.values()
        and lo <= float(r["wall_s"]) <= hi]
s = [(float(r["Y2_mm"]) + 3.2) - (float(r["Y_mm"]) + 4.0) for r in rows]
drives = [k[:-3] for k in rows[0] if k.endswith("_mm")]
span = max(max(float(r[d + "_mm"]) for r in rows) - min(float(r[d + "_mm"]) for r in rows) for d in drives)
on = max(int(r[d + "_on"]) for r in rows for d in drives)
print(f"{s[0]:.6f} {s[-1]:.6f} {max(abs(v) for v in s):.6f} {span:.6f} {on} {len(rows)}")
PY
}
wall() { date +%s.%N; }
minus() { /usr/bin/python3 -c "print(f'{$1 - $2:.4f}')"; }
# settled_skew TOL: waits (at most 4 s) until the trace's newest rows show the skew
# within TOL, and prints it.
settled_skew() {
  local i now v
  for ((i = 0; i < 40; i++)); do
    sleep 0.1
    now=$(wall)
    read -r _ v _ _ _ _ < <(skew "$(minus "$now" 0.1)" "$now")
    cmp_le "$v" "$1" && break
  done
  echo "$v"
}
cmp_le() { /usr/bin/python3 -c "import sys; sys.exit(0 if abs($1) <= $2 else 1)"; }

# ---- 1. Homing squares the gantry ----------------------------------------------------
t0=$(wall)
for ((i = 0; i < 100; i++)); do
  rc=0
  "${CTL[@]}" --do home --axis Y --timeout 30 >"$WORK/home.out" 2>&1 || rc=$?
  [ "$rc" -eq 3 ] && grep -qE "enable the drives first|no AXIS_STATUS|no JOINT_STATUS|is lost" "$WORK/home.out" || break
  sleep 0.1
done
[ "$rc" -eq 0 ] || { cat "$WORK/home.out" >&2; fail "homing Y: cnc-ctl exit $rc"; }
grep -q "gantry_squared" "$WORK/home.out" || { cat "$WORK/home.out" >&2; fail "no gantry_squared alarm"; }
note "$(grep -o 'gantry Y: Y2 squared.*' "$WORK/home.out" | head -1)"
read -r before _ _ _ _ _ < <(skew "$t0")
after=$(settled_skew 0.010)  # the squaring moves at the search velocity: 0.8 mm in 0.1 s
note "skew before homing $before mm, after homing $after mm"
cmp_le "$before + 0.8" 0.005 || fail "the simulated gantry did not start 0.8 mm out of square ($before mm)"
cmp_le "$after" 0.010 || fail "the skew after homing is $after mm (tolerance 10 um)"

"${CTL[@]}" --do status --timeout 0.3 >"$WORK/status.out" 2>&1 || true
grep -q "^gantry Y: Y2 at .* squaring 0.80" "$WORK/status.out" || { cat "$WORK/status.out" >&2; fail "cnc-ctl status does not show Y2 squared"; }
note "status: $(grep '^gantry Y:' "$WORK/status.out")"

# ---- 2. A short program ----------------------------------------------------------------
t2=$(wall)
ok short "${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 30
read -r _ _ max_run _ _ rows < <(skew "$t2")
note "largest skew while the program ran: $max_run mm ($rows trace rows)"
cmp_le "$max_run" 0.05 || fail "the skew reached $max_run mm during the program"

# ---- 3. A jammed side: the skew fault ----------------------------------------------------
"${CTL[@]}" --do run --program "$WORK/long.ngc" --timeout 30 >"$WORK/ctl.out" 2>&1 &
ctl_pid=$!
for ((i = 0; i < 300; i++)); do  # Y past 10 mm, at its 50 mm/s
  tail -n 1 "$WORK/trace.csv" | awk -F, '{ exit !($5 + 0 > 10) }' && break
  sleep 0.02
done
echo "jam Y2" >&7
expect_drive_fault "$ctl_pid" "gantry skew: axis Y's drives Y (unit 2)"
text=$(grep -o "gantry skew: .*" "$WORK/drive-bridge.log" | head -1)
note "$text"
grep -q "and Y2 (unit 4)" <<<"$text" || fail "the fault does not name Y2"
# The drives disabled once the axes stand (the jammed side's following error never
# settles: kStandstillWaitS, 0.2 s, after the stop); from then on nothing moves.
for ((i = 0; i < 40; i++)); do grep -q "gantry skew: the axes stand" "$WORK/drive-bridge.log" && break; sleep 0.05; done
grep -q "gantry skew: the axes stand" "$WORK/drive-bridge.log" || fail "the bridge did not disable the drives at standstill"
sleep 0.05  # the disable's round and the trace's next row
t3=$(wall)
sleep 1.0
read -r _ _ _ span on _ < <(skew "$t3")
note "after the fault: $(grep -o 'the axes stand .*' "$WORK/drive-bridge.log" | head -1); then in 1 s the largest drive motion $span mm, drives on: $on"
cmp_le "$span" 0.0001 || fail "a drive moved $span mm after the skew fault"
[ "$on" -eq 0 ] || fail "the drives are still enabled after the skew fault"
echo "clear" >&7
ok fault_reset "${CTL[@]}" --do fault-reset
grep -q "the gantry's skew fault reset" "$WORK/fault_reset.out" || fail "the bridge did not answer the FAULT_RESET"
ok reset "${CTL[@]}" --do reset --timeout 20
resq=$(settled_skew 0.010)
note "after FAULT_RESET and ENABLE the bridge squared the gantry again: skew $resq mm"
cmp_le "$resq" 0.010 || fail "the skew after the re-enable is $resq mm"

# The bridge's own skew (the drives' actual positions as read) and the monitor's (JOINT_STATUS).
for name in monitor interpolator drive-bridge program-server servo-sim logger; do stop "$name"; done
note "bridge: $(grep -o 'gantry Y: squaring.*' "$WORK/drive-bridge.log" | tail -1)"
note "monitor: $(grep -o 'gantry Y: largest skew.*' "$WORK/monitor.log" | tail -1)"
grep -q "gantry Y: largest skew" "$WORK/monitor.log" || fail "the monitor did not see the gantry's joint"
"$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" >"$WORK/replay.out" 2>&1 || { cat "$WORK/replay.out" >&2; fail "replay is not identical"; }
grep "^identical: " "$WORK/replay.out" >&2 || fail "no verdict from cnc-replay"
echo "PASS: gantry homed square ($before -> $after mm), program skew <= $max_run mm, skew fault and stop, replay identical" >&2
