#!/usr/bin/env bash
# Single block, optional stop (M1) and block delete ('/') on the live cell:
# with single block on, START and each RESUME run one program line and the path holds
# at rest before the next (cnc-ctl names the line); an M1 holds with optional stop on
# and not with it off; a '/' line is skipped with block delete on and runs with it off
# (read at the load; switching it while loaded reloads the program); single block
# switched on while a program runs at speed holds at a line start, and off again lets
# it run to its end; block delete is refused while a program runs or is held; the
# session replays bit for bit, also with --program (the '/' lines read as each load read them).
#   switches_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-switches-test.XXXXXX)"
trap 'cleanup' EXIT
make_machine "$SRC/config/machines/sim3.yaml" "$WORK/machine.yaml"
M="$WORK/machine.yaml"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")

start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start_cell --no-monitor

# step NAME CMD EXPECT: start or resume under single block; its report names EXPECT.
step() {
  ok "$1" "${CTL[@]}" --do "$2" --timeout 20
  grep -q -- "$3" "$WORK/$1.out" || { cat "$WORK/$1.out" >&2; fail "$1: expected '$3'"; }
}

cat >"$WORK/sw.ngc" <<'NGC'
G21 G90 G54 G0 X0 Y1 Z0
G1 X10 F1500
/G1 X15
G1 X20
M1
G1 X30
G1 X40
M2
NGC

# 1. Bad switch values are cnc-ctl's (exit 2); the cell takes on and off.
rc=0; "${CTL[@]}" --do single-block --value maybe >"$WORK/bad.out" 2>&1 || rc=$?
[ "$rc" -eq 2 ] && grep -q "needs --value on or off" "$WORK/bad.out" || fail "single-block --value maybe: exit $rc, expected 2"
ok sb_on "${CTL[@]}" --do single-block --value on
ok os_on "${CTL[@]}" --do optional-stop --value on
ok bd_on "${CTL[@]}" --do block-delete --value on

# 2. Single block, block delete on: the '/' line 3 is skipped; START runs line 1..2
#    (line 1 is the first motion line: G0), each RESUME one more; the M1 holds by itself.
ok load1 "${CTL[@]}" --do load --program "$WORK/sw.ngc"
step start1 start "held before line 2"
step r1 resume "held before line 4"
step r2 resume "held before line 5"
step r3 resume "held before line 6"
step r4 resume "held before line 7"
step r5 resume "done at line"
note "single block, block delete on: held before lines 2 4 5 6 7, then done"

# 3. Block delete off while loaded: the program is read again and line 3 runs.
ok load2 "${CTL[@]}" --do load --program "$WORK/sw.ngc"
ok bd_off "${CTL[@]}" --do block-delete --value off
step start2 start "held before line 2"
step r6 resume "held before line 3"
step r7 resume "held before line 4"
expect_refused bd_held "is held: block delete is read when a program is loaded" "${CTL[@]}" --do block-delete --value on
ok stop2 "${CTL[@]}" --do stop

# 4. Single block off, optional stop off: the program runs through (M1 does not hold).
ok sb_off "${CTL[@]}" --do single-block --value off
ok os_off "${CTL[@]}" --do optional-stop --value off
ok run_through "${CTL[@]}" --do run --program "$WORK/sw.ngc" --timeout 30
grep -q "program done" "$WORK/run_through.out" || fail "the program did not run through"

# 5. Optional stop on: the M1 holds the running program; RESUME lets it end.
ok os_on2 "${CTL[@]}" --do optional-stop --value on
"${CTL[@]}" --do run --program "$WORK/sw.ngc" --timeout 30 >"$WORK/run_m1.out" 2>&1 &
TEST_PIDS[run_m1]=$!
wait_state held
grep -q "line 5," "$WORK/status.out" || { cat "$WORK/status.out" >&2; fail "not held at the M1 of line 5"; }
note "M1 holds: $(grep '^interpolator' "$WORK/status.out")"
expect_refused bd_m1 "is held: block delete" "${CTL[@]}" --do block-delete --value on
ok resume_m1 "${CTL[@]}" --do resume
rc=0; wait "${TEST_PIDS[run_m1]}" || rc=$?; unset "TEST_PIDS[run_m1]"
[ "$rc" -eq 0 ] || { cat "$WORK/run_m1.out" >&2; fail "the program held at M1 did not end after RESUME"; }

# 6. Single block switched on while a program runs at speed: it holds at a line start
#    (X a multiple of 4 mm, the lines' length), exactly; off and RESUME: it runs to its end.
{
  echo "G21 G90 G54 G0 X0 Y0 Z0"
  for i in $(seq 1 30); do echo "G1 X$((4 * i)) F2400"; done
  echo "M2"
} >"$WORK/long.ngc"
"${CTL[@]}" --do run --program "$WORK/long.ngc" --timeout 60 >"$WORK/run_long.out" 2>&1 &
TEST_PIDS[run_long]=$!
wait_state running
# On the G1 lines (line 4 on: past X 8, after the rapid back to X 0).
for ((i = 0; i < 200; i++)); do
  "${CTL[@]}" --do status --timeout 0.1 >"$WORK/status.out" 2>&1 || true
  x=$(sed -n 's/^position: X \(-\?[0-9.]*\) .*/\1/p' "$WORK/status.out")
  l=$(sed -n 's/^interpolator: running, .*, line \([0-9]*\),.*/\1/p' "$WORK/status.out")
  [ -n "$x" ] && [ -n "$l" ] && [ "$l" -ge 4 ] && [ "$l" -le 20 ] && break
done
note "switching single block on at X $x (line $l)"
expect_refused bd_running "is running: block delete is read when a program is loaded" "${CTL[@]}" --do block-delete --value off
ok sb_on_running "${CTL[@]}" --do single-block --value on
wait_state held
/usr/bin/python3 - "$WORK/status.out" <<'PY' || fail "single block switched on in a run did not hold at a line start"
import re, sys
t = open(sys.argv[1]).read()
x = float(re.search(r"position: X (-?[0-9.]+)", t).group(1))
line = int(re.search(r"line (\d+),", t).group(1))
print(f"# single block switched on at speed: held at X {x:.4f} before line {line}", file=sys.stderr)
sys.exit(0 if 8 < x < 120 and abs(x / 4 - round(x / 4)) < 1e-9 and line == round(x / 4) + 2 else 1)
PY
ok sb_off2 "${CTL[@]}" --do single-block --value off
ok resume_long "${CTL[@]}" --do resume
rc=0; wait "${TEST_PIDS[run_long]}" || rc=$?; unset "TEST_PIDS[run_long]"
[ "$rc" -eq 0 ] || { cat "$WORK/run_long.out" >&2; fail "the program did not end after single block off"; }
note "long program: $(tail -1 "$WORK/run_long.out")"

stop interpolator TERM
stop program-server TERM
stop drive-bridge TERM
stop servo-sim TERM
stop logger TERM

# 7. Replay: the switches are recorded inputs; the session reproduces bit for bit.
"$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" >"$WORK/replay.out" 2>&1 || { cat "$WORK/replay.out" >&2; fail "replay is not identical"; }
grep "^identical: " "$WORK/replay.out" >&2 || fail "no verdict from cnc-replay"
# --program with the same file: read again with the switch each load had (the server's,
# on PROGRAM_STATE: on for the first, off from the second), the same blocks.
"$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" --program "$WORK/sw.ngc" >"$WORK/replay_p.out" 2>&1 \
  || { cat "$WORK/replay_p.out" >&2; fail "replay --program sw.ngc is not identical (block delete as loaded?)"; }
grep "^identical: " "$WORK/replay_p.out" >&2 || fail "no verdict from cnc-replay --program"
echo "PASS"
