#!/usr/bin/env bash
# Killed processes: SIGKILL of one process of the cell in the
# middle of a program, and what the rest of the cell must do about it.
#   kill_test.sh WHO BUILD_DIR SOURCE_DIR
# WHO:
#   interpolator    the bridge stops the axes at timing.stop_decel_mm_s2 (jerk-limited), braking
#                   within setpoint_timeout + 50 ms of the kill, over v^2/(2a) + v*a/(2j) (the
#                   braking measured by stop_trace.py on the simulated world's time); the bridge and the program server
#                   raise peer_lost naming cnc-interpolator; cnc-ctl exits 5 with the reason.
#   interpolator-restart
#                   the interpolator killed mid-move and started again at once, before the
#                   bridge's setpoint watchdog (raised to 2 s here so the restart surely beats
#                   it): the bridge does not take the new process's stream for a RESET's,
#                   it faults naming the stream that broke off moving; the axes stop within
#                   the same braking bound as above, cnc-ctl exits 5 with the reason.
#   drive-bridge    the drives stop by their own communication watchdog (the simulator's,
#                   comm_timeout_s 0.1 s, 2000 mm/s^2) within v*(timeout + 40 ms) + v^2/(2a),
#                   braking at no more than 1.25 a, and fault (0x8130); the interpolator
#                   stops the program (FAULT) and raises peer_lost naming cnc-drive-bridge;
#                   cnc-ctl exits 5 with the reason.
#   program-server  the interpolator runs out the blocks it holds and stops at the end of the
#                   last one (a programmed point; no fault, no axis over 1.5x its acceleration),
#                   raises peer_lost naming cnc-program-server, and goes on when the server is
#                   restarted (--state): the program reaches its end, cnc-ctl exits 0.
#   program-server-stateless
#                   the same kill, the server started again without --state: the
#                   interpolator stops the program it can no longer be served (ALARM
#                   program_lost naming it), cnc-ctl exits 5 at once, loaded again it runs.
#   logger          the killed logger's file reads to its last whole event (cnc-logstat,
#                   lcm-logplayer), a restarted logger writes a new file next to it (the old
#                   one unchanged), the program is unaffected.
#   monitor         (the cell under ./cnc up) motion is unaffected: the program ends at its
#                   end point (1 um), no fault, and ./cnc up keeps the other services running.
# After a kill that stopped the axes (interpolator, drive-bridge) the killed process is
# restarted: a program is refused and nothing moves until ./cnc ctl --do reset; after it
# a program runs to its end.
# Alarm latencies (ALARM time stamp minus the kill, from the log) must be within
# timing.heartbeat_timeout_s + 0.5 s (the README's bound, with margin for this VM).
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
WHO="$1"; BUILD="$2"; SRC="$3"
HERE="$(cd "$(dirname "$0")" && pwd)"
WORK="$(mktemp -d "/tmp/cnc-kill-$WHO.XXXXXX")"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
CTL="$BUILD/tools/cnc-ctl"
HB_TIMEOUT=$(awk '/heartbeat_timeout_s:/ {print $2}' "$M")
JERK_X=$(awk '/max_jerk_mm_s3:/ {print $2; exit}' "$M")  # X's: the bridge's stop is jerk-limited
[ -n "$HB_TIMEOUT" ] || fail "no timing.heartbeat_timeout_s in $M"

# wait_for DESC TIMEOUT_S COMMAND...: polls COMMAND every 50 ms until it succeeds.
wait_for() {
  local desc="$1" limit="$2"; shift 2
  local n=$(( ${limit%.*} * 20 )) i
  for ((i = 0; i < n; i++)); do
    "$@" && return 0
    sleep 0.05
  done
  fail "timed out after $limit s waiting for: $desc"
}
x_over() { trace_over 2 "$1" >/dev/null; }  # the simulator's X past $1 mm
# The axes stand: the trace's last 0.3 s (30 rows) without motion (1 um).
standing() {
  /usr/bin/python3 - "$WORK/trace.csv" <<'PY'
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if None not in r.values() and "" not in r.values()]
if len(rows) < 40: sys.exit(1)
last = rows[-30:]
ok = all(abs(float(r[a + "_mm"]) - float(last[-1][a + "_mm"])) < 1e-3 for r in last for a in "XYZ")
sys.exit(0 if ok else 1)
PY
}
in_log() { grep -q -- "$2" "$WORK/$1.log" 2>/dev/null; }
# ctl_rc ARGS...: runs cnc-ctl (output in $WORK/ctl2.out) and prints its exit status.
ctl_rc() {
  local rc=0
  "$CTL" --machine "$M" "$@" >"$WORK/ctl2.out" 2>&1 || rc=$?
  cat "$WORK/ctl2.out" >&2
  echo "$rc"
}
# export_log: the tables of the run's first log file (cnc-logexport) in $WORK/export.
export_log() {
  [ -d "$WORK/export" ] && return 0
  "$BUILD/tools/cnc-logexport" --log "$WORK/cell.lcmlog" --out "$WORK/export" >"$WORK/export.out" 2>&1 \
    || { cat "$WORK/export.out" >&2; fail "cnc-logexport cannot read the run's log"; }
}
# alarm_latency SOURCE CODE PATTERN KILL_UTIME: the first such ALARM after the kill, in
# the run's log; prints its latency in seconds and checks it against the bound.
alarm_latency() {
  export_log
  /usr/bin/python3 - "$WORK/export/alarms.csv" "$@" "$HB_TIMEOUT" <<'PY' || fail "no ALARM $2 from $1 matching '$3' within the bound"
import csv, sys
f, source, code, pattern, kill, bound = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5]), float(sys.argv[6])
rows = list(csv.DictReader(open(f)))
for r in rows:
    if r["source"] == source and r["code"] == code and pattern in r["text"] and int(r["utime"]) >= kill:
        lat = (int(r["utime"]) - kill) / 1e6
        print(f"# ALARM {source} [{code}] {lat:.3f} s after the kill (bound {bound:g} + 0.5 s): {r['text']}",
              file=sys.stderr)
        sys.exit(0 if lat <= bound + 0.5 else 1)
print("# alarms in the log:", *(f"{r['source']} [{r['code']}] {r['text']}" for r in rows), sep="\n# ", file=sys.stderr)
sys.exit(1)
PY
}
# stop_distance KILL_WALL DECEL DELAY_S [MAX_DECEL_FACTOR]: from the trace, X's travel after
# the kill against v^2/(2a) + v*DELAY + 0.05 mm; with a factor, the braking no harder than it.
stop_distance() {
  /usr/bin/python3 - "$WORK/trace.csv" "$@" <<'PY' || fail "the axes did not stop within the bound"
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if None not in r.values() and "" not in r.values()]
kill, a, delay = float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
factor = float(sys.argv[5]) if len(sys.argv) > 5 else 0
t = [float(r["wall_s"]) for r in rows]
x = [float(r["X_mm"]) for r in rows]
# The simulator's velocity column, each row the median of it and its neighbours: a row
# can jump where the simulated world stood through a stall (304.6 mm/s between 213.9 and
# 211.6, 10 ms apart; 295.4 right after the kill at 266): read as braking, 5407-7327 mm/s^2
# in a stop at 2000, in 3 of 3 suite runs on fresh clones (fc5fc46, 0d76631).
raw = [float(r["X_mm_s"]) for r in rows]
v = [sorted(raw[max(0, k - 1):k + 2])[len(raw[max(0, k - 1):k + 2]) // 2] for k in range(len(raw))]
i = max(k for k in range(len(t)) if t[k] <= kill)
# the axis came to rest: the first sample from which it stays within 1 um
rest = next(k for k in range(i, len(t)) if all(abs(x[j] - x[k]) < 1e-3 for j in range(k, min(len(t), k + 30))))
dist = x[rest] - x[i]
bound = v[i] ** 2 / (2 * a) + v[i] * delay
worst = max((abs(v[k + 1] - v[k]) / (t[k + 1] - t[k]) for k in range(i, rest) if t[k + 1] - t[k] > 0.004), default=0)
print(f"# at the kill: X = {x[i]:.3f} mm at {v[i]:.1f} mm/s; at rest at X = {x[rest]:.3f} mm "
      f"{(t[rest] - kill) * 1e3:.0f} ms later", file=sys.stderr)
print(f"# stop distance {dist:.3f} mm; bound v^2/(2a) + v*delay = {v[i]**2/(2*a):.3f} + {v[i]*delay:.3f} = "
      f"{bound:.3f} mm (+0.05) (a = {a:g} mm/s^2, delay = {delay*1e3:g} ms); hardest braking {worst:.0f} mm/s^2",
      file=sys.stderr)
ok = v[i] > 150 and 0 <= dist <= bound + 0.05 and (factor == 0 or worst <= factor * a)
sys.exit(0 if ok else 1)
PY
}
# no_motion_since WALL: nothing moved (1 um) in the trace after WALL.
no_motion_since() {
  /usr/bin/python3 - "$WORK/trace.csv" "$1" <<'PY' || fail "the axes moved without a reset"
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if None not in r.values() and "" not in r.values()]
since = float(sys.argv[2])
after = [r for r in rows if float(r["wall_s"]) >= since]
ref = after[0]
moved = max(abs(float(r[a + "_mm"]) - float(ref[a + "_mm"])) for r in after for a in "XYZ")
print(f"# largest motion since then: {moved*1e3:.4f} um over {len(after)} samples", file=sys.stderr)
sys.exit(0 if moved < 1e-3 else 1)
PY
}

# 380 mm along X at 200 mm/s (12000 mm/min): about 2 s, cruising from 0.1 s on.
printf 'G21 G90\nG1 X380 F12000\nM30\n' >"$WORK/long.ngc"
# After a reset: back to a known point.
printf 'G21 G90\nG1 X50 Y20 Z-5 F6000\nM30\n' >"$WORK/short.ngc"
# A raster of 301 moves of 2 mm: X 0 -> 300 at Y 0, over to Y 10, X 300 -> 0, at
# 150 mm/s: more blocks than the interpolator's window (32, 64 mm), about 5 s; the
# moves of a row are collinear, so the path runs through them at full feed and must
# brake for the end of the last block it holds when the blocks stop coming.
raster_points() {
  /usr/bin/python3 -c '
for x in range(2, 301, 2): print(x, 0)
for x in range(300, -1, -2): print(x, 10)'
}
{ echo "G21 G90 G64"; raster_points | awk '{print "G1 X" $1 " Y" $2 " F9000"}'; echo "M30"; } >"$WORK/many.ngc"
raster_points >"$WORK/many.xy"
END_XY="0 10"
y_over() { trace_over 5 "$1" >/dev/null; }  # the simulator's Y past $1 mm

run_cell() {  # the cell, each process on its own (the monitor test uses ./cnc up)
  start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
  start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --trace "$WORK/trace.csv" --final-state "$WORK/final.json"
  start drive-bridge "$BUILD/services/cnc-drive-bridge" --machine "$M"
  start program-server "$BUILD/services/cnc-program-server" --machine "$M" --state "$WORK/pps.state"
  start interpolator "$BUILD/services/cnc-interpolator" --machine "$M"
}
stop_cell() {
  local s
  for s in interpolator program-server drive-bridge servo-sim logger; do
    [ -n "${TEST_PIDS[$s]:-}" ] && stop "$s" TERM
  done
  return 0
}
# After the kill: the restarted cell refuses to move until a reset, then runs a program.
reset_then_run() {
  local t0 rc
  t0=$(date +%s.%N)
  rc=$(ctl_rc --do run --program "$WORK/short.ngc" --timeout 20)
  [ "$rc" -ne 0 ] || fail "a program ran after the kill without a reset"
  note "before the reset: cnc-ctl --do run refused with exit $rc: $(tail -n 1 "$WORK/ctl2.out")"
  no_motion_since "$t0"
  rc=$(ctl_rc --do reset --timeout 20)
  [ "$rc" -eq 0 ] || fail "cnc-ctl --do reset exited $rc"
  rc=$(ctl_rc --do run --program "$WORK/short.ngc" --timeout 30)
  [ "$rc" -eq 0 ] || fail "after the reset the program did not run to its end (cnc-ctl exit $rc)"
  grep -q "program done" "$WORK/ctl2.out" || fail "cnc-ctl did not report the program done"
  settle_at "$WORK/trace.csv" 50 20 -5
  stop_cell
  final_at "$WORK/final.json" 50 20 -5 || fail "the axes did not end at the short program's end point"
}

case "$WHO" in
interpolator)
  run_cell
  sim_world_steady "$WORK/trace.csv"
  "$CTL" --machine "$M" --do run --program "$WORK/long.ngc" --timeout 30 >"$WORK/ctl.out" 2>&1 &
  ctl_pid=$!
  wait_for "X past 100 mm" 20 x_over 100
  kill_wall=$(date +%s.%N); kill_utime=$(date +%s%6N)
  kill_hard interpolator
  kill_after=$(date +%s.%N)
  rc=0; wait "$ctl_pid" || rc=$?
  cat "$WORK/ctl.out" >&2
  [ "$rc" -eq 5 ] || fail "cnc-ctl exit $rc after the interpolator was killed, expected 5"
  grep -qE "no setpoint for|cnc-interpolator" "$WORK/ctl.out" || fail "cnc-ctl did not name the reason"
  wait_for "the axes stand" 10 standing
  decel=$(awk '/stop_decel_mm_s2:/ {print $2}' "$M"); timeout=$(awk '/setpoint_timeout_s:/ {print $2}' "$M")
  # The bridge brakes (jerk-limited) once the stream has run dry, and faults at the
  # watchdog's timeout: braking within the timeout + 50 ms of the kill.
  onset=$(/usr/bin/python3 -c "print($timeout + 0.05)")
  /usr/bin/python3 "$HERE/stop_trace.py" "interpolator killed" "$WORK/trace.csv" "$kill_wall" "$kill_after" \
    "$decel" "$JERK_X" 150 0.75 "$onset" || fail "the axes did not stop within the bound"
  wait_for "the bridge's peer_lost alarm" 10 in_log drive-bridge "\[peer_lost\] no heartbeat from cnc-interpolator"
  wait_for "the program server's peer_lost alarm" 10 in_log program-server "\[peer_lost\] no heartbeat from cnc-interpolator"
  start interpolator "$BUILD/services/cnc-interpolator" --machine "$M"
  wait_for "the bridge sees the interpolator back" 10 in_log drive-bridge "\[peer_back\] cnc-interpolator is back"
  reset_then_run
  alarm_latency cnc-drive-bridge peer_lost "cnc-interpolator" "$kill_utime"
  alarm_latency cnc-program-server peer_lost "cnc-interpolator" "$kill_utime"
  ;;
interpolator-restart)
  sed -i -E 's#setpoint_timeout_s: [0-9.]+#setpoint_timeout_s: 2.0#' "$M"
  grep -q 'setpoint_timeout_s: 2.0' "$M" || fail "cannot set the setpoint watchdog in $M"
  run_cell
  sim_world_steady "$WORK/trace.csv"
  "$CTL" --machine "$M" --do run --program "$WORK/long.ngc" --timeout 30 >"$WORK/ctl.out" 2>&1 &
  ctl_pid=$!
  wait_for "X past 100 mm" 20 x_over 100
  kill_wall=$(date +%s.%N)
  kill_hard interpolator
  kill_after=$(date +%s.%N)
  start interpolator "$BUILD/services/cnc-interpolator" --machine "$M"
  wait_for "the bridge's fault for the broken-off stream" 10 in_log drive-bridge "had left off moving"
  grep -h "had left off moving" "$WORK/drive-bridge.log" | head -n 1 | sed 's/^/# /' >&2
  # Before the watchdog: the fault came from the new stream, not from the silence.
  ! in_log drive-bridge "no setpoint for" || fail "the bridge's watchdog tripped first: the restart was too slow to test"
  rc=0; wait "$ctl_pid" || rc=$?
  cat "$WORK/ctl.out" >&2
  [ "$rc" -eq 5 ] || fail "cnc-ctl exit $rc after the interpolator was killed and restarted, expected 5"
  wait_for "the axes stand" 10 standing
  decel=$(awk '/stop_decel_mm_s2:/ {print $2}' "$M")
  # The bridge brakes once the stream has run dry (one period past its newest setpoint).
  /usr/bin/python3 "$HERE/stop_trace.py" "interpolator killed and restarted" "$WORK/trace.csv" "$kill_wall" \
    "$kill_after" "$decel" "$JERK_X" 150 0.75 0.1 || fail "the axes did not stop within the bound"
  reset_then_run
  ;;
drive-bridge)
  # The simulated drives' communication watchdog: 0.1 s, braking at 2000 mm/s^2.
  sed -i -E 's#sim: \{bandwidth_hz: ([0-9.]+), damping: ([0-9.]+)\}#sim: {bandwidth_hz: \1, damping: \2, comm_timeout_s: 0.1, comm_stop_decel_mm_s2: 2000}#' "$M"
  [ "$(grep -c 'comm_timeout_s: 0.1' "$M")" -eq 3 ] || fail "cannot set the drives' watchdog in $M"
  run_cell
  "$CTL" --machine "$M" --do run --program "$WORK/long.ngc" --timeout 30 >"$WORK/ctl.out" 2>&1 &
  ctl_pid=$!
  wait_for "X past 100 mm" 20 x_over 100
  kill_wall=$(date +%s.%N); kill_utime=$(date +%s%6N)
  kill_hard drive-bridge
  kill_after=$(date +%s.%N)
  rc=0; wait "$ctl_pid" || rc=$?
  cat "$WORK/ctl.out" >&2
  [ "$rc" -eq 5 ] || fail "cnc-ctl exit $rc after the drive bridge was killed, expected 5"
  grep -q "drive bridge\|cnc-drive-bridge" "$WORK/ctl.out" || fail "cnc-ctl did not name the drive bridge"
  wait_for "the drives' watchdog fault" 10 in_log servo-sim "axis X: stopped at .*fault 0x8130"
  grep -q "axis X: communication watchdog" "$WORK/servo-sim.log" || fail "the simulator's watchdog did not brake X"
  wait_for "the axes stand" 10 standing
  # The drives' own quick stop after the watchdog's 0.1 s. Delay: the watchdog's 0.1 s, the
  # time the kill took to land (from its time stamp until the process was reaped: 3-50 ms,
  # more on a loaded VM), plus 40 ms of measurement slack (the trace row before the kill is
  # up to 10 ms older). (Measured from the kill, not from an onset of braking: the drive's
  # demand after its stream ends is no clean cruise.)
  delay=$(/usr/bin/python3 -c "print(0.14 + $kill_after - $kill_wall)")
  note "the kill landed within $(/usr/bin/python3 -c "print(round(($kill_after - $kill_wall) * 1e3))") ms of its time stamp"
  stop_distance "$kill_wall" 2000 "$delay" 1.25
  wait_for "the interpolator's peer_lost alarm" 10 in_log interpolator "\[peer_lost\] no heartbeat from cnc-drive-bridge"
  grep -q "fault: .*drive bridge" "$WORK/interpolator.log" || fail "the interpolator did not stop the program for the lost bridge"
  start drive-bridge "$BUILD/services/cnc-drive-bridge" --machine "$M"
  wait_for "the interpolator sees the bridge back" 10 in_log interpolator "\[peer_back\] cnc-drive-bridge is back"
  reset_then_run
  alarm_latency cnc-interpolator peer_lost "cnc-drive-bridge" "$kill_utime"
  ;;
program-server)
  run_cell
  "$CTL" --machine "$M" --do run --program "$WORK/many.ngc" --timeout 60 >"$WORK/ctl.out" 2>&1 &
  ctl_pid=$!
  wait_for "X past 60 mm (first row)" 30 x_over 60
  kill_utime=$(date +%s%6N)
  kill_hard program-server
  wait_for "the interpolator's peer_lost alarm" 10 in_log interpolator "\[peer_lost\] no heartbeat from cnc-program-server"
  wait_for "the axes stand (starved)" 20 standing
  # Where it stands: a programmed point, short of the program's end, no fault.
  /usr/bin/python3 - "$WORK/trace.csv" "$WORK/many.xy" <<'PY' || fail "the interpolator did not stop at the end of a block it had"
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if None not in r.values() and "" not in r.values()]
pts = [tuple(map(float, l.split())) for l in open(sys.argv[2])]
x, y = float(rows[-1]["X_mm"]), float(rows[-1]["Y_mm"])
d, i = min((abs(x - p[0]) + abs(y - p[1]), k) for k, p in enumerate(pts))
ok = d < 2e-3 and i + 1 < len(pts) and rows[-1]["X_on"] == "1"
print(f"# starved: standing at X = {x:.4f}, Y = {y:.4f}: the end of raster move {i + 1} of {len(pts)} "
      f"(|dx| + |dy| = {d*1e3:.2f} um), drives enabled", file=sys.stderr)
sys.exit(0 if ok else 1)
PY
  kill -0 "$ctl_pid" || fail "cnc-ctl ended while the program server was away"
  start program-server "$BUILD/services/cnc-program-server" --machine "$M" --state "$WORK/pps.state"
  rc=0; wait "$ctl_pid" || rc=$?
  cat "$WORK/ctl.out" >&2
  [ "$rc" -eq 0 ] || fail "cnc-ctl exit $rc: the program did not go on to its end after the server came back"
  grep -q "resumed .* from the state file" "$WORK/program-server.log" || fail "the restarted server did not resume the program"
  grep -q "\[peer_back\] cnc-program-server is back" "$WORK/interpolator.log" || fail "no peer_back alarm"
  end_utime=$(date +%s%6N)  # the program's end: the bridge's setpoint watchdog trips at the cell's stop
  settle_at "$WORK/trace.csv" $END_XY 0
  stop_cell
  final_at "$WORK/final.json" $END_XY 0 || fail "the program did not end at its end point"
  # No jump: the interpolator's setpoints (from the log), every cycle of the run, within
  # each axis's acceleration limit (second differences), and no FAULT alarm until its end.
  export_log
  /usr/bin/python3 - "$WORK/export/setpoints.csv" "$WORK/export/alarms.csv" "$(awk '/ipo_period_s:/ {print $2}' "$M")" "$end_utime" <<'PY' || fail "the path jumped, or a fault was raised"
import csv, sys
sp = list(csv.DictReader(open(sys.argv[1])))
T = float(sys.argv[3])
worst, n = {"X": 0.0, "Y": 0.0}, 0
for k in range(1, len(sp) - 1):
    c = [int(sp[j]["cycle"]) for j in (k - 1, k, k + 1)]
    if c[1] != c[0] + 1 or c[2] != c[1] + 1: continue
    n += 1
    for a in worst:
        x = [float(sp[j][a.lower() + "_mm"]) for j in (k - 1, k, k + 1)]
        worst[a] = max(worst[a], abs(x[2] - 2 * x[1] + x[0]) / T ** 2)
faults = [r for r in csv.DictReader(open(sys.argv[2])) if r["severity"] == "fault" and int(r["utime"]) < int(sys.argv[4])]
print(f"# setpoints: hardest acceleration X {worst['X']:.0f}, Y {worst['Y']:.0f} mm/s^2 over {n} cycles "
      f"(axis limit 3000); {len(faults)} fault alarm(s)", file=sys.stderr)
for r in faults: print(f"# FAULT {r['source']} [{r['code']}] {r['text']}", file=sys.stderr)
sys.exit(0 if n > 1000 and max(worst.values()) <= 3000 * 1.001 and not faults else 1)
PY
  alarm_latency cnc-interpolator peer_lost "cnc-program-server" "$kill_utime"
  ;;
program-server-stateless)
  # Restarted without its state file: the interpolator stops the program it can no longer
  # be served (not a starved wait until an operator's STOP), naming why; cnc-ctl exits 5.
  run_cell
  "$CTL" --machine "$M" --do run --program "$WORK/many.ngc" --timeout 60 >"$WORK/ctl.out" 2>&1 &
  ctl_pid=$!
  wait_for "X past 60 mm (first row)" 30 x_over 60
  kill_hard program-server
  wait_for "the interpolator's peer_lost alarm" 10 in_log interpolator "\[peer_lost\] no heartbeat from cnc-program-server"
  t_back=$SECONDS
  start program-server "$BUILD/services/cnc-program-server" --machine "$M"
  rc=0; wait "$ctl_pid" || rc=$?
  t_stop=$((SECONDS - t_back))
  cat "$WORK/ctl.out" >&2
  [ "$rc" -eq 5 ] || fail "cnc-ctl exit $rc (want 5) after the server came back without the program"
  grep -q "cnc-ctl: the program stopped: program .*many.ngc lost: the program server has no program loaded" "$WORK/ctl.out" ||
    fail "cnc-ctl does not say the program was lost, and why"
  grep -q "many.ngc lost: .* block [0-9]* of [0-9]* was not served yet" "$WORK/interpolator.log" ||
    { tail -n 20 "$WORK/interpolator.log" >&2; fail "the interpolator did not stop the lost program"; }
  [ "$t_stop" -lt 10 ] || fail "the lost program took $t_stop s to stop"
  wait_for "the axes stand" 20 standing
  # Loaded again, the program runs to its end.
  rc=$(ctl_rc --do run --program "$WORK/many.ngc" --timeout 60)
  [ "$rc" -eq 0 ] || fail "loaded again, the program did not run to its end (cnc-ctl exit $rc)"
  settle_at "$WORK/trace.csv" $END_XY 0
  stop_cell
  final_at "$WORK/final.json" $END_XY 0 || fail "the program did not end at its end point"
  note "stopped within $t_stop s of the server's start: $(grep -o 'lost: .*' "$WORK/interpolator.log" | head -1)"
  ;;
logger)
  run_cell
  "$CTL" --machine "$M" --do run --program "$WORK/many.ngc" --timeout 60 >"$WORK/ctl.out" 2>&1 &
  ctl_pid=$!
  wait_for "X past 60 mm (first row)" 30 x_over 60
  wait_for "the logger's first LOGGER_STATS in its file" 10 grep -qa LOGGER_STATS "$WORK/cell.lcmlog"
  kill_hard logger
  log="$WORK/cell.lcmlog"
  sum_before=$(sha256sum <"$log")
  # Restarted at once, with the same --out: a new file beside the old one.
  start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
  wait_for "the restarted logger's file" 10 in_log logger "writing .*cell-2.lcmlog"
  "$BUILD/tools/cnc-logstat" --log "$log" >"$WORK/killed.logstat" 2>&1 \
    || { cat "$WORK/killed.logstat" >&2; fail "cnc-logstat cannot read the killed logger's file"; }
  events=$(awk '/ events in /{print $1}' "$WORK/killed.logstat")
  timeout 60 lcm-logplayer -v -s 1000 -l "udpm://239.255.76.67:$((TEST_LCM_PORT + 5))?ttl=0" "$log" >"$WORK/play.out" 2>&1 \
    || { tail "$WORK/play.out" >&2; fail "lcm-logplayer failed on the killed logger's file"; }
  played=$(grep -c ' Channel ' "$WORK/play.out" || true)
  [ "$played" -eq "$events" ] || fail "lcm-logplayer played $played of $events events"
  python3 "$HERE/logger_logcheck.py" "$log" --prefix "$TEST_PREFIX" >"$WORK/killed.check" \
    || { cat "$WORK/killed.check" >&2; fail "the killed logger's file fails its checks"; }
  note "killed logger's file: $events events, cnc-logstat and lcm-logplayer read them all; $(tr '\n' ';' <"$WORK/killed.check")"
  rc=0; wait "$ctl_pid" || rc=$?
  cat "$WORK/ctl.out" >&2
  [ "$rc" -eq 0 ] || fail "cnc-ctl exit $rc: the program did not run to its end without the logger"
  settle_at "$WORK/trace.csv" $END_XY 0
  stop_cell
  [ "$(sha256sum <"$log")" = "$sum_before" ] || fail "the restarted logger changed the killed one's file"
  "$BUILD/tools/cnc-logstat" --log "$WORK/cell-2.lcmlog" --require-no-gaps "${TEST_PREFIX}SETPOINTS" >"$WORK/new.logstat" 2>&1 \
    || { cat "$WORK/new.logstat" >&2; fail "the restarted logger's file does not read, or has setpoint gaps"; }
  note "restarted logger: $(awk '/ events in /' "$WORK/new.logstat") in cell-2.lcmlog"
  final_at "$WORK/final.json" $END_XY 0 || fail "the program did not end at its end point"
  ;;
monitor)
  # The whole cell under ./cnc up, as the issue found it: a killed monitor ended the cell.
  # On a failure ./cnc up stops its services itself (SIGTERM) before the rest is killed.
  stop_up() { local rc=$? p="${TEST_PIDS[up]:-}"; [ -z "$p" ] || { kill -TERM "$p" 2>/dev/null; wait "$p" 2>/dev/null; }; cleanup "$rc"; }
  trap 'stop_up' EXIT
  (cd "$WORK" && CNC_BUILD_DIR="$BUILD" CNC_STATE_DIR="$WORK" exec "$SRC/cnc" up --machine "$M" \
     --log-out "$WORK/cell" --sim-final-state "$WORK/final.json" --sim-trace "$WORK/trace.csv") >"$WORK/up.log" 2>&1 &
  TEST_PIDS[up]=$!
  wait_for "the monitor started" 20 in_log up "started monitor (pid"
  monitor_pid=$(sed -n 's/.*started monitor (pid \([0-9]*\)).*/\1/p' "$WORK/up.log")
  "$CTL" --machine "$M" --do run --program "$WORK/many.ngc" --timeout 60 >"$WORK/ctl.out" 2>&1 &
  ctl_pid=$!
  wait_for "X past 60 mm (first row)" 30 x_over 60
  kill -KILL "$monitor_pid"
  rc=0; wait "$ctl_pid" || rc=$?
  cat "$WORK/ctl.out" >&2
  [ "$rc" -eq 0 ] || fail "cnc-ctl exit $rc: the program did not run to its end without the monitor"
  grep -q "monitor ended by itself" "$WORK/up.log" || fail "./cnc up did not notice the monitor's end"
  grep -q "stopping the cell" "$WORK/up.log" && fail "./cnc up stopped the cell"
  grep -q "ALARM .*FAULT\|interp_fault\|publish_failed" "$WORK/ctl.out" && fail "a fault was raised"
  settle_at "$WORK/trace.csv" $END_XY 0
  stop up TERM
  final_at "$WORK/final.json" $END_XY 0 || fail "the program did not end at its end point"
  ;;
*) fail "unknown WHO '$WHO'" ;;
esac
echo "PASS"
