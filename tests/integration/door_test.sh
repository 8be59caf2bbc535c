#!/usr/bin/env bash
# The guard door on the live cell (config/machines/sim3_guarded.yaml): a normally
# closed switch on the I/O module's discrete input door_closed, opened and shut by
# cnc-servo-sim's control FIFO ("at X 100 input door_closed 0": opened when X passes
# 100 mm, logged with the wall clock and X's position and speed).
#  1. Opened mid-program (G1 X200 at 100 mm/s, spindle at 3000 rpm): a feed hold from
#     the edge, within v*(t + lead) + v^2/(2a) + 2*v*a/(2j) (a, j the path's), the
#     spindle stopped once the path stands, the drives enabled; RESUME refused naming
#     the door; shut, nothing moves until the operator's RESUME; then the spindle runs
#     up, and the program goes on to its end.
#  2. Open with the cell idle: START, a jog and MDI refused naming the door; shut: an
#     MDI line runs.
#   door_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-door.XXXXXX)"
trap 'cleanup $?' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3_guarded.yaml" "$M"
CTL=("$BUILD/tools/cnc-ctl" --machine "$M")
printf 'G21 G90\nM3 S3000\nG1 X200 F6000\nM30\n' >"$WORK/cut.ngc"
printf 'G21 G90\nG1 X150 F3000\nM30\n' >"$WORK/idle.ngc"

mkfifo "$WORK/sim.ctl"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --control "$WORK/sim.ctl"
exec 7<>"$WORK/sim.ctl"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/cell"
start_cell
now_us() { date +%s%6N; }

# ---- 1. opened mid-program -----------------------------------------------------------
echo "at X 100 input door_closed 0" >&7
"${CTL[@]}" --do run --program "$WORK/cut.ngc" --timeout 60 >"$WORK/run.out" 2>&1 &
RUN=$!
wait_state held
sleep 0.3
expect_refused resume_open "the guard door (input door_closed on module io1) is open" "${CTL[@]}" --do resume --timeout 5
echo "input door_closed 1" >&7
sleep 0.5
echo "resume $(now_us)" >"$WORK/resumes"
ok resume "${CTL[@]}" --do resume --timeout 10
rc=0; wait "$RUN" || rc=$?
[ "$rc" -eq 0 ] || { cat "$WORK/run.out" >&2; fail "the program did not run to its end after the resume (exit $rc)"; }
note "the program ran to its end after the door was shut and the operator resumed"

# ---- 2. open with the cell idle ---------------------------------------------------------
echo "input door_closed 0" >&7
sleep 0.3
expect_refused start_open "the guard door (input door_closed on module io1) is open" "${CTL[@]}" --do run --program "$WORK/idle.ngc" --timeout 10
expect_refused jog_open "the guard door (input door_closed on module io1) is open" "${CTL[@]}" --do jog --axis Y --value 1 --timeout 5
expect_refused mdi_open "the guard door (input door_closed on module io1) is open" "${CTL[@]}" --do mdi --line "G0 Y20" --timeout 5
echo "input door_closed 1" >&7
sleep 0.3
ok mdi_shut "${CTL[@]}" --do mdi --line "G0 Y20" --timeout 20

for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
exec 7>&-
grep -E "door|spindle: (stop|run)|axis [XYZ]: (enabled|disabled)" "$WORK/servo-sim.log" "$WORK/interpolator.log" |
  sed 's#^.*/##' >&2 || true

/usr/bin/python3 - "$WORK/cell.lcmlog" "$TEST_PREFIX" "$(dirname "$0")" "$WORK/servo-sim.log" "$WORK/resumes" "$M" \
  "$WORK/interpolator.log" <<'PY' || fail "the door's reaction is not as it should be"
import datetime, re, sys
log, prefix, here, simlog, resumes, machine, interplog = sys.argv[1:8]
sys.path.insert(0, here)
import safety_figures
from safety_figures import read_io_status, stop_figures
text = open(machine).read()
x_axis = text[text.index("- name: X"):text.index("- name: Y")]
accel = min(float(re.search(r"max_accel_mm_s2:\s*([0-9.]+)", x_axis).group(1)),
            float(re.search(r"path_accel_mm_s2:\s*([0-9.]+)", text).group(1)))
jerk = min(float(re.search(r"max_jerk_mm_s3:\s*([0-9.]+)", x_axis).group(1)),
           float(re.search(r"path_jerk_mm_s3:\s*([0-9.]+)", text).group(1)))
ipo = float(re.search(r"ipo_period_s:\s*([0-9.]+)", text).group(1))
def stamp(hms, ref_us):
    """A log line's local time of day (HH:MM:SS.mmm) as wall-clock us, on the day of ref_us."""
    day = datetime.datetime.fromtimestamp(ref_us * 1e-6).date()
    t = datetime.datetime.strptime(hms, "%H:%M:%S.%f").time()
    return datetime.datetime.combine(day, t).timestamp() * 1e6
spindle = []
lines = open(simlog).read().splitlines()
edges, power = safety_figures.sim_edges(lines, "door_closed")
ref = edges[0][0] if edges else 0
for line in lines:
    m = re.match(r"([0-9:.]+) .*spindle: (stop|run)", line)
    if m: spindle.append((stamp(m.group(1), ref), m.group(2)))
holds = []
for line in open(interplog):
    m = re.match(r"([0-9:.]+) .*the guard door \(input door_closed on module io1\) opened: feed hold", line)
    if m: holds.append(stamp(m.group(1), ref))
t_resume = int(open(resumes).read().split()[1])
axis, io = read_io_status(log, prefix)
from checks import Checks
check = Checks()
check(len(edges) == 2, f"two openings in the simulator's log ({len(edges)})")
t0, x0, _ = edges[0]
seen = sorted({s["door_utime"] for s in io if t0 <= s["door_utime"] < t0 + 1e6})
check(len(seen) == 1, "IO_STATUS: the bridge saw the door open")
if seen: print(f"# the bridge saw the door open {(seen[0] - t0) * 1e-3:.2f} ms after the edge", file=sys.stderr)
hold = [h for h in holds if t0 - 1e3 <= h < t0 + 1e6]
check(len(hold) == 1, "the interpolator held the feed once for the opening")
if not check.ok: sys.exit(1)
# The interpolator's log stamps to the millisecond: the hold at most 1 ms later than logged.
t_hold = max(hold[0], t0) + 1e3
# The drives' command brakes about the bridge's playback lead after the path: lead_cycles
# (2) + half a period + the smoothing's period.
lead = 3.5 * ipo
check.ok = stop_figures("door opened", t0, x0, t_hold, float("nan"), t_resume, axis, power, accel, jerk, check,
                  disabled=False, lead_s=lead) and check.ok
stops = [t for t, w in spindle if w == "stop" and t0 < t < t_resume]
runs = [t for t, w in spindle if w == "run" and t > t_resume]
check(bool(stops), f"the spindle stopped {(stops[0] - t0) * 1e-3 if stops else float('nan'):.0f} ms after the edge")
check(bool(runs), "the spindle ran again after the operator's RESUME")
after = [s for s in axis if t_resume <= s[0]]
moved = next((s for s in after if abs(s[2] - after[0][2]) > 1e-3), None)
if runs and moved:
    # At speed within 2 %: ln(50) time constants of its first-order response after the switch-on.
    tau = float(re.search(r"time_constant_s:\s*([0-9.]+)", text).group(1))
    check(moved[0] - runs[0] >= 0.9 * 3.91 * tau * 1e6,
          f"X moved again {(moved[0] - runs[0]) * 1e-3:.0f} ms after the spindle was switched on (at speed after "
          f"about {3.91 * tau * 1e3:.0f} ms; {(moved[0] - t_resume) * 1e-3:.0f} ms after the RESUME's send)")
sys.exit(0 if check.ok else 1)
PY
grep -q "spindle: stop" "$WORK/servo-sim.log" || fail "the spindle did not stop"
echo "PASS"
