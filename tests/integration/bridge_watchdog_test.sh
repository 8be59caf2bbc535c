#!/usr/bin/env bash
# SIGKILL of the interpolator in the middle of a fast move: the drive bridge's
# watchdog stops the axes at the configured deceleration. From the simulator's
# trace (the drives' actual positions every 10 ms, wall-clock stamped): the speed
# v at the kill and the distance travelled after it must satisfy
#   distance <= v^2 / (2 * stop_decel) + v * setpoint_timeout + 0.05 mm,
# the axes must stand still afterwards, and the bridge must report why.
#   bridge_watchdog_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-bridge-watchdog.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"

# 380 mm along X at 200 mm/s (12000 mm/min): about 2 s, cruising from 0.1 s on.
cat >"$WORK/long.ngc" <<'NGC'
G21 G90
G1 X380 F12000
M30
NGC

start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --trace "$WORK/trace.csv"
start_cell --no-monitor
sim_world_steady "$WORK/trace.csv"
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/long.ngc" --timeout 30 >"$WORK/ctl.out" 2>&1 &
ctl_pid=$!
# Wait until X is past 100 mm (cruising), then kill the interpolator outright.
x=""
for ((i = 0; i < 200; i++)); do
  x=$(trace_over 2 100) && break
  sleep 0.05
done
kill_time=$(date +%s.%N)
kill_hard interpolator
kill_after=$(date +%s.%N)  # reaped: its last setpoint is out (46-58 ms measured after the time stamp)
note "interpolator SIGKILLed at X = $x mm"
expect_drive_fault "$ctl_pid" "no setpoint for"
sleep 0.5
stop program-server TERM
stop drive-bridge TERM
stop servo-sim TERM

/usr/bin/python3 - "$WORK/trace.csv" "$kill_time" "$M" "$kill_after" <<'PY' || fail "the axes did not stop within the stopping distance"
import csv, sys, re
rows = [r for r in csv.DictReader(open(sys.argv[1])) if None not in r.values()]
kill = float(sys.argv[2])
cfg = open(sys.argv[3]).read()
decel = float(re.search(r"stop_decel_mm_s2:\s*([0-9.]+)", cfg).group(1))
timeout = float(re.search(r"setpoint_timeout_s:\s*([0-9.]+)", cfg).group(1))
jerk = float(re.findall(r"^\s+max_jerk_mm_s3:\s*([0-9.]+)", cfg, re.M)[0])  # X, the first axis
landed = float(sys.argv[4]) - kill
t = [float(r["wall_s"]) for r in rows]
x = [float(r["X_mm"]) for r in rows]
v = [float(r["X_mm_s"]) for r in rows]
i = max(k for k in range(len(t)) if t[k] <= kill)
x_kill, v_kill = x[i], v[i]
x_stop = x[-1]
still = all(abs(x[k] - x_stop) < 1e-4 for k in range(len(t)) if t[k] > t[-1] - 0.3)
dist = x_stop - x_kill
# The bridge's stop is jerk-limited (its ramp adds v*a/(2j)); the interpolator
# publishes until it is reaped.
bound = v_kill ** 2 / (2 * decel) + v_kill * decel / (2 * jerk) + v_kill * (timeout + landed)
# When the axis came to rest: the first sample from which it stays within 1 um of the end.
rest = next(k for k in range(i, len(t)) if all(abs(x[j] - x_stop) < 1e-3 for j in range(k, len(t))))
print(f"# at the kill: X = {x_kill:.3f} mm at {v_kill:.1f} mm/s; stopped at X = {x_stop:.3f} mm "
      f"{(t[rest] - kill) * 1e3:.0f} ms later", file=sys.stderr)
print(f"# stopping distance {dist:.3f} mm; bound v^2/(2a) + v*a/(2j) + v*(timeout + kill) = "
      f"{v_kill**2/(2*decel):.3f} + {v_kill*decel/(2*jerk):.3f} + {v_kill*(timeout + landed):.3f} = {bound:.3f} mm "
      f"(a = {decel:g} mm/s^2, j = {jerk:g} mm/s^3, timeout = {timeout*1e3:g} ms, the kill landed after "
      f"{landed*1e3:.0f} ms)", file=sys.stderr)
ok = v_kill > 150 and 0 <= dist <= bound + 0.05 and still
sys.exit(0 if ok else 1)
PY
echo "PASS"
