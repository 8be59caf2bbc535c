#!/usr/bin/env bash
# The shipped probing subroutines (config/subroutines) live on the simulator's fixture, a
# box X 50..150, Y 50..150 with its top at Z -20, with the drives' touch-probe latches
# (probe.latch: drives): o<probe_z> finds the top, o<probe_boss> the four side faces
# (through o<probe_edge_x> and o<probe_edge_y>), the centre and the size. Every touch
# (fast and slow) within 1 um of its face; the program then moves to the centre plus a
# tenth of the size, 5 mm above the top it found: (110, 110, -15) within 1 um.
#   probe_cycles_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-probe-cycles.XXXXXX)"
trap 'cleanup $?' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3_probe.yaml" "$M"
sed -i 's/^  input: probe_tip .*/  input: probe_tip\n  latch: drives/' "$M"
printf '\nprogram:\n  subroutine_path: %s\n' "$SRC/config/subroutines" >>"$M"
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
settle_at "$WORK/trace.csv" 110 110 -15
stop_cell_services() { for s in interpolator program-server monitor drive-bridge logger servo-sim; do [ -n "${TEST_PIDS[$s]:-}" ] && stop "$s" TERM; done; return 0; }
stop_cell_services
final_at "$WORK/final.json" 110 110 -15 ||
  fail "the program did not end at the centre plus a tenth of the size, 5 mm above the top (110, 110, -15)"
echo "PASS"
