#!/usr/bin/env bash
# Homing at the edge of the travel: a search never commands past the travel
# the drive bridge checks. X's switch is put 0.5 mm outside its travel: the search
# stops at the travel's end (-5 mm) and the homing ends with "no home switch up to the
# end of its travel", with no drive fault. (Unclamped, the search ran on past -5 mm
# into the bridge's travel fault; a search that sees its latch late over the bus ran
# 1.04 mm past a switch 1 mm inside the travel on a loaded machine.) Then X and Y
# home on their switches as usual.
#   homing_edge_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-homing-edge-test.XXXXXX)"
trap 'cleanup' EXIT
make_machine "$SRC/config/machines/sim3.yaml" "$WORK/base.yaml"
/usr/bin/python3 "$SRC/tests/integration/operator_machine.py" "$WORK/base.yaml" "$WORK/switches.yaml" "$WORK/mdi"
M="$WORK/machine.yaml"
# X's switch (the simulator's and the homing's) at -5.5 mm, outside the travel [-5, 400].
sed -E 's/home_switch_mm: -4, home_switch_sigma_mm: 0.002, home_switch_seed: 11/home_switch_mm: -5.5, home_switch_sigma_mm: 0.002, home_switch_seed: 11/' \
  "$WORK/switches.yaml" >"$M"
grep -q "home_switch_mm: -5.5" "$M" || fail "cannot move X's switch in $M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")

start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start_cell --no-monitor

# The cell is ready when the interpolator takes a HOME: until the bridge's first
# AXIS_STATUS with the drives enabled, it refuses one (exit 3, naming why).
for ((i = 0; i < 100; i++)); do
  rc=0
  "${CTL[@]}" --do home --axis X --timeout 30 >"$WORK/home_x.out" 2>&1 || rc=$?
  [ "$rc" -eq 3 ] && grep -qE "enable the drives first|no AXIS_STATUS|is lost" "$WORK/home_x.out" || break
  sleep 0.1
done
cat "$WORK/home_x.out" >&2
[ "$rc" -eq 5 ] || fail "homing X with its switch outside the travel: cnc-ctl exit $rc, expected 5 (aborted)"
grep -q "no home switch up to the end of its travel (-5.0000 mm)" "$WORK/home_x.out" ||
  fail "the homing did not end at the travel's end saying there is no switch"
if grep -q "drive_fault\|outside its travel" "$WORK"/*.log "$WORK/home_x.out"; then fail "a drive fault: the search went past the travel"; fi
note "X with its switch outside the travel: $(grep -o 'no home switch up to the end of its travel.*' "$WORK/home_x.out" | head -1)"
# The cell carries on: Y homes on its switch, and X stands at -5 mm, not homed.
ok home_y "${CTL[@]}" --do home --axis Y --timeout 30
grep -q "X -5.0000 Y 0.0000 (homed)" "$WORK/home_y.out" || { cat "$WORK/home_y.out" >&2; fail "after it, Y did not home (or X is not at -5)"; }
note "then: $(grep -o 'homed: .*' "$WORK/home_y.out" | tail -1)"
for name in interpolator drive-bridge program-server servo-sim logger; do stop "$name"; done
