#!/usr/bin/env bash
# The dry run ends: `./cnc plan --override 0` is refused at once with a clear error
# (the motion can never finish at override 0 without a resume), and a dry run that
# would run for hours ends on SIGTERM from `timeout`, through the ./cnc script,
# leaving no process behind.
#   plan_signal_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-plan-signal-test.XXXXXX)"
pid=""
trap '[ -z "$pid" ] || kill -KILL "$pid" 2>/dev/null || true; rm -rf "$WORK"' EXIT
export CNC_BUILD_DIR="$BUILD"
M="$SRC/config/machines/sim3.yaml"
P="$SRC/config/programs/demo.ngc"

# No cnc-plan of this test (they all write into $WORK) may be left running.
none_left() {
  sleep 0.3
  if pgrep -f "$WORK/" >/dev/null; then pgrep -af "$WORK/" >&2; fail "$1: a process is left behind"; fi
}

# 1. --override 0 alone: the clear error, exit 2, at once, nothing written.
rc=0; start_s=$SECONDS
timeout -s TERM 5 "$SRC/cnc" plan "$P" --machine "$M" --override 0 --csv "$WORK/zero.csv" 2>"$WORK/zero.err" || rc=$?
[ "$rc" -eq 2 ] || { cat "$WORK/zero.err" >&2; fail "--override 0: exit $rc, expected 2 (124 is the timeout)"; }
grep -q "override 0" "$WORK/zero.err" && grep -q "never finish" "$WORK/zero.err" \
  || { cat "$WORK/zero.err" >&2; fail "--override 0: no clear error"; }
[ ! -s "$WORK/zero.csv" ] || fail "--override 0 wrote setpoints"
none_left "--override 0"
note "override 0: $(cat "$WORK/zero.err")"

# 2. A dry run of days of program time (override 1e-4), through ./cnc, with and
#    without a plot (exec and forwarding), ends on SIGTERM within the timeout.
for plot in "" "$WORK/slow.png"; do
  rc=0; start_s=$SECONDS
  timeout -s TERM 5 "$SRC/cnc" plan "$P" --machine "$M" --override 0.0001 --csv "$WORK/slow.csv" ${plot:+--plot "$plot"} \
    2>"$WORK/slow.err" || rc=$?
  elapsed=$((SECONDS - start_s))
  [ "$rc" -eq 124 ] || { cat "$WORK/slow.err" >&2; fail "slow dry run${plot:+ with plot}: exit $rc, expected 124 (stopped by the timeout)"; }
  [ "$elapsed" -le 7 ] || fail "slow dry run${plot:+ with plot}: took $elapsed s after a 5 s timeout"
  grep -q "stopped by signal 15" "$WORK/slow.err" || { cat "$WORK/slow.err" >&2; fail "cnc-plan did not see the SIGTERM"; }
  none_left "slow dry run${plot:+ with plot}"
  note "slow dry run${plot:+ with plot}: ended in $elapsed s: $(cat "$WORK/slow.err")"
done

# 3. cnc-plan itself on SIGINT: ends with 128 + 2.
"$BUILD/tools/cnc-plan" --machine "$M" --program "$P" --override 0.0001 --csv "$WORK/int.csv" 2>"$WORK/int.err" &
pid=$!
sleep 1
kill -INT "$pid"
rc=0
for ((i = 0; i < 50; i++)); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
kill -0 "$pid" 2>/dev/null && { kill -KILL "$pid"; fail "cnc-plan did not end within 5 s of SIGINT"; }
wait "$pid" || rc=$?
[ "$rc" -eq 130 ] || { cat "$WORK/int.err" >&2; fail "cnc-plan on SIGINT: exit $rc, expected 130"; }
none_left "SIGINT"
echo PASS
