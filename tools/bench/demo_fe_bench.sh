#!/usr/bin/env bash
# The demo's tracking, measured: runs config/programs/demo.ngc (or PROGRAM) on the
# whole cell in a private network namespace, optionally with LOAD busy loops, and
# prints the figures of the real-time core: the largest following error (axis, time,
# program line), watchdog trips, setpoint gaps, alarms by code, and the bridge's and
# the simulator's account of stalls. With KEEP=DIR the run's files stay in DIR.
#   tools/bench/demo_fe_bench.sh BUILD_DIR SOURCE_DIR [LOAD] [PROGRAM]
source "$(dirname "$0")/../../tests/integration/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"; LOAD="${3:-0}"; PROGRAM="${4:-$SRC/config/programs/demo.ngc}"
WORK="${KEEP:-$(mktemp -d /tmp/cnc-demo-fe.XXXXXX)}"
mkdir -p "$WORK"
LOAD_PIDS=()
stop_load() { for p in "${LOAD_PIDS[@]}"; do kill "$p" 2>/dev/null || true; wait "$p" 2>/dev/null || true; done; LOAD_PIDS=(); }
trap 'stop_load; cleanup; [ -n "${KEEP:-}" ] || rm -rf "$WORK"' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
export CNC_SIM_DEBUG_TRACE="${CNC_SIM_DEBUG_TRACE:-}" CNC_BRIDGE_DEBUG_TRACE="${CNC_BRIDGE_DEBUG_TRACE:-}"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
sleep 0.2
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" ${SIM_ARGS:-}
start drive-bridge "$BUILD/services/cnc-drive-bridge" --machine "$M"
start monitor "$BUILD/services/cnc-monitor" --machine "$M"
start program-server "$BUILD/services/cnc-program-server" --machine "$M"
start interpolator "$BUILD/services/cnc-interpolator" --machine "$M"
for ((i = 0; i < LOAD; i++)); do (while :; do :; done) & LOAD_PIDS+=($!); done
rc=0
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$PROGRAM" --timeout 120 >"$WORK/ctl.out" 2>&1 || rc=$?
stop_load
trips=$(grep -c "no setpoint for" "$WORK/drive-bridge.log" || true)
# The bridge first: stopped after the interpolator, its setpoint watchdog would trip.
for s in drive-bridge interpolator program-server monitor servo-sim logger; do stop "$s" TERM; done
echo "# cnc-ctl exit $rc, load $LOAD busy loop(s), work $WORK"
"$BUILD/tools/cnc-logstat" --log "$WORK/cell.lcmlog" --summary --machine "$M" 2>&1 | grep -E "largest foll|setpoints  " | sed 's/^ */# /'
echo "# watchdog trips during the program: $trips"
grep -h "ticks held for a stalled link" "$WORK/drive-bridge.log" | sed 's/^.*\] /# bridge: /'
grep -hE "stalled .* time|ran dry" "$WORK/servo-sim.log" | sed 's/^.*\] /# simulator: /'
grep -h "overruns" "$WORK"/*.log | grep -iE "servo cycle|T_ipo|dynamics" | sed "s/^.*\] /# timing: /" | cut -c1-200 || true
echo "# alarms by code (monitor + bridge, from the log):"
"$BUILD/tools/cnc-logexport" --log "$WORK/cell.lcmlog" --out "$WORK/export" >/dev/null 2>&1 || true
if [ -f "$WORK/export/alarms.csv" ]; then
  /usr/bin/python3 - "$WORK/export/alarms.csv" <<'PY'
import csv, sys, collections
rows = list(csv.DictReader(open(sys.argv[1])))
c = collections.Counter((r.get("source", "?"), r.get("code", "?")) for r in rows)
for (src, code), n in sorted(c.items()):
    print(f"#   {src} {code}: {n}")
PY
fi
[ "$rc" -eq 0 ]
