#!/usr/bin/env bash
# The simulator is SIGKILLed in the middle of a move and started again (its drives
# keep their positions, like absolute encoders: --persist). The drive bridge must
# report the lost link as a fault, reconnect on its back-off schedule (counted),
# and keep every drive disabled and still until ENABLE; after ENABLE the drives are
# enabled and hold. Then faults are injected into the running simulator through
# its control FIFO: Modbus exceptions and late replies are counted and are not
# fatal (mb2hal quits on a failed transaction; this bridge goes on).
#   bridge_reconnect_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-bridge-reconnect.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")

cat >"$WORK/long.ngc" <<'NGC'
G21 G90
G1 X300 Y200 F6000
M30
NGC
sim() { start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --persist "$WORK/positions.json" \
          --trace "$WORK/trace$1.csv" --control "$WORK/sim.ctl"; }
# Largest change of any axis over the trace's rows from time $2 on, and whether any drive was on.
moved() {
  /usr/bin/python3 - "$1" "$2" <<'PY'
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if None not in r.values() and float(r["wall_s"]) >= float(sys.argv[2])]
axes = [k[:-3] for k in rows[0] if k.endswith("_mm")]
span = max(max(float(r[a + "_mm"]) for r in rows) - min(float(r[a + "_mm"]) for r in rows) for a in axes)
on = max(int(r[a + "_on"]) for r in rows for a in axes)
print(f"{span:.6f} {on} {len(rows)}")
PY
}

sim 1
start_cell --no-monitor
"${CTL[@]}" --do run --program "$WORK/long.ngc" --timeout 30 >"$WORK/ctl.out" 2>&1 &
ctl_pid=$!
for ((i = 0; i < 200; i++)); do
  x=$(tail -n 1 "$WORK/trace1.csv" 2>/dev/null | cut -d, -f2 || true)
  /usr/bin/python3 -c "import sys; sys.exit(0 if float('${x:-0}') > 60 else 1)" 2>/dev/null && break
  sleep 0.05
done
kill_hard servo-sim
note "simulator SIGKILLed at X = $x mm"
expect_drive_fault "$ctl_pid" "lost"

# Down for a second, then back where it was.
sleep 1
restart=$(date +%s.%N)
sim 2
for ((i = 0; i < 100; i++)); do
  grep -q "drive answers again" "$WORK/drive-bridge.log" && break
  sleep 0.1
done
grep "drive answers again" "$WORK/drive-bridge.log" >&2 || fail "the bridge did not reconnect within 10 s"
reconnected=$(date +%s.%N)
note "reconnected $(/usr/bin/python3 -c "print(f'{($reconnected - $restart) * 1000:.0f}')") ms after the restart"
sleep 1.5
read -r span on rows < <(moved "$WORK/trace2.csv" "$restart")
note "after the restart, before ENABLE: largest axis motion $span mm over $rows samples, drives on: $on"
[ "$on" -eq 0 ] || fail "a drive was enabled without ENABLE"
/usr/bin/python3 -c "import sys; sys.exit(0 if $span < 1e-4 else 1)" || fail "an axis moved ($span mm) before ENABLE"

# ENABLE: every axis enabled; the axes hold (the interpolator's stream stands
# elsewhere, so the bridge waits for setpoints from where the axes are).
t_enable=$(date +%s.%N)
"${CTL[@]}" --do enable --timeout 10 >&2 || fail "cnc-ctl --do enable failed"
sleep 0.5
read -r span on rows < <(moved "$WORK/trace2.csv" "$t_enable")
note "after ENABLE: largest axis motion $span mm, drives on: $on"
[ "$on" -eq 1 ] || fail "the drives are not enabled after ENABLE"
/usr/bin/python3 -c "import sys; sys.exit(0 if $span < 1e-3 else 1)" || fail "an axis moved ($span mm) on ENABLE"

# Injected faults: 20 exception answers, then replies 80 ms late for 0.1 s
# (response timeout 50 ms): counted, and the drives stay enabled. Then a dropped
# connection: a fault, reconnected and counted.
echo "exception 6 20" >"$WORK/sim.ctl"
sleep 0.3
echo "delay 80 0.1" >"$WORK/sim.ctl"
sleep 0.5
"${CTL[@]}" --do enable --timeout 5 >&2 || fail "the drives did not stay enabled through the injected faults"
grep -cF "drive(s) enabled" "$WORK/drive-bridge.log" | grep -qx 2 || fail "the injected exceptions or delays disabled the drives"
grep -q "(reconnect 2)" "$WORK/drive-bridge.log" && fail "the injected delays already lost the link (reconnect 2 before the drop)"
# The simulator drops every connection for half a second: a lost link again,
# reconnected, and the drives stay disabled until ENABLE. The simulator keeps its
# drives as they were while the connection is down (enabled: nothing tells them
# otherwise); the bridge disables them when it reaches them again, so they are
# measured from that reconnection on, never during the drop.
echo "drop 0.5" >"$WORK/sim.ctl"
for ((i = 0; i < 60; i++)); do
  [ "$(grep -c "(reconnect 2)" "$WORK/drive-bridge.log")" -eq 3 ] && break
  sleep 0.1
done
[ "$(grep -c "(reconnect 2)" "$WORK/drive-bridge.log")" -eq 3 ] || fail "no reconnection of every axis after the dropped connection"
# The disable is the first write after the reconnection: one round of the link worker.
sleep 0.1
t_drop=$(date +%s.%N)
sleep 0.9
read -r span on rows < <(moved "$WORK/trace2.csv" "$t_drop")
note "after the dropped connection and the reconnection: largest axis motion $span mm, drives on: $on"
[ "$on" -eq 0 ] || fail "the drives were enabled again after the dropped connection without ENABLE"
"${CTL[@]}" --do enable --timeout 10 >&2 || fail "ENABLE after the dropped connection failed"
stop interpolator TERM
stop program-server TERM
stop drive-bridge TERM
stop servo-sim TERM
grep -E "axis [XYZ]: [0-9]+ transactions" "$WORK/drive-bridge.log" >&2
/usr/bin/python3 - "$WORK/drive-bridge.log" <<'PY' || fail "the counters do not show the reconnect and the injected faults"
import re, sys
tot = {"timeouts": 0, "exceptions": 0, "reconnects": 0}
per_axis_reconnects = []
for m in re.finditer(r"axis [XYZ]: \d+ transactions, (\d+) timeouts, (\d+) exceptions, \d+ CRC errors, \d+ other errors, (\d+) reconnects", open(sys.argv[1]).read()):
    tot["timeouts"] += int(m.group(1)); tot["exceptions"] += int(m.group(2)); per_axis_reconnects.append(int(m.group(3)))
print(f"# counted: {tot['exceptions']} exceptions (20 injected), {tot['timeouts']} timeouts, reconnects per axis {per_axis_reconnects}", file=sys.stderr)
sys.exit(0 if tot["exceptions"] == 20 and tot["timeouts"] >= 1 and per_axis_reconnects == [2, 2, 2] else 1)
PY
echo "PASS"
