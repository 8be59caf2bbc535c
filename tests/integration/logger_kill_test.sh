#!/usr/bin/env bash
# The logger's file after SIGKILL, SIGTERM and SIGINT. cnc-interpolator alone
# publishes SETPOINTS every 4 ms (idle setpoints are setpoints too); three loggers
# record it at once. The killed one's file must read, through the bus's file back
# end (cnc-logstat) and with lcm-logplayer, up to its last whole event without an
# error, hold at least what the logger's last stats said it had written, and lose
# no more than about a flush period. The stopped ones must exit 0 with a clean file
# whose last event is the closing LOGGER_STATS.
#   logger_kill_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
HERE="$(cd "$(dirname "$0")" && pwd)"
WORK="$(mktemp -d /tmp/cnc-logger-kill-test.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
FLUSH_S=$(awk '/flush_period_s:/ {print $2}' "$M")
URL="udpm://239.255.76.67:${TEST_LCM_PORT}?ttl=0"

start interpolator "$BUILD/services/cnc-interpolator" --machine "$M"
for sig in KILL TERM INT; do
  start "logger-$sig" "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/$sig"
done
sleep 3

kill_utime=$(date +%s%6N)
kill -KILL "${TEST_PIDS[logger-KILL]}"
rc=0
wait "${TEST_PIDS[logger-KILL]}" || rc=$?
unset "TEST_PIDS[logger-KILL]"
[ "$rc" -eq 137 ] || fail "the SIGKILLed logger exited with $rc, expected 137"
stop logger-TERM TERM
stop logger-INT INT
stop interpolator TERM

for sig in KILL TERM INT; do
  log="$WORK/$sig.lcmlog"
  # The bus's file back end reads it to the end.
  "$BUILD/tools/cnc-logstat" --log "$log" --require-no-gaps "${TEST_PREFIX}SETPOINTS" >"$WORK/$sig.logstat" 2>&1 \
    || { cat "$WORK/$sig.logstat" >&2; fail "SIG$sig: cnc-logstat could not read the log, or it has setpoint gaps"; }
  events=$(awk '/ events in /{print $1}' "$WORK/$sig.logstat")
  # lcm-logplayer plays every event and ends without an error.
  timeout 30 lcm-logplayer -v -s 1000 -l "$URL" "$log" >"$WORK/$sig.play" 2>&1 \
    || { tail "$WORK/$sig.play" >&2; fail "SIG$sig: lcm-logplayer failed on the log"; }
  played=$(grep -c ' Channel ' "$WORK/$sig.play" || true)
  [ "$played" -eq "$events" ] || fail "SIG$sig: lcm-logplayer played $played of $events events"
  # Byte by byte: whole events, the logger's stats, and per signal what must hold.
  if [ "$sig" = KILL ]; then
    check=(--kill-utime "$kill_utime" --flush-period "$FLUSH_S")
  else
    check=(--closing)
  fi
  python3 "$HERE/logger_logcheck.py" "$log" --prefix "$TEST_PREFIX" "${check[@]}" >"$WORK/$sig.check" \
    || { cat "$WORK/$sig.check" >&2; fail "SIG$sig: the file fails its checks"; }
  note "SIG$sig: $events events, cnc-logstat and lcm-logplayer read them all; $(tr '\n' ';' <"$WORK/$sig.check")"
done
rm -rf "$WORK"
echo "PASS"
