#!/usr/bin/env bash
# The browser HMI: the cell started by ./cnc up (cnc-hmi
# with it) in a private network namespace, listening with a users file; the page
# driven in headless Chromium (tests/integration/hmi_drive.py: selenium with Debian's
# chromium-driver): the login page and a refused WebSocket without a session, two
# wrong passwords refused alike (and counted: the hmi_login_refused ALARM, the
# heartbeat), home X, jog X by 10 mm, touch off X, load and start a program and see
# the highlighted line move, hold (motion stands), resume, feed override 50 % and
# back, stop, single block on and three single steps, MDI, a fault injected from
# outside (DRIVE_CMD DISABLE) shown in the alarm list, reset; the session's run listed
# (programs, alarms) and its report made and opened from the page; a second cnc-hmi
# with read_only_without_login: the page without a login shows the machine and
# refuses actions; the machine panel (a spindle and an I/O module: the program's M3 S6000
# M8, the spindle override slider, the E-stop and door, every I/O point by name). Timings from the click to the change on the page and the position
# display rate, measured in the page; screenshots in
# BUILD/test-output/hmi/ (timings.json beside them).
#   hmi_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-hmi-test.XXXXXX)"
OUT="$BUILD/test-output/hmi"
trap 'cleanup' EXIT
[ -x /usr/bin/chromedriver ] || fail "chromium-driver is not installed (./cnc installs it: PACKAGES)"
/usr/bin/python3 -c 'import selenium' 2>/dev/null || fail "python3-selenium is not installed (./cnc installs it: PACKAGES)"
rm -rf "$OUT" && mkdir -p "$OUT"

# sim3 with a spindle and a small I/O module (the coolant, the E-stop, the guard door)
# for the page's machine panel: few points, so that IO_STATUS (every T_ipo) adds
# little to the session's log, which the runs list and the report read.
{ cat "$SRC/config/machines/sim3.yaml"; cat <<'EOF3'

spindle:
  drive: {transport: modbus_tcp, host: 127.0.0.1, port: 1502, unit_id: 4, profile: delta_vfd}
  at_speed_tolerance: 0.02
  sim: {time_constant_s: 0.1}   # each start's at-speed wait about 0.4 s
io:
  modules:
    - {name: io1, transport: modbus_tcp, host: 127.0.0.1, port: 1502, unit_id: 5}
  points:
    - {name: coolant_mist, module: io1, kind: coil, address: 0}
    - {name: coolant_flood, module: io1, kind: coil, address: 1}
    - {name: door_closed, module: io1, kind: discrete_input, address: 1}
    - {name: estop_ok, module: io1, kind: discrete_input, address: 2}
    - {name: lamp, module: io1, kind: coil, address: 8}
  coolant: {mist: coolant_mist, flood: coolant_flood}
  digital_outputs: [lamp]
safety:
  estop: {input: estop_ok}
  door: {input: door_closed}
EOF3
} >"$WORK/src.yaml"
make_machine "$WORK/src.yaml" "$WORK/base.yaml"
M="$WORK/machine.yaml"
# Home switches on the simulated axes (X homes on its switch from the page), homing not required.
/usr/bin/python3 "$SRC/tests/integration/operator_machine.py" "$WORK/base.yaml" "$M" "$WORK/mdi"
sed -i 's/homing_required: true/homing_required: false/' "$M"
mkdir -p "$WORK/programs" "$WORK/mdi"
cat >"$WORK/programs/square.ngc" <<'NGC'
G21 G90 G17 G54
G0 X20 Y10 Z2 M3 S6000 M8
G1 Z-1 F600
G1 X40
G1 Y50
G1 X0
G1 Y10
G1 X40
G1 Y50
G0 Z5
M2
NGC
export HMI_PASSWORD="chips-and-$RANDOM-coolant"
printf '%s\n' "$HMI_PASSWORD" | "$BUILD/services/cnc-hmi" --hash-password operator >"$WORK/users" ||
  fail "cnc-hmi --hash-password failed"
grep -q '^operator:\$argon2id\$' "$WORK/users" || fail "the users file line is not an argon2id hash: $(cat "$WORK/users")"
chmod 600 "$WORK/users"
printf 'T1 P1 Z0 D3 ;centre drill\nT2 P2 Z5 D10 ;end mill\n' >"$WORK/tools.tbl"
cat >>"$M" <<EOF2
program:
  var_file: $WORK/cnc.var
  tool_table: $WORK/tools.tbl
hmi:
  listen: 127.0.0.1
  port: 8093
  users_file: users
  program_dir: programs
  runs_dir: .
EOF2

# Bad input: a shop-network address without a users file is a config error naming the key.
sed -e 's/^  users_file: users$//' -e 's/listen: 127.0.0.1/listen: 0.0.0.0/' "$M" >"$WORK/open.yaml"
rc=0; "$BUILD/services/cnc-hmi" --machine "$WORK/open.yaml" >"$WORK/open.out" 2>&1 || rc=$?
[ "$rc" -eq 2 ] && grep -q 'hmi.users_file.*is required when hmi.listen is not a localhost address' "$WORK/open.out" ||
  { cat "$WORK/open.out" >&2; fail "listening on 0.0.0.0 without a users file: exit $rc, expected 2 naming hmi.users_file"; }
note "0.0.0.0 without users file refused: $(head -1 "$WORK/open.out")"

# On a failure ./cnc up stops its services itself (SIGTERM) before the rest is killed.
stop_up() { local rc=$? p="${TEST_PIDS[up]:-}"; [ -z "$p" ] || { kill -TERM "$p" 2>/dev/null; wait "$p" 2>/dev/null; }; cleanup "$rc"; }
trap 'stop_up' EXIT
(cd "$WORK" && CNC_BUILD_DIR="$BUILD" CNC_STATE_DIR="$WORK" exec "$SRC/cnc" up --machine "$M" --log-out "$WORK/cell") \
  >"$WORK/up.log" 2>&1 &
TEST_PIDS[up]=$!
for _ in $(seq 1 300); do grep -q "cnc-hmi: open http://127.0.0.1:8093/" "$WORK/up.log" && break; sleep 0.1; done
grep -q "cnc-hmi: open http://127.0.0.1:8093/" "$WORK/up.log" || { cat "$WORK/up.log" >&2; fail "cnc-hmi did not print its URL"; }
grep -q "the operator's page: http://127.0.0.1:8093/" "$WORK/up.log" || fail "./cnc up did not print the page's URL"
"$BUILD/tools/cnc-ctl" --machine "$M" --do enable --timeout 30 >"$WORK/enable.out" 2>&1 || { cat "$WORK/enable.out" >&2; fail "the drives did not enable"; }

# A second page on the same cell with a view-only page for browsers that have not logged in.
sed -e 's/port: 8093/port: 8094/' -e 's/^  runs_dir: \.$/  runs_dir: .\n  read_only_without_login: true/' "$M" >"$WORK/view.yaml"
grep -q 'read_only_without_login: true' "$WORK/view.yaml" || fail "view.yaml: no read_only_without_login"
start hmi-view "$BUILD/services/cnc-hmi" --machine "$WORK/view.yaml"
for _ in $(seq 1 300); do grep -q "open http://127.0.0.1:8094/" "$WORK/hmi-view.log" && break; sleep 0.1; done
grep -q "open http://127.0.0.1:8094/" "$WORK/hmi-view.log" || { cat "$WORK/hmi-view.log" >&2; fail "the view-only cnc-hmi did not start"; }

rc=0
# The session's budget: 50-70 s on a quiet machine; headless Chromium (its WebGL in
# software) beside a CPU-bound test of the suite took up to 160 s.
HMI_VIEW_URL="http://127.0.0.1:8094/" timeout 300 /usr/bin/python3 "$SRC/tests/integration/hmi_drive.py" "http://127.0.0.1:8093/" "$OUT" \
  "$BUILD/tools/cnc-ctl" --machine "$M" 2>&1 | tee "$WORK/drive.log" >&2 || rc=$?
[ "${PIPESTATUS[0]}" -eq 0 ] && [ "$rc" -eq 0 ] || { tail -40 "$WORK/up.log" >&2; fail "the browser session failed (screenshots in $OUT)"; }

# The rapid slider's RAPID_OVERRIDE reached the interpolator (50 %, then 100 %).
grep -q "rapid override 0.5" "$WORK/up.log" || fail "the page's rapid override 50 % did not reach the interpolator"
# The touch-off reached the var file (G10 L20 P0 X0 at X = 10: the G54 X offset 10).
grep -qE '^5221[[:space:]]+10\.0' "$WORK/cnc.var" || { cat "$WORK/cnc.var" >&2 2>/dev/null; fail "the touch-off is not in the var file (5221 10.0)"; }
# The page's offset and tool edits reached the var file and the tool table (G10 L2 P2
# X5.25: #5241; G10 L1 P1 Z12.5 R3), and its upload the program directory.
grep -qE '^5241[[:space:]]+5\.25' "$WORK/cnc.var" || { cat "$WORK/cnc.var" >&2; fail "the page's G55 X offset is not in the var file (5241 5.25)"; }
grep -qE '^T1 .*Z\+?12\.5' "$WORK/tools.tbl" || { cat "$WORK/tools.tbl" >&2; fail "the page's tool 1 length is not in the tool table (Z12.5)"; }
[ "$(cat "$WORK/programs/uploaded.ngc" 2>/dev/null)" = "$(printf 'G21 G90\nG0 X5 Y5\nM2')" ] ||
  fail "the uploaded program is not in the program directory as sent"
# The refused logins counted: in the log and in the heartbeat's detail.
grep -q "login refused for user 'operator'" "$WORK/up.log" || fail "the refused login is not in the log"
grep -q "login refused for user 'nobody'" "$WORK/up.log" || fail "the refused unknown user is not in the log"
"$BUILD/tools/cnc-ctl" --machine "$M" --do status >"$WORK/status.out" 2>&1 || true
grep -q '^cnc-hmi ' "$WORK/status.out" || { cat "$WORK/status.out" >&2; fail "cnc-ctl --do status does not list cnc-hmi"; }
# ... and the machine's devices: the spindle, the safety chain by its inputs.
for want in '^spindle: ' '^E-stop: OK, input estop_ok reads 1$' '^door: shut, input door_closed reads 1$' \
    '^io coolant_flood +digital out 0 +io1 \(M8 flood\)$'; do
  grep -qE "$want" "$WORK/status.out" || { cat "$WORK/status.out" >&2; fail "cnc-ctl --do status: no line $want"; }
done
stop hmi-view TERM
stop up TERM
grep -q "cnc-hmi: stopped (1 logins, 2 refused)" "$WORK/up.log" || { grep cnc-hmi "$WORK/up.log" >&2; fail "cnc-hmi's count of logins is not 1 accepted, 2 refused"; }
# The operator's session (homing, jogs, touch-off, MDI, a program) raises no monitor
# alarm: the monitor knows the manual moves' blocks and the homing offsets.
if grep -E "\[warning\] (chord_error|rmax|force|deflection)" "$WORK/up.log" >&2; then
  fail "the monitor raised alarms during the operator's session"
fi
note "timings: $(cat "$OUT/timings.json" | tr -d '\n ')"
note "screenshots: $(ls "$OUT"/*.png | tr '\n' ' ')"
echo "hmi test passed"
