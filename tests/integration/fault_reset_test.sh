#!/usr/bin/env bash
# Faults end in a controlled stop, and RESET brings the cell back without a restart.
#  1. A publish failure mid-program: the multicast route is removed for 1 s while X
#     moves at 200 mm/s (every sendto fails). No process may exit; the axes stop at
#     the configured deceleration (the simulator's trace, 10 ms rows); once the route
#     is back the bridge and the interpolator raise publish_failed ALARMs with their
#     counts and stay in FAULT: a new program is refused (cnc-ctl exit 3, reason
#     "FAULT"). `cnc-ctl --do reset`, then a program runs to its end.
#  2. Interlock: LOAD, RUN and START while a program runs (standing in a dwell) are
#     refused at once (exit 3, naming the running program); STOP then ends it.
#  3. A drive fault mid-program (the simulator's fault injection on Y, X moving at
#     about 100 mm/s): the bridge stops X at the configured deceleration (the
#     simulator's trace), the interpolator goes to FAULT; reset; a program runs to
#     its end.
#  Both stops are measured by stop_ticks.py on the bridge's own ticks (its tick trace,
#  written when it exits in 4), with the drive's following error and rest beside them.
#  4. Every process exits 0 on SIGTERM, and the log replays bit for bit (the RESETs
#     and the positions they took are recorded inputs).
#   fault_reset_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
[ -n "${CNC_IN_NETNS:-}" ] || { echo "SKIP: needs a private network namespace (unshare -n) to remove the multicast route"; exit 0; }
WORK="$(mktemp -d /tmp/cnc-fault-reset.XXXXXX)"
trap 'rc=$?; ip route replace 224.0.0.0/4 dev lo 2>/dev/null || true; cleanup "$rc"' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")
DECEL=$(sed -n 's/^ *stop_decel_mm_s2: *\([0-9.]*\).*/\1/p' "$M")
# X's jerk limit (the first axis in the file): the bridge's stop is jerk-limited.
JERK_X=$(sed -n 's/^ *max_jerk_mm_s3: *\([0-9.]*\).*/\1/p' "$M" | head -n 1)
HERE="$(cd "$(dirname "$0")" && pwd)"

cat >"$WORK/long.ngc" <<'NGC'
G21 G90
G1 X380 F12000
M30
NGC
cat >"$WORK/diag.ngc" <<'NGC'
G21 G90
G1 X40 Y40 F9000
G1 X390 Y100 F6000
M30
NGC
# Stands still in a dwell long enough for the interlock's refusals on any machine.
cat >"$WORK/dwell.ngc" <<'NGC'
G21 G90
G1 X40 Y40 F6000
G4 P30
M30
NGC
cat >"$WORK/short.ngc" <<'NGC'
G21 G90
G1 X20 Y20 Z-5 F6000
M30
NGC

start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --trace "$WORK/trace.csv" --control "$WORK/sim.ctl"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
export CNC_BRIDGE_DEBUG_TRACE="$WORK/ticks.csv"
start_cell
unset CNC_BRIDGE_DEBUG_TRACE
FE_X=$(sed -n 's/^ *max_following_error_mm: *\([0-9.]*\).*/\1/p' "$M" | head -n 1)
SERVO_T=$(sed -n 's/^ *servo_period_s: *\([0-9.]*\).*/\1/p' "$M")

all_alive() {
  local name
  for name in servo-sim logger drive-bridge monitor program-server interpolator; do
    kill -0 "${TEST_PIDS[$name]}" 2>/dev/null || { cat "$WORK/$name.log" >&2; fail "$name exited ($1)"; }
  done
}
# wait_x LIMIT: until the trace shows X beyond LIMIT mm (polled without a python per
# poll: under two busy loops a python start took long enough that the route was cut
# at X = 265.7 mm, where X already braked for its end point at 380).
wait_x() {
  local i
  for ((i = 0; i < 1500; i++)); do
    trace_over 2 "$1" && return 0
    sleep 0.02
  done
  fail "X did not pass $1 mm"
}
# refused_within_3s OUT_FILE PATTERN CMD...: cnc-ctl exits 3 within 3 s, its reason matching PATTERN.
refused_within_3s() {
  local out="$1" pat="$2" rc=0 t0 t1; shift 2
  t0=$(date +%s.%N)
  "$@" >"$out" 2>&1 || rc=$?
  t1=$(date +%s.%N)
  cat "$out" >&2
  [ "$rc" -eq 3 ] || fail "cnc-ctl exit $rc, expected 3 (refused): $*"
  grep -q "$pat" "$out" || fail "the refusal does not say '$pat'"
  /usr/bin/python3 -c "import sys; sys.exit(0 if $t1 - $t0 < 3 else 1)" || fail "the refusal took more than 3 s"
}

# ---- 1. publish failure -------------------------------------------------------
sim_world_steady "$WORK/trace.csv"
"${CTL[@]}" --do run --program "$WORK/long.ngc" --timeout 30 >"$WORK/ctl1.out" 2>&1 &
ctl_pid=$!
stimulus_rt on
x=$(wait_x 100)
cut_before=$(date +%s.%N)
ip route del 224.0.0.0/4 dev lo
cut_after=$(date +%s.%N)
stimulus_rt off
note "multicast route removed at X = $x mm"
sleep 1
all_alive "with the route removed"
ip route add 224.0.0.0/4 dev lo
note "multicast route back"
rc=0; wait "$ctl_pid" || rc=$?
cat "$WORK/ctl1.out" >&2
[ "$rc" -eq 5 ] || fail "cnc-ctl exit $rc during the outage, expected 5 (fault)"
sleep 1
all_alive "after the route came back"
grep -q "fault: the bus failed" "$WORK/drive-bridge.log" || fail "the bridge did not fault on its failed publishes"
grep -q "fault: publish on" "$WORK/interpolator.log" || fail "the interpolator did not fault on its failed publishes"

# In FAULT: a new program is refused with the reason.
refused_within_3s "$WORK/refused1.out" "FAULT" "${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 10
"${CTL[@]}" --do reset --timeout 20 >&2 || fail "cnc-ctl --do reset failed after the publish failure"
"${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 30 >&2 || fail "no program ran after the reset"

# ---- 2. interlock while a program runs ----------------------------------------
# In dwell.ngc's 30 s dwell: a program that ends before the refusals arrive (a loaded
# machine starts each cnc-ctl in 0.7-1 s) cannot leave them nothing to refuse.
"${CTL[@]}" --do load --program "$WORK/dwell.ngc" >&2 || fail "dwell.ngc was not loaded"
"${CTL[@]}" --do start >&2 || fail "dwell.ngc did not start"
pids=()
(refused_within_3s "$WORK/refused2.out" "dwell.ngc is running" "${CTL[@]}" --do load --program "$WORK/short.ngc") & pids+=($!)
(refused_within_3s "$WORK/refused3.out" "dwell.ngc is running" "${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 30) & pids+=($!)
(refused_within_3s "$WORK/refused4.out" "dwell.ngc is running" "${CTL[@]}" --do start) & pids+=($!)
for p in "${pids[@]}"; do wait "$p" || fail "a command was not refused within 3 s while dwell.ngc runs (above)"; done
"${CTL[@]}" --do stop >&2 || fail "dwell.ngc was not stopped"

# ---- 3. drive fault -----------------------------------------------------------
"${CTL[@]}" --do run --program "$WORK/diag.ngc" --timeout 30 >"$WORK/ctl.out" 2>&1 &
ctl_pid=$!
stimulus_rt on
x=$(wait_x 120)
fault_before=$(date +%s.%N)
echo "fault Y" >"$WORK/sim.ctl"
fault_after=$(date +%s.%N)
stimulus_rt off
note "drive Y faulted at X = $x mm"
expect_drive_fault "$ctl_pid" "fault"
sleep 1
all_alive "after the drive fault"
refused_within_3s "$WORK/refused5.out" "FAULT" "${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 10
"${CTL[@]}" --do reset --timeout 20 >&2 || fail "cnc-ctl --do reset failed after the drive fault"
"${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 30 >&2 || fail "no program ran after the second reset"

# ---- 4. clean exit, recorded ALARMs and stop, replay --------------------------
stop interpolator TERM
stop program-server TERM
stop monitor TERM
stop drive-bridge TERM
stop servo-sim TERM
stop logger TERM
/usr/bin/python3 - "$WORK/cell.lcmlog" "$TEST_PREFIX" "$DECEL" "$HERE" <<'PY' || fail "the recorded ALARMs are wrong"
import sys
log, prefix, decel = sys.argv[1], sys.argv[2], float(sys.argv[3])
sys.path.insert(0, sys.argv[4])
from lcmlog import events, Fields
alarms = []
for ts, ch, b in events(log):
    if ch == prefix + "ALARM":
        r = Fields(b); r.get("q"); r.get("q"); r.get("i")
        alarms.append((ts, r.str(), r.get("b"), r.str(), r.str()))
ok = True
for src in ("cnc-drive-bridge", "cnc-interpolator"):
    a = [x for x in alarms if x[1] == src and x[3] == "publish_failed"]
    print(f"# {src}: {a[0][4] if a else 'NO publish_failed ALARM'}", file=sys.stderr)
    ok = ok and len(a) >= 1 and "failed over" in a[0][4]
resets = [x for x in alarms if x[3] == "reset"]
print(f"# reset ALARMs: {len(resets)}", file=sys.stderr)
ok = ok and len(resets) >= 2
sys.exit(0 if ok else 1)
PY
# The stops, on the bridge's ticks (its trace is written as it exits). From about
# 100 mm/s (section 3: X cruising, or already slowing for diag.ngc's corner) the
# jerk-limited stop spends most of its ~80 ms ramping: from 50 mm/s on there.
/usr/bin/python3 "$HERE/stop_ticks.py" "publish failure" "$WORK/ticks.csv" "$cut_before" "$cut_after" "$DECEL" \
  "$JERK_X" "$SERVO_T" 150 "$FE_X" || fail "the axes did not come to a controlled stop after the publish failure"
/usr/bin/python3 "$HERE/stop_ticks.py" "drive fault on Y" "$WORK/ticks.csv" "$fault_before" "$fault_after" "$DECEL" \
  "$JERK_X" "$SERVO_T" 50 "$FE_X" || fail "X did not come to a controlled stop after Y's drive fault"
"$BUILD/tools/cnc-replay" --log "$WORK/cell.lcmlog" >"$WORK/replay.out" 2>&1 || { cat "$WORK/replay.out" >&2; fail "the run does not replay"; }
cat "$WORK/replay.out" >&2
echo "PASS"
