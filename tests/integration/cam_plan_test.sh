#!/bin/bash
# cnc-cam's G-code through the project's own dry run: rasters over a
# generated terrain mesh, with a fixed step and with Hwang's step control, are each
# accepted by cnc-plan on sim3, every setpoint of a G1 move lies within 1 um of that
# move's segment (tools/cam/check_plan.py), and every axis keeps its velocity,
# acceleration and jerk limits (cnc-plan's finite differences, 1 %).
set -euo pipefail
BUILD=$1
SRC=$2
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

# A smooth terrain, 40 x 30 mm at 1 mm, as ASCII STL (2,400 triangles).
/usr/bin/python3 "$SRC/tests/integration/grid_stl.py" "$WORK/terrain.stl" 40 30 "2.0 * math.sin(x / 7.0) * math.cos(y / 9.0)"

for mode in fixed beta; do
  if [ "$mode" = fixed ]; then args=(--step 0.5); else args=(--step 2 --tol-beta 0.005); fi
  "$BUILD/tools/cam/cnc-cam" raster --stl "$WORK/terrain.stl" --tool ball:4 --pick 3 "${args[@]}" \
    --threads 1 --out "$WORK/$mode.ngc" >"$WORK/$mode.cam" 2>&1 || { cat "$WORK/$mode.cam" >&2; fail "cnc-cam raster ($mode) failed"; }
  "$BUILD/tools/cnc-plan" --machine "$SRC/config/machines/sim3.yaml" --program "$WORK/$mode.ngc" \
    --csv "$WORK/$mode.csv" >"$WORK/$mode.plan" 2>&1 || { cat "$WORK/$mode.plan" >&2; fail "cnc-plan refused the $mode raster"; }
  out=$(/usr/bin/python3 "$SRC/tools/cam/check_plan.py" "$WORK/$mode.ngc" "$WORK/$mode.csv")
  echo "# $mode: $(grep -c '^G1\|^X\|^Y\|^Z' "$WORK/$mode.ngc") move lines; $out" >&2
  grep 'peak use' "$WORK/$mode.plan" | sed 's/^/# /' >&2
  /usr/bin/python3 - "$out" "$WORK/$mode.plan" <<'PY' || fail "the $mode raster's dry run strays from its moves or breaks a limit (above)"
import re, sys
kv = dict(w.split("=", 1) for w in sys.argv[1].split())
ok = int(kv["setpoints_checked"]) > 1000 and float(kv["max_distance_mm"]) <= 1e-3
use = re.findall(r"[vaj] ([0-9.]+)", open(sys.argv[2]).read().split("peak use", 1)[1])
ok = ok and len(use) == 9 and max(map(float, use)) <= 1.01
sys.exit(0 if ok else 1)
PY
done
echo "PASS: cnc-cam rasters (fixed step, step control) accepted by cnc-plan, within 1 um of their moves" >&2
