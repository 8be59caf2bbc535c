#!/usr/bin/env bash
# Deterministic replay from a live run's log, and the monitor driven by lcm-logplayer:
#  * the cell (sim4_rotary: sim3 with a rotary A) runs three programs (lines only, a
#    NURBS, a roughness-controlled NURBS) and a short one turning A (rotary_program.ngc);
#  * cnc-replay re-runs the interpolator core from the log: bit-identical setpoints;
#  * a changed config and a changed program are detected at a named cycle;
#  * lcm-logplayer plays the log (less the monitor's own output) to a fresh monitor:
#    its reports equal the live monitor's.
#   replay_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-replay-test.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim4_rotary.yaml" "$M"

start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
sleep 0.2
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start_cell
for p in config/programs/lines config/programs/butterfly config/programs/fig11_valley tests/integration/rotary_program; do
  rc=0
  "$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$SRC/$p.ngc" --timeout 90 >"$WORK/ctl.out" 2>&1 || rc=$?
  cat "$WORK/ctl.out" >&2
  [ "$rc" -eq 0 ] || fail "$p did not complete (cnc-ctl exit $rc)"
done
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done

# The rotary A (degrees) went where rotary_program.ngc sent it, commanded and on the drive.
"$BUILD/tools/cnc-logexport" --log "$WORK/run.lcmlog" --out "$WORK/export" >"$WORK/export.out" 2>&1 \
  || { cat "$WORK/export.out" >&2; fail "cnc-logexport failed"; }
python3 - "$WORK/export" >"$WORK/rotary.out" <<'PY' || { cat "$WORK/rotary.out" >&2; fail "the A axis did not turn as programmed"; }
import csv, sys
d = sys.argv[1]
a = [float(r['a_mm']) for r in csv.DictReader(open(d + '/setpoints.csv'))]
st = list(csv.DictReader(open(d + '/axis_status.csv')))
act = [float(r['a_actual_mm']) for r in st]
cmd = [float(r['a_commanded_mm']) for r in st]
fe = max(abs(float(r['a_following_error_mm'])) for r in st)
print(f'A: setpoints to {max(a):.6f} deg and back to {a[-1]:.6f}, the bridge\'s command to {max(cmd):.4f} deg, '
      f'the drive to {max(act):.4f} deg, largest following error {fe:.4f} deg')
# The command never passes the turn at 180 (it did by 0.63 deg, and 0.93 in CI, while the
# bridge made up a hold's lag braking at the limit); the drive follows it within its error.
assert abs(max(a) - 180) < 1e-9 and abs(a[-1]) < 1e-9 and fe < 2.0
assert max(cmd) - 180 < 0.01 and abs(max(act) - 180) < 0.01 + fe
PY
note "$(cat "$WORK/rotary.out")"

# Bit for bit.
"$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" >"$WORK/replay.out" 2>&1 || { cat "$WORK/replay.out" >&2; fail "replay is not identical"; }
grep -q "^identical: " "$WORK/replay.out" || fail "no verdict from cnc-replay"
note "$(cat "$WORK/replay.out")"
n=$(sed -nE 's/^identical: ([0-9]+) setpoints.*/\1/p' "$WORK/replay.out" | head -1)
[ "$n" -gt 3000 ] || fail "only $n setpoints compared"

# A changed config: one unit of path acceleration.
pa=$(sed -n 's/^ *path_accel_mm_s2: *\([0-9]*\) *$/\1/p' "$M")
[ -n "$pa" ] || fail "no path_accel_mm_s2 in $M"
sed "s/path_accel_mm_s2: $pa\$/path_accel_mm_s2: $((pa - 1))/" "$M" >"$WORK/changed.yaml"
cmp -s "$M" "$WORK/changed.yaml" && fail "the changed config is not changed"
rc=0; "$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" --machine "$WORK/changed.yaml" >"$WORK/c.out" 2>&1 || rc=$?
[ "$rc" -eq 1 ] || { cat "$WORK/c.out" >&2; fail "changed config: exit $rc, expected 1"; }
grep -qE "^diverges at cycle [0-9]+ \(t = [0-9.]+ s, block [0-9]+, line [0-9]+\): position_mm\[[0-9]\]" "$WORK/c.out" \
  || { cat "$WORK/c.out" >&2; fail "changed config: divergence not located"; }
note "changed config: $(grep "^diverges" "$WORK/c.out")"

# A changed program: one control point of the valley 0.5 mm lower.
mkdir -p "$WORK/edited"
sed 's/N90 K0 X30 Z-20 R1/N90 K0 X30 Z-20.5 R1/' "$SRC/config/programs/fig11_valley.ngc" >"$WORK/edited/fig11_valley.ngc"
rc=0; "$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" --program "$WORK/edited/fig11_valley.ngc" >"$WORK/p.out" 2>&1 || rc=$?
[ "$rc" -eq 1 ] || { cat "$WORK/p.out" >&2; fail "changed program: exit $rc, expected 1"; }
grep -qE "^diverges at cycle [0-9]+ \(t = [0-9.]+ s, block [0-9]+, line [0-9]+\): " "$WORK/p.out" \
  || { cat "$WORK/p.out" >&2; fail "changed program: divergence not located"; }
# The first two programs are untouched: they replay identically up to the third.
same=$(sed -nE 's/^([0-9]+) setpoints identical before it/\1/p' "$WORK/p.out")
[ "${same:-0}" -gt 4000 ] || { cat "$WORK/p.out" >&2; fail "changed program: diverged too early ($same)"; }
note "changed program: $(grep "^diverges" "$WORK/p.out")"

# lcm-logplayer drives a fresh monitor; its reports equal the live monitor's.
# (An unsigned analysis cell: the signing cell drops a played-back log as a replay.)
# The played-back monitor must see every message (its reports are compared one by
# one): it gets a receive buffer like the logger's, and the log plays at the speed it
# was recorded at. At twice that speed, under the suite's parallel load, a played
# monitor once reported a cycle without its setpoint (commanded feed 0 vs 2000).
unsigned_machine "$M" "$WORK/unsigned.yaml"
sed -e 's#^\( *lcm_url: *"udpm://[^"?]*?[^"]*\)"#\1\&recv_buf_size=8388608"#' "$WORK/unsigned.yaml" >"$WORK/analysis.yaml"
grep -q 'recv_buf_size=8388608' "$WORK/analysis.yaml" || fail "analysis.yaml: no receive buffer set on the cell's URL"
start logger2 "$BUILD/services/cnc-logger" --machine "$WORK/unsigned.yaml" --out "$WORK/played"
start monitor2 "$BUILD/services/cnc-monitor" --machine "$WORK/analysis.yaml"
sleep 0.5
timeout 120 lcm-logplayer --speed 1 --regexp "^${TEST_PREFIX//./\\.}(SETPOINTS|AXIS_STATUS|INTERP_INPUT)\$" \
  --lcm-url "udpm://239.255.76.67:${TEST_LCM_PORT}?ttl=0" "$WORK/run.lcmlog" || fail "lcm-logplayer failed"
sleep 0.5
stop monitor2 TERM
stop logger2 TERM
"$BUILD/tools/cnc-logstat" --log "$WORK/run.lcmlog" --compare-monitor "$WORK/played.lcmlog" >"$WORK/m.out" 2>&1 \
  || { cat "$WORK/m.out" >&2; fail "the played-back monitor reports differ"; }
note "$(cat "$WORK/m.out")"
echo PASS
