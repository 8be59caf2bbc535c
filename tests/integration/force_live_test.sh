#!/usr/bin/env bash
# config/machines/sim3_cutting_limit.yaml (VMCS 1999's
# model live, the force feed limit on) runs a corner into the stock box: a wall taking
# 0.5 mm radially, then a left turn into a 2 mm deep slot. The interpolator's setpoints
# carry limit = force after the corner; the monitor's MONITOR reports carry a finite
# predicted force and deflection, within the tolerance (5 % margin: a lost setpoint
# makes the monitor's step longer); no deflection alarm; the run report plots it.
#   force_live_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
PY=/usr/bin/python3
WORK="$(mktemp -d /tmp/cnc-force-live-test.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3_cutting_limit.yaml" "$M"
# The tool and material files by absolute path (the copy is elsewhere); the test's stock box.
sed -i -e "s#tool: \.\./tools/#tool: $SRC/config/tools/#" -e "s#material: \.\./materials/#material: $SRC/config/materials/#" \
    -e "s#stock: {.*}#stock: {x_min_mm: 0, y_min_mm: 0, x_max_mm: 20, y_max_mm: 20, top_z_mm: 0, pitch_mm: 0.05}#" \
    -e "s#deflection_tolerance_mm: [0-9.]*#deflection_tolerance_mm: 0.04#" "$M"
grep -q "tool: $SRC/config/tools/hss_flat_4f_d6.yaml" "$M" || fail "no cutting.tool to rewrite in $M"
grep -q "x_max_mm: 20," "$M" || fail "no cutting.stock to rewrite in $M"

cat >"$WORK/corner.ngc" <<'NGC'
( integration test: a wall, then a corner into a slot )
G21 G90 G17
S1250 M3
G0 X-5 Y-2.5 Z2
G1 Z-2 F100
G1 X8 F100
G1 Y6
G0 Z5
M5
M30
NGC

start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start_cell

rc=0
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/corner.ngc" --timeout 90 >"$WORK/ctl.out" 2>&1 || rc=$?
cat "$WORK/ctl.out" >&2
[ "$rc" -eq 0 ] || fail "program did not complete (cnc-ctl exit $rc)"
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done

R="$WORK/report"
"$BUILD/tools/cnc-logexport" --log "$WORK/run.lcmlog" --out "$R" >"$WORK/export.out" 2>&1 \
  || { cat "$WORK/export.out" >&2; fail "cnc-logexport failed"; }
"$PY" - "$R" <<'PY' || fail "the monitor's force and deflection, or the force limit, are not as expected"
import csv, math, os, sys
d = sys.argv[1]
mon = list(csv.DictReader(open(os.path.join(d, "monitor.csv"))))
sp = list(csv.DictReader(open(os.path.join(d, "setpoints.csv"))))
alarms = open(os.path.join(d, "alarms.csv")).read()
defl = [float(r["deflection_mm"]) for r in mon]
finite = [v for v in defl if math.isfinite(v)]
tol = float(mon[-1]["deflection_tolerance_mm"])
force = sum(1 for r in sp if r["limit"] == "force")
peak = max(float(r["force_peak_n"]) for r in mon if math.isfinite(float(r["force_peak_n"])))
print(f"# {len(mon)} reports, {len(finite)} with a deflection, max {max(finite) * 1e3:.2f} um "
      f"(tolerance {tol * 1e3:.0f} um), peak force {peak:.1f} N; {force} setpoints limited by force", file=sys.stderr)
assert tol == 0.04
assert len(finite) > 0.95 * len(mon) and len(mon) > 2000
assert 0.9 * tol < max(finite) <= 1.05 * tol
assert force > 100
assert peak > 10
assert "deflection" not in alarms, alarms
PY
"$PY" "$SRC/tools/report/make_report.py" "$R" >"$WORK/report.out" 2>&1 \
  || { cat "$WORK/report.out" >&2; fail "make_report.py failed"; }
[ -s "$R/deflection.png" ] || fail "the report has no deflection panel"
grep -q 'deflection.png' "$R/index.html" || fail "the report page does not show the deflection panel"
note "force live: ok"
