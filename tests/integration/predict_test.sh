#!/usr/bin/env bash
# `./cnc predict slot` prints the simulated full-slot
# means as one line, within 0.5 % of the closed form (Al7075-T6, N 4, D 6, helix 30°,
# a 3 mm, c 0.05 mm: fx −142.9673, fy 225.2212, fz 42.3989 N); `./cnc predict PROGRAM`
# runs the dry run through the stock model and writes an HTML report whose worst places
# are program lines that cut, and headless Chromium renders it without load errors
# (3 images, all PNGs, a screenshot that is not blank). No multicast: no namespace.
#   predict_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
BUILD="$1"; SRC="$2"
PY=/usr/bin/python3
WORK="$(mktemp -d /tmp/cnc-predict-test.XXXXXX)"
trap 'rm -rf "$WORK"' EXIT
command -v chromium >/dev/null || fail "chromium is not installed (./cnc installs it: PACKAGES)"
export CNC_BUILD_DIR="$BUILD"

line="$("$SRC/cnc" predict slot --material "$SRC/config/materials/al7075_t6.yaml" --flutes 4 --diameter 6 --helix 30 \
        --axial-depth 3 --feed-per-tooth 0.05)" || fail "./cnc predict slot failed"
note "$line"
"$PY" - "$line" <<'PY' || fail "slot means not within 0.5 % of the closed form: $line"
import sys
kv = dict(w.split("=") for w in sys.argv[1].split())
assert sorted(kv) == ["fx_mean_N", "fy_mean_N", "fz_mean_N"], kv
for k, ref in (("fx_mean_N", -142.9673), ("fy_mean_N", 225.2212), ("fz_mean_N", 42.3989)):
    assert abs(float(kv[k]) / ref - 1) < 0.005, (k, kv[k], ref)
PY

cat >"$WORK/corner.ngc" <<'NGC'
( predict test: a slot, a wall, a corner )
G21 G90 G17
S1250 M3
G0 X-4 Y0 Z2
G1 Z-2 F300
G1 X10 F300
G1 Y3
G1 X-4
G0 Z5
M5
M30
NGC
R="$WORK/out"
"$SRC/cnc" predict "$WORK/corner.ngc" --tool "$SRC/config/tools/hss_flat_4f_d6.yaml" \
  --material "$SRC/config/materials/al_paper004.yaml" --stock-top 0 --out "$R" >"$WORK/predict.out" 2>"$WORK/predict.err" \
  || { tail -20 "$WORK/predict.err" >&2; fail "./cnc predict PROGRAM failed"; }
grep -q "cnc-predict program: 100 %" "$WORK/predict.err" || fail "no progress on stderr"
for f in index.html setpoints.csv predict.csv stock.csv worst_lines.csv force.png deflection.png surface.png; do
  [ -s "$R/$f" ] || fail "the report has no $f"
done
# The worst places are the cutting lines (5-8), with a finite, positive error below 1 mm.
"$PY" - "$R/worst_lines.csv" <<'PY' || fail "worst_lines.csv does not name the cutting lines"
import csv, math, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert rows, "no rows"
for r in rows:
    e = float(r["surface_error_mm"])
    assert int(r["line"]) in (5, 6, 7, 8) and math.isfinite(e) and 0 < e < 1, r
print(f"# worst line {rows[0]['line']} ({rows[0]['text']}): {1e3 * float(rows[0]['surface_error_mm']):.1f} um", file=sys.stderr)
PY

profile="$WORK/chromium-profile"
flags=(--headless --no-sandbox --disable-gpu --disable-quic --no-first-run --disable-background-networking
       --disable-component-update --disable-sync --user-data-dir="$profile" --enable-logging=stderr --v=1
       --window-size=1100,2200 --hide-scrollbars --virtual-time-budget=5000)
timeout 60 chromium "${flags[@]}" --screenshot="$WORK/shot.png" "file://$R/index.html" >"$WORK/shot.log" 2>&1 \
  || { tail -20 "$WORK/shot.log" >&2; fail "chromium could not render the report"; }
timeout 60 chromium "${flags[@]}" --dump-dom "file://$R/index.html" >"$WORK/dom.html" 2>"$WORK/dom.log" \
  || { tail -20 "$WORK/dom.log" >&2; fail "chromium could not load the report"; }
if grep -E "Failed to load resource|Uncaught|ERR_FILE_NOT_FOUND" "$WORK/shot.log" "$WORK/dom.log" >&2; then
  fail "the report has load errors"
fi
"$PY" - "$WORK/dom.html" "$R" "$WORK/shot.png" <<'PY' || fail "the rendered report is incomplete"
import os, re, sys
import matplotlib.image as mpimg
dom, root = open(sys.argv[1]).read(), sys.argv[2]
imgs = re.findall(r'<img[^>]* src="([^"]+)"', dom)
assert imgs == ["force.png", "deflection.png", "surface.png"], imgs
for src in imgs:
    assert open(os.path.join(root, src), "rb").read(8) == b"\x89PNG\r\n\x1a\n", src
assert "Worst places" in dom and "G1 Y3" in dom, "no worst-places table with the program's text"
img = mpimg.imread(sys.argv[3])[..., :3]
h, w = img.shape[:2]
ink = (img.mean(axis=2) < 0.9).mean()
colours = len({tuple(p) for p in (img[::7, ::7].reshape(-1, 3) * 255).astype(int).tolist()})
print(f"# screenshot {w}x{h}, {ink * 100:.1f} % ink, {colours} colours", file=sys.stderr)
assert (w, h) == (1100, 2200) and ink > 0.03 and colours > 50
PY
echo "PASS"
