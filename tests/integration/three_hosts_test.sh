#!/usr/bin/env bash
# A cell over three hosts: three network namespaces joined by a Linux bridge (one
# veth pair each, 10.77.0.1-3/24, multicast routed out on the veth), the machine
# config's LCM URL at ttl=1, one key file for all. Each host runs its part with
# `./cnc up --only ...`, as on real PCs:
#   h1: program-server, interpolator      h2: servo-sim, drive-bridge
#   h3: logger, monitor (and the operator's cnc-ctl)
# 1. The demo program (config/programs/demo.ngc) runs to its end; the simulated axes
#    end on its end point within 1 µm; the logger on h3 recorded every channel the
#    cell publishes with no sequence gap (cnc-logstat), the setpoint stream complete.
# 2. A long X move at 200 mm/s; the link of h2 is cut (its veth on the bridge set
#    down) past X = 50 (read from the trace): the drive bridge on h2 stops the axes by its watchdog at the
#    configured deceleration, within v^2/(2a) + v*timeout + 0.05 mm; its braking on its
#    own ticks (stop_ticks.py) within the deceleration and jerk and no shorter than
#    v^2/(2a) (not a hard stop); they stay still when the link is back.
#    h1 and the operator end in a fault, never "program done": today h1's
#    interpolator learns of it only when the link is back and the bridge's
#    AXIS_STATUS says FAULT (nothing watches the bridge's heartbeat yet: during the
#    cut it streams on with no alarm); when it learns is reported, not asserted.
# 3. Every `cnc up` exits 0 on SIGTERM.
#   three_hosts_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
[ -n "${CNC_IN_NETNS:-}" ] || { echo "SKIP: needs network namespaces (unshare -n)"; exit 0; }
WORK="$(mktemp -d /tmp/cnc-three-hosts.XXXXXX)"
# The simulator's trace, read as it is written to time the cut, on tmpfs: a write to
# /tmp's disk can wait seconds for writeback when other work on the PC writes a lot.
SHM="$(mktemp -d /dev/shm/cnc-three-hosts.XXXXXX)"
trap 'cleanup; { [ -d "$WORK" ] && cp "$SHM"/* "$WORK"/; } 2>/dev/null || true; rm -rf "$SHM"' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
# Multicast leaves each host: ttl=1 (one hop: the bridge is a switch, not a router).
sed -i 's#\(udpm://[^?"]*\)?ttl=0#\1?ttl=1#' "$M"
grep -q "ttl=1" "$M" || fail "the machine config's LCM URL has no ttl=0 to change"
# The simulator and the bridge talk Modbus TCP on h2's loopback; a 10 ms stall of
# this 2-core VM under the suite's load lags the simulated axes 2 mm at 200 mm/s,
# sim3's following-error limit (a fault: seen once in 3 runs with two busy loops,
# the single-host demo reached 1.54 mm). This test is about the network, not the
# servo loop: the limit is 10 mm here.
sed -i 's#max_following_error_mm: 2.0#max_following_error_mm: 10.0#' "$M"
grep -q "max_following_error_mm: 10.0" "$M" || fail "no max_following_error_mm: 2.0 in the machine config to relax"
PROGRAM="$SRC/config/programs/demo.ngc"

# The switch: this test's namespace holds the bridge; each host a namespace with one
# veth pair to it. No IGMP querier here: snooping off, the bridge floods multicast.
ip link add cncbr type bridge
ip link set cncbr type bridge mcast_snooping 0
ip link set cncbr up
for i in 1 2 3; do
  netns_host "h$i"
  ip link add "vs$i" type veth peer name "vh$i"
  ip link set "vh$i" netns "${NETNS_PID[h$i]}"
  ip link set "vs$i" master cncbr
  ip link set "vs$i" up
  ${HOST[h$i]} ip addr add "10.77.0.$i/24" dev "vh$i"
  ${HOST[h$i]} ip link set "vh$i" up
  ${HOST[h$i]} ip route add 224.0.0.0/4 dev "vh$i"
done
note "three hosts on bridge cncbr: h1 10.77.0.1, h2 10.77.0.2, h3 10.77.0.3"

up() {  # up NAME HOST SERVICES [ARGS...]: ./cnc up --only SERVICES on HOST
  local name="$1" host="$2" only="$3"; shift 3
  start "$name" ${HOST[$host]} env CNC_BUILD_DIR="$BUILD" "$SRC/cnc" up --machine "$M" --only "$only" "$@"
}
up up-h3 h3 logger,monitor --log-out "$WORK/h3"
up up-h2 h2 servo-sim,drive-bridge --sim-final-state "$WORK/final.json"
up up-h1 h1 program-server,interpolator

# 1. The demo, commanded from h3.
t0=$(date +%s.%N)
rc=0
${HOST[h3]} "$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$PROGRAM" --timeout 120 >"$WORK/ctl.out" 2>&1 || rc=$?
t1=$(date +%s.%N)
cat "$WORK/ctl.out" >&2
[ "$rc" -eq 0 ] || { tail -n 20 "$WORK"/up-h*.log >&2; fail "the demo did not complete over three hosts (cnc-ctl exit $rc)"; }
grep -q "program done" "$WORK/ctl.out" || fail "no completion report"
note "demo over three hosts: cnc-ctl $(awk -v a="$t0" -v b="$t1" 'BEGIN{printf "%.1f", b-a}') s"
# Every host sees every service: the cell's status from h3 names each on its host,
# with this build's version.
${HOST[h3]} "$BUILD/tools/cnc-ctl" --machine "$M" --do status >"$WORK/status.out" 2>&1 || { cat "$WORK/status.out" >&2; fail "cnc-ctl --do status on h3"; }
cat "$WORK/status.out" >&2
version="$("$BUILD/tools/cnc-ctl" --version | awk '{print $2}')"
for sh in cnc-program-server:h1 cnc-interpolator:h1 cnc-drive-bridge:h2 cnc-logger:h3 cnc-monitor:h3; do
  status_lists "$WORK/status.out" "${sh%%:*}" "${sh##*:}" "$version" || fail "status on h3 does not list ${sh%%:*} running on ${sh##*:} with version $version"
done
# The log of this run ends here: h3's part stops (the logger last), and starts again
# for the second part with a new log.
stop up-h3 TERM
"$BUILD/tools/cnc-logstat" --log "$WORK/h3.lcmlog" --summary --machine "$M" >"$WORK/logstat.out" 2>&1 \
  || { cat "$WORK/logstat.out" >&2; fail "the log on h3 does not verify"; }
cat "$WORK/logstat.out" >&2
# Every channel the cell publishes, each with events and no sequence gap or restart
# as the logger on h3 counted them.
/usr/bin/python3 - "$WORK/logstat.out" "$TEST_PREFIX" <<'PY' || fail "the log on h3 misses a channel or has sequence gaps (table above)"
import re, sys
text = open(sys.argv[1]).read()
prefix = sys.argv[2]
table = text.split(" events in ")[0]
rows = {l.split()[0][len(prefix):]: list(map(int, l.split()[1:5])) for l in table.splitlines() if l.startswith(prefix)}
want = ["SETPOINTS", "AXIS_STATUS", "PROGRAM_BLOCKS", "PROGRAM_CMD", "PROGRAM_STATE", "BLOCK_REQUEST",
        "INTERP_INPUT", "INTERP_STATE", "INTERP_CONFIG", "MONITOR", "HEARTBEAT", "LOGGER_STATS"]  # ALARM: when one is raised
missing = [w for w in want if w not in rows]
gaps = {c: r[2] for c, r in rows.items() if r[2] or r[3]}
# The heartbeats' counts, from every receiver on every host (reported, not required).
others = re.findall(r"^\s+" + re.escape(prefix) + r"(\S+)\s+(.*)$", text.split("sequence gaps")[1].split("dropped")[0], re.M)
nonzero = [f"{c}: {r}" for c, r in others if re.search(r" [1-9]", r)]
print(f"# h3's log: {len(rows)} channels, {sum(r[0] for r in rows.values())} events, gaps {sum(r[2] for r in rows.values())}"
      f", restarts {sum(r[3] for r in rows.values())}; receivers on h1/h2/h3 reporting gaps: {nonzero or 'none'}", file=sys.stderr)
if missing: print(f"# missing channels: {missing}", file=sys.stderr)
if gaps: print(f"# gaps or restarts: {gaps}", file=sys.stderr)
sys.exit(1 if missing or gaps else 0)
PY
grep -qE "blocks +22 of 22 done \(sent 22," "$WORK/logstat.out" || fail "the log on h3 does not show the demo's 22 blocks done"
# The simulator's final positions (h2's part stops: it writes them) on the demo's end point.
stop up-h2 TERM
note "final positions on h2: $(cat "$WORK/final.json")"
final_at "$WORK/final.json" 0 0 0 || fail "the axes do not end on the demo's end point within 1 µm"

# 2. Cut h2's link mid-program. h2's and h3's parts start again (a new trace and log);
# h1 carries on, standing where the demo ended (0, 0, 0), as does the new simulator.
up up-h3 h3 logger,monitor --log-out "$WORK/h3-cut"
# The bridge's ticks (written as it exits): its stop, on its own clock.
export CNC_BRIDGE_DEBUG_TRACE="$WORK/ticks-cut.csv"
up up-h2 h2 servo-sim,drive-bridge --sim-trace "$SHM/trace.csv"
unset CNC_BRIDGE_DEBUG_TRACE
# 380 mm along X at 200 mm/s, back and again: about 6 s, cruising from 0.1 s on
# (the link is back long before the program would end).
cat >"$WORK/long.ngc" <<'NGC'
G21 G90
G1 X380 F12000
G1 X10
G1 X380
M30
NGC
${HOST[h3]} "$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/long.ngc" --timeout 30 >"$WORK/ctl-cut.out" 2>&1 &
ctl_pid=$!
# The cut: as soon as the simulator's trace (a row every 10 ms) shows X past 50 mm
# cruising. The rows are read as they are written, from the end of the file (no
# backlog), by bash's read (unbuffered; mawk reading a pipe waits for a block).
x=""
while IFS=, read -r w xm xv rest; do
  [[ "$xm" =~ ^-?[0-9]+\.[0-9]+$ && "$xv" =~ ^-?[0-9]+\.[0-9]+$ ]] || continue
  if [ "${xm%.*}" -ge 50 ] && [ "${xv%.*}" -ge 150 ]; then x="$xm"; xw="$w"; break; fi
done < <(timeout 20 tail -s 0.01 -n 0 -F "$SHM/trace.csv" 2>/dev/null)
[ -n "$x" ] || fail "X never passed 50 mm at more than 150 mm/s"
ip link set vs2 down
cut_ns=$(date +%s%N)
cut_time="${cut_ns:0:10}.${cut_ns:10}"
note "h2's link cut (vs2 down) at X = $x mm by the trace, $(awk -v a="$xw" -v b="$cut_time" 'BEGIN{printf "%.0f", (b-a)*1e3}') ms after that row"
# The link stays down until the axes have stood still for 0.3 s (30 trace rows at
# rest after the cut; at most 10 s), then 0.5 s more.
n=0
while IFS=, read -r w xm xv rest; do
  [[ "$w" =~ ^[0-9]+\.[0-9]{4}$ ]] && [ "${w/./}" -gt "${cut_ns:0:14}" ] || continue
  if [[ "$xv" =~ ^-?0\.0+$ ]]; then n=$((n + 1)); else n=0; fi
  [ "$n" -ge 30 ] && break
done < <(timeout 10 tail -s 0.01 -n 0 -F "$SHM/trace.csv" 2>/dev/null)
sleep 0.5
ip link set vs2 up
relink_time=$(date +%s.%N)
note "h2's link back up $(awk -v a="$cut_time" -v b="$relink_time" 'BEGIN{printf "%.2f", b-a}') s after the cut"
ctl_rc=0
wait "$ctl_pid" || ctl_rc=$?
# The axes stay where they stopped after the link is back: 1 s of trace after it.
sleep 1
stop up-h1 TERM
stop up-h2 TERM
stop up-h3 TERM
cat "$WORK/ctl-cut.out" >&2
grep -h "no setpoint for\|fault\|FAULT" "$WORK/up-h2.log" | head -5 >&2 || true

/usr/bin/python3 - "$SHM/trace.csv" "$cut_time" "$relink_time" "$M" <<'PY' || fail "the axes did not stop at the configured deceleration within the stopping distance"
import csv, re, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if None not in r.values()]
cut, relink = float(sys.argv[2]), float(sys.argv[3])
cfg = open(sys.argv[4]).read()
decel = min(float(re.search(r"stop_decel_mm_s2:\s*([0-9.]+)", cfg).group(1)),
            float(re.search(r"max_accel_mm_s2:\s*([0-9.]+)", cfg).group(1)))  # X's limit is the first
timeout = float(re.search(r"setpoint_timeout_s:\s*([0-9.]+)", cfg).group(1))
t = [float(r["wall_s"]) for r in rows]
x = [float(r["X_mm"]) for r in rows]
v = [float(r["X_mm_s"]) for r in rows]
i = max(k for k in range(len(t)) if t[k] <= cut)
x_cut, v_cut = x[i], v[i]
before = [k for k in range(len(t)) if t[k] <= relink]
x_stop = x[before[-1]]
after = [x[k] for k in range(len(t)) if t[k] > relink]
moved_after = max((abs(a - x_stop) for a in after), default=0.0)
sign = 1.0 if v_cut >= 0 else -1.0
dist = (x_stop - x_cut) * sign
v_cut = abs(v_cut)
# The bound takes the fastest the drive went after the cut: under load a simulated
# drive that lagged its commands at the cut (170 mm/s against 200 commanded, seen
# once) catches up after it (218 mm/s), and that lag is distance the stop must cover.
vmax = max(abs(v[k]) for k in range(i, before[-1] + 1))
v_bound = max(v_cut, vmax)
brake = v_bound ** 2 / (2 * decel)
bound = brake + v_bound * timeout
rest = next(k for k in range(i, len(t)) if all(abs(x[j] - x_stop) < 1e-3 for j in range(k, before[-1] + 1)))
print(f"# at the cut: X = {x_cut:.3f} mm at {v_cut:.1f} mm/s; stopped at X = {x_stop:.3f} mm "
      f"{(t[rest] - cut) * 1e3:.0f} ms later", file=sys.stderr)
print(f"# stopping distance {dist:.3f} mm; bound v^2/(2a) + v*timeout = {brake:.3f} + {v_bound * timeout:.3f} = "
      f"{bound:.3f} mm (a = {decel:g} mm/s^2, timeout {timeout * 1e3:g} ms)", file=sys.stderr)
print(f"# after the link came back: {len(after)} trace rows, largest move {moved_after * 1e3:.4f} µm", file=sys.stderr)
ok = v_cut > 150 and 0 <= dist <= bound + 0.05 and len(after) >= 20 and moved_after < 1e-4
sys.exit(0 if ok else 1)
PY
# The braking itself, on the bridge's ticks: within the stop deceleration and jerk,
# no shorter than v^2/(2a) (not a hard stop), the drive following it. (Read off the
# simulator's world in seconds it once read 2,560 mm/s^2 for 2,000: the world stands
# while the stream is late and the bridge's playback catches up after.)
DECEL=$(sed -n 's/^ *stop_decel_mm_s2: *\([0-9.]*\).*/\1/p' "$M")
JERK_X=$(sed -n 's/^ *max_jerk_mm_s3: *\([0-9.]*\).*/\1/p' "$M" | head -n 1)
FE_X=$(sed -n 's/^ *max_following_error_mm: *\([0-9.]*\).*/\1/p' "$M" | head -n 1)
SERVO_T=$(sed -n 's/^ *servo_period_s: *\([0-9.]*\).*/\1/p' "$M")
/usr/bin/python3 "$(dirname "$0")/stop_ticks.py" "cut of h2's link" "$WORK/ticks-cut.csv" "$cut_time" "$cut_time" \
  "$DECEL" "$JERK_X" "$SERVO_T" 150 "$FE_X" 0 0.1 || fail "the bridge on h2 did not brake at the configured deceleration"
grep -q "no setpoint for" "$WORK/up-h2.log" || fail "the drive bridge on h2 did not report the lost setpoint stream"
# h1 and the operator: a fault, never "program done". Today h1 learns of the stop
# only when the link is back (the drive bridge's AXIS_STATUS in FAULT); nothing
# watches the bridge's heartbeat while the link is down.
grep -q "program done" "$WORK/ctl-cut.out" && fail "cnc-ctl reported the cut program done"
[ "$ctl_rc" -ne 0 ] || fail "cnc-ctl exited 0 on the cut program"
grep -q "\] fault: " "$WORK/up-h1.log" || fail "the interpolator on h1 never went to FAULT"
/usr/bin/python3 - "$WORK/up-h1.log" "$cut_time" "$relink_time" <<'PY' >&2 || true
import re, sys, time
cut, relink = float(sys.argv[2]), float(sys.argv[3])
line = next(l for l in open(sys.argv[1]) if "] fault: " in l)
hms = re.match(r"(\d+):(\d+):(\d+\.\d+)", line)
day = cut - cut % 86400  # the logs print UTC times of day here (spdlog, TZ unset)
t = day + int(hms.group(1)) * 3600 + int(hms.group(2)) * 60 + float(hms.group(3))
print(f"# h1's interpolator faulted {t - cut:.3f} s after the cut, {t - relink:+.3f} s from the relink: "
      f"{line.split('] ', 1)[1].strip()}")
PY
note "cnc-ctl on h3 exited $ctl_rc: $(grep -v "^ALARM\|^loaded" "$WORK/ctl-cut.out" | tail -n 1)"
# What h3 recorded across the cut: the messages of h2 lost while it was cut off.
"$BUILD/tools/cnc-logstat" --log "$WORK/h3-cut.lcmlog" >"$WORK/logstat-cut.out" 2>&1 || true
note "h3's log across the cut: $(awk -v p="$TEST_PREFIX" '$1 == p"AXIS_STATUS" || $1 == p"SETPOINTS" {printf "%s %s events %s gaps; ", $1, $2, $4}' "$WORK/logstat-cut.out")"
# CNC_KEEP_WORK=1 keeps the logs, traces and outputs (e.g. to compare with a single-host run).
if [ -n "${CNC_KEEP_WORK:-}" ]; then cp "$SHM/trace.csv" "$WORK/"; note "kept $WORK"; else rm -rf "$WORK"; fi
echo "PASS"
