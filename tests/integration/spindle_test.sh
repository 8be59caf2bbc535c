#!/usr/bin/env bash
# The spindle on the bus: a VFD (profile delta_vfd) simulated by cnc-servo-sim on the
# axes' Modbus TCP link (unit 4, a first-order speed response), commanded by the
# program's M3 / M5 in order with motion (config/machines/sim3_spindle.yaml).
#  1. M3 S6000, a feed move, M5, M30: the feed move starts only once the spindle is
#     within spindle.at_speed_tolerance of 6000 rpm (measured from the logged
#     SPINDLE_CMD, SPINDLE_STATUS and SETPOINTS: the time from M3 to at speed, the
#     speed when X starts to move); M5 reaches the drive when the path reaches it (X
#     at the move's end); after M30 the spindle runs down to a stop; the run replays
#     bit for bit (the at-speed input is recorded).
#  2. The same program on a VFD too slow for spindle.at_speed_timeout_s (time constant
#     5 s, timeout 1 s): a drive fault naming the reason, X never moves, the VFD is
#     told to stop.
#  3. The interpolator killed (SIGKILL) while the spindle turns in a dwell: the
#     bridge's setpoint watchdog faults and the bridge stops the spindle itself.
#  4. A Huanyang VFD (its own function codes, config/machines/sim3_huanyang.yaml) on a
#     serial line of its own (a socat pty pair), answered by a third party
#     (huanyang_vfd.py, pyserial): M3 S6000, a feed move after at speed, a dwell in
#     which the operator sets the spindle override to 0.8 (cnc-ctl: commanded 4800 rpm
#     at once, no wait), M4 S3000 (2400 under the override; the reversal waited for),
#     a feed move back, M5; the commanded and actual speeds on SPINDLE_STATUS, the
#     drive's own log of its commands; the run replays bit for bit (the override is a
#     recorded input). The program's PROCESS (the roughness law: at S3000 it allows 1959
#     mm/min along X, under F3000) makes the move back run at the law's feed for the
#     spindle's measured speed: 0.8 of it (the recorded SPINDLE_SPEED inputs).
#   spindle_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-spindle.XXXXXX)"
trap 'cleanup $?' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3_spindle.yaml" "$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")
TOL=$(sed -n 's/^ *at_speed_tolerance: *\([0-9.]*\).*/\1/p' "$M")

cat >"$WORK/spindle.ngc" <<'NGC'
G21 G90
M3 S6000
G1 X20 F3000
M5
M30
NGC

# ---- 1. at speed before the feed move -------------------------------------------
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
start_cell
"${CTL[@]}" --do run --program "$WORK/spindle.ngc" --timeout 60 >"$WORK/ctl1.out" 2>&1 ||
  { cat "$WORK/ctl1.out" >&2; fail "the spindle program did not run to its end"; }
sleep 3  # the spindle runs down after M30 (SPINDLE_STATUS in the log)
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
grep "spindle" "$WORK/drive-bridge.log" >&2 || true
/usr/bin/python3 - "$WORK/cell.lcmlog" "$TEST_PREFIX" "$TOL" "$(dirname "$0")" <<'PY' || fail "the spindle did not run as it should"
import sys
log, prefix, tol = sys.argv[1], sys.argv[2], float(sys.argv[3])
sys.path.insert(0, sys.argv[4])
from lcmlog import events, fields
cmds, stats, xs = [], [], []
for ts, ch, b in events(log):
    if ch == prefix + "SPINDLE_CMD":
        _, _, _, seq, d, rpm, _ = fields(b, "qqiqbdq")
        cmds.append((ts, seq, d, rpm))
    elif ch == prefix + "SPINDLE_STATUS":
        _, _, _, state, seq, at_seq, d, crpm, arpm, cur = fields(b, "qqibqqbddd")
        stats.append((ts, state, seq, at_seq, d, crpm, arpm, cur))
    elif ch == prefix + "SETPOINTS":
        _, _, _, cycle, _, n, x = fields(b, "qqiqdid")
        xs.append((ts, x))
from checks import Checks
check = Checks()
m3 = next((c for c in cmds if c[2] == 1 and c[3] == 6000), None)
check(m3 is not None, "SPINDLE_CMD clockwise 6000 rpm sent")
if not m3: sys.exit(1)
at = next((s for s in stats if s[3] >= m3[1] and s[0] >= m3[0]), None)
check(at is not None, "SPINDLE_STATUS reports the change at speed")
if not at: sys.exit(1)
x0 = xs[0][1]
move = next((x for x in xs if x[1] > x0 + 1e-6), None)
check(move is not None, "X moved")
if not move: sys.exit(1)
before = [s for s in stats if s[0] <= move[0]]
rpm_at_move = before[-1][6] if before else float("nan")
print(f"# time from M3 (SPINDLE_CMD) to at speed: {(at[0] - m3[0]) * 1e-6:.3f} s", file=sys.stderr)
print(f"# speed at at-speed: {at[6]:.0f} rpm; current then {at[7]:.2f} A", file=sys.stderr)
print(f"# time from M3 to the feed move's first setpoint: {(move[0] - m3[0]) * 1e-6:.3f} s", file=sys.stderr)
print(f"# spindle speed when the feed move begins: {rpm_at_move:.0f} rpm", file=sys.stderr)
check(move[0] >= at[0], "the feed move began after the at-speed report")
check(abs(rpm_at_move - 6000) <= tol * 6000, f"within {tol * 100:.1f} % of 6000 rpm when the feed move began")
peak_current = max(s[7] for s in stats if m3[0] <= s[0] <= at[0])
print(f"# output current while accelerating: up to {peak_current:.1f} A", file=sys.stderr)
check(peak_current > 0, "a load figure (output current) on the bus")
# M5 in order with motion: sent when X had reached the feed move's end.
m5 = next((c for c in cmds if c[0] > m3[0] and c[2] == 0), None)
check(m5 is not None, "SPINDLE_CMD stop sent (M5)")
if m5:
    x_at_m5 = [x for x in xs if x[0] <= m5[0]][-1][1]
    check(abs(x_at_m5 - (x0 + 20)) < 1e-6 or abs(x_at_m5 - 20) < 1e-6, f"M5 sent with X at the move's end ({x_at_m5:.4f})")
last = stats[-1]
print(f"# last SPINDLE_STATUS: state {last[1]}, commanded {last[5]:.0f} rpm, actual {last[6]:.0f} rpm", file=sys.stderr)
check(last[5] == 0 and abs(last[6]) < 0.05 * 6000, "stopped after M30 (commanded 0, below 5 % of the speed 3 s on)")
sys.exit(0 if check.ok else 1)
PY
"$BUILD/tools/cnc-replay" --log "$WORK/cell.lcmlog" >"$WORK/replay.out" 2>&1 || { cat "$WORK/replay.out" >&2; fail "the run does not replay"; }
grep "^identical" "$WORK/replay.out" >&2 || fail "no verdict from cnc-replay"

# ---- 2. a VFD too slow: the at-speed timeout --------------------------------------
sed -e 's#time_constant_s: [0-9.]*#time_constant_s: 5#' -e 's#at_speed_timeout_s: [0-9.]*#at_speed_timeout_s: 1#' \
  "$M" >"$WORK/slow.yaml"
M="$WORK/slow.yaml"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/slow"
start_cell
rc=0
"${CTL[@]}" --do run --program "$WORK/spindle.ngc" --timeout 30 >"$WORK/ctl.out" 2>&1 || rc=$?
cat "$WORK/ctl.out" >&2
[ "$rc" -eq 5 ] || fail "cnc-ctl exit $rc on the slow VFD, expected 5 (fault)"
grep "not reached" "$WORK/drive-bridge.log" >&2 || true
grep -q "spindle: 6000 rpm not reached within 1.0 s (at [0-9]* rpm" "$WORK/drive-bridge.log" ||
  fail "the bridge did not name the at-speed timeout"
grep -q "not reached within 1.0 s" "$WORK/ctl.out" || fail "cnc-ctl's fault report does not name the reason"
sleep 1
grep -q "spindle: stop" "$WORK/servo-sim.log" || fail "the VFD was not told to stop after the fault"
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
/usr/bin/python3 - "$WORK/slow.lcmlog" "$TEST_PREFIX" <<'PY' || fail "X moved although the spindle never reached its speed"
import struct, sys
data = open(sys.argv[1], "rb").read()
prefix, p, xs, stats = sys.argv[2], 0, [], []
while p + 28 <= len(data):
    sync, _, ts, clen, dlen = struct.unpack(">IqqII", data[p:p + 28])
    if sync != 0xEDA1DA01: break
    ch, b = data[p + 28:p + 28 + clen].decode(), data[p + 28 + clen:p + 28 + clen + dlen]
    if ch == prefix + "SETPOINTS": xs.append(struct.unpack_from(">qqiqdid", b, 8)[6])
    if ch == prefix + "SPINDLE_STATUS": stats.append(struct.unpack_from(">qqibqqbddd", b, 8))
    p += 28 + clen + dlen
faults = [s for s in stats if s[3] == 3]
print(f"# X setpoints from {min(xs):.6f} to {max(xs):.6f} mm; speed at the fault {faults[0][8]:.0f} rpm" if faults else
      "# no SPINDLE_STATUS in FAULT", file=sys.stderr)
sys.exit(0 if faults and max(xs) - min(xs) < 1e-9 and faults[-1][7] == 0 else 1)
PY

# ---- 3. the interpolator killed while the spindle turns ---------------------------
M="$WORK/machine.yaml"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")
cat >"$WORK/dwell.ngc" <<'NGC'
G21 G90
M3 S6000
G4 P30
M5
M30
NGC
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start_cell
"${CTL[@]}" --do run --program "$WORK/dwell.ngc" --timeout 60 >"$WORK/ctl3.out" 2>&1 &
ctl_pid=$!
for ((i = 0; i < 100; i++)); do
  grep -q "spindle: at speed" "$WORK/drive-bridge.log" && break
  sleep 0.1
done
grep -q "spindle: at speed" "$WORK/drive-bridge.log" || fail "the spindle did not reach its speed for the dwell"
kill_hard interpolator
sleep 1
wait "$ctl_pid" 2>/dev/null || true
grep -E "fault|spindle" "$WORK/drive-bridge.log" | tail -n 3 >&2
grep -q "fault: .*setpoint" "$WORK/drive-bridge.log" || fail "the bridge did not fault on the lost setpoints"
# This simulator's VFD started stopped: its one "stop" line is the bridge's stop.
grep -q "cnc-servo-sim: spindle: stop" "$WORK/servo-sim.log" ||
  fail "the bridge did not stop the spindle when its interpolator was lost"
for s in program-server monitor drive-bridge servo-sim; do stop "$s" TERM; done

# ---- 4. a Huanyang VFD on its own line, a third party's ------------------------------
M="$WORK/huanyang.yaml"
make_machine "$SRC/config/machines/sim3_huanyang.yaml" "$M"
sed -i "s#/tmp/cnc-hy-bridge#$WORK/hy-bridge#" "$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")
cat >"$WORK/reverse.ngc" <<'NGC'
G21 G90
(PROCESS, BALL_RADIUS=5, FLUTES=2, PICK_FEED=0.5, RMAX_UM=10.67)
M3 S6000
G1 X5 F3000
G4 P3
M4 S3000
G1 X0
M5
M30
NGC
# socat relays every byte of the "line": real-time like the cell's services when permitted
# (as bridge_profiles_test.sh: a real RS-485 line has no user-space worker in its path).
rt=(); chrt -f 39 true 2>/dev/null && rt=(chrt -f 39)
start socat "${rt[@]}" socat pty,raw,echo=0,link="$WORK/hy-bridge" pty,raw,echo=0,link="$WORK/hy-vfd"
for ((i = 0; i < 50; i++)); do [ -e "$WORK/hy-vfd" ] && break; sleep 0.1; done
[ -e "$WORK/hy-vfd" ] || fail "socat made no pseudo-terminal pair"
# The VFD answers on its own processor; here a Python process on a shared host, real-time
# like socat when permitted. Even so the busy host left it (or the line) silent for the
# shipped 0.25 s link-loss timeout in 3 of 14 runs under two busy loops and three builds:
# a lost link (the fault itself: spindle_control_test, bridge_node_test); here the timeout is 1 s.
sed -i 's/^  link_loss_timeout_s: 0.25 /  link_loss_timeout_s: 1.0 /' "$M"
grep -q "^  link_loss_timeout_s: 1.0 " "$M" || fail "could not set drive_bridge.link_loss_timeout_s in $M"
start hy-vfd "${rt[@]}" /usr/bin/python3 "$(dirname "$0")/huanyang_vfd.py" --device "$WORK/hy-vfd" --tau 0.15
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/hy"
start_cell
"${CTL[@]}" --do run --program "$WORK/reverse.ngc" --timeout 30 >"$WORK/ctl4.out" 2>&1 &
ctl_pid=$!
for ((i = 0; i < 100; i++)); do
  grep -q "spindle: at speed" "$WORK/drive-bridge.log" && break
  sleep 0.05
done
"${CTL[@]}" --do spindle-override --value 0.8 >"$WORK/override.out" 2>&1 ||
  { cat "$WORK/override.out" >&2; fail "cnc-ctl could not set the spindle override"; }
"${CTL[@]}" --do spindle-override --value 1.2 >"$WORK/override_bad.out" 2>&1 && fail "a spindle override above 1.0 was taken"
grep -q "spindle override 1.200000 is outside 0.5 .. 1" "$WORK/override_bad.out" ||
  { cat "$WORK/override_bad.out" >&2; fail "the refusal of 1.2 does not name the range"; }
wait "$ctl_pid" || { cat "$WORK/ctl4.out" "$WORK/drive-bridge.log" >&2; fail "the program did not run to its end on the Huanyang VFD"; }
sleep 0.3
for s in interpolator program-server monitor drive-bridge servo-sim logger hy-vfd; do stop "$s" TERM; done
kill "${TEST_PIDS[socat]}"; wait "${TEST_PIDS[socat]}" 2>/dev/null || true; unset "TEST_PIDS[socat]"
cat "$WORK/hy-vfd.log" >&2
grep -q "run forward at 100.00 Hz" "$WORK/hy-vfd.log" || fail "the VFD was not run forward at 100 Hz (M3 S6000)"
grep -q "run reverse at 40.00 Hz" "$WORK/hy-vfd.log" || fail "the VFD was not run in reverse at 40 Hz (M4 S3000 at 0.8)"
grep -q "stop at" "$WORK/hy-vfd.log" || fail "the VFD was not stopped (M5)"
/usr/bin/python3 - "$WORK/hy.lcmlog" "$TEST_PREFIX" "$TOL" "$(dirname "$0")" <<'PY' || fail "the Huanyang spindle did not run as it should"
import sys
log, prefix, tol = sys.argv[1], sys.argv[2], float(sys.argv[3])
sys.path.insert(0, sys.argv[4])
from lcmlog import events, fields
cmds, stats, xs = [], [], []
for ts, ch, b in events(log):
    if ch == prefix + "SPINDLE_CMD":
        _, _, _, seq, d, rpm, _ = fields(b, "qqiqbdq")
        cmds.append((ts, seq, d, rpm))
    elif ch == prefix + "SPINDLE_STATUS":
        _, _, _, state, seq, at_seq, d, crpm, arpm, cur = fields(b, "qqibqqbddd")
        stats.append((ts, state, seq, at_seq, d, crpm, arpm, cur))
    elif ch == prefix + "SETPOINTS":
        _, _, _, cycle, _, n, x = fields(b, "qqiqdid")
        xs.append((ts, cycle, x))
from checks import Checks
check = Checks()
m3 = next((c for c in cmds if c[2] == 1 and c[3] == 6000), None)
ov = next((c for c in cmds if c[2] == 1 and c[3] == 4800), None)
m4 = next((c for c in cmds if c[2] == -1 and c[3] == 2400), None)
m5 = next((c for c in cmds if m4 and c[0] > m4[0] and c[2] == 0), None)
check(m3 is not None and ov is not None and m4 is not None and m5 is not None,
      "SPINDLE_CMD M3 6000, the override's 4800, M4 2400 (3000 at 0.8) and M5 sent")
if not check.ok: sys.exit(1)
def at_speed(c):
    return next((s for s in stats if s[3] >= c[1] and s[0] >= c[0]), None)
a3, a4 = at_speed(m3), at_speed(m4)
# The override's own at-speed (not the next speed change's): the dwell gives it 3 s, of which
# a cnc-ctl under the thread sanitizer took 1.3 s to start (it was then superseded by S3000).
aov = next((s for s in stats if s[3] == ov[1] and s[0] >= ov[0]), None)
check(a3 is not None and a4 is not None and aov is not None, "SPINDLE_STATUS reports M3, the override and M4 at speed")
if not check.ok: sys.exit(1)
first_ov = next(s for s in stats if s[0] >= ov[0] and s[2] >= ov[1])
print(f"# override 0.8: SPINDLE_STATUS commanded {first_ov[5]:.0f} rpm {(first_ov[0] - ov[0]) * 1e-6:.3f} s after the "
      f"SPINDLE_CMD; actual {aov[6]:.0f} rpm at speed {(aov[0] - ov[0]) * 1e-6:.3f} s after it", file=sys.stderr)
check(first_ov[5] == 4800 and abs(aov[6] - 4800) <= tol * 4800, "the override: commanded 4800, actual follows within tolerance")
check(ov[0] < m4[0], "the override came before M4 (in the dwell)")
print(f"# M3: commanded {a3[5]:.0f} rpm, actual {a3[6]:.0f} rpm at speed {(a3[0] - m3[0]) * 1e-6:.3f} s after it; "
      f"current then {a3[7]:.2f} A", file=sys.stderr)
print(f"# M4: commanded {a4[5]:.0f} rpm, actual {a4[6]:.0f} rpm at speed {(a4[0] - m4[0]) * 1e-6:.3f} s after it",
      file=sys.stderr)
check(a3[5] == 6000 and abs(a3[6] - 6000) <= tol * 6000, "M3: commanded 6000, actual within tolerance")
check(a4[4] == -1 and a4[5] == 2400 and abs(a4[6] + 2400) <= tol * 2400, "M4: reverse, commanded 2400, actual -2400 within tolerance")
x0 = xs[0][2]
out = next((x for x in xs if x[2] > x0 + 1e-6), None)
back = next((x for x in xs if x[0] > m4[0] and x[2] < x0 + 5 - 1e-6), None)
check(out is not None and out[0] >= a3[0], "the feed move out began after M3 was at speed")
check(back is not None and back[0] >= a4[0], "the feed move back began after M4 was at speed")
# The move back's feed from its setpoints (4 ms cycles), on its middle 3 mm.
period = 0.004
vel = [(xs[k][2], (xs[k - 1][2] - xs[k][2]) / ((xs[k][1] - xs[k - 1][1]) * period))
       for k in range(1, len(xs)) if xs[k][0] > m4[0] and xs[k][1] > xs[k - 1][1]]
mid = [v for x, v in vel if x0 + 1 <= x <= x0 + 4]
law_at_s = 1958.8 / 60  # the roughness law along X at S3000 (roughness_feed_test: 1305.9 at S2000)
check(len(mid) > 20, "the move back's middle sampled")
if mid:
    lo, hi = min(mid) / law_at_s, max(mid) / law_at_s
    print(f"# the move back under the roughness law: {min(mid) * 60:.1f}..{max(mid) * 60:.1f} mm/min over its middle "
          f"3 mm = {lo:.3f}..{hi:.3f} of the law at S3000 ({law_at_s * 60:.1f}); spindle {abs(a4[6]):.0f} of 3000 rpm",
          file=sys.stderr)
    # The law's scale is the measured speed over S rounded to 1/128; at speed within the tolerance.
    check(0.8 * (1 - tol) - 1 / 128 <= lo and hi <= 0.8 * (1 + tol) + 1 / 128,
          "the move back at the law's feed for the spindle's measured speed (0.8 of S's)")
check(max(s[7] for s in stats if m3[0] <= s[0] <= a3[0]) > 0, "a load figure (output current) on the bus")
last = stats[-1]
print(f"# last SPINDLE_STATUS: commanded {last[5]:.0f} rpm, actual {last[6]:.0f} rpm; {len(stats)} messages", file=sys.stderr)
check(last[5] == 0 and last[4] == 0, "M5: commanded 0")
sys.exit(0 if check.ok else 1)
PY
"$BUILD/tools/cnc-replay" --log "$WORK/hy.lcmlog" >"$WORK/replay4.out" 2>&1 || { cat "$WORK/replay4.out" >&2; fail "the run with the override does not replay"; }
grep "^identical" "$WORK/replay4.out" >&2 || fail "no verdict from cnc-replay"
echo "PASS"
