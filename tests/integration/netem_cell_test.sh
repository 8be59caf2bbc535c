#!/usr/bin/env bash
# The cell through cnc-netem: two network namespaces, each with multicast on its
# loopback and nothing between them but the forwarder (both ways, no loss, 2 ± 1 ms,
# reordering allowed). Host a: logger, monitor, program server, interpolator
# (`./cnc up --only`); host b: simulator and drive bridge. A program of straight
# lines runs to its end, the axes end on its end point within 1 µm, the setpoints
# cross the forwarder (its counters: none lost) and the log on a holds the setpoint
# stream without a gap. The loss tests build
# on this set-up.
#   netem_cell_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
[ -n "${CNC_IN_NETNS:-}" ] || { echo "SKIP: needs network namespaces (unshare -n)"; exit 0; }
WORK="$(mktemp -d /tmp/cnc-netem-cell.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
# End point X 123.4567 Y 45.6789 Z -7.0 (cell_test.sh's program).
cat >"$WORK/lines.ngc" <<'NGC'
G21 G90
G0 X5 Y5 Z1
G1 Z-2 F600
G1 X80 Y20 F3000
G1 X80.5 Y45.6789 Z-4
G91 G1 X20 Z-3 F2400
G90 G4 P0.05
G1 X123.4567 F1800
M30
NGC

netns_host a lo
netns_host b lo
# The cell's LCM URL keeps ttl=0: each side's services reach each other on their
# loopback; the forwarder's sending socket (--ttl 0) reaches the other side's.
start netem "$BUILD/tools/cnc-netem" --group "239.255.76.67:$TEST_LCM_PORT" --from "/proc/${NETNS_PID[a]}/ns/net" \
  --to "/proc/${NETNS_PID[b]}/ns/net" --both --ttl 0 --delay 2 --jitter 1 --seed 5
for ((i = 0; i < 500; i++)); do grep -q "queue" "$WORK/netem.log" 2>/dev/null && break; sleep 0.01; done
grep -q "queue" "$WORK/netem.log" || { cat "$WORK/netem.log" >&2; fail "cnc-netem did not start"; }
start up-a ${HOST[a]} env CNC_BUILD_DIR="$BUILD" "$SRC/cnc" up --machine "$M" \
  --only logger,monitor,program-server,interpolator --log-out "$WORK/a"
start up-b ${HOST[b]} env CNC_BUILD_DIR="$BUILD" "$SRC/cnc" up --machine "$M" --only servo-sim,drive-bridge \
  --sim-final-state "$WORK/final.json" --sim-trace "$WORK/trace.csv"

rc=0
${HOST[a]} "$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/lines.ngc" --timeout 60 >"$WORK/ctl.out" 2>&1 || rc=$?
cat "$WORK/ctl.out" >&2
[ "$rc" -eq 0 ] || { tail -n 20 "$WORK"/up-*.log "$WORK/netem.log" >&2; fail "the program did not complete through cnc-netem (cnc-ctl exit $rc)"; }
settle_at "$WORK/trace.csv" 123.4567 45.6789 -7.0
stop up-b TERM
stop up-a TERM
stop netem TERM
grep "received" "$WORK/netem.log" >&2
final_at "$WORK/final.json" 123.4567 45.6789 -7.0 || fail "final positions differ from the end point by more than 1 µm"
# a -> b carried the setpoints (and the rest of a's traffic): none lost.
ab=$(grep "ns/net -> .*received" "$WORK/netem.log" | head -n 1)
[[ "$ab" =~ lost\ 0\ .*queue\ full\ 0.*send\ errors\ 0 ]] || fail "the forwarder lost datagrams: $ab"
[[ "$ab" =~ received\ ([0-9]+) ]] && [ "${BASH_REMATCH[1]}" -gt 1000 ] || fail "the forwarder carried too little: $ab"
"$BUILD/tools/cnc-logstat" --log "$WORK/a.lcmlog" --summary --require-no-gaps "${TEST_PREFIX}SETPOINTS" >"$WORK/logstat.out" 2>&1 \
  || { cat "$WORK/logstat.out" >&2; fail "the setpoint stream in the log has gaps"; }
sed -n '/^run summary/,/largest/p' "$WORK/logstat.out" >&2
echo "PASS"
