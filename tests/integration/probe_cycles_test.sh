#!/usr/bin/env bash
# The shipped probing subroutines (config/subroutines) live on the simulator's fixture, a
# box X 50..150, Y 50..150 with its top at Z -20, with the drives' touch-probe latches
# (probe.latch: drives): o<probe_z> finds the top, o<probe_boss> the four side faces
# (through o<probe_edge_x> and o<probe_edge_y>), the centre and the size. Every touch
# (fast and slow) within 1 um of its face; the program then moves to the centre plus a
# tenth of the size, 5 mm above the top it found: (110, 110, -15) within 1 um. Then
# o<tool_length> takes the fixture for a tool setter (reference Z -25: the tool is 5 mm
# long), under a G54 Z offset of -3 and a G92 offset of 2: the tool table's T1 gets Z 5
# (0.1 um), and the program ends at X 100 + the length, at the safe Z 0: (105, 100, 0).
# Then o<probe_bore> in a bore of the fixture (D 20 at X 125 Y 125, probe.sim_box.bore_*),
# started 2 mm off its centre: six touches, each within 1 um of the wall; the program ends
# at the centre plus a tenth of each diameter, (127, 127, -10), within 1 um.
# Last, M6 remapped to o<change_and_measure> (program.m6_remap): T2 M6 G0 X60 Y60 goes to
# the change position, holds for the change until RESUME, measures T2 on the setter
# (T2 Z +5 in the tool table), applies it, and the block's G0 ends at (60, 60, 0).
#   probe_cycles_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-probe-cycles.XXXXXX)"
trap 'cleanup $?' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3_probe.yaml" "$M"
sed -i 's/^  input: probe_tip .*/  input: probe_tip\n  latch: drives/' "$M"
sed -i 's/z_max_mm: -20}/z_max_mm: -20, bore_x_mm: 125, bore_y_mm: 125, bore_diameter_mm: 20}/' "$M"
grep -q "bore_diameter_mm: 20" "$M" || fail "could not add the bore to probe.sim_box in $M"
printf 'T1 P1 Z0 D6 ;\nT2 P2 Z0 D6 ;\n' >"$WORK/tools.tbl"
printf '\nprogram:\n  subroutine_path: %s\n  tool_table: %s\n  m6_remap: change_and_measure\n' \
  "$SRC/config/subroutines" "$WORK/tools.tbl" >>"$M"
grep -q "^  latch: drives" "$M" || fail "could not set probe.latch: drives in $M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")

cat >"$WORK/cycles.ngc" <<'NGC'
G21 G90
G0 Z-10
G0 X100 Y100
o<probe_z> call [15] [300] [50] [0.5]
#<top> = #<_value>
G0 Z[#<top> + 5]
o<probe_boss> call [100] [100] [8] [5] [600] [60] [0.5] [0]
G0 X[#<_probe_boss_x> + #<_probe_boss_size_x> / 10] Y[#<_probe_boss_y> + #<_probe_boss_size_y> / 10]
M2
NGC

start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --final-state "$WORK/final.json" --trace "$WORK/trace.csv"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
start_cell
t0=$SECONDS
"${CTL[@]}" --do run --program "$WORK/cycles.ngc" --timeout 90 >"$WORK/ctl.out" 2>&1 ||
  { cat "$WORK/ctl.out" >&2; tail -n 20 "$WORK/interpolator.log" >&2; fail "the probing cycles did not run to their end"; }
note "probe_z and probe_boss in $((SECONDS - t0)) s"
/usr/bin/python3 - "$WORK/interpolator.log" <<'PY' || fail "a touch off its face"
import re, sys
trips = [(m.group(1), *map(float, m.group(2, 3, 4))) for m in re.finditer(
    r"probe: G38\.2 at (\S+):\d+ \(block \d+\): tripped at X (\S+) Y (\S+) Z (\S+)", open(sys.argv[1]).read())]
kinds = [t[0].rsplit("/", 1)[-1] for t in trips]
want = ["probe_z.ngc"] * 2 + ["probe_edge_x.ngc"] * 4 + ["probe_edge_y.ngc"] * 4
ok = kinds == want
print(("# " if ok else "# FAILED: ") + f"{len(trips)} touches: {', '.join(kinds)}", file=sys.stderr)
errs = []
for (f, x, y, z), k in zip(trips, kinds):
    if k == "probe_z.ngc": errs.append(abs(z + 20))
    elif k == "probe_edge_x.ngc": errs.append(min(abs(x - 50), abs(x - 150)))
    else: errs.append(min(abs(y - 50), abs(y - 150)))
worst = max(errs, default=float("nan")) * 1e3
print(f"# every touch against its face: largest error {worst:.4f} um (bound 1 um)", file=sys.stderr)
sys.exit(0 if ok and worst <= 1.0 else 1)
PY
# ends_at X Y Z: the simulator's axes at the end (its trace's last whole row; settled
# within 0.5 um) within 1 um of (X, Y, Z).
ends_at() {
  /usr/bin/python3 - "$WORK/trace.csv" "$@" <<'PY'
import sys, time
end = tuple(float(v) for v in sys.argv[2:5])
for _ in range(250):
    lines = open(sys.argv[1]).read().splitlines()
    f = lines[-2].split(",") if len(lines) > 2 else []
    pos = [float(f[1]), float(f[4]), float(f[7])] if len(f) >= 10 else [float("nan")] * 3
    worst = max(abs(p - e) for p, e in zip(pos, end))
    if worst < 5e-4: break
    time.sleep(0.02)
print(f"# at the end: X {pos[0]:.4f} Y {pos[1]:.4f} Z {pos[2]:.4f}, {worst * 1e3:.4f} um from {end}", file=sys.stderr)
sys.exit(0 if worst <= 1e-3 else 1)
PY
}
ends_at 110 110 -15 || fail "the program did not end at the centre plus a tenth of the size, 5 mm above the top (110, 110, -15)"

cat >"$WORK/bore.ngc" <<'NGC'
G21 G90
G0 Z-10
G0 X127 Y123
o<probe_bore> call [20] [15] [3] [600] [60] [0.5] [0]
G0 X[#<_probe_bore_x> + #<_probe_bore_d_x> / 10] Y[#<_probe_bore_y> + #<_probe_bore_d_y> / 10]
M2
NGC
n_before=$(grep -c "probe: G38.2 at" "$WORK/interpolator.log" || true)
"${CTL[@]}" --do run --program "$WORK/bore.ngc" --timeout 90 >"$WORK/ctl_bore.out" 2>&1 ||
  { cat "$WORK/ctl_bore.out" >&2; tail -n 20 "$WORK/interpolator.log" >&2; fail "the bore's program did not run to its end"; }
/usr/bin/python3 - "$WORK/interpolator.log" "$n_before" <<'PY' || fail "o<probe_bore> did not find the bore"
import math, re, sys
trips = [(m.group(1).rsplit("/", 1)[-1], *map(float, m.group(2, 3, 4))) for m in re.finditer(
    r"probe: G38\.2 at (\S+):\d+ \(block \d+\): tripped at X (\S+) Y (\S+) Z (\S+)", open(sys.argv[1]).read())]
trips = trips[int(sys.argv[2]):]
kinds = [t[0] for t in trips]
ok = kinds == ["probe_edge_x.ngc"] * 4 + ["probe_edge_y.ngc"] * 4 + ["probe_edge_x.ngc"] * 4
errs = [abs(math.hypot(x - 125, y - 125) - 10) for _, x, y, z in trips]
worst = max(errs, default=float("nan")) * 1e3
print(("# " if ok else "# FAILED: ") + f"o<probe_bore>: {len(trips)} touches, each against the wall within {worst:.4f} um (bound 1 um)",
      file=sys.stderr)
sys.exit(0 if ok and worst <= 1.0 else 1)
PY
ends_at 127 127 -10 || fail "o<probe_bore> did not end at the centre plus a tenth of each diameter (127, 127, -10)"

cat >"$WORK/length.ngc" <<'NGC'
G21 G90
M61 Q1
G10 L2 P1 Z-3
G92 Z1
o<tool_length> call [100] [100] [-25] [0] [25] [300] [50] [0.5]
G92.1
G43 H1
G0 X[100 + #<_value>] Y100
M2
NGC
"${CTL[@]}" --do run --program "$WORK/length.ngc" --timeout 90 >"$WORK/ctl2.out" 2>&1 ||
  { cat "$WORK/ctl2.out" >&2; tail -n 20 "$WORK/interpolator.log" "$WORK/program-server.log" >&2; fail "the tool setter's program did not run to its end"; }
# length_is_5 TOOL: the tool's Z in the table (into $len) is 5: the setter's trip at -20
# less the reference -25.
length_is_5() {
  len=$(sed -n "s/^T$1 .*Z\([-+0-9.]*\).*/\1/p" "$WORK/tools.tbl")
  awk -v z="$len" 'BEGIN { exit !(z != "" && z - 5 < 1e-4 && 5 - z < 1e-4) }' ||
    { cat "$WORK/tools.tbl" >&2; fail "the tool table's T$1 has Z '$len', not 5"; }
}
length_is_5 1
note "tool_length wrote T1 Z $len to the tool table (want 5)"
settle_at "$WORK/trace.csv" 105 100 0

printf 'G21 G90\nT2 M6 G0 X60 Y60\nM2\n' >"$WORK/change.ngc"
"${CTL[@]}" --do run --program "$WORK/change.ngc" --timeout 90 >"$WORK/ctl3.out" 2>&1 &
TEST_PIDS[change]=$!
wait_state held  # the tool change waits for RESUME
"${CTL[@]}" --do resume >"$WORK/resume3.out" 2>&1 || { cat "$WORK/resume3.out" >&2; fail "RESUME after the change failed"; }
rc=0; wait "${TEST_PIDS[change]}" || rc=$?; unset "TEST_PIDS[change]"
[ "$rc" -eq 0 ] || { cat "$WORK/ctl3.out" >&2; tail -n 20 "$WORK/interpolator.log" >&2; fail "the remapped M6's program did not run to its end ($rc)"; }
length_is_5 2
note "M6 remapped to o<change_and_measure>: held for the change, then T2 Z $len (want 5)"
settle_at "$WORK/trace.csv" 60 60 0
stop_cell_services() { for s in interpolator program-server monitor drive-bridge logger servo-sim; do [ -n "${TEST_PIDS[$s]:-}" ] && stop "$s" TERM; done; return 0; }
stop_cell_services
final_at "$WORK/final.json" 60 60 0 ||
  fail "the remapped M6's block did not end at (60, 60, 0) with T2's length applied"
echo "PASS"
