#!/usr/bin/env bash
# `./cnc report` on a log the test records itself: the whole cell (servo simulator +
# the five services) runs a short program with lines, arcs and a ramp; then
# `./cnc report LOG --out DIR` (cnc-logexport + make_report.py) and headless
# Chromium renders DIR/index.html to a PNG. Checks: every table and plot is
# written, the page's images all exist and load (no "Failed to load resource",
# no "Uncaught" in Chromium's log), the screenshot is not blank, the panels with
# data say so; and, from the same tables with the chord error and R_max blanked
# to NaN, the report still builds and shows "no data" in exactly those panels.
#   report_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
PY=/usr/bin/python3  # Debian's, with matplotlib
WORK="$(mktemp -d /tmp/cnc-report-test.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
command -v chromium >/dev/null || fail "chromium is not installed (./cnc installs it: PACKAGES)"

cat >"$WORK/part.ngc" <<'NGC'
( report test: lines, arcs - the small one chord-limited - a ramp, with the spindle on )
(PROCESS, BALL_RADIUS=5, FLUTES=2, PICK_FEED=0.5, RMAX_UM=10.67)
G21 G90 G17
S8000 M3
G0 X10 Y10 Z1
G1 Z-0.5 F600
G1 X40 F3000
G3 X60 Y30 R20
G2 X66 Y36 R6 F6000
G1 Y45 Z-1.0 F2000
G1 X20 F3000
G0 Z5
M5
M30
NGC

start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start_cell
rc=0
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/part.ngc" --timeout 40 >"$WORK/ctl.out" 2>&1 || rc=$?
# A drive fault (exit 5: on a loaded machine the bridge can fall behind) still leaves
# a log worth a report; anything else does not.
case "$rc" in
  0) ;;
  5) note "the run ended in a drive fault: $(grep -m1 'fault' "$WORK/ctl.out")" ;;
  *) cat "$WORK/ctl.out" >&2; fail "the program did not run (cnc-ctl exit $rc)" ;;
esac
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done

R="$WORK/report"
CNC_BUILD_DIR="$BUILD" "$SRC/cnc" report "$WORK/run.lcmlog" --out "$R" >"$WORK/report.out" 2>&1 \
  || { cat "$WORK/report.out" >&2; fail "./cnc report failed"; }
for f in index.html summary.json setpoints.csv monitor.csv axis_status.csv alarms.csv \
         feed.png chord_error.png rmax.png following_error.png path.png; do
  [ -s "$R/$f" ] || fail "the report has no $f"
done

# render ROOT NAME: headless Chromium, a screenshot and the DOM, its log on stderr.
render() {
  local dir="$1" name="$2" profile
  profile="$(mktemp -d "$WORK/chromium-profile.XXXXXX")"
  local flags=(--headless --no-sandbox --disable-gpu --disable-quic --no-first-run --disable-background-networking
               --disable-component-update --disable-sync --user-data-dir="$profile" --enable-logging=stderr --v=1
               --window-size=1200,3000 --hide-scrollbars --virtual-time-budget=5000)
  timeout 60 chromium "${flags[@]}" --screenshot="$WORK/$name.png" "file://$dir/index.html" \
    >"$WORK/$name.shot.log" 2>&1 || { tail -20 "$WORK/$name.shot.log" >&2; fail "chromium could not render $dir"; }
  timeout 60 chromium "${flags[@]}" --dump-dom "file://$dir/index.html" >"$WORK/$name.dom" 2>"$WORK/$name.dom.log" \
    || { tail -20 "$WORK/$name.dom.log" >&2; fail "chromium could not load $dir"; }
  if grep -E "Failed to load resource|Uncaught|ERR_FILE_NOT_FOUND" "$WORK/$name.shot.log" "$WORK/$name.dom.log" >&2; then
    fail "$name: the page has load errors"
  fi
  # Every image the page references exists and is a PNG.
  "$PY" - "$WORK/$name.dom" "$dir" <<'PY' || fail "$name: the page references missing images"
import re, sys, os
dom, root = open(sys.argv[1]).read(), sys.argv[2]
imgs = re.findall(r'<img[^>]* src="([^"]+)"', dom)
assert len(imgs) == 5, imgs
for src in imgs:
    p = os.path.join(root, src)
    assert os.path.exists(p) and open(p, "rb").read(8) == b"\x89PNG\r\n\x1a\n", src
PY
  # The screenshot: present, the page's size, not blank.
  "$PY" - "$WORK/$name.png" <<'PY' || fail "$name: the screenshot is blank or missing"
import sys
import matplotlib.image as mpimg
img = mpimg.imread(sys.argv[1])[..., :3]
h, w = img.shape[:2]
ink = (img.mean(axis=2) < 0.9).mean()
colours = len({tuple(p) for p in (img[::7, ::7].reshape(-1, 3) * 255).astype(int).tolist()})
print(f"# screenshot {w}x{h}, {ink * 100:.1f} % ink, {colours} colours", file=sys.stderr)
assert (w, h) == (1200, 3000) and ink > 0.03 and colours > 50
PY
}

render "$R" report
# The run's panels have data: feed, following error and path from any run; chord
# error and R_max from the monitor (it computes both for this program).
for png in feed following_error path chord_error rmax; do
  grep -q "data-empty=\"false\"><img src=\"$png.png\"" "$WORK/report.dom" || fail "the $png panel says no data"
done
note "$(grep -E '^  "(program_time_s|setpoints|running_setpoints|max_chord_error_mm|max_predicted_rmax_um|largest_following_error_mm)"' "$R/summary.json" | tr -d '\n')"

# The same tables with the chord error and R_max all NaN (a monitor that computes
# neither): the report still builds, and exactly those panels say "no data".
N="$WORK/nan"
mkdir -p "$N"
cp "$R"/*.csv "$R/summary.json" "$N/"
"$PY" - "$N" <<'PY'
import csv, json, sys, os
d = sys.argv[1]
rows = list(csv.DictReader(open(os.path.join(d, "monitor.csv"))))
with open(os.path.join(d, "monitor.csv"), "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
    w.writeheader()
    for r in rows:
        r.update(chord_error_mm="nan", predicted_rmax_um="nan", target_rmax_um="nan")
        w.writerow(r)
s = json.load(open(os.path.join(d, "summary.json")))
s.update(max_chord_error_mm=None, max_predicted_rmax_um=None, target_rmax_um=None, target_rmax_source=None)
json.dump(s, open(os.path.join(d, "summary.json"), "w"))
PY
"$PY" "$SRC/tools/report/make_report.py" "$N" --target-rmax-um 10 >"$WORK/nan.out" 2>&1 \
  || { cat "$WORK/nan.out" >&2; fail "make_report.py failed on NaN columns"; }
render "$N" nan
for png in chord_error rmax; do
  grep -q "data-empty=\"true\"><img src=\"$png.png\"" "$WORK/nan.dom" || fail "the NaN $png panel does not say no data"
done
for png in feed following_error path; do
  grep -q "data-empty=\"false\"><img src=\"$png.png\"" "$WORK/nan.dom" || fail "the $png panel lost its data"
done
# REPORT_EXAMPLE_OUT=FILE keeps the screenshot (docs/img/report_example.png comes from here).
if [ -n "${REPORT_EXAMPLE_OUT:-}" ]; then cp "$WORK/report.png" "$REPORT_EXAMPLE_OUT"; fi
echo "PASS"
