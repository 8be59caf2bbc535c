#!/usr/bin/env bash
# Loss and jitter between two hosts (item 2's figure): two network
# namespaces joined only by cnc-netem, both ways, LOSS_PCT % (default 5) random loss
# and 2 ± 1 ms delay (reordering allowed). Host a: program server and interpolator;
# host b: servo simulator, drive bridge, logger, monitor, and the operator's cnc-ctl.
# So setpoints, the interpolator's inputs (to the logger), the logger's
# confirmations, commands and state reports all cross the lossy link. A program of
# lines, arcs, a helix and a NURBS runs to its end, and:
#  * cnc-ctl reports it done (exit 0);
#  * the bridge's watchdog never trips during the run; lost setpoints come back from
#    the next one's history (counted);
#  * the axes end on the program's end point within 1 µm (as without loss);
#  * the log recorded on host b replays bit for bit.
#   loss_jitter_test.sh BUILD_DIR SOURCE_DIR [LOSS_PCT]
# By hand, another program and its end point: LOSS_PROGRAM=FILE LOSS_END="X Y Z".
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"; LOSS="${3:-${LOSS_PCT:-5}}"
[ -n "${CNC_IN_NETNS:-}" ] || { echo "SKIP: needs network namespaces (unshare -n)"; exit 0; }
WORK="$(mktemp -d /tmp/cnc-loss-jitter.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
# A lossy network with jitter: the bridge plays LEAD_CYCLES (default 4) behind the
# newest setpoint, so a run of three lost comes back before the playback needs it.
sed -i "s/^drive_bridge:/drive_bridge:\n  lead_cycles: ${LEAD_CYCLES:-4}/" "$M"
grep -q "^  lead_cycles: " "$M" || fail "no drive_bridge section in $M"
# Lines, arcs (one a helix) and a cubic NURBS. End point: X 61.2345 Y 32.1 Z -1.5
cp "$SRC/tests/integration/loss_program.ngc" "$WORK/loss.ngc"

netns_host a lo
netns_host b lo
start netem "$BUILD/tools/cnc-netem" --group "239.255.76.67:$TEST_LCM_PORT" --from "/proc/${NETNS_PID[a]}/ns/net" \
  --to "/proc/${NETNS_PID[b]}/ns/net" --both --ttl 0 --loss "$LOSS" --delay 2 --jitter 1 --seed 11
for ((i = 0; i < 500; i++)); do grep -q "queue" "$WORK/netem.log" 2>/dev/null && break; sleep 0.01; done
grep -q "queue" "$WORK/netem.log" || { cat "$WORK/netem.log" >&2; fail "cnc-netem did not start"; }
start up-a ${HOST[a]} env CNC_BUILD_DIR="$BUILD" "$SRC/cnc" up --machine "$M" --only program-server,interpolator
start up-b ${HOST[b]} env CNC_BUILD_DIR="$BUILD" "$SRC/cnc" up --machine "$M" \
  --only logger,servo-sim,drive-bridge,monitor --log-out "$WORK/b" --sim-final-state "$WORK/final.json"

rc=0
PROGRAM="${LOSS_PROGRAM:-$WORK/loss.ngc}"
read -r END_X END_Y END_Z <<<"${LOSS_END:-61.2345 32.1 -1.5}"
${HOST[b]} "$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$PROGRAM" --timeout 90 >"$WORK/ctl.out" 2>&1 || rc=$?
grep -v "^ALARM.*seq_gap" "$WORK/ctl.out" >&2
[ "$rc" -eq 0 ] || { tail -n 20 "$WORK"/up-*.log "$WORK/netem.log" >&2; fail "the program did not complete at $LOSS % loss, 2 +- 1 ms (cnc-ctl exit $rc)"; }
sleep 2.5  # the logger's next reports confirm the last inputs
grep -q "no setpoint for" "$WORK/up-b.log" && fail "the bridge's watchdog tripped during the run"
stop up-a TERM
stop up-b TERM
stop netem TERM
grep "received" "$WORK/netem.log" | sed 's/^/# netem: /' >&2
bridge_summary=$(grep -h "recovered from the next one's history" "$WORK/up-b.log" | tail -1)
note "bridge: ${bridge_summary#*] }"
recovered=$(sed -nE "s/.*history ([0-9]+),.*/\1/p" <<<"$bridge_summary")
lost=$(grep "ns/net -> .*received" "$WORK/netem.log" | head -n 1 | sed -nE 's/.*lost ([0-9]+).*/\1/p')
[ "${lost:-0}" -gt 0 ] || fail "the forwarder lost nothing"
[ "${recovered:-0}" -gt 0 ] || fail "no lost setpoint was recovered from a history"
[ -s "$WORK/final.json" ] || fail "the simulator wrote no final positions"
final_at "$WORK/final.json" "$END_X" "$END_Y" "$END_Z" || fail "final positions differ from the end point by more than 1 µm"
rc=0
"$BUILD/tools/cnc-replay" --log "$WORK/b.lcmlog" --key "$TEST_KEY" >"$WORK/replay.out" 2>&1 || rc=$?
cat "$WORK/replay.out" >&2
[ "$rc" -eq 0 ] || fail "the log of the run at $LOSS % loss does not replay (cnc-replay exit $rc)"
grep -q "^identical: " "$WORK/replay.out" || fail "no verdict from cnc-replay"
echo "PASS"
