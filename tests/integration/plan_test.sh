#!/usr/bin/env bash
# The dry run: two runs of the same program give identical files, byte for byte;
# a malformed program is refused with file:line:column and writes no setpoint; the
# program-time cap is the machine file's, and LinuxCNC's 52 h arc at F1 passes under its default.
#   plan_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-plan-test.XXXXXX)"
trap 'rm -rf "$WORK"' EXIT
M="$SRC/config/machines/sim3.yaml"
for prog in "$SRC/config/programs/fig11_valley.ngc" "$SRC/config/programs/demo.ngc" \
            "$SRC/tests/golden/programs/valid/arcs_planes_helix.ngc" \
            "$SRC/tests/golden/programs/valid/linuxcnc_doc_example.ngc" \
            "$SRC/tests/golden/programs/valid/landing_into_lower_jerk.ngc"; do
  name=$(basename "$prog" .ngc)
  "$BUILD/tools/cnc-plan" --machine "$M" --program "$prog" --csv "$WORK/$name.1.csv" >"$WORK/out1" \
    || fail "$name: dry run failed"
  "$BUILD/tools/cnc-plan" --machine "$M" --program "$prog" --csv "$WORK/$name.2.csv" >"$WORK/out2" \
    || fail "$name: second dry run failed"
  cmp "$WORK/$name.1.csv" "$WORK/$name.2.csv" || fail "$name: the two dry runs differ"
  head -1 "$WORK/$name.1.csv" | grep -qx "cycle,t_s,x_mm,y_mm,z_mm,line,u,feed_mm_min,limit" || fail "$name: CSV header"
  rows=$(($(wc -l <"$WORK/$name.1.csv") - 1))
  [ "$rows" -gt 100 ] || fail "$name: only $rows setpoints"
  grep -q "program time" "$WORK/out1" || fail "$name: no program time printed"
  # No axis's velocity, acceleration or jerk over its limit by more than 1 %.
  worst=$(grep "peak use of the axis limits" "$WORK/out1" | grep -oE ' [vaj] [0-9.]+' | awk '{if ($2 > m) m = $2} END {print m + 0}')
  awk -v w="$worst" 'BEGIN {exit !(w > 0 && w <= 1.01)}' || fail "$name: peak use of an axis limit $worst"
  note "$name: $rows setpoints, identical twice ($(sha256sum <"$WORK/$name.1.csv" | cut -c1-16)); $(cat "$WORK/out1")"
done
rc=0
"$BUILD/tools/cnc-plan" --machine "$M" --program "$SRC/tests/golden/programs/malformed/$(ls "$SRC/tests/golden/programs/malformed" | head -1)" \
  --csv "$WORK/bad.csv" 2>"$WORK/bad.err" || rc=$?
[ "$rc" -eq 3 ] || fail "malformed program: exit $rc, expected 3"
grep -qE '\.ngc:[0-9]+:[0-9]+: ' "$WORK/bad.err" || { cat "$WORK/bad.err" >&2; fail "refusal without file:line:column"; }
[ ! -s "$WORK/bad.csv" ] || fail "a refused program wrote setpoints"
note "malformed program refused: $(cat "$WORK/bad.err")"

# A dry run reads the machine's parameters (program.var_file) but never writes them:
# a program that sets a work offset (G10 L2 P1 X5: parameter 5221) leaves the file as it was.
{ cat "$M"; printf 'program:\n  var_file: %s\n' "$WORK/cell.var"; } >"$WORK/var.yaml"
printf '5221\t-7.000000\n' >"$WORK/cell.var"
cp "$WORK/cell.var" "$WORK/cell.var.before"
printf 'G21 G90\nG10 L2 P1 X5\nG0 X10\nM2\n' >"$WORK/g10.ngc"
"$BUILD/tools/cnc-plan" --machine "$WORK/var.yaml" --program "$WORK/g10.ngc" --csv "$WORK/g10.csv" >"$WORK/g10.out" 2>&1 \
  || { cat "$WORK/g10.out" >&2; fail "the G10 program's dry run failed"; }
cmp -s "$WORK/cell.var" "$WORK/cell.var.before" || { cat "$WORK/cell.var" >&2; fail "the dry run wrote the parameter file"; }
note "dry run with program.var_file: the parameter file unchanged ($(wc -l <"$WORK/cell.var") line)"

# --show-setup prints what programs may do on the machine, the program server's setup
# (dry_run_agreement_test compares the two field by field); --block-delete sets the
# server's switch as the HMI's preview passes it, and refuses anything but on and off.
P="$BUILD/tools/cnc-plan"
"$P" --machine "$SRC/config/machines/sim3_probe.yaml" --show-setup | grep -qx "machine.has_probe = true" \
  || fail "--show-setup: sim3_probe.yaml without its probe"
"$P" --machine "$M" --show-setup | grep -qx "machine.has_probe = false" || fail "--show-setup: sim3.yaml with a probe"
"$P" --machine "$M" --show-setup --block-delete off | grep -qx "machine.block_delete = false" \
  || fail "--block-delete off does not reach the setup"
rc=0; "$P" --machine "$M" --show-setup --block-delete maybe >/dev/null 2>"$WORK/bd.err" || rc=$?
[ "$rc" -eq 2 ] && grep -q -- "--block-delete maybe: expected on or off" "$WORK/bd.err" \
  || { cat "$WORK/bd.err" >&2; fail "--block-delete maybe: exit $rc"; }
note "--show-setup: $("$P" --machine "$M" --show-setup | wc -l) fields; --block-delete maybe refused: $(cat "$WORK/bd.err")"
# The executables themselves: on every shipped machine file cnc-program-server and
# cnc-plan print the same setup, but that the dry run never writes the var file.
n=0
for f in "$SRC"/config/machines/*.yaml; do
  "$BUILD/services/cnc-program-server" --machine "$f" --show-setup >"$WORK/cell.setup" || fail "$f: cnc-program-server --show-setup"
  "$P" --machine "$f" --show-setup >"$WORK/dry.setup" || fail "$f: cnc-plan --show-setup"
  d="$(diff "$WORK/cell.setup" "$WORK/dry.setup" | grep '^[<>]' | tr '\n' ' ' || true)"
  [ "$d" = "< machine.write_var_file = true > machine.write_var_file = false " ] \
    || fail "$(basename "$f"): the server's and the dry run's setups differ: $d"
  n=$((n + 1))
done
[ "$n" -ge 10 ] || fail "only $n machine files"
note "cnc-program-server and cnc-plan --show-setup: alike on $n machine files ($(wc -l <"$WORK/dry.setup") fields), but machine.write_var_file"
# --start: the program loaded from where the machine stands (the server's load, the
# HMI's preview): an incremental move ends 10 mm on from it, and leaves X's travel
# [-5, 400] from X 395 (refused, exit 3, as the server refuses it).
printf 'G21 G91\nG1 X10 Y-5 F600\nM2\n' >"$WORK/inc.ngc"
"$P" --machine "$M" --program "$WORK/inc.ngc" --csv "$WORK/inc.csv" --start 100,50,-10 >/dev/null \
  || fail "--start 100,50,-10: the incremental program's dry run failed"
[ "$(tail -1 "$WORK/inc.csv" | cut -d, -f3-5)" = "110.000000000,45.000000000,-10.000000000" ] \
  || fail "--start 100,50,-10: the incremental move ends at $(tail -1 "$WORK/inc.csv" | cut -d, -f3-5)"
rc=0; "$P" --machine "$M" --program "$WORK/inc.ngc" --start 395,0,0 2>"$WORK/start.err" >/dev/null || rc=$?
[ "$rc" -eq 3 ] && grep -q "inc.ngc:2:1: X 405.0000 mm .* outside the axis's travel" "$WORK/start.err" \
  || { cat "$WORK/start.err" >&2; fail "--start 395,0,0: exit $rc, expected the travel refusal"; }
rc=0; "$P" --machine "$M" --program "$WORK/inc.ngc" --start 1,2 2>"$WORK/start.err" >/dev/null || rc=$?
[ "$rc" -eq 2 ] && grep -q -- "--start 1,2: expected 3 machine positions" "$WORK/start.err" \
  || { cat "$WORK/start.err" >&2; fail "--start 1,2: exit $rc"; }
note "--start: the incremental move from (100, 50, -10) ends at (110, 45, -10); from X 395 refused at inc.ngc:2:1"

# The dry run's program-time cap is the machine's setting (program.dry_run_max_time_s),
# and a program beyond it is an error that names it: 10 s here, a 5 s dwell within it,
# a 30 s one not.
{ cat "$M"; printf 'program:\n  dry_run_max_time_s: 10\n'; } >"$WORK/cap.yaml"
printf 'G21 G90\nG0 X1\nG4 P5\nM2\n' >"$WORK/short.ngc"
printf 'G21 G90\nG0 X1\nG4 P30\nM2\n' >"$WORK/long.ngc"
"$BUILD/tools/cnc-plan" --machine "$WORK/cap.yaml" --program "$WORK/short.ngc" >"$WORK/short.out" 2>&1 \
  || { cat "$WORK/short.out" >&2; fail "a 5 s program under a 10 s cap was refused"; }
rc=0
"$BUILD/tools/cnc-plan" --machine "$WORK/cap.yaml" --program "$WORK/long.ngc" >"$WORK/long.out" 2>&1 || rc=$?
[ "$rc" -eq 1 ] || { cat "$WORK/long.out" >&2; fail "a 30 s program under a 10 s cap: exit $rc, expected 1"; }
grep -q "did not finish within 10 s of program time.*program.dry_run_max_time_s" "$WORK/long.out" \
  || { cat "$WORK/long.out" >&2; fail "the cap's message does not name program.dry_run_max_time_s"; }
note "program-time cap: $(grep -o 'did not finish.*' "$WORK/long.out")"

# LinuxCNC's interpreter test good-arc.medium.metric.center-format.ngc (its geometry,
# written here): a half circle of r 1,000 mm (999.5 at the start, 1000.5 at the end) at
# F1, about pi x 1,000 min = 52.4 h of program time. Under the default cap (a week) it
# is planned to its end; under a cap of 10 s it is refused naming the key. On a machine
# with the travel for it, at a 16 ms period (4x fewer cycles than sim3's 4 ms: ~4 s).
sed -e '0,/max_mm: 400/s//max_mm: 2100/' -e '0,/max_mm: 300/s//max_mm: 1100/' \
    -e 's/ipo_period_s: 0.004 /ipo_period_s: 0.016 /' "$M" >"$WORK/big.yaml"
grep -q 'ipo_period_s: 0.016 ' "$WORK/big.yaml" && grep -q 'max_mm: 2100' "$WORK/big.yaml" \
  || fail "the large machine's file was not made from $M"
{ cat "$WORK/big.yaml"; printf 'program:\n  dry_run_max_time_s: 10\n'; } >"$WORK/big_cap.yaml"
printf 'G21 G90 G17 F1\nG0 X0 Y0 Z0\nG2 X2000 I[0.9995 * 1000]\nM2\n' >"$WORK/good_arc_medium.ngc"
rc=0
"$BUILD/tools/cnc-plan" --machine "$WORK/big_cap.yaml" --program "$WORK/good_arc_medium.ngc" >"$WORK/arc_cap.out" 2>&1 || rc=$?
[ "$rc" -eq 1 ] && grep -q "did not finish within 10 s of program time.*program.dry_run_max_time_s" "$WORK/arc_cap.out" \
  || { cat "$WORK/arc_cap.out" >&2; fail "the 52 h arc under a 10 s cap: exit $rc, or no key named"; }
t0=$(date +%s.%N)
"$BUILD/tools/cnc-plan" --machine "$WORK/big.yaml" --program "$WORK/good_arc_medium.ngc" >"$WORK/arc.out" 2>&1 \
  || { cat "$WORK/arc.out" >&2; fail "the 52 h arc is not planned under the default cap"; }
wall=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN {printf "%.1f", b - a}')
t=$(sed -n 's/^program time \([0-9.]*\) s.*/\1/p' "$WORK/arc.out")
# pi x 1,000 mm at 1 mm/min (the spiral's length is within 0.01 mm of it) = 188,495.6 s; 10 s for the ends.
awk -v t="$t" 'BEGIN {exit !(t > 188485 && t < 188506)}' \
  || { cat "$WORK/arc.out" >&2; fail "the arc's program time $t s, expected 188,495.6 +- 10 s"; }
note "good-arc.medium (F1, r 1,000 mm): planned to its end, $t s of program time ($(awk -v t="$t" 'BEGIN {printf "%.1f", t / 3600}') h) in $wall s; refused under a 10 s cap: $(grep -o 'did not finish.*' "$WORK/arc_cap.out")"
echo PASS
