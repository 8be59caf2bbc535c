#!/usr/bin/env bash
# The whole cell from the real executables: servo simulator + the five services,
# LCM over UDP multicast, Modbus over TCP. Runs a program of straight lines and
# checks that it completes, that the simulated axes end on the program's end point
# within 1 µm, that the log holds the setpoint stream without a sequence gap, that
# a malformed program is refused with file:line:column and sends no block, and that
# every process exits 0 on SIGTERM (one on SIGINT).
#   cell_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-cell-test.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"

# Straight lines in all three axes, G0 and G1, incremental moves, a dwell. End point:
# X 123.4567 Y 45.6789 Z -7.0
cat >"$WORK/lines.ngc" <<'NGC'
( integration test: straight lines )
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
cat >"$WORK/bad.ngc" <<'NGC'
G21 G90
G1 X10 F1000
G1 X20 Q7
NGC

start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --final-state "$WORK/final.json" --trace "$WORK/trace.csv"
start_cell

# A malformed program: refused with its place, nothing of it sent.
rc=0
"$BUILD/tools/cnc-ctl" --machine "$M" --do load --program "$WORK/bad.ngc" 2>"$WORK/bad.err" || rc=$?
[ "$rc" -eq 3 ] || fail "bad program: cnc-ctl exit $rc, expected 3 (refused)"
grep -q "bad.ngc:3:8: Q word with no G code" "$WORK/bad.err" || { cat "$WORK/bad.err" >&2; fail "refusal does not name bad.ngc:3:8"; }
note "malformed program refused: $(cat "$WORK/bad.err")"

rc=0
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/lines.ngc" --timeout 60 >"$WORK/ctl.out" 2>&1 || rc=$?
cat "$WORK/ctl.out" >&2
[ "$rc" -eq 0 ] || fail "program did not complete (cnc-ctl exit $rc)"
grep -q "program done" "$WORK/ctl.out" || fail "no completion report"

settle_at "$WORK/trace.csv" 123.4567 45.6789 -7.0
stop interpolator TERM
stop program-server TERM
stop monitor INT
stop drive-bridge TERM
stop servo-sim TERM
stop logger TERM

# Final positions of the simulated drives against the program end point.
[ -s "$WORK/final.json" ] || fail "the simulator wrote no final positions"
note "final positions: $(cat "$WORK/final.json")"
final_at "$WORK/final.json" 123.4567 45.6789 -7.0 || fail "final positions differ from the end point by more than 1 µm"

# The log: lcm-logplayer's format, the setpoint stream complete.
"$BUILD/tools/cnc-logstat" --log "$WORK/run.lcmlog" --summary --require-no-gaps "${TEST_PREFIX}SETPOINTS" >"$WORK/logstat.out" \
  || { cat "$WORK/logstat.out" >&2; fail "setpoint stream in the log has gaps or is empty"; }
cat "$WORK/logstat.out" >&2
sp=$(awk -v c="${TEST_PREFIX}SETPOINTS" '/ events in /{exit} $1 == c {print $2}' "$WORK/logstat.out")
[ "${sp:-0}" -gt 500 ] || fail "only ${sp:-0} setpoints in the log"
# Only the good program's blocks were ever sent: 8 blocks (7 moves/dwell + END).
grep -qE "blocks +8 of 8 done \(sent 8," "$WORK/logstat.out" || fail "blocks sent differ from the good program's 8"
blocks=$(awk -v c="${TEST_PREFIX}PROGRAM_BLOCKS" '/ events in /{exit} $1 == c {print $2}' "$WORK/logstat.out")
[ "${blocks:-0}" -ge 8 ] || fail "log holds ${blocks:-0} program blocks, expected at least 8"

# lcm-logplayer (Debian's liblcm-bin) plays the log back onto the bus; a fresh
# logger records it again: the same setpoint stream, still without a gap. The
# playback is a replay of signed messages: the fresh logger is an unsigned analysis
# cell's; a logger of the signing cell beside it records none of the setpoints.
unsigned_machine "$M" "$WORK/unsigned.yaml"
start logger2 "$BUILD/services/cnc-logger" --machine "$WORK/unsigned.yaml" --out "$WORK/replayed"
start logger3 "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/replayed-signed"
sleep 0.3
timeout 60 lcm-logplayer --speed 4 --lcm-url "udpm://239.255.76.67:${TEST_LCM_PORT}?ttl=0" "$WORK/run.lcmlog" \
  || fail "lcm-logplayer could not play the log"
sleep 0.3
stop logger2 TERM
stop logger3 TERM
"$BUILD/tools/cnc-logstat" --log "$WORK/replayed-signed.lcmlog" >"$WORK/replayed-signed.out" 2>&1 || true
sp3=$(awk -v c="${TEST_PREFIX}SETPOINTS" '/ events in /{exit} $1 == c {print $2}' "$WORK/replayed-signed.out")
[ "${sp3:-0}" -eq 0 ] || { cat "$WORK/replayed-signed.out" >&2; fail "the signing cell's logger recorded ${sp3} played-back setpoints"; }
"$BUILD/tools/cnc-logstat" --log "$WORK/replayed.lcmlog" --require-no-gaps "${TEST_PREFIX}SETPOINTS" >"$WORK/replayed.out" \
  || { cat "$WORK/replayed.out" >&2; fail "the played-back setpoint stream has gaps"; }
sp2=$(awk -v c="${TEST_PREFIX}SETPOINTS" '/ events in /{exit} $1 == c {print $2}' "$WORK/replayed.out")
[ "${sp2:-0}" -eq "$sp" ] || fail "lcm-logplayer delivered ${sp2:-0} of $sp setpoints"
note "lcm-logplayer played back all $sp setpoints"
echo "PASS"
