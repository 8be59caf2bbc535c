#!/bin/bash
# cnc-cam raster --nurbs through the project's own dry run: the passes
# over a generated terrain written as G6.2 cubic NURBS fitted within 5 um are accepted by
# cnc-plan on sim3, every CL point (the G1 program's end points, same passes) lies within
# 5 um + 0.1 um (the written digits: 8.7e-5 mm) of the dry run's path, and every axis keeps
# its limits (1 %).
set -euo pipefail
BUILD=$1
SRC=$2
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

# The terrain of cam_plan_test.sh: 40 x 30 mm at 1 mm, ASCII STL (2,400 triangles).
/usr/bin/python3 "$SRC/tests/integration/grid_stl.py" "$WORK/terrain.stl" 40 30 "2.0 * math.sin(x / 7.0) * math.cos(y / 9.0)"

TOL=0.005
args=(--stl "$WORK/terrain.stl" --tool ball:4 --pick 3 --step 0.1 --threads 1)
"$BUILD/tools/cam/cnc-cam" raster "${args[@]}" --out "$WORK/lines.ngc" >/dev/null 2>&1 || fail "cnc-cam raster (lines) failed"
"$BUILD/tools/cam/cnc-cam" raster "${args[@]}" --nurbs $TOL --out "$WORK/nurbs.ngc" >"$WORK/nurbs.cam" 2>&1 ||
  { cat "$WORK/nurbs.cam" >&2; fail "cnc-cam raster --nurbs failed"; }
grep 'NURBS' "$WORK/nurbs.cam" | sed 's/^/# /' >&2
"$BUILD/tools/cnc-plan" --machine "$SRC/config/machines/sim3.yaml" --program "$WORK/nurbs.ngc" \
  --csv "$WORK/nurbs.csv" >"$WORK/nurbs.plan" 2>&1 || { cat "$WORK/nurbs.plan" >&2; fail "cnc-plan refused the NURBS raster"; }
out=$(/usr/bin/python3 "$SRC/tools/cam/check_nurbs_plan.py" "$WORK/lines.ngc" "$WORK/nurbs.ngc" "$WORK/nurbs.csv")
echo "# $(wc -l <"$WORK/lines.ngc") lines as G1, $(wc -l <"$WORK/nurbs.ngc") as NURBS; $out" >&2
grep 'program time\|peak use' "$WORK/nurbs.plan" | sed 's/^/# /' >&2
/usr/bin/python3 - "$out" "$WORK/nurbs.plan" $TOL <<'PY' || fail "the NURBS raster's dry run strays from its CL points or breaks a limit (above)"
import re, sys
kv = dict(w.split("=", 1) for w in sys.argv[1].split())
tol = float(sys.argv[3])
ok = int(kv["cl_points"]) > 4000 and int(kv["setpoints"]) > 1000 and float(kv["max_cl_to_plan_mm"]) <= tol + 1e-4
use = re.findall(r"[vaj] ([0-9.]+)", open(sys.argv[2]).read().split("peak use", 1)[1])
ok = ok and len(use) == 9 and max(map(float, use)) <= 1.01
sys.exit(0 if ok else 1)
PY
echo "PASS: cnc-cam raster --nurbs $TOL accepted by cnc-plan, every CL point within $TOL mm + 0.1 um of the dry run's path" >&2
