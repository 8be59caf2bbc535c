#!/usr/bin/env bash
# The 3+2 demo on a trunnion: config/programs/twp_cube.ngc (a pocket on three faces of
# a cube, each in a tilted work plane with the tool turned normal to it by G53.1) runs
# through the dry run to its end on config/machines/five_axis/sim5_trt.yaml, which
# applies the kinematics: each pocket lies in one plane of the machine (joint Z
# constant within 1e-9 mm while it is cut), its circles are circles about the face's
# centre in the machine, and no joint leaves its travel or limits. A program that
# would carry a joint out of its travel is refused naming the joint and the line.
#   twp_plan_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-twp-test.XXXXXX)"
trap 'rm -rf "$WORK"' EXIT
M="$SRC/config/machines/five_axis/sim5_trt.yaml"
"$BUILD/tools/cnc-plan" --machine "$M" --program "$SRC/config/programs/twp_cube.ngc" --csv "$WORK/cube.csv" \
  >"$WORK/out" 2>"$WORK/err" || { cat "$WORK/err" >&2; fail "twp_cube: the dry run failed"; }
head -1 "$WORK/cube.csv" | grep -qx "cycle,t_s,x_mm,y_mm,z_mm,line,u,feed_mm_min,limit,j_X,j_Y,j_Z,j_A,j_C" \
  || fail "twp_cube: CSV header $(head -1 "$WORK/cube.csv")"
worst=$(grep "peak use of the joint limits" "$WORK/out" | grep -oE ' [vaj] [0-9.]+' | awk '{if ($2 > m) m = $2} END {print m + 0}')
awk -v w="$worst" 'BEGIN {exit !(w > 0 && w <= 1.01)}' || fail "twp_cube: peak use of a joint limit $worst"
# Per face (A, C at rest), while cutting (the pocket's lines after the plunge, 14-22):
# joint Z's range, and the largest distance of the circles' joint XY (lines 15, 17)
# from 4 and 8 mm about where the face's centre stands in the machine.
python3 - "$WORK/cube.csv" >"$WORK/faces" <<'PY' || fail "twp_cube: $(cat "$WORK/faces")"
import csv, sys
faces = {}
for r in csv.DictReader(open(sys.argv[1])):
    line = int(r["line"])
    if 14 <= line <= 22:
        faces.setdefault((round(float(r["j_A"]), 6), round(float(r["j_C"]) % 360, 6)), []).append(r)
if len(faces) != 3:
    sys.exit(f"{len(faces)} faces, not 3: {sorted(faces)}")
for (a, c), rows in sorted(faces.items()):
    z = [float(r["j_Z"]) for r in rows]
    # The face's centre: the middle of the square's corners (line 20 ends at one of them).
    xs = [float(r["j_X"]) for r in rows]
    ys = [float(r["j_Y"]) for r in rows]
    cx, cy = (max(xs) + min(xs)) / 2, (max(ys) + min(ys)) / 2
    dev = 0.0
    for r in rows:
        if int(r["line"]) in (15, 17):
            radius = 4 if int(r["line"]) == 15 else 8
            d = ((float(r["j_X"]) - cx) ** 2 + (float(r["j_Y"]) - cy) ** 2) ** 0.5
            dev = max(dev, abs(d - radius))
    print(f"A {a:g} C {c:g}: joint Z {min(z):.9f}..{max(z):.9f}, circles off by {dev:.2e} mm")
    if max(z) - min(z) > 1e-9 or abs(min(z) - 17) > 1e-9 or dev > 1e-3:
        sys.exit(f"A {a:g} C {c:g}: joint Z {min(z)}..{max(z)}, circles off by {dev} mm")
PY
note "twp_cube: $(tr '\n' ';' <"$WORK/faces") $(head -1 "$WORK/out"); $(sed -n 3p "$WORK/out")"
# A point in the axes' travel that a tilted table carries out of joint Z's [-200, 200].
printf 'G21 G90\nG0 A90\nG0 X0 Y250 Z150\nM2\n' >"$WORK/far.ngc"
rc=0; "$BUILD/tools/cnc-plan" --machine "$M" --program "$WORK/far.ngc" --csv "$WORK/far.csv" >/dev/null 2>"$WORK/far.err" || rc=$?
[ "$rc" -eq 1 ] && grep -q "far.ngc: joint Z at .* outside its travel \[-200, 200\], at line 3" "$WORK/far.err" \
  || { cat "$WORK/far.err" >&2; fail "far.ngc: exit $rc, expected joint Z's travel refused at line 3"; }
note "out of travel: $(cat "$WORK/far.err")"
