#!/bin/bash
# cnc-cam rough's G-code through the project's own dry run: Shin
# et al.'s Table 1 part "b" (generated, 7,200 triangles) roughed with a flat and a filleted
# D10 at cusp 5 in its box stock, and a frustum with a 3 mm margin and a ball D6 at cusp
# 1 entering down 3° ramps, each accepted by cnc-plan on sim3, every setpoint of a G1 move within 1 um of that
# move's segment (tools/cam/check_plan.py), every axis within its limits (1 %); --compare
# and --png work.
set -euo pipefail
BUILD=$1
SRC=$2
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
CAM="$BUILD/tools/cam/cnc-cam"

"$CAM" part --shape table1-b --cells 60 --out "$WORK/b.stl" 2>/dev/null || fail "cnc-cam part table1-b"
"$CAM" part --shape frustum --out "$WORK/f.stl" 2>/dev/null || fail "cnc-cam part frustum"

run() {  # name stl stock tool cusp [extra...]
  local name=$1 stl=$2 stock=$3 tool=$4 cusp=$5
  shift 5
  "$CAM" rough --stl "$stl" --stock "$stock" --tool "$tool" --cusp "$cusp" --out "$WORK/$name.ngc" "$@" \
    >"$WORK/$name.cam" 2>&1 || { cat "$WORK/$name.cam" >&2; fail "cnc-cam rough ($name) failed"; }
  "$BUILD/tools/cnc-plan" --machine "$SRC/config/machines/sim3.yaml" --program "$WORK/$name.ngc" \
    --csv "$WORK/$name.csv" >"$WORK/$name.plan" 2>&1 || { cat "$WORK/$name.plan" >&2; fail "cnc-plan refused $name"; }
  out=$(/usr/bin/python3 "$SRC/tools/cam/check_plan.py" "$WORK/$name.ngc" "$WORK/$name.csv")
  echo "# $name: $(grep '^tool=' "$WORK/$name.cam" | head -1); $out" >&2
  grep 'program time\|peak use' "$WORK/$name.plan" | sed 's/^/# /' >&2
  /usr/bin/python3 - "$out" "$WORK/$name.plan" <<'PY' || fail "the $name program's dry run strays from its moves or breaks a limit (above)"
import re, sys
kv = dict(w.split("=", 1) for w in sys.argv[1].split())
ok = int(kv["setpoints_checked"]) > 1000 and float(kv["max_distance_mm"]) <= 1e-3
use = re.findall(r"[vaj] ([0-9.]+)", open(sys.argv[2]).read().split("peak use", 1)[1])
ok = ok and len(use) == 9 and max(map(float, use)) <= 1.01
sys.exit(0 if ok else 1)
PY
}

run b_flat "$WORK/b.stl" box flat:10 5
run b_bull "$WORK/b.stl" box bull:10:2 5 --compare flat:10,bull:10:2,ball:10 --png "$WORK/b.png"
run f_ball "$WORK/f.stl" margin:3 ball:6 1 --ramp 3
grep -q '^compare' "$WORK/b_bull.cam" || fail "--compare printed no comparison"
[ "$(grep -c '^tool=' "$WORK/b_bull.cam")" = 4 ] || fail "--compare did not print one line per tool"
[ -s "$WORK/b.png" ] || fail "--png wrote no picture"
echo "PASS: cnc-cam rough programs (flat, bull, ball; box and margin stock) accepted by cnc-plan, within 1 um of their moves" >&2
