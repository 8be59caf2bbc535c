#!/usr/bin/env bash
# What a stalled process does to the cell: runs a program (default lines.ngc) on the
# cell in a private network namespace while cnc-stall-inject stops one service for
# STOP_MS every 400 ms, 20 times, and prints the largest following error, the stalls'
# real durations and the drive bridge's account (ticks held for a stalled link, ...).
#   tools/bench/stall_bench.sh BUILD_DIR SOURCE_DIR SERVICE STOP_MS [PROGRAM]
#   SERVICE: servo-sim | drive-bridge | interpolator | program-server | monitor | logger
source "$(dirname "$0")/../../tests/integration/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"; VICTIM="$3"; MS="$4"; PROGRAM="${5:-$SRC/config/programs/lines.ngc}"
WORK="$(mktemp -d /tmp/cnc-stall-bench.XXXXXX)"
trap 'cleanup; rm -rf "$WORK"' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
sleep 0.2
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" ${SIM_ARGS:-}  # SIM_ARGS="--master-stall-pause-s 0": stalls as real drives would see them
start drive-bridge "$BUILD/services/cnc-drive-bridge" --machine "$M"
start monitor "$BUILD/services/cnc-monitor" --machine "$M"
start program-server "$BUILD/services/cnc-program-server" --machine "$M"
start interpolator "$BUILD/services/cnc-interpolator" --machine "$M"
[ -n "${TEST_PIDS[$VICTIM]:-}" ] || fail "no service named $VICTIM"
( sleep 1.5; "$BUILD/tools/bench/cnc-stall-inject" "${TEST_PIDS[$VICTIM]}" "$MS" 400 20 >"$WORK/stalls.out" ) &
rc=0
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$PROGRAM" --timeout 120 >"$WORK/ctl.out" 2>&1 || rc=$?
wait $! 2>/dev/null || true
grep -E "program done|cnc-ctl:" "$WORK/ctl.out" | sed 's/^/# /'
echo "# $VICTIM stopped for $MS ms: $(cat "$WORK/stalls.out" 2>/dev/null)"
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
grep -h "ticks held for a stalled link" "$WORK/drive-bridge.log" | sed 's/^.*\] /# bridge: /'
grep -hE "stalled .* time|ran dry" "$WORK/servo-sim.log" | sed "s/^.*\] /# simulator: /" || true
echo "cnc-ctl exit $rc"
