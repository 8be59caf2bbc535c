#!/usr/bin/env bash
# Spindle-synchronised motion live: config/programs/thread_and_tap.ngc on a servo
# spindle (config/machines/sim3_servo_spindle.yaml: a CiA-402 drive in profile velocity
# mode with its 17-bit encoder, simulated by cnc-servo-sim, on the axes' Modbus TCP
# link): three G33 passes of a 1.5 mm thread, two G33.1 rigid taps (M8 x 1.25, the
# second retracting at twice the speed), M19 R90 Q5. From the log, with the bridge's
# own measurements (AXIS_STATUS actual Z at its playback cycle, SPINDLE_STATUS position
# at the playback cycle of its sample):
#  * the synchronisation error of each pass while it tracks (Z + K x revolutions is
#    constant along a thread; its spread), and the thread's phase on the three passes
#    (they must cut one thread);
#  * each tap's error down and up, the offset of the thread up from the thread down
#    (the axis's lag behind the playback, not yet compensated), its depth past the
#    programmed one;
#  * the spindle oriented at 90 degrees after M19;
#  * the run replays bit for bit (the spindle's positions are recorded inputs).
#   spindle_sync_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-spindle-sync.XXXXXX)"
trap 'cleanup $?' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3_servo_spindle.yaml" "$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")

start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
start_cell
"${CTL[@]}" --do run --program "$SRC/config/programs/thread_and_tap.ngc" --timeout 120 >"$WORK/ctl.out" 2>&1 ||
  { cat "$WORK/ctl.out" >&2; fail "thread_and_tap.ngc did not run to its end"; }
sleep 1
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
/usr/bin/python3 - "$WORK/cell.lcmlog" "$TEST_PREFIX" "$(dirname "$0")" <<'PY' || fail "the synchronised motion is not as it should be"
import bisect, statistics, sys
log, prefix = sys.argv[1], sys.argv[2]
sys.path.insert(0, sys.argv[3])
from lcmlog import events, fields, Fields
from checks import Checks
check = Checks()
T = 0.004
sp = []   # (sample playback cycle, revolutions, rev/s, orient_state)
ax = []   # (playback cycle, actual x, actual z)
cmd = []  # (setpoint cycle, x, z)
for ts, ch, b in events(log):
    if ch == prefix + "SPINDLE_STATUS":
        f = Fields(b)
        f.get("qqi"); f.get("b"); f.get("q"); f.get("q"); f.get("b"); _, rpm, _ = f.get("ddd"); f.get("i"); f.str(); f.get("qq")
        rev = f.get("d"); valid = f.get("b"); cyc = f.get("d"); orient = f.get("b")
        if valid and cyc >= 0:
            sp.append((cyc, rev, rpm / 60.0, orient))
    elif ch == prefix + "AXIS_STATUS":
        f = Fields(b)
        f.get("qqi"); f.get("q"); n = f.get("i")
        for _ in range(n): f.str()
        f.get("d" * n); act = f.get("d" * n); f.get("d" * n); f.get("b" * n)
        for _ in range(n): f.str()
        for _ in range(5): f.get("q" * n)
        f.get("qq")
        ax.append((f.get("d"), act[0], act[2]))
    elif ch == prefix + "SETPOINTS":
        _, _, _, cycle, _, n, x, y, z = fields(b, "qqiqdiddd")
        cmd.append((cycle, x, z))
check(len(sp) > 1000 and len(ax) > 1000 and len(cmd) > 1000,
      f"spindle samples ({len(sp)}), axis states ({len(ax)}) and setpoints ({len(cmd)}) in the log")
sp.sort()
cycles = [s[0] for s in sp]
# A busy host stalls the bridge's playback now and then: its clock stands while the
# spindle turns on, and no controller can follow then. Such stretches show as samples
# whose revolutions disagree with their stamps by more than half a cycle (2 ms; the
# stamps scatter by up to 1 ms otherwise); the 30 cycles around each are left out of
# the error (and counted).
bad = []
for a, b2 in zip(sp, sp[1:]):
    if b2[0] > a[0] and abs(a[2]) > 1:
        if abs((b2[1] - a[1]) / (0.5 * (a[2] + b2[2]) * T) - (b2[0] - a[0])) > 0.5:
            bad.append(b2[0])
def disturbed(c):
    i = bisect.bisect_left(bad, c - 30)
    return i < len(bad) and bad[i] <= c + 30
def rev_at(c):
    i = bisect.bisect_left(cycles, c)
    if i <= 0 or i >= len(sp):
        return None
    (c0, r0, _, _), (c1, r1, _, _) = sp[i - 1], sp[i]
    return r0 + (r1 - r0) * (c - c0) / (c1 - c0) if c1 > c0 else r0
def stretch(states, x, pitch, zlo, zhi):
    """(cycle, k = Z + pitch x rev, disturbed) where X is x and Z within [zlo, zhi]."""
    out = []
    for c, xa, za in states:
        if abs(xa - x) < 0.01 and zlo <= za <= zhi:
            r = rev_at(c)
            if r is not None:
                out.append((c, za + pitch * r, disturbed(c)))
    return out
def error(s):
    """The median of k, and |k - median| at its 75th percentile and at its largest."""
    k = [p[1] for p in s if not p[2]]
    if len(k) < 50:
        return None, None, None, 0
    med = statistics.median(k)
    d = sorted(abs(v - med) for v in k)
    return med, d[int(0.75 * (len(d) - 1))], d[-1], sum(1 for p in s if p[2])
print(f"# bridge playback stalls seen in the spindle's stamps: {len(bad)}", file=sys.stderr)
phases = []
measured = {"commanded": 0, "actual": 0}
for i, x in enumerate((10.0, 9.8, 9.6)):
    # Each pass down from Z 2 to -20; its acquisition and phase catch-up (the first
    # 3 mm) and its end brake (the last 1.5 mm) left out.
    for name, states in (("commanded", cmd), ("actual", ax)):
        med, p90, err, nbad = error(stretch(states, x, 1.5, -18.5, -1.0))
        if med is None:
            print(f"# G33 pass {i + 1} (X {x}), {name} Z: too few states between stalls to measure", file=sys.stderr)
            continue
        measured[name] += 1
        print(f"# G33 pass {i + 1} (X {x}), {name} Z: synchronisation error {p90 * 1e3:.1f} um at the 75th "
              f"percentile, {err * 1e3:.1f} um at most ({nbad} states left out for stalls)", file=sys.stderr)
        # The largest is the host's: on this shared machine the samples' stamps scatter
        # and the bridge's playback stalls (2-8 um quiet, up to 138 um seen in a suite
        # run, 23 um at the 75th percentile then). Three states in four are the
        # controller's: a lost prediction (v x 12 ms: 300 um), a wrong pitch or a ringing
        # tracker put them far above 50 um.
        check(p90 < 0.05, f"pass {i + 1}: {name} synchronisation error {p90 * 1e3:.1f} um < 50 um (75th percentile)")
        if name == "actual":
            phases.append(med % 1.5)
check(min(measured.values()) >= 2, f"at least two of the three passes measured between stalls ({measured})")
if len(phases) >= 2:
    spread = max(min(abs(a - b), 1.5 - abs(a - b)) for a in phases for b in phases)
    print(f"# thread phase on the passes measured: {', '.join(f'{p:.4f}' for p in phases)} mm (spread {spread * 1e3:.1f} um)",
          file=sys.stderr)
    # 0.0-0.7 um on quiet runs, 25 um once between stalls; 41-44 um before the phase came from the index.
    check(spread < 0.03, f"the passes cut one thread (phase spread {spread * 1e3:.1f} um < 30 um)")
for x, scale in ((40.0, 1), (60.0, 2)):
    # Each way on its own (down to the reversal, up from it): a constant lag of the
    # axis behind the playback shifts k one way going down and the other going up.
    states = [st for st in ax if abs(st[1] - x) < 0.01]
    if not states:
        check(False, f"tap at X {x}: no states")
        continue
    deepest_c = min(states, key=lambda st: st[2])[0]
    meds = []
    for way, part in (("down", [st for st in states if st[0] <= deepest_c]), ("up", [st for st in states if st[0] > deepest_c])):
        med, p75, err, nbad = error(stretch(part, x, 1.25, -14.0, -2.0))
        if med is None:
            print(f"# G33.1 at X {x} {way}: too few states between stalls to measure", file=sys.stderr)
            continue
        meds.append(med)
        print(f"# G33.1 at X {x} (retract x{scale}) {way}: error {p75 * 1e3:.1f} um at the 75th percentile, "
              f"{err * 1e3:.1f} um at most ({nbad} states left out for stalls)", file=sys.stderr)
        check(p75 < 0.05, f"tap at X {x} {way}: error {p75 * 1e3:.1f} um < 50 um (75th percentile)")
    deepest = min(st[2] for st in states)
    if len(meds) == 2:
        # Without spindle.sync_lead_s: 2 x speed x the axes' lag behind the playback
        # (about a cycle here), 100-170 um; with it (4 ms) 13-17 um.
        print(f"# G33.1 at X {x}: the thread up {abs(meds[1] - meds[0]) * 1e3:.1f} um off the thread down", file=sys.stderr)
        check(abs(meds[1] - meds[0]) < 0.05, f"tap at X {x}: up within 50 um of down (the axes' lag led by sync_lead_s)")
    print(f"# G33.1 at X {x}: {-15 - deepest:.3f} mm past the programmed depth", file=sys.stderr)
    check(0 < -15 - deepest < 3, f"tap at X {x}: past the depth by {-15 - deepest:.3f} mm (the spindle's stopping distance)")
oriented = [s for s in sp if s[3] == 2]
check(oriented, "the spindle reported ORIENTED after M19")
if oriented:
    ang = (oriented[-1][1] % 1.0) * 360
    print(f"# M19 R90: the spindle at {ang:.2f} degrees", file=sys.stderr)
    check(min(abs(ang - 90), 360 - abs(ang - 90)) < 1.0, f"oriented at 90 degrees within 1 ({ang:.2f})")
sys.exit(0 if check.ok else 1)
PY
"$BUILD/tools/cnc-replay" --log "$WORK/cell.lcmlog" >"$WORK/replay.out" 2>&1 || { cat "$WORK/replay.out" >&2; fail "the run does not replay"; }
grep "^identical" "$WORK/replay.out" >&2 || fail "no verdict from cnc-replay"
