#!/usr/bin/env bash
# Faults end in a controlled stop, and RESET brings the cell back without a restart.
#  1. A publish failure mid-program: the multicast route is removed for 1 s while X
#     moves at 200 mm/s (every sendto fails). No process may exit; the axes stop at
#     the configured deceleration (the simulator's trace, 10 ms rows); once the route
#     is back the bridge and the interpolator raise publish_failed ALARMs with their
#     counts and stay in FAULT: a new program is refused (cnc-ctl exit 3, reason
#     "FAULT"). `cnc-ctl --do reset`, then a program runs to its end.
#  2. Interlock: LOAD and RUN while a program runs are refused at once (exit 3,
#     naming the running program); the running program goes on.
#  3. A drive fault mid-program (the simulator's fault injection on Y, X moving at
#     about 100 mm/s): the bridge stops X at the configured deceleration (the
#     recorded AXIS_STATUS, receive-time stamped), the
#     interpolator goes to FAULT; reset; a program runs to its end.
#  4. Every process exits 0 on SIGTERM, and the log replays bit for bit (the RESETs
#     and the positions they took are recorded inputs).
#   fault_reset_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
[ -n "${CNC_IN_NETNS:-}" ] || { echo "SKIP: needs a private network namespace (unshare -n) to remove the multicast route"; exit 0; }
WORK="$(mktemp -d /tmp/cnc-fault-reset.XXXXXX)"
trap 'ip route replace 224.0.0.0/4 dev lo 2>/dev/null || true; cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")
DECEL=$(sed -n 's/^ *stop_decel_mm_s2: *\([0-9.]*\).*/\1/p' "$M")

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
cat >"$WORK/short.ngc" <<'NGC'
G21 G90
G1 X20 Y20 Z-5 F6000
M30
NGC

start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --trace "$WORK/trace.csv" --control "$WORK/sim.ctl"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
start drive-bridge "$BUILD/services/cnc-drive-bridge" --machine "$M"
start monitor "$BUILD/services/cnc-monitor" --machine "$M"
start program-server "$BUILD/services/cnc-program-server" --machine "$M"
start interpolator "$BUILD/services/cnc-interpolator" --machine "$M"

all_alive() {
  local name
  for name in servo-sim logger drive-bridge monitor program-server interpolator; do
    kill -0 "${TEST_PIDS[$name]}" 2>/dev/null || { cat "$WORK/$name.log" >&2; fail "$name exited ($1)"; }
  done
}
# wait_x LIMIT: until the trace shows X beyond LIMIT mm.
wait_x() {
  local i x
  for ((i = 0; i < 300; i++)); do
    x=$(tail -n 1 "$WORK/trace.csv" 2>/dev/null | cut -d, -f2 || true)
    /usr/bin/python3 -c "import sys; sys.exit(0 if float('${x:-0}') > $1 else 1)" 2>/dev/null && { echo "$x"; return 0; }
    sleep 0.02
  done
  fail "X did not pass $1 mm"
}
# expect_refused OUT_FILE PATTERN CMD...: cnc-ctl exits 3 within 3 s, its reason matching PATTERN.
expect_refused() {
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
"${CTL[@]}" --do run --program "$WORK/long.ngc" --timeout 30 >"$WORK/ctl1.out" 2>&1 &
ctl_pid=$!
x=$(wait_x 100)
cut_time=$(date +%s.%N)
ip route del 224.0.0.0/4 dev lo
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
/usr/bin/python3 - "$WORK/trace.csv" "$cut_time" "$DECEL" <<'PY' || fail "the axes did not come to a controlled stop"
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if None not in r.values()]
cut, decel = float(sys.argv[2]), float(sys.argv[3])
t = [float(r["wall_s"]) for r in rows]
# The simulated world's own time (wall time less the stalls it stood through: the
# simulator's process stalled, or its master's stream ran dry): the axes' motion is
# smooth on it, where a stall would be a flat step on the wall clock.
world = lambda r: float(r.get("world_s") or r["wall_s"])
rows = [r for k, r in enumerate(rows) if k == 0 or world(r) > world(rows[k - 1])]  # rows in a stall: one
t = [float(r["wall_s"]) for r in rows]
tw = [world(r) for r in rows]
x = [float(r["X_mm"]) for r in rows]
def decel_fit(t, x, v, vmax, lo=0, hi=None):
    # Least-squares parabola x(t) over the braking phase (speed from 90 % down to 10 %
    # of where it started): its deceleration, robust to the jitter of single samples.
    hi = len(v) if hi is None else hi
    idx = [k for k in range(lo, hi) if 0.1 * vmax < v[k] < 0.9 * vmax]
    k0, k1 = idx[0], idx[-1] + 1
    ts = [t[k] - t[k0] for k in range(k0, k1 + 1)]; xs = [x[k] for k in range(k0, k1 + 1)]
    n = len(ts); S = lambda f: sum(f(i) for i in range(n))
    A = [[S(lambda i: ts[i] ** (r + c)) for c in range(3)] for r in range(3)]
    b = [S(lambda i: xs[i] * ts[i] ** r) for r in range(3)]
    for c in range(3):  # Gaussian elimination
        for r in range(c + 1, 3):
            f = A[r][c] / A[c][c]
            A[r] = [A[r][j] - f * A[c][j] for j in range(3)]; b[r] -= f * b[c]
    q = [0.0] * 3
    for r in (2, 1, 0):
        q[r] = (b[r] - sum(A[r][j] * q[j] for j in range(r + 1, 3))) / A[r][r]
    return -2 * q[2], n
# Speeds from the positions (the trace's velocity column is a noisy instantaneous one).
v = [(x[k + 1] - x[k]) / (tw[k + 1] - tw[k]) for k in range(len(t) - 1)]
i = max(k for k in range(len(t) - 1) if t[k] <= cut) - 1
rest = next(k for k in range(i, len(t)) if all(abs(x[j] - x[k]) < 1e-3 for j in range(k, min(len(t), k + 30))))
fitted, n = decel_fit(tw, x, v, v[i], i, rest)
# Single 50 ms windows: the samples' time stamps jitter by about a millisecond.
worst = max((v[k] - v[k + 5]) / (tw[k + 5] - tw[k]) for k in range(i, max(i + 1, rest - 5)))
dist = x[rest] - x[i]
# The bridge's stop is jerk-limited (X: 60000 mm/s^3, config/machines/sim3.yaml): it
# reaches the full deceleration after a/j and releases it over a/j, which adds v*a/j.
jerk = 60000.0
bound = v[i] ** 2 / (2 * decel) + v[i] * (0.05 + decel / jerk) + 0.1
print(f"# publish failure at X = {x[i]:.3f} mm, {v[i]:.1f} mm/s; at rest {(t[rest] - cut) * 1e3:.0f} ms later at "
      f"X = {x[rest]:.3f} mm: {dist:.3f} mm (bound v^2/2a + v*(timeout + a/j) + 0.1 = {bound:.3f} mm); deceleration "
      f"{fitted:.0f} mm/s^2 fitted over {n} samples (configured {decel:g}: within -25/+10 %), largest over 50 ms "
      f"{worst:.0f} mm/s^2 (within +25 %)", file=sys.stderr)
ok = v[i] > 150 and 0 <= dist <= bound and 0.75 * decel <= fitted <= 1.10 * decel and worst <= 1.25 * decel
sys.exit(0 if ok else 1)
PY
grep -q "fault: the bus failed" "$WORK/drive-bridge.log" || fail "the bridge did not fault on its failed publishes"
grep -q "fault: publish on" "$WORK/interpolator.log" || fail "the interpolator did not fault on its failed publishes"

# In FAULT: a new program is refused with the reason.
expect_refused "$WORK/refused1.out" "FAULT" "${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 10
"${CTL[@]}" --do reset --timeout 20 >&2 || fail "cnc-ctl --do reset failed after the publish failure"
"${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 30 >&2 || fail "no program ran after the reset"

# ---- 2. interlock while a program runs ----------------------------------------
"${CTL[@]}" --do run --program "$WORK/diag.ngc" --timeout 30 >"$WORK/ctl.out" 2>&1 &
ctl_pid=$!
wait_x 60 >/dev/null
expect_refused "$WORK/refused2.out" "diag.ngc is running" "${CTL[@]}" --do load --program "$WORK/short.ngc"
expect_refused "$WORK/refused3.out" "diag.ngc is running" "${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 30
expect_refused "$WORK/refused4.out" "diag.ngc is running" "${CTL[@]}" --do start

# ---- 3. drive fault -----------------------------------------------------------
x=$(wait_x 120)
/usr/bin/python3 -c "import sys; sys.exit(0 if float('$x') < 330 else 1)" || fail "the refusals took too long: X at $x mm"
echo "fault Y" >"$WORK/sim.ctl"
note "drive Y faulted at X = $x mm"
expect_drive_fault "$ctl_pid" "fault"
sleep 1
all_alive "after the drive fault"
expect_refused "$WORK/refused5.out" "FAULT" "${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 10
"${CTL[@]}" --do reset --timeout 20 >&2 || fail "cnc-ctl --do reset failed after the drive fault"
"${CTL[@]}" --do run --program "$WORK/short.ngc" --timeout 30 >&2 || fail "no program ran after the second reset"

# ---- 4. clean exit, recorded ALARMs and stop, replay --------------------------
stop interpolator TERM
stop program-server TERM
stop monitor TERM
stop drive-bridge TERM
stop servo-sim TERM
stop logger TERM
/usr/bin/python3 - "$WORK/cell.lcmlog" "$TEST_PREFIX" "$DECEL" <<'PY' || fail "the recorded ALARMs or the drive-fault stop are wrong"
import struct, sys
log, prefix, decel = sys.argv[1], sys.argv[2], float(sys.argv[3])
data = open(log, "rb").read()
events, p = [], 0
while p + 28 <= len(data):
    sync, _, ts, clen, dlen = struct.unpack(">IqqII", data[p:p + 28])
    if sync != 0xEDA1DA01: break
    ch = data[p + 28:p + 28 + clen].decode()
    events.append((ts, ch, data[p + 28 + clen:p + 28 + clen + dlen]))
    p += 28 + clen + dlen
class R:
    def __init__(s, b): s.b, s.p = b, 8
    def get(s, f):
        n = struct.calcsize(f); v = struct.unpack(">" + f, s.b[s.p:s.p + n]); s.p += n; return v[0]
    def str(s):
        n = s.get("i"); v = s.b[s.p:s.p + n - 1].decode(); s.p += n; return v
def decel_fit(t, x, v, vmax, lo=0, hi=None):
    # Least-squares parabola x(t) over the braking phase (speed from 90 % down to 10 %
    # of where it started): its deceleration, robust to the jitter of single samples.
    hi = len(v) if hi is None else hi
    idx = [k for k in range(lo, hi) if 0.1 * vmax < v[k] < 0.9 * vmax]
    k0, k1 = idx[0], idx[-1] + 1
    ts = [t[k] - t[k0] for k in range(k0, k1 + 1)]; xs = [x[k] for k in range(k0, k1 + 1)]
    n = len(ts); S = lambda f: sum(f(i) for i in range(n))
    A = [[S(lambda i: ts[i] ** (r + c)) for c in range(3)] for r in range(3)]
    b = [S(lambda i: xs[i] * ts[i] ** r) for r in range(3)]
    for c in range(3):  # Gaussian elimination
        for r in range(c + 1, 3):
            f = A[r][c] / A[c][c]
            A[r] = [A[r][j] - f * A[c][j] for j in range(3)]; b[r] -= f * b[c]
    q = [0.0] * 3
    for r in (2, 1, 0):
        q[r] = (b[r] - sum(A[r][j] * q[j] for j in range(r + 1, 3))) / A[r][r]
    return -2 * q[2], n
alarms, status = [], []
for ts, ch, b in events:
    if ch == prefix + "ALARM":
        r = R(b); r.get("q"); r.get("q"); r.get("i")
        alarms.append((ts, r.str(), r.get("b"), r.str(), r.str()))
    elif ch == prefix + "AXIS_STATUS":
        r = R(b); r.get("q"); r.get("q"); r.get("i"); r.get("q"); n = r.get("i")
        names = [r.str() for _ in range(n)]
        r.p += 8 * n  # commanded
        actual = [r.get("d") for _ in range(n)]
        r.p += 8 * n  # following error
        state = [r.get("b") for _ in range(n)]
        status.append((ts * 1e-6, actual, state))
ok = True
for src in ("cnc-drive-bridge", "cnc-interpolator"):
    a = [x for x in alarms if x[1] == src and x[3] == "publish_failed"]
    print(f"# {src}: {a[0][4] if a else 'NO publish_failed ALARM'}", file=sys.stderr)
    ok = ok and len(a) >= 1 and "failed over" in a[0][4]
resets = [x for x in alarms if x[3] == "reset"]
print(f"# reset ALARMs: {len(resets)}", file=sys.stderr)
ok = ok and len(resets) >= 2
# The drive fault: X's deceleration from the recorded AXIS_STATUS, from the first
# status not ENABLED until X stands.
# (The last such change between two consecutive statuses: the outage left a gap.)
first = [k for k in range(1, len(status)) if status[k][2][1] != 2 and status[k - 1][2][1] == 2
         and status[k][0] - status[k - 1][0] < 0.02 and abs(status[k][1][0] - status[k - 1][1][0]) > 0.1][-1]
ts = [s[0] for s in status]; xs = [s[1][0] for s in status]
k0 = first - 1
rest = next(k for k in range(first, len(status)) if abs(xs[k] - xs[k - 1]) < 1e-4)
v = [(xs[k + 1] - xs[k]) / (ts[k + 1] - ts[k]) for k in range(k0 - 3, rest)]
# Receive times jitter: the deceleration fitted over the braking phase, and the
# largest over windows of 13 statuses (about 50 ms).
tt = ts[k0 - 3:rest + 1]; xx = xs[k0 - 3:rest + 1]
fitted, n = decel_fit(tt, xx, v, v[3])
w = 13
worst = max((v[k] - v[k + w]) / (tt[k + w] - tt[k]) for k in range(0, len(v) - w))
print(f"# drive fault on Y: X at {v[3]:.1f} mm/s stopped within {(ts[rest] - ts[k0]) * 1e3:.0f} ms; deceleration "
      f"{fitted:.0f} mm/s^2 fitted over {n} statuses (configured {decel:g}: within -40/+10 %), largest over 50 ms "
      f"{worst:.0f} mm/s^2 (within +25 %)", file=sys.stderr)
# From 100 mm/s the bridge's jerk-limited stop (60000 mm/s^3: 33 ms to reach the full
# deceleration, 33 ms to release it) spends most of its ~80 ms ramping, so the parabola
# fitted between 90 % and 10 % of the speed reads well below the plateau (1275-1640
# mm/s^2 seen); the stop time and the 50 ms maximum still bound it.
# The fault lands where the FIFO write happens to meet the path: X cruising at 100 mm/s
# or already slowing for diag.ngc's corner (74 mm/s seen once in ten loaded suite
# runs). From 50 mm/s on the stop is long enough to fit.
ok = ok and v[3] > 50 and 0.6 * decel <= fitted <= 1.10 * decel and worst <= 1.25 * decel
sys.exit(0 if ok else 1)
PY
"$BUILD/tools/cnc-replay" --log "$WORK/cell.lcmlog" >"$WORK/replay.out" 2>&1 || { cat "$WORK/replay.out" >&2; fail "the run does not replay"; }
cat "$WORK/replay.out" >&2
rm -rf "$WORK"
echo "PASS"
