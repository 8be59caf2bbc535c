# Shared by the integration tests: a private network namespace when the machine
# allows it (and private ports in any case), a private copy of the machine config,
# and helpers to start and stop the real executables.
set -euo pipefail

# fail MESSAGE: the test fails; the last warnings and errors of each service's log in
# $WORK go with it (CI keeps only the test's output, and a flake must be diagnosable
# from that: a following-error fault under load said only "did not report held").
fail() {
  echo "FAIL: $*" >&2
  if [ -n "${WORK:-}" ] && [ -d "$WORK" ]; then
    local f
    for f in "$WORK"/*.log; do
      [ -f "$f" ] || continue
      grep -E "\[(warning|error|critical)\]" "$f" | tail -n 5 | sed "s#^#  $(basename "$f"): #" >&2 || true
    done
  fi
  exit 1
}
note() { echo "# $*" >&2; }

# Re-executes the calling script inside a new network namespace with multicast on
# loopback, unless already inside one or unshare is not permitted here.
enter_private_netns() {
  if [ -z "${CNC_IN_NETNS:-}" ] && unshare -n true 2>/dev/null; then
    export CNC_IN_NETNS=1
    exec unshare -n bash -c 'ip link set lo up && ip route add 224.0.0.0/4 dev lo && exec "$0" "$@"' "$0" "$@"
  fi
  if [ -n "${CNC_IN_NETNS:-}" ]; then note "private network namespace"; else note "no namespace: private ports only"; fi
}

# make_machine SRC DST: a copy of SRC with private LCM and Modbus ports and a
# private channel prefix, so parallel tests never see each other.
make_machine() {
  local src="$1" dst="$2"
  local base=$(( (RANDOM % 2000) * 10 + 20000 ))
  export TEST_LCM_PORT=$base TEST_MODBUS_PORT=$((base + 1))
  sed -e "s#udpm://239.255.76.67:7667#udpm://239.255.76.67:${TEST_LCM_PORT}#" \
      -e "s#port: 1502#port: ${TEST_MODBUS_PORT}#g" \
      -e "s#channel_prefix: \"SIM3.\"#channel_prefix: \"T${base}.\"#" "$src" >"$dst"
  export TEST_PREFIX="T${base}."
  # Signing on (security.key_file, relative to the config): the test's own key beside the copy.
  local key
  key="$(sed -n 's/^ *key_file: *\([^ #]*\).*/\1/p' "$dst")"
  if [ -n "$key" ]; then
    case "$key" in /*) ;; *) key="$(dirname "$dst")/$key" ;; esac
    "$BUILD/tools/cnc-key" gen --file "$key" --if-missing >/dev/null || fail "cannot make the key $key"
    export TEST_KEY="$key"
  fi
}

# unsigned_machine SRC DST: SRC with signing off. lcm-logplayer playing a log back
# is a replay: a signing cell drops every message of it (too old, sequence not
# newer); an analysis cell that is fed a recorded log runs unsigned.
unsigned_machine() {
  sed -e 's#^\( *signing:\) *true#\1 false#' "$1" >"$2"
  grep -qE '^ *signing: false' "$2" || fail "unsigned_machine: no 'signing: true' in $1"
}

declare -A TEST_PIDS=()
# start NAME EXECUTABLE ARGS...: starts a process with its output in $WORK/NAME.log
start() {
  local name="$1"; shift
  "$@" >"$WORK/$name.log" 2>&1 &
  TEST_PIDS[$name]=$!
}

# sim_world_steady TRACE: waits (at most 15 s) until the simulator's world clock has run
# at 0.95 of the wall's or better over the trace's last half second. A measurement on
# the simulated world's time needs it: in a cell's first second the world stands up to
# 30 % of the time (the bridge's stream late for the drives' buffer), and stop_trace.py
# refuses a trace below 0.8 (0.748 and 0.788 seen right after start).
sim_world_steady() {
  local i
  for ((i = 0; i < 150; i++)); do
    # The last 2 s of rows but the last (it may be half written); awk, not a python
    # per poll (a python start takes 100 ms and more under two busy loops).
    tail -n 200 "$1" 2>/dev/null | head -n -1 | awk -F, '
      $1 ~ /^[0-9.]+$/ && $NF ~ /^[0-9.]+$/ { n++; w[n] = $1; s[n] = $NF }
      END {
        if (n < 60) exit 1
        for (k = n; k >= 1; k--) if (w[n] - w[k] >= 0.5) exit !((s[n] - s[k]) / (w[n] - w[k]) >= 0.95)
        exit 1
      }' && return 0
    sleep 0.1
  done
  note "the simulator's world clock stayed below 0.95 of the wall's for 15 s"
}

# trace_over COLUMN LIMIT [TRACE]: the servo simulator's trace ($WORK/trace.csv) shows
# COLUMN (1-based: 2 X, 5 Y, 8 Z) above LIMIT in its last whole row; prints the value.
trace_over() {
  tail -n 2 "${3:-$WORK/trace.csv}" 2>/dev/null | head -n 1 |
    awk -F, -v c="$1" -v lim="$2" '$c ~ /^-?[0-9.]+$/ && $c + 0 > lim + 0 { print $c; found = 1 } END { exit !found }'
}

# stimulus_rt on|off: the test's own shell (and what it starts) as a real-time process
# (SCHED_FIFO 30, below the cell's 40/41) while it times a stimulus against the
# motion, and back. Under two busy loops the shell's polls of the trace came 0.6 s
# late at normal priority: a cut meant for X = 100 mm landed after the 380 mm move
# had ended (fault_reset, a 50-run). Without the privilege it stays as it is.
stimulus_rt() {
  if [ "$1" = on ]; then chrt -f -p 30 $$ 2>/dev/null || note "no SCHED_FIFO for the test's shell"
  else chrt -o -p 0 $$ 2>/dev/null || true; fi
}

# services_list: config/services.txt, the cell's services in start order (name, executable).
services_list() { grep -v -e '^[[:space:]]*#' -e '^[[:space:]]*$' "$(dirname "${BASH_SOURCE[0]}")/../../config/services.txt"; }

# start_cell [--no-monitor]: the cell's services on machine $M, as every live test
# starts them, in the list's order: all but the logger and the drives (servo-sim, with
# each test's own options), which the test starts first itself, and the HMI, the
# OPC UA server and the MQTT publisher, which only their own tests start; the monitor
# unless --no-monitor.
start_cell() {
  local s exe
  while read -r s exe _; do
    case "$s" in logger|servo-sim|hmi|opcua|mqtt) continue ;; esac
    [ "$s" = monitor ] && [ "${1:-}" = --no-monitor ] && continue
    start "$s" "$BUILD/$exe" --machine "$M"
  done < <(services_list)
}

# stop NAME SIGNAL: signals the process and checks that it exits 0 within 10 s.
stop() {
  local name="$1" sig="${2:-TERM}" pid="${TEST_PIDS[$1]}"
  kill -"$sig" "$pid" 2>/dev/null || fail "$name (pid $pid) was not running at stop"
  local i
  for ((i = 0; i < 100; i++)); do
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.1
  done
  kill -0 "$pid" 2>/dev/null && { kill -KILL "$pid"; fail "$name did not exit within 10 s of SIG$sig"; }
  local rc=0
  wait "$pid" || rc=$?
  unset "TEST_PIDS[$name]"
  [ "$rc" -eq 0 ] || { cat "$WORK/$name.log" >&2; fail "$name exited with status $rc on SIG$sig"; }
  note "$name exited 0 on SIG$sig"
}

# cleanup [STATUS]: kills what the test started; the test's folder goes when it passed
# (STATUS, else the exit status the EXIT trap was called with) and stays, named, when
# it failed or CNC_KEEP_WORK is set (a soak or a loop of runs otherwise fills /tmp).
cleanup() {
  local rc="${1:-$?}" name
  for name in "${!TEST_PIDS[@]}"; do kill -KILL "${TEST_PIDS[$name]}" 2>/dev/null || true; done
  for name in "${!TEST_PIDS[@]}"; do wait "${TEST_PIDS[$name]}" 2>/dev/null || true; done
  [ -n "${WORK:-}" ] && [ -d "$WORK" ] || return 0
  if [ "$rc" -eq 0 ] && [ -z "${CNC_KEEP_WORK:-}" ]; then
    rm -rf "$WORK" 2>/dev/null || true
  else
    note "the test's files are kept in $WORK"
    # A watchdog that tripped cannot tell a stalled publisher from a stalled
    # delivery; the run's log can (cnc-logstat --delivery).
    local log
    for log in "$WORK"/*.lcmlog; do
      [ -f "$log" ] && [ -x "${BUILD:-}/tools/cnc-logstat" ] || continue
      "$BUILD/tools/cnc-logstat" --log "$log" --delivery 2>&1 | grep -E "^delivery stalls|^  at .*delivery stalled" | sed "s|^|# $(basename "$log"): |" >&2 || true
    done
  fi
}

# kill_hard NAME: SIGKILL a started process and forget it.
kill_hard() {
  local pid="${TEST_PIDS[$1]}"
  kill -KILL "$pid"
  wait "$pid" 2>/dev/null || true
  unset "TEST_PIDS[$1]"
}

# expect_drive_fault CTL_PID PATTERN: cnc-ctl (output in $WORK/ctl.out) ends with
# exit 5, a drive fault whose report matches PATTERN.
expect_drive_fault() {
  local rc=0
  wait "$1" || rc=$?
  cat "$WORK/ctl.out" >&2
  [ "$rc" -eq 5 ] || fail "cnc-ctl exit $rc, expected 5 (drive fault)"
  grep -q "$2" "$WORK/ctl.out" || fail "the bridge did not report '$2'"
}

# final_at FILE X Y Z: the simulator's final positions (by axis name, from --final-state)
# within 1 µm of (X, Y, Z); prints the largest deviation.
# settle_at TRACE X Y Z: waits (at most 5 s) until the simulator's trace (--trace,
# or `cnc up --sim-trace`) shows the axes within 0.5 um of X Y Z. cnc-ctl reports a
# program done once they stand within 10 um; the drive bridge's limiter settles the
# last micrometres after that (a 1.5 um overshoot at the end of a jerk-limited stop).
# Stopping the simulator at once froze the axes 1.1-1.2 um from the end point
# (integration.kill_* and integration.netem_cell, 1 of 10 suite runs each). A trace
# that never settles is only noted: final_at decides.
settle_at() {
  /usr/bin/python3 - "$@" <<'PY' || note "the axes did not settle within 0.5 um of the end point in 5 s"
import sys, time
path, end = sys.argv[1], [float(v) for v in sys.argv[2:5]]
deadline = time.monotonic() + 5.0
while time.monotonic() < deadline:
    try:
        lines = open(path).read().splitlines()
    except OSError:
        lines = []
    f = lines[-2].split(",") if len(lines) > 2 else []   # the last whole row
    if len(f) >= 10:
        pos = [float(f[1]), float(f[4]), float(f[7])]
        if max(abs(p - e) for p, e in zip(pos, end)) < 5e-4:
            sys.exit(0)
    time.sleep(0.02)
sys.exit(1)
PY
}

final_at() {
  /usr/bin/python3 - "$@" <<'PY'
import json, sys
pos = json.load(open(sys.argv[1]))
end = dict(zip("XYZ", map(float, sys.argv[2:5])))
worst = max(abs(pos[a] - end[a]) for a in end)
print(f"# largest end-point deviation {worst*1000:.4f} µm (tolerance 1 µm)", file=sys.stderr)
sys.exit(0 if worst <= 1e-3 else 1)
PY
}

# status_lists FILE SERVICE HOST VERSION: `cnc-ctl --do status` output FILE lists
# SERVICE running on HOST with VERSION.
status_lists() {
  awk -v s="$2" -v h="$3" -v v="$4" '$1 == s && $2 == h && $4 == v && $5 == "running" {ok = 1} END {exit !ok}' "$1"
}

# netns_host NAME [MCAST_DEV]: a network namespace standing for one host, held by a
# sleeping process (registered like a started process, so cleanup removes it), with
# its loopback up; with MCAST_DEV "lo", multicast goes out on the loopback (a host
# with nothing but its own services and, for example, cnc-netem beside it). Sets
# NETNS_PID[NAME] and HOST[NAME], the prefix that runs a command inside:
#   start logger ${HOST[h3]} "$BUILD/services/cnc-logger" ...   (nsenter execs it: its pid is the logger's)
#   ${HOST[h2]} ip addr add 10.77.0.2/24 dev vh2
declare -A NETNS_PID=() HOST=()
netns_host() {
  local name="$1" dev="${2:-}" ready="$WORK/netns-$1.pid"
  local setup='ip link set lo up'
  [ "$dev" = lo ] && setup="$setup && ip route add 224.0.0.0/4 dev lo"
  # Its own network and host name (UTS namespace): a PC of its own, named NAME.
  unshare -n -u bash -c "hostname '$name' && $setup"' && echo $$ >"$0" && exec sleep 3600' "$ready" &
  TEST_PIDS[netns-$name]=$!
  disown "$!"  # killed by cleanup without a job report
  local i
  for ((i = 0; i < 500; i++)); do [ -s "$ready" ] && break; sleep 0.01; done
  [ -s "$ready" ] || fail "network namespace $name was not set up"
  NETNS_PID[$name]=$(cat "$ready")
  HOST[$name]="nsenter -t ${NETNS_PID[$name]} -n -u --"
}

# Operator commands through cnc-ctl (the array CTL holds its command and --machine).
# expect_refused NAME PATTERN CMD...: cnc-ctl exits 3 with PATTERN in its message.
expect_refused() {
  local name="$1" pattern="$2"; shift 2
  local rc=0
  "$@" >"$WORK/$name.out" 2>&1 || rc=$?
  [ "$rc" -eq 3 ] || { cat "$WORK/$name.out" >&2; fail "$name: cnc-ctl exit $rc, expected 3 (refused)"; }
  grep -q -- "$pattern" "$WORK/$name.out" || { cat "$WORK/$name.out" >&2; fail "$name: no '$pattern' in the refusal"; }
  note "$name refused: $(grep -- "$pattern" "$WORK/$name.out" | head -1)"
}
# ok NAME CMD...: cnc-ctl exits 0; its output in $WORK/NAME.out.
ok() {
  local name="$1"; shift
  local rc=0
  "$@" >"$WORK/$name.out" 2>&1 || rc=$?
  [ "$rc" -eq 0 ] || { cat "$WORK/$name.out" >&2; fail "$name: cnc-ctl exit $rc"; }
  note "$name: $(grep -vE '^ALARM' "$WORK/$name.out" | tail -1)"
}
# wait_state STATE: the interpolator reports STATE in `cnc-ctl --do status` (at most
# 100 tries of 0.2 s).
wait_state() {
  local i
  for ((i = 0; i < 100; i++)); do
    "${CTL[@]}" --do status --timeout 0.2 >"$WORK/status.out" 2>&1 || true
    grep -q "^interpolator: $1," "$WORK/status.out" && return 0
  done
  cat "$WORK/status.out" >&2
  fail "the interpolator did not report $1"
}
