#!/usr/bin/env bash
# Run from line N on the live cell: a program with work offsets (G10 L2,
# G55, G92), a tool change with its length (T2 M6, G43), spindle, coolant and an
# O-word subroutine runs whole; then loaded from line 8 the cell names the approach
# (safe height, across, tool change, spindle, coolant, down), refuses START until it is
# confirmed, runs it after --do confirm (the tool change holds until RESUME) and ends
# where the whole run ended; CONFIRM with nothing to confirm and a line the program
# never reaches are refused; the session replays bit for bit. (The modal state at N
# against a full run's, field by field, and the setpoints from N bit for bit:
# tests/unit/run_from_line_test.cc.)
#   run_from_line_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-run-from-line-test.XXXXXX)"
trap 'cleanup' EXIT
make_machine "$SRC/config/machines/sim3.yaml" "$WORK/machine.yaml"
M="$WORK/machine.yaml"
mkdir -p "$WORK/subs"
printf 'T2 P2 Z1.5 D6\n' >"$WORK/tools.tbl"
printf '\nprogram:\n  subroutine_path: %s\n  tool_table: %s\n' "$WORK/subs" "$WORK/tools.tbl" >>"$M"  # absolute: replay reads the config from the log
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")

cat >"$WORK/subs/corner.ngc" <<'NGC'
o<corner> sub
G1 X#1 Y0 F300
G1 X#1 Y#1
G1 X0 Y#1
o<corner> endsub
M2
NGC
cat >"$WORK/p.ngc" <<'NGC'
G21 G90 G17 G94
G10 L2 P2 X10 Y5 Z0
G54 G0 X0 Y0 Z3
T2 M6
G43 H2
S8000 M3
M8
G1 Z-1 F600
G1 X30 Y10
G55
G92 X0 Y0
o<corner> call [5]
G0 Z2
G54 G92.1
G1 X40 Y20 F900
M9
M5
G1 X50 Z-2
G2 X60 Y20 I5 J0
M2
NGC

start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start_cell --no-monitor

# The machine position from the status (X Y Z).
position() { sed -n 's/^position: //p' "$WORK/status.out"; }

# 1. The whole program (pauses: the tool change holds until RESUME).
"${CTL[@]}" --do run --program "$WORK/p.ngc" --timeout 60 >"$WORK/full.out" 2>&1 &
TEST_PIDS[full]=$!
wait_state held
ok resume_full "${CTL[@]}" --do resume
rc=0; wait "${TEST_PIDS[full]}" || rc=$?; unset "TEST_PIDS[full]"
[ "$rc" -eq 0 ] || { cat "$WORK/full.out" >&2; fail "the whole program did not run"; }
wait_state done
full_end="$(position)"
note "whole program: $(tail -1 "$WORK/full.out"); ends at $full_end"

# 2. Refusals: nothing to confirm; a line the program never reaches.
expect_refused confirm_none "no approach waits for confirmation" "${CTL[@]}" --do confirm
expect_refused from_99 "run from line 99: the program never gets there" "${CTL[@]}" --do load --program "$WORK/p.ngc" --from 99

# 3. From line 8: the approach is named; START is refused until it is confirmed.
ok load8 "${CTL[@]}" --do load --program "$WORK/p.ngc" --from 8
grep -q "^approach from line 8: rapid up (safe height) to X 60.0000 Y 20.0000 Z 5.0000; rapid across to X 0.0000 Y 0.0000 Z 5.0000; tool change T2.*spindle cw 8000 rpm; coolant flood; rapid down to the start of the line to X 0.0000 Y 0.0000 Z 3.0000" "$WORK/load8.out" \
  || { cat "$WORK/load8.out" >&2; fail "the approach of line 8 is not as expected"; }
note "$(grep '^approach' "$WORK/load8.out")"
expect_refused start_unconfirmed "CONFIRM the approach first" "${CTL[@]}" --do start

# 4. run --from 8 waits for the confirmation (another client's), then runs: the tool
#    change of the approach holds until RESUME, and the program ends where the whole one did.
"${CTL[@]}" --do run --program "$WORK/p.ngc" --from 8 --timeout 60 >"$WORK/from8.out" 2>&1 &
TEST_PIDS[from8]=$!
for ((i = 0; i < 200; i++)); do grep -q "waiting for the approach to be confirmed" "$WORK/from8.out" 2>/dev/null && break; sleep 0.05; done
grep -q "waiting for the approach to be confirmed" "$WORK/from8.out" || { cat "$WORK/from8.out" >&2; fail "run --from 8 does not wait for the confirmation"; }
"${CTL[@]}" --do status --timeout 0.2 >"$WORK/status.out" 2>&1 || true
grep -qE "^interpolator: (idle|done)," "$WORK/status.out" || fail "something moves before the confirmation"
ok confirm8 "${CTL[@]}" --do confirm
wait_state held
note "held at the approach's tool change: $(grep '^interpolator' "$WORK/status.out"), $(position)"
grep -q "^position: X 0.0000 Y 0.0000 Z 5.0000" "$WORK/status.out" || fail "the tool change is not held at the safe height"
ok resume8 "${CTL[@]}" --do resume
rc=0; wait "${TEST_PIDS[from8]}" || rc=$?; unset "TEST_PIDS[from8]"
[ "$rc" -eq 0 ] || { cat "$WORK/from8.out" >&2; fail "the run from line 8 did not end"; }
wait_state done
[ "$(position)" = "$full_end" ] || fail "the run from line 8 ends at $(position), the whole one at $full_end"
note "from line 8: $(tail -1 "$WORK/from8.out"); ends at $(position)"

stop interpolator TERM
stop program-server TERM
stop drive-bridge TERM
stop servo-sim TERM
stop logger TERM

# 5. Replay: the whole session (both runs, the approach) reproduces bit for bit.
"$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" >"$WORK/replay.out" 2>&1 || { cat "$WORK/replay.out" >&2; fail "replay is not identical"; }
grep "^identical: " "$WORK/replay.out" >&2 || fail "no verdict from cnc-replay"
echo "PASS"
