#!/usr/bin/env bash
# Operator functions in the cell on the live cell, with homing
# required: the refusals before homing (run, MDI), a jog before homing, homing one
# axis and all in order (Z first) on the simulator's home switches, the repeatability
# of the latched position, incremental jogs (to the soft limit and refused there),
# a continuous jog whose client is SIGKILLed (the stop distance against its bound),
# touch-off (G10 L20, in the var file; the tool's length, G10 L10, in the tool
# table, used by G43 in the next program), MDI through the program server, the
# refusals while something moves, and the log replayed bit for bit.
#   operator_test.sh BUILD_DIR SOURCE_DIR     (HOMINGS=20: the repeatability figure)
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
HOMINGS="${HOMINGS:-5}"
WORK="$(mktemp -d /tmp/cnc-operator-test.XXXXXX)"
trap 'cleanup' EXIT
make_machine "$SRC/config/machines/sim3.yaml" "$WORK/base.yaml"
M="$WORK/machine.yaml"
/usr/bin/python3 "$SRC/tests/integration/operator_machine.py" "$WORK/base.yaml" "$M" "$WORK/mdi"
# Parameters persist in the var file (LinuxCNC's), as a program's do.
# The tool table: G10 L10 (tool touch-off) writes it back.
printf 'T1 P1 Z0 D6 ;end mill\n' >"$WORK/tools.tbl"
printf '\nprogram:\n  var_file: %s\n  tool_table: %s\n' "$WORK/cnc.var" "$WORK/tools.tbl" >>"$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")

start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --final-state "$WORK/final.json"
start_cell --no-monitor

# axis_at NAME AXIS VALUE: the position cnc-ctl printed for AXIS within 1e-4 mm of VALUE.
axis_at() {
  /usr/bin/python3 - "$WORK/$1.out" "$2" "$3" <<'PY' || fail "$1: axis $2 not at $3"
import re, sys
text = open(sys.argv[1]).read()
m = re.findall(r"(?:jogged|homed):.* %s (-?[0-9.]+)" % sys.argv[2], text)
sys.exit(0 if m and abs(float(m[-1]) - float(sys.argv[3])) <= 1e-4 else 1)
PY
}

# axis_near NAME AXIS VALUE TOL
axis_near() {
  /usr/bin/python3 - "$WORK/$1.out" "$2" "$3" "$4" <<'PY' || fail "$1: axis $2 not within $4 of $3"
import re, sys
m = re.findall(r"(?:jogged|homed):.* %s (-?[0-9.]+)" % sys.argv[2], open(sys.argv[1]).read())
sys.exit(0 if m and abs(float(m[-1]) - float(sys.argv[3])) <= float(sys.argv[4]) else 1)
PY
}

cat >"$WORK/part.ngc" <<'NGC'
G21 G90 G54
G1 X10 Y5 F1200
G1 X12
M2
NGC
# 1. Before homing: program motion and MDI are refused; jogging is allowed.
expect_refused run_unhomed "axis X is not homed: HOME first" "${CTL[@]}" --do run --program "$WORK/part.ngc" --timeout 20
expect_refused mdi_unhomed "axis X is not homed: HOME first" "${CTL[@]}" --do mdi --line "G0 X1"
ok jog_unhomed "${CTL[@]}" --do jog --axis X --value 2 --timeout 20
axis_at jog_unhomed X 2

# 2. Homing one axis, then all in order (Z first: order 0).
ok home_x "${CTL[@]}" --do home --axis X --timeout 30
grep -q "X 0.0000 (homed)" "$WORK/home_x.out" || fail "X not homed at 0"
ok home_all "${CTL[@]}" --do home --timeout 60
grep -q "homed: X 0.0000 (homed) Y 0.0000 (homed) Z 0.0000 (homed)" "$WORK/home_all.out" || fail "not every axis homed at 0"
z_line=$(grep -n "axis Z homed" "$WORK/home_all.out" | head -1 | cut -d: -f1)
x_line=$(grep -n "axis X homed" "$WORK/home_all.out" | head -1 | cut -d: -f1)
[ -n "$z_line" ] && [ -n "$x_line" ] && [ "$z_line" -lt "$x_line" ] || fail "Z was not homed before X (order)"
# The repeatability of the switch: HOMINGS homings of X, the latched positions' spread.
for ((i = 0; i < HOMINGS; i++)); do
  ok "home_x_$i" "${CTL[@]}" --do home --axis X --timeout 30
  grep -o "switch latched at -\?[0-9.]* mm" "$WORK/home_x_$i.out" | head -1 >>"$WORK/latches.txt"
done
/usr/bin/python3 - "$WORK/latches.txt" <<'PY' || fail "homing repeatability out of bounds"
import re, statistics, sys
v = [float(re.search(r"at (-?[0-9.]+)", l).group(1)) for l in open(sys.argv[1])]
spread = (max(v) - min(v)) * 1000
sd = statistics.stdev(v) * 1000
print(f"# homing repeatability: {len(v)} homings of X, latched at mean {statistics.mean(v):.4f} mm (switch at -4), "
      f"sd {sd:.2f} um, spread {spread:.2f} um (switch sigma 2 um, latch at 1 mm/s)", file=sys.stderr)
# The switch's sigma is 2 um and the latch speed 1 mm/s (1 um a 1 ms step): a spread
# within 6 sigma + 2 steps, and not zero (the switch's noise reaches the latch).
sys.exit(0 if 0 < spread <= 14 and abs(statistics.mean(v) + 4) <= 0.01 else 1)
PY

# A STOP while homing aborts it (cnc-ctl home exits 5 naming why); homing again works.
"${CTL[@]}" --do home --axis Y --timeout 30 >"$WORK/home_abort.out" 2>&1 &
TEST_PIDS[home_abort]=$!
for ((i = 0; i < 300; i++)); do
  "${CTL[@]}" --do load --program "$WORK/part.ngc" >"$WORK/probe0.out" 2>&1 || true  # loads (no more) until homing runs
  grep -q "home Y: .* runs: STOP it first" "$WORK/probe0.out" && break
  sleep 0.02
done
grep -q "home Y: .* runs: STOP it first" "$WORK/probe0.out" || { cat "$WORK/probe0.out" >&2; fail "homing Y did not start"; }
note "while homing: $(tail -1 "$WORK/probe0.out")"
ok stop_homing "${CTL[@]}" --do stop
rc=0; wait "${TEST_PIDS[home_abort]}" || rc=$?; unset "TEST_PIDS[home_abort]"
[ "$rc" -eq 5 ] && grep -q "homing aborted: homing stopped by the operator" "$WORK/home_abort.out" \
  || { cat "$WORK/home_abort.out" >&2; fail "STOP while homing: cnc-ctl exit $rc, expected 5 (aborted)"; }
note "home aborted: $(grep 'homing aborted' "$WORK/home_abort.out" | tail -1)"
ok home_y_again "${CTL[@]}" --do home --axis Y --timeout 30
# Homing from past the switch, where it is closed (a homing stopped there, as the STOP
# above may leave it): Y at -4.5 mm, beyond its switch at -4; the search alone would
# see no closing edge and run into the travel's end. It backs off first.
ok jog_y_past_switch "${CTL[@]}" --do jog --axis Y --value -4.5 --timeout 20
axis_at jog_y_past_switch Y -4.5
ok home_y_from_switch "${CTL[@]}" --do home --axis Y --timeout 30
grep -q "Y 0.0000 (homed)" "$WORK/home_y_from_switch.out" || { cat "$WORK/home_y_from_switch.out" >&2; fail "Y not homed from past its switch"; }
grep -q "home Y: off the switch" "$WORK/interpolator.log" || fail "the homing from past the switch did not back off first"
note "homing from past the switch: $(grep -o 'home Y: off the switch.*' "$WORK/interpolator.log" | head -1)"

# 3. Jogging: incremental, clamped at the soft limit, refused there.
ok jog_x10 "${CTL[@]}" --do jog --axis X --value 10 --feed 3000 --timeout 20
axis_at jog_x10 X 10
ok jog_to_limit "${CTL[@]}" --do jog --axis X --value -1000 --feed 6000 --timeout 20
axis_near jog_to_limit X -5 0.01
expect_refused jog_past_limit "stands at its soft limit -" "${CTL[@]}" --do jog --axis X --value -1
ok jog_back "${CTL[@]}" --do mdi --line "G53 G0 X0" --timeout 20

# 4. A continuous jog whose client vanishes (SIGKILL): the interpolator stops it
#    jerk-limited after jog_keepalive_timeout_s; and the refusals while it moves.
"${CTL[@]}" --do jog --axis Y --value 1 --feed 600 --hold 100 --timeout 120 >"$WORK/jog_cont.out" 2>&1 &
TEST_PIDS[jog]=$!
for ((i = 0; i < 500; i++)); do
  "${CTL[@]}" --do load --program "$WORK/part.ngc" >"$WORK/probe.out" 2>&1 || true  # loads (no more) until the jog runs
  grep -q "jog Y+ continuous runs" "$WORK/probe.out" && break
  sleep 0.02
done
grep -q "jog Y+ continuous runs" "$WORK/probe.out" || { cat "$WORK/jog_cont.out" >&2; fail "the continuous jog did not start"; }
expect_refused run_jogging "jog Y+ continuous runs: STOP it first" "${CTL[@]}" --do run --program "$WORK/part.ngc" --timeout 20
expect_refused jog_jogging "jog Y+ continuous runs: STOP it first" "${CTL[@]}" --do jog --axis X --value 1
expect_refused home_jogging "jog Y+ continuous runs: STOP it first" "${CTL[@]}" --do home --axis X
expect_refused mdi_jogging "jog Y+ continuous runs: STOP it first" "${CTL[@]}" --do mdi --line "G0 X1"
expect_refused touch_jogging "jog Y+ continuous runs: STOP it first" "${CTL[@]}" --do touch-off --axis X --value 1
kill_hard jog
# Accepted only once the jog has stopped (the interlock refuses it before).
for ((i = 0; i < 500; i++)); do
  rc=0; "${CTL[@]}" --do jog --axis Z --value -1 --timeout 20 >"$WORK/after_vanish.out" 2>&1 || rc=$?
  [ "$rc" -eq 0 ] && break
  [ "$rc" -eq 3 ] || { cat "$WORK/after_vanish.out" >&2; fail "jog after the vanished client: exit $rc"; }
  sleep 0.02
done
[ "$rc" -eq 0 ] || fail "the jog of the vanished client never stopped"
grep "no keepalive from the jogging client" "$WORK/interpolator.log" >"$WORK/lost.txt" || fail "the jog was not stopped for its lost keepalive"
/usr/bin/python3 - "$WORK/lost.txt" "$WORK/after_vanish.out" <<'PY' || fail "the vanished client's jog ran past its bound"
import math, re, sys
lost = open(sys.argv[1]).read()
m = re.search(r"for ([0-9.]+) s: stopped \(at the last keepalive Y (-?[0-9.]+) mm at ([0-9.]+) mm/s\)", lost)
t_lost, y_k, v = float(m.group(1)), float(m.group(2)), float(m.group(3))
y_end = float(re.findall(r"jogged:.* Y (-?[0-9.]+)", open(sys.argv[2]).read())[-1])
d = y_end - y_k
# Bound: the keepalive timeout (0.2 s) at the jog speed, with 50 ms for the watching
# cycle (4 ms) and its scheduling on a loaded VM, then a jerk-limited brake at half of
# Y's limits (jerk 30000, accel 1500: v*sqrt(v/J) while sqrt(v*J) < A), never shorter
# than the jog's own (a line between two stops: 0.97 of them).
J, A = 30000.0, 1500.0
brake = v * math.sqrt(v / J) if math.sqrt(v * J) <= A else v * v / (2 * A) + v * A / (2 * J)
bound = v * (0.2 + 0.05) + brake
print(f"# continuous jog, client SIGKILLed at {v:.2f} mm/s: stopped {t_lost:.3f} s after its last keepalive, "
      f"{d:.3f} mm past it (bound {bound:.3f} mm = v*(0.2 s + 0.05 s) + brake {brake:.3f} mm)", file=sys.stderr)
sys.exit(0 if v > 9.9 and 0 < d <= bound else 1)
PY

# 5. Touch-off: X reads 100 here (G10 L20 P0, G54), kept in the var file.
ok touch_x "${CTL[@]}" --do touch-off --axis X --value 100 --timeout 20
grep -qE "^5221[[:space:]]+-100" "$WORK/cnc.var" || { grep -E "^52(2|4)" "$WORK/cnc.var" >&2; fail "G54 X offset (#5221) is not -100 in the var file"; }
note "var file: $(grep -E '^5221' "$WORK/cnc.var")"
expect_refused touch_tool "no tool in the spindle" "${CTL[@]}" --do touch-off --axis Z --value 50 --tool
rc=0; "${CTL[@]}" --do touch-off --axis Q --value 1 >"$WORK/touch_q.out" 2>&1 || rc=$?
[ "$rc" -eq 2 ] && grep -q "no such axis" "$WORK/touch_q.out" || fail "touch-off of axis Q: exit $rc, expected 2"

# 6. MDI: one line through the program server's interpreter, in G54 (X100 is machine 0 + 100 - 100).
ok mdi_g0 "${CTL[@]}" --do mdi --line "G0 X105 Y3" --timeout 20
grep -q "program done" "$WORK/mdi_g0.out" || fail "MDI did not run"
ok jog_probe "${CTL[@]}" --do jog --axis Z --value 1 --timeout 20
axis_at jog_probe X 5
axis_at jog_probe Y 3
# MDI lines share their modes (LinuxCNC's): G91 in one line stays for the next, and a
# line of only X5 moves in the G0 of the line before it (incremental: X 5 -> 10).
ok mdi_g91 "${CTL[@]}" --do mdi --line "G91" --timeout 20
# Rapid override (a recorded interpolator input): X5 in G0 at 5 % of the rapids' speed.
expect_refused rapid_bad "rapid override 1.500000 is outside 0 .. 1" "${CTL[@]}" --do rapid-override --value 1.5
ok rapid_5 "${CTL[@]}" --do rapid-override --value 0.05
ok rapid_status "${CTL[@]}" --do status --timeout 1
grep -q "rapid override 0.05," "$WORK/rapid_status.out" || { cat "$WORK/rapid_status.out" >&2; fail "INTERP_STATE does not report the rapid override 0.05"; }
ok mdi_x5 "${CTL[@]}" --do mdi --line "X5" --timeout 20
grep -q "program done" "$WORK/mdi_x5.out" || fail "MDI X5 did not run"
ok rapid_100 "${CTL[@]}" --do rapid-override --value 1
ok jog_probe_rel "${CTL[@]}" --do jog --axis Z --value -1 --timeout 20
axis_at jog_probe_rel X 10
ok mdi_g90 "${CTL[@]}" --do mdi --line "G90 X105" --timeout 20
ok jog_probe_abs "${CTL[@]}" --do jog --axis Z --value 1 --timeout 20
axis_at jog_probe_abs X 5
# The same 5 mm rapid: program time (interpolator cycles, not wall time) at 5 % at least
# 5 mm / (0.05 * 250 mm/s) = 0.4 s; at 100 % it took 0.2 s.
/usr/bin/python3 - "$WORK/mdi_x5.out" "$WORK/mdi_g90.out" <<'PY' || fail "the rapid override did not slow the rapid"
import re, sys
t = [float(re.search(r"program done: ([0-9.]+) s program time", open(f).read()).group(1)) for f in sys.argv[1:]]
print(f"# rapid override: X 5 mm in G0 at 5 %: {t[0]:.3f} s program time, at 100 %: {t[1]:.3f} s", file=sys.stderr)
sys.exit(0 if t[0] >= 5 / 12.5 and t[1] < 0.3 else 1)
PY
expect_refused mdi_bad "Q word" "${CTL[@]}" --do mdi --line "G1 X1 Q7 F100"

# 6b. Tool-length touch-off (G10 L10): the tool in the spindle (M61 Q1: it is there,
#     kept as #5400 in the var file) gets the length that makes Z read 0 where it
#     touches (machine Z -2.5 here); the tool table is written back, and a program
#     with T1 M6 G43 H1 G0 Z0 ends there.
ok jog_z_surface "${CTL[@]}" --do jog --axis Z --value -2.5 --timeout 20
z_s=$(grep -o "jogged:.* Z -\?[0-9.]*" "$WORK/jog_z_surface.out" | tail -1 | grep -o -- "-\?[0-9.]*$")
[ -n "$z_s" ] || fail "no Z position after the jog"
ok tool_in_spindle "${CTL[@]}" --do mdi --line "M61 Q1" --timeout 20
grep -qE "^5400[[:space:]]+1(\.0+)?$" "$WORK/cnc.var" || { grep -E "^54" "$WORK/cnc.var" >&2; fail "the tool in the spindle (#5400) is not 1 in the var file"; }
ok touch_tool "${CTL[@]}" --do touch-off --axis Z --value 0 --tool --timeout 20
note "tool table after the touch-off at machine Z $z_s: $(cat "$WORK/tools.tbl")"
/usr/bin/python3 - "$WORK/tools.tbl" "$WORK/cnc.var" "$z_s" <<'PY' || fail "tool 1's length in the tool table is not Z where it touched"
import re, sys
table = open(sys.argv[1]).read()
g54z = float(re.search(r"^5223\s+(\S+)", open(sys.argv[2]).read(), re.M).group(1))
m = re.fullmatch(r"T1 P1 Z(\S+) D\+6\.000000 ;end mill\n", table)
sys.exit(0 if m and abs(float(m.group(1)) - (float(sys.argv[3]) - g54z)) <= 1e-6 else 1)
PY
ok jog_z_up "${CTL[@]}" --do jog --axis Z --value 3 --timeout 20
cat >"$WORK/tool.ngc" <<'NGC'
T1 M6
G43 H1
G0 Z0
M2
NGC
"${CTL[@]}" --do run --program "$WORK/tool.ngc" --timeout 60 >"$WORK/tool_run.out" 2>&1 &
TEST_PIDS[tool]=$!
# The tool change holds until RESUME (RESUME while it runs is allowed and does nothing:
# wait for the hold).
wait_state held  # the tool change waits for RESUME
ok tool_resume "${CTL[@]}" --do resume
rc=0; wait "${TEST_PIDS[tool]}" || rc=$?; unset "TEST_PIDS[tool]"
[ "$rc" -eq 0 ] || { cat "$WORK/tool_run.out" >&2; fail "the program with G43 H1 did not complete ($rc)"; }
ok jog_after_tool "${CTL[@]}" --do jog --axis Z --value 1 --timeout 20
z_end=$(/usr/bin/python3 -c "print(f'{$z_s + 1:.4f}')")
axis_at jog_after_tool Z "$z_end"
note "G43 H1 G0 Z0 ended at machine Z $z_s (+1 jogged: $z_end), where the tool touched"
# A program runs now that the axes are homed; MDI, jog and homing are refused while it runs.
cat >"$WORK/long.ngc" <<'NGC'
G21 G90 G53 G1 X5 Y3 Z0 F600
G53 G1 X60 F600
M2
NGC
"${CTL[@]}" --do run --program "$WORK/long.ngc" --timeout 60 >"$WORK/long.out" 2>&1 &
TEST_PIDS[long]=$!
# Both the program server (naming the program) and the interpolator (which moves
# the axes: "a program is running") refuse; whichever answers first is reported.
# Running once RESUME is allowed (it has no effect on a program that runs; refused before).
for ((i = 0; i < 300; i++)); do
  "${CTL[@]}" --do resume >"$WORK/probe2.out" 2>&1 && break
  sleep 0.02
done
expect_refused jog_running "\\(long.ngc\\|a program\\) is running: STOP it first" "${CTL[@]}" --do jog --axis X --value 1
expect_refused mdi_running "\\(long.ngc\\|a program\\) is running: STOP it first" "${CTL[@]}" --do mdi --line "G0 X1"
expect_refused home_running "\\(long.ngc\\|a program\\) is running: STOP it first" "${CTL[@]}" --do home
expect_refused touch_running "\\(long.ngc\\|a program\\) is running: STOP it first" "${CTL[@]}" --do touch-off --axis X --value 0
rc=0; wait "${TEST_PIDS[long]}" || rc=$?; unset "TEST_PIDS[long]"
[ "$rc" -eq 0 ] || { cat "$WORK/long.out" >&2; fail "the program after homing did not complete ($rc)"; }

# A program was loaded since: the next MDI line starts as a program does (G80: no motion mode).
expect_refused mdi_after_program "motion mode is G80" "${CTL[@]}" --do mdi --line "X1"

# The one-line programs of MDI and touch-off do not pile up: each goes when another program is loaded.
n_mdi=$(find "$WORK/mdi" -name 'mdi-*.ngc' | wc -l)
[ "$n_mdi" -le 1 ] || fail "$n_mdi MDI files left in $WORK/mdi"
stop interpolator TERM
stop program-server TERM
stop drive-bridge TERM
stop servo-sim TERM
stop logger TERM

# 7. Replay: the operator moves (jogs, homing with its HOMED offsets, the lost
#    keepalive's STOP, MDI) reproduce bit for bit from the log.
"$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" >"$WORK/replay.out" 2>&1 || { cat "$WORK/replay.out" >&2; fail "replay is not identical"; }
grep "^identical: " "$WORK/replay.out" >&2 || fail "no verdict from cnc-replay"
echo "PASS"
