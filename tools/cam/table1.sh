#!/bin/bash
# Shin et al.'s Table 1 side by side: builds the two parts (cnc-cam part, CELLS cells a side,
# default 200), roughs them at cusp 5 with a flat D10 and a filleted D10 r2 in their box
# stock, and prints the levels and path lengths next to the paper's.
#   tools/cam/table1.sh [BUILD_DIR] [CELLS]
set -euo pipefail
BUILD=${1:-build}
CELLS=${2:-200}
CAM="$BUILD/tools/cam/cnc-cam"
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
for p in a b; do
  "$CAM" part --shape "table1-$p" --cells "$CELLS" --out "$WORK/$p.stl" 2>/dev/null
  "$CAM" rough --stl "$WORK/$p.stl" --stock box --tool flat:10 --cusp 5 --out "$WORK/$p.ngc" \
    --compare flat:10,bull:10:2 2>/dev/null | sed -n '/^compare/,$p' | grep '^tool=' >"$WORK/$p.txt"
done
/usr/bin/python3 - "$WORK" <<'PY'
import re, sys
paper = {"a": (43.9, [6.3, 13.9, 23.5, 32.5, 40.0, 43.9], [6.4, 19.6, 31.6, 40.5, 43.9], 23.8),
         "b": (32.4, [6.1, 15.3, 26.2, 32.4], [6.2, 18.2, 28.0, 32.4], 6.5)}
for p, (h, pf, pb, red) in paper.items():
    rows = [dict(re.findall(r"(\w+)=(\S+)", l)) for l in open(f"{sys.argv[1]}/{p}.txt")]
    f, b = rows
    print(f"part {p} (height {h}), cusp 5: levels (mm above the base)")
    print(f"  paper flat D10      {len(pf)}: " + " / ".join(f"{z:.1f}" for z in pf))
    print(f"  ours  flat D10      {f['levels']}: " + " / ".join(f"{float(z):.1f}" for z in f['heights'].split('/')))
    print(f"  paper bull D10 r2   {len(pb)}: " + " / ".join(f"{z:.1f}" for z in pb))
    print(f"  ours  bull D10 r2   {b['levels']}: " + " / ".join(f"{float(z):.1f}" for z in b['heights'].split('/')))
    fc, bc, fp, bp = (float(x) for x in (f["contour_mm"], b["contour_mm"], f["path_mm"], b["path_mm"]))
    print(f"  path shorter with the bull: paper {red:.1f} %; ours, contours alone {100 * (1 - bc / fc):.1f} % "
          f"({fc:.0f} -> {bc:.0f} mm), pocketing paths {100 * (1 - bp / fp):.1f} % ({fp:.0f} -> {bp:.0f} mm)")
PY
