#!/bin/bash
# cnc-cam's pictures: drop --png (the CL surface of a grid of points
# as a shaded height map), raster --png (the CL surface with the cuts and their CL
# points) and rough --png (the levels) each write a PNG (its signature, a size and a
# picture of some hundred pixels a side), and stdout keeps only the tool's figures line
# (progress and the plot script's words go to stderr). The mesh: a V-groove (walls at
# 31 deg, its crease on mesh edges) under a wave along y, so the raster's step control
# also finds concave corners. Skipped (77) only if Debian's python3 has no matplotlib.
set -euo pipefail
BUILD=$1
SRC=$2
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
CAM="$BUILD/tools/cam/cnc-cam"
if ! /usr/bin/python3 -c 'import matplotlib' 2>/dev/null; then
  echo "SKIP: /usr/bin/python3 has no matplotlib (Debian: apt-get install python3-matplotlib); --png cannot be tested" >&2
  exit 77
fi

/usr/bin/python3 "$SRC/tests/integration/grid_stl.py" "$WORK/groove.stl" 30 20 "0.6 * abs(x - 12) + 1.5 * math.sin(y / 4.0)"
/usr/bin/python3 - "$WORK/xy.csv" <<'PY'
import sys
with open(sys.argv[1], "w") as f:
    f.write("x,y\n")
    for j in range(81):
        for i in range(121):
            f.write("%g,%g\n" % (i * 0.25, j * 0.25))
PY

check_png() {  # file what
  /usr/bin/python3 - "$1" <<'PY' || fail "$2: $1 is not a PNG picture (above)"
import struct, sys
data = open(sys.argv[1], "rb").read()
if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
    sys.exit(f"{sys.argv[1]}: no PNG signature ({len(data)} bytes)")
w, h = struct.unpack(">II", data[16:24])
print(f"# {sys.argv[1].rsplit('/', 1)[-1]}: {len(data)} bytes, {w} x {h} px", file=sys.stderr)
sys.exit(0 if len(data) > 10000 and w >= 300 and h >= 300 else f"too small: {len(data)} bytes, {w} x {h}")
PY
}
figures_only() {  # stdout-file pattern what
  [ "$(grep -cv "$2" "$1")" = 0 ] && [ "$(grep -c "$2" "$1")" -ge 1 ] || { cat "$1" >&2; fail "$3: stdout holds more than its figures (above)"; }
}

"$CAM" drop --stl "$WORK/groove.stl" --tool ball:4 --points "$WORK/xy.csv" --out "$WORK/xyz.csv" --threads 2 \
  --png "$WORK/drop.png" >"$WORK/drop.out" 2>"$WORK/drop.err" || { cat "$WORK/drop.err" >&2; fail "cnc-cam drop --png"; }
figures_only "$WORK/drop.out" '^points=[0-9]* seconds=[0-9.]* pts_per_s=[0-9]*$' "drop"
check_png "$WORK/drop.png" "drop --png"

"$CAM" raster --stl "$WORK/groove.stl" --tool ball:4 --pick 2 --step 2 --tol-beta 0.005 --threads 2 \
  --out "$WORK/r.ngc" --png "$WORK/raster.png" >"$WORK/raster.out" 2>"$WORK/raster.err" \
  || { cat "$WORK/raster.err" >&2; fail "cnc-cam raster --png"; }
figures_only "$WORK/raster.out" '^points=[0-9]* seconds=[0-9.]* pts_per_s=[0-9]*$' "raster"
grep 'concave corners found' "$WORK/raster.err" | sed 's/^/# /' >&2
corners=$(sed -n 's/.* \([0-9]*\) concave corners found.*/\1/p' "$WORK/raster.err")
[ "${corners:-0}" -ge 11 ] || fail "raster: the step control found ${corners:-no} concave corners on 11 passes over the groove"
check_png "$WORK/raster.png" "raster --png"

"$CAM" rough --stl "$WORK/groove.stl" --stock margin:1 --tool bull:6:1 --cusp 0.5 --out "$WORK/rough.ngc" \
  --png "$WORK/rough.png" >"$WORK/rough.out" 2>"$WORK/rough.err" || { cat "$WORK/rough.err" >&2; fail "cnc-cam rough --png"; }
figures_only "$WORK/rough.out" '^tool=' "rough"
check_png "$WORK/rough.png" "rough --png"
echo "PASS: cnc-cam drop, raster and rough --png wrote PNG pictures; stdout kept to the figures" >&2
