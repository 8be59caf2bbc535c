#!/usr/bin/env bash
# Loss that loses nothing (architecture: loss contract). The whole cell in a private
# network namespace, with LOSS_PCT % (default 5) of the cell's UDP datagrams dropped
# at random on the input hook (nftables numgen: every receiver of a multicast
# datagram loses it together, as on a lossy segment). A program of lines, arcs and a
# NURBS runs to its end, and:
#  * cnc-ctl reports it done (exit 0): lost commands and state reports are sent again;
#  * the drive bridge's watchdog never trips; setpoints lost in a row (up to three) are
#    recovered exactly from the history the next setpoint carries (counted);
#  * the simulated axes end on the program's end point within 1 µm;
#  * the log replays bit for bit: inputs the logger did not confirm were sent again
#    (cnc-replay takes each input index once).
#   loss_test.sh BUILD_DIR SOURCE_DIR [LOSS_PCT]
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"; LOSS="${3:-${LOSS_PCT:-5}}"
[ -n "${CNC_IN_NETNS:-}" ] || fail "needs a private network namespace (unshare -n) for the loss rule"
command -v nft >/dev/null || fail "nft (Debian package nftables) is missing: ./cnc test installs it"
WORK="$(mktemp -d /tmp/cnc-loss-test.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"

# Lines, arcs (one a helix) and a cubic NURBS. End point: X 61.2345 Y 32.1 Z -1.5
cp "$SRC/tests/integration/loss_program.ngc" "$WORK/loss.ngc"

start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
sleep 0.2
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --final-state "$WORK/final.json" --trace "$WORK/trace.csv"
start_cell

# Loss on the cell's LCM port only (Modbus TCP stays clean: TCP's own retransmission
# timeout, 200 ms at least, is a different problem).
nft add table inet loss
nft add chain inet loss in '{ type filter hook input priority 0; }'
nft add rule inet loss in udp dport "$TEST_LCM_PORT" numgen random mod 100 "<" "$LOSS" counter drop
note "dropping $LOSS % of the datagrams to udp port $TEST_LCM_PORT"

rc=0
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/loss.ngc" --timeout 90 >"$WORK/ctl.out" 2>&1 || rc=$?
cat "$WORK/ctl.out" >&2
[ "$rc" -eq 0 ] || fail "the program did not complete at $LOSS % loss (cnc-ctl exit $rc)"
# The logger's next report confirms the last inputs (it reports every second).
sleep 2.5
dropped=$(nft list chain inet loss in | sed -nE 's/.*counter packets ([0-9]+).*/\1/p')
nft delete table inet loss

# Before the cell stops (the interpolator stops first, and the bridge then rightly
# stops on its watchdog): no watchdog trip during the run.
grep -q "no setpoint for" "$WORK/drive-bridge.log" && fail "the bridge's watchdog tripped during the run"
settle_at "$WORK/trace.csv" 61.2345 32.1 -1.5
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done

bridge_summary=$(grep -h "recovered from the next one's history" "$WORK/drive-bridge.log" | tail -1)
note "datagrams dropped: $dropped; bridge: ${bridge_summary#*] }"
recovered=$(sed -nE "s/.*history ([0-9]+),.*/\1/p" <<<"$bridge_summary")
[ "${dropped:-0}" -gt 0 ] || fail "the loss rule dropped nothing"
[ "${recovered:-0}" -gt 0 ] || fail "no lost setpoint was recovered from a history (dropped $dropped)"
grep -h "sent again that the logger did not confirm" "$WORK/interpolator.log" | tail -1 | sed 's/^/# interpolator: /' >&2 || true

[ -s "$WORK/final.json" ] || fail "the simulator wrote no final positions"
final_at "$WORK/final.json" 61.2345 32.1 -1.5 || fail "final positions differ from the end point by more than 1 µm"

rc=0
"$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" --key "$TEST_KEY" >"$WORK/replay.out" 2>&1 || rc=$?
cat "$WORK/replay.out" >&2
[ "$rc" -eq 0 ] || fail "the log of the run at $LOSS % loss does not replay (cnc-replay exit $rc)"
grep -q "^identical: " "$WORK/replay.out" || fail "no verdict from cnc-replay"
echo "PASS"
