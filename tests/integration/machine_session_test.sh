#!/usr/bin/env bash
# The whole machine in one session: config/programs/machine_demo.ngc on
# config/machines/sim3_machine.yaml (spindle VFD, I/O module, E-stop, touch probe), the
# devices simulated by cnc-servo-sim on the axes' Modbus TCP link.
#  1. The demo runs to its end: G38.2 trips on the fixture's top (Z -20), the pocket is
#     cut 0.5 mm below the probed top (the lowest Z commanded: #5063 - 0.5, within the
#     sampled probe's bound); the path stands at M66 until the clamp closes (the
#     simulator's input, set 1 s into the wait); the spindle runs and the flood is on
#     before the pocket's first cut and both are off at M30 (the simulator's own log).
#  2. The demo again, the E-stop pressed as Z passes -20.3 plunging into the pocket (the
#     probing move stops above that): a fault that names
#     the E-stop, the spindle and the flood off; released, fault-reset and reset, the demo
#     runs to its end a third time.
#  3. The session (three runs of the demo, the probe's trips, the M66 input, the E-stop's
#     stop and the resets, all recorded inputs) replays bit for bit: cnc-replay.
#   machine_session_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-machine.XXXXXX)"
trap 'cleanup $?' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3_machine.yaml" "$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")
DEMO="$SRC/config/programs/machine_demo.ngc"

mkfifo "$WORK/sim.ctl"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --control "$WORK/sim.ctl"
exec 7<>"$WORK/sim.ctl"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
start_cell
sim_says() {  # sim_says PATTERN SECONDS: the simulator's log shows PATTERN within SECONDS
  local i
  for ((i = 0; i < $2 * 10; i++)); do grep -qE "$1" "$WORK/servo-sim.log" && return 0; sleep 0.1; done
  return 1
}

# ---- 1. the demo to its end ---------------------------------------------------------
echo "input clamp_closed 0" >&7
"${CTL[@]}" --do run --program "$DEMO" --timeout 90 >"$WORK/run1.out" 2>&1 &
ctl_pid=$!
sim_says "io io1: lamp_green on" 30 || fail "the demo did not reach its M64 P2 (lamp_green) after probing"
sleep 1
grep -q "io io1: coolant_flood on" "$WORK/servo-sim.log" && fail "the flood came on before the clamp closed (M66 did not wait)"
echo "input clamp_closed 1" >&7
wait "$ctl_pid" || { cat "$WORK/run1.out" >&2; fail "the demo did not run to its end"; }
grep -q "program done" "$WORK/run1.out" || { cat "$WORK/run1.out" >&2; fail "cnc-ctl did not report the demo done"; }
sim_says "io io1: coolant_flood off" 5 || fail "the flood did not go off at M30"
sim_says "spindle: stop" 5 || fail "the spindle did not stop at M30"
cp "$WORK/servo-sim.log" "$WORK/run1.sim.log"

# ---- 2. the E-stop in the pocket, recovery, the demo again ----------------------------
: >"$WORK/run2.mark"
echo "input clamp_closed 1" >&7
echo "at Z -20.3 input estop_ok 0" >&7  # plunging into the pocket (the probe stops above it)
rc=0
"${CTL[@]}" --do run --program "$DEMO" --timeout 90 >"$WORK/run2.out" 2>&1 || rc=$?
[ "$rc" -eq 5 ] && grep -q "E-stop" "$WORK/run2.out" || { cat "$WORK/run2.out" >&2; fail "the E-stop in the pocket: cnc-ctl exit $rc, expected 5 naming the E-stop"; }
note "run 2: $(grep -m1 "E-stop" "$WORK/run2.out")"
sleep 0.5
echo "input estop_ok 1" >&7
sleep 0.3
"${CTL[@]}" --do fault-reset >"$WORK/fr.out" 2>&1 || { cat "$WORK/fr.out" >&2; fail "fault-reset after the E-stop's release"; }
"${CTL[@]}" --do reset --timeout 20 >"$WORK/reset.out" 2>&1 || { cat "$WORK/reset.out" >&2; fail "reset after the E-stop"; }
"${CTL[@]}" --do run --program "$DEMO" --timeout 90 >"$WORK/run3.out" 2>&1 || { cat "$WORK/run3.out" >&2; fail "the demo after the E-stop's recovery"; }
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
exec 7>&-

/usr/bin/python3 - "$WORK/run1.sim.log" "$WORK/servo-sim.log" "$WORK/cell.lcmlog" "$TEST_PREFIX" "$(dirname "$0")" <<'PY' || fail "the session's devices did not do what the demo says"
import re, sys
run1, full, log, prefix, here = sys.argv[1:6]
sys.path.insert(0, here)
from lcmlog import events, Fields
from checks import Checks
check = Checks()
def events_of(path):
    out = []
    for line in open(path):
        m = re.search(r"io io1: (\w+) (on|off) at X (-?[0-9.]+)", line)
        if m: out.append((m.group(1), m.group(2), float(m.group(3))))
        if "cnc-servo-sim: spindle: run" in line: out.append(("spindle", "run", None))
        if "cnc-servo-sim: spindle: stop" in line: out.append(("spindle", "stop", None))
        m = re.search(r"probe probe_tip (\w+): crossed at X (\S+) Y (\S+) Z (-?[0-9.]+)", line)
        if m: out.append(("probe", m.group(1), float(m.group(4))))
        if "estop_ok set to 0" in line: out.append(("estop", "pressed", None))
    return out
e1 = events_of(run1)
names = [(n, s) for n, s, _ in e1]
check(("probe", "rise") in names or any(n == "probe" for n, _, _ in e1), f"run 1: the probe touched the fixture ({[x for x in e1 if x[0] == 'probe'][:2]})")
order = [k for k in (("lamp_green", "on"), ("spindle", "run"), ("coolant_flood", "on"), ("coolant_flood", "off"), ("spindle", "stop"))]
idx = [names.index(k) if k in names else -1 for k in order]
check(all(i >= 0 for i in idx) and idx == sorted(idx),
      "run 1: lamp_green on (M64 P2), spindle run (M3), flood on (M8), flood off (M9), spindle stop (M5), in that order")
flood_x = [x for n, s, x in e1 if n == "coolant_flood" and s == "on"]
check(bool(flood_x) and abs(flood_x[0] - 100.0) < 1e-3, f"run 1: the flood on with X still over the probed point (X {flood_x[:1]})")
# The lowest Z commanded (SETPOINTS) in run 1: the probed top less 0.5 mm.
zs = []
for ts, ch, b in events(log):
    if ch == prefix + "SETPOINTS":
        f = Fields(b)
        f.get("qqi")  # utime, seq, sender
        cycle, period, n = f.get("qdi")
        pos = f.get("d" * n)
        zs.append(pos[2])
zmin = min(zs)
check(abs(zmin - (-20.5)) <= 0.02, f"the pocket's floor at Z {zmin:.4f} (the probed top -20 less 0.5; bound 0.02 mm: 300 mm/min x the sampled probe's 2 ms and the stop's overshoot)")
e = events_of(full)
press = [i for i, x in enumerate(e) if x[0] == "estop"]
check(len(press) == 1, "run 2: one E-stop press in the simulator's log")
if press:
    rest = [(n, s) for n, s, _ in e[press[0]:]]
    nxt = lambda name: next((s for n, s in rest if n == name), None)
    check(nxt("coolant_flood") == "off" and nxt("spindle") == "stop",
          f"run 2: after the press the flood goes off and the spindle stops first ({nxt('coolant_flood')}, {nxt('spindle')})")
    check(rest.count(("coolant_flood", "on")) == 1 and rest.count(("coolant_flood", "off")) == 2,
          "run 3, after the recovery: the flood on once more and off at its M9")
def show(n, s, x):
    return f"{n} {s}" + ("" if x is None else f" at {'Z' if n == 'probe' else 'X'} {x:.3f}")
print("# run 1's devices: " + ", ".join(show(*x) for x in e1), file=sys.stderr)
sys.exit(0 if check.ok else 1)
PY

# ---- 3. the session replays bit for bit ------------------------------------------------
"$BUILD/tools/cnc-replay" --log "$WORK/cell.lcmlog" >"$WORK/replay.out" 2>&1 || { cat "$WORK/replay.out" >&2; fail "the session does not replay"; }
grep -E "^identical|interpolator runs" "$WORK/replay.out" >&2 || true
grep -q "^identical" "$WORK/replay.out" || { cat "$WORK/replay.out" >&2; fail "no verdict 'identical' from cnc-replay"; }
echo "PASS"
