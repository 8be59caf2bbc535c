#!/usr/bin/env bash
# The whole cell (logger, simulator, drive bridge, monitor, program server,
# interpolator) runs one program against the simulator with the CiA-402-style and
# the Leadshine-style drive profile, over Modbus TCP or Modbus RTU (a socat
# pseudo-terminal pair standing in for the RS-485 line). The only difference
# between the runs is the machine config, and the configs differ from sim3.yaml
# only in their drive lines (checked). Each run must complete, end on the
# program's end point within 1 µm, and count no exception and no lost link; over
# RTU three replies with a corrupted CRC are then injected and must be counted.
#   bridge_profiles_test.sh tcp|rtu BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
TRANSPORT="$1"; BUILD="$2"; SRC="$3"
WORK="$(mktemp -d /tmp/cnc-bridge-profiles.XXXXXX)"
trap 'cleanup' EXIT

cat >"$WORK/part.ngc" <<'NGC'
( bridge profiles: lines in all axes, end X 123.4567 Y 45.6789 Z -7 )
G21 G90
G0 X5 Y5 Z1
G1 Z-2 F600
G1 X80 Y20 F3000
G1 X80.5 Y45.6789 Z-4
G91 G1 X20 Z-3 F2400
G90 G1 X123.4567 F1800
M30
NGC

# The monitor is part of the cell but not under test here: one that does not exit
# on SIGTERM within 10 s is noted and killed (integration.cell checks its exit).
stop_monitor() {
  local pid="${TEST_PIDS[monitor]}" i
  kill -TERM "$pid" 2>/dev/null || true
  for ((i = 0; i < 100; i++)); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
  if kill -0 "$pid" 2>/dev/null; then
    note "NOTE: cnc-monitor did not exit within 10 s of SIGTERM; killed"
    kill -KILL "$pid"
  fi
  wait "$pid" 2>/dev/null || true
  unset "TEST_PIDS[monitor]"
}

for profile in cia402 leadshine; do
  cfg="$SRC/config/machines/sim3_${profile}_${TRANSPORT}.yaml"
  [ -f "$cfg" ] || fail "no machine config $cfg"
  # Only drive lines (and comments) differ from sim3.yaml.
  if diff "$SRC/config/machines/sim3.yaml" "$cfg" | grep -E '^[<>]' | grep -vE '^[<>] *(#|drive: \{)' >&2; then
    fail "$cfg differs from sim3.yaml in more than its drive lines"
  fi
  M="$WORK/$profile.yaml"
  make_machine "$cfg" "$M"
  if [ "$TRANSPORT" = rtu ]; then
    # The "line" is a pty pair: the kernel moves its bytes in a worker thread of normal
    # priority (the tty flip buffer's work), which the real-time services cannot
    # protect. With both cores loaded (two busy loops) the line was late by up to
    # ~100 ms: following errors of 1.0 and 4.7 mm at 50 mm/s, a fault over the 2 mm
    # limit in 1 of 2 runs; with those workers made SCHED_FIFO by hand, 4 of 4 passed.
    # A real RS-485 driver has no such worker in its path. This test is about the
    # profiles and the protocol over RTU, so its copy allows 20 mm; the end point is
    # still checked to 1 um, and the TCP runs and the demo keep 2 mm.
    sed -i -E 's/^( *max_following_error_mm:) *[0-9.]+/\1 20.0/' "$M"
    [ "$(grep -c 'max_following_error_mm: 20.0' "$M")" -eq 3 ] || fail "cannot set the following-error limit in $M"
  fi
  sim_args=()
  if [ "$TRANSPORT" = rtu ]; then
    # socat relays every byte of the "line": real-time like the cell's services when permitted.
    rt=(); chrt -f 39 true 2>/dev/null && rt=(chrt -f 39)
    start socat "${rt[@]}" socat pty,raw,echo=0,link="$WORK/tty-bridge" pty,raw,echo=0,link="$WORK/tty-sim"
    for ((i = 0; i < 50; i++)); do [ -e "$WORK/tty-sim" ] && [ -e "$WORK/tty-bridge" ] && break; sleep 0.1; done
    [ -e "$WORK/tty-sim" ] || fail "socat made no pseudo-terminal pair"
    sed -i "s#device: /tmp/cnc-rtu-bridge#device: $WORK/tty-bridge#" "$M"
    sim_args=(--device "$WORK/tty-sim" --control "$WORK/sim.ctl")
  fi
  start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/$profile"
  start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" "${sim_args[@]}" --final-state "$WORK/$profile.final.json"
  start drive-bridge "$BUILD/services/cnc-drive-bridge" --machine "$M"
  start monitor "$BUILD/services/cnc-monitor" --machine "$M"
  start program-server "$BUILD/services/cnc-program-server" --machine "$M"
  start interpolator "$BUILD/services/cnc-interpolator" --machine "$M"
  rc=0
  "$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/part.ngc" --timeout 60 >"$WORK/ctl.out" 2>&1 || rc=$?
  cat "$WORK/ctl.out" >&2
  [ "$rc" -eq 0 ] || { cat "$WORK/drive-bridge.log" >&2; fail "$profile over $TRANSPORT: program did not complete (cnc-ctl exit $rc)"; }
  stop_monitor
  crc_injected=0
  if [ "$TRANSPORT" = rtu ]; then
    # Three replies with a corrupted CRC: counted as CRC errors, nothing else happens.
    echo "crc 3" >"$WORK/sim.ctl"
    crc_injected=3
    sleep 0.5
  fi
  stop interpolator TERM
  stop program-server TERM
  stop drive-bridge TERM
  stop servo-sim TERM
  stop logger TERM
  if [ "$TRANSPORT" = rtu ]; then kill "${TEST_PIDS[socat]}"; wait "${TEST_PIDS[socat]}" || true; unset "TEST_PIDS[socat]"; fi
  grep -q "profile ${profile}" "$WORK/servo-sim.log" || fail "the simulator did not serve the $profile profile"
  grep -E "axis [XYZ]: [0-9]+ transactions" "$WORK/drive-bridge.log" | sed "s/^/# $profile $TRANSPORT: /" >&2
  /usr/bin/python3 - "$WORK/drive-bridge.log" "$crc_injected" <<'PY' || fail "$profile over $TRANSPORT: exceptions or lost links, or the CRC errors miscounted"
import re, sys
rows = re.findall(r"axis [XYZ]: \d+ transactions, (\d+) timeouts, (\d+) exceptions, (\d+) CRC errors, (\d+) other errors, (\d+) reconnects", open(sys.argv[1]).read())
crc = sum(int(r[2]) for r in rows)
exc = sum(int(r[1]) for r in rows)
reconnects = sum(int(r[4]) for r in rows)
slow = sum(int(r[i]) for r in rows for i in (0, 3))
# Timeouts and garbled answers may happen on a loaded test machine: they are
# counted (that is the point) and must not stop the program.
print(f"# CRC errors counted {crc} (injected {sys.argv[2]}); exceptions {exc}, reconnects {reconnects}, "
      f"timeouts and garbled answers {slow}", file=sys.stderr)
sys.exit(0 if len(rows) == 3 and crc == int(sys.argv[2]) and exc == 0 and reconnects == 0 else 1)
PY
  /usr/bin/python3 - "$WORK/$profile.final.json" "$profile" "$TRANSPORT" <<'PY' || fail "$profile over $TRANSPORT: final positions off the end point by more than 1 µm"
import json, sys
pos = json.load(open(sys.argv[1]))
end = {"X": 123.4567, "Y": 45.6789, "Z": -7.0}
worst = max(abs(pos[a] - end[a]) for a in end)
print(f"# {sys.argv[2]} over {sys.argv[3]}: final {pos}, largest deviation {worst*1000:.4f} µm (tolerance 1 µm)", file=sys.stderr)
sys.exit(0 if worst <= 1e-3 else 1)
PY
  note "$profile over $TRANSPORT: $(grep 'program done' "$WORK/ctl.out")"
done
echo "PASS"
