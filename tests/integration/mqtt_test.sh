#!/usr/bin/env bash
# cnc-mqtt on a live cell and a real broker (Debian's mosquitto) in a private network
# namespace: TLS (the test's own CA), a password file with a user per cell and one for
# the fleet's reader, an ACL that lets each cell write only cnc/<its name>/#. One
# cell (sim3, with the logger) and two more publishers (cells sim3b and sim3c whose
# buses are quiet: three whole cells would take some 2.6 of this VM's 2 cores). The
# fleet's reader is mosquitto_sub (mosquitto-clients), a persistent QoS 1 session.
# Checked: the birth retained; a program's job start and end arrive once each with
# the run's summary; a broker stopped (persistence) while a program runs and started
# again loses none of its records; a cnc-mqtt killed (SIGKILL) and one gone silent
# (SIGSTOP, after its keepalive) are marked offline by their wills (times measured); a cell's user publishing on another cell's topics is
# dropped by the broker; cnc-fleet's page (fleet.json, and the page in headless
# Chromium) lists the three cells and sim3's jobs. Before the cell: config errors exit
# 2 naming the key.
#   mqtt_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-mqtt-test.XXXXXX)"
trap 'cleanup $?' EXIT
MQTT="$BUILD/services/cnc-mqtt"
for p in mosquitto mosquitto_sub mosquitto_pub mosquitto_passwd openssl chromium; do
  command -v "$p" >/dev/null || fail "$p is not installed (./cnc installs mosquitto, mosquitto-clients, openssl)"
done

make_machine "$SRC/config/machines/sim3.yaml" "$WORK/base.yaml"
PORT=$((TEST_LCM_PORT + 5))

# ---- the broker's TLS: a CA and a certificate for 127.0.0.1 (P-256: made in ms) -------
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 2 -subj "/CN=cnc test CA" \
  -keyout "$WORK/ca.key" -out "$WORK/ca.crt" 2>"$WORK/openssl.log" || { cat "$WORK/openssl.log" >&2; fail "openssl: CA"; }
openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -subj "/CN=127.0.0.1" \
  -keyout "$WORK/broker.key" -out "$WORK/broker.csr" 2>>"$WORK/openssl.log" || fail "openssl: broker key"
openssl x509 -req -in "$WORK/broker.csr" -CA "$WORK/ca.crt" -CAkey "$WORK/ca.key" -CAcreateserial -days 2 \
  -extfile <(printf 'subjectAltName=IP:127.0.0.1\n') -out "$WORK/broker.crt" 2>>"$WORK/openssl.log" ||
  { cat "$WORK/openssl.log" >&2; fail "openssl: broker certificate"; }

# ---- users (one per cell, the fleet's reader) and the ACL ----------------------------
: >"$WORK/passwd"
for u in sim3 sim3b sim3c fleet; do
  printf '%s\n' "pw-$u-$RANDOM$RANDOM" >"$WORK/$u.pw"
  chmod 600 "$WORK/$u.pw"
  mosquitto_passwd -b "$WORK/passwd" "$u" "$(cat "$WORK/$u.pw")" || fail "mosquitto_passwd $u"
done
cat >"$WORK/acl" <<'ACL'
# the fleet's reader reads every cell
user fleet
topic read cnc/#
# every other user is a cell: it writes its own topics only
pattern write cnc/%u/#
ACL
mkdir -p "$WORK/broker-db"
cat >"$WORK/mosquitto.conf" <<EOF2
user root
per_listener_settings false
allow_anonymous false
password_file $WORK/passwd
acl_file $WORK/acl
persistence true
persistence_location $WORK/broker-db/
autosave_interval 1
log_dest stderr
log_type error
log_type warning
log_type notice
log_type information
log_type debug
listener $PORT 127.0.0.1
cafile $WORK/ca.crt
certfile $WORK/broker.crt
keyfile $WORK/broker.key
EOF2
chmod 600 "$WORK/passwd" "$WORK/acl"

# ---- the three cells' configs ----------------------------------------------------------
cell_config() {  # NAME OUT LCM_PORT_OFFSET KEEPALIVE: base.yaml as cell NAME on a bus of its own, with the mqtt: section
  local name="$1" out="$2" lcm=$((TEST_LCM_PORT + $3)) keepalive="$4"
  sed -e "s/^  name: sim3$/  name: $name/" -e "s#:${TEST_LCM_PORT}?#:${lcm}?#" -e "s#channel_prefix: \"${TEST_PREFIX}\"#channel_prefix: \"${TEST_PREFIX%.}$name.\"#" \
    "$WORK/base.yaml" >"$out"
  cat >>"$out" <<EOF2
mqtt:
  port: $PORT
  username: $name
  password_file: $name.pw
  ca_file: ca.crt
  keepalive_s: $keepalive
EOF2
  grep -q "^  name: $name$" "$out" || fail "cell_config: no name $name in $out"
}
M="$WORK/machine.yaml"
cp "$WORK/base.yaml" "$M"
cat >>"$M" <<EOF2
mqtt:
  port: $PORT
  username: sim3
  password_file: sim3.pw
  ca_file: ca.crt
  keepalive_s: 5
EOF2
cell_config sim3b "$WORK/sim3b.yaml" 2 5
cell_config sim3c "$WORK/sim3c.yaml" 3 5

# ---- config errors name the key (exit 2); no section: exit 3 ---------------------------
expect_exit() {
  local want="$1" pattern="$2"; shift 2
  local rc=0
  "$@" >"$WORK/exit.out" 2>&1 || rc=$?
  [ "$rc" -eq "$want" ] && grep -q -- "$pattern" "$WORK/exit.out" ||
    { cat "$WORK/exit.out" >&2; fail "$*: exit $rc, expected $want with '$pattern'"; }
  note "exit $rc: $(grep -- "$pattern" "$WORK/exit.out" | head -1)"
}
expect_exit 3 'has no mqtt: section' "$MQTT" --machine "$WORK/base.yaml" --print-url
sed 's/^  keepalive_s: 5$/  keepalive_s: 5\n  topic_prefix: "cnc\/+"/' "$M" >"$WORK/bad.yaml"
expect_exit 2 'mqtt.topic_prefix' "$MQTT" --machine "$WORK/bad.yaml" --print-url
chmod 640 "$WORK/sim3.pw"
expect_exit 2 'mqtt.password_file .* has mode 0640' "$MQTT" --machine "$M"
chmod 600 "$WORK/sim3.pw"
[ "$("$MQTT" --machine "$M" --print-url)" = "mqtts://127.0.0.1:$PORT/cnc/sim3" ] || fail "--print-url: $("$MQTT" --machine "$M" --print-url)"

# ---- the broker, the fleet's reader, the cell and the publishers -----------------------
broker_up() {
  start broker mosquitto -c "$WORK/mosquitto.conf"
  local i
  for ((i = 0; i < 100; i++)); do grep -q "Opening ipv4 listen socket on port $PORT" "$WORK/broker.log" && return 0; sleep 0.05; done
  cat "$WORK/broker.log" >&2; fail "the broker did not start"
}
broker_up
cp "$WORK/broker.log" "$WORK/broker-1.txt"
SUB=(-h 127.0.0.1 -p "$PORT" --cafile "$WORK/ca.crt" -q 1)
start fleet mosquitto_sub "${SUB[@]}" -u fleet -P "$(cat "$WORK/fleet.pw")" -i fleet-reader -c -t 'cnc/#' -F '%U %r %t %p'
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start_cell
start mqtt "$MQTT" --machine "$M"
# The fleet page, a reader of the broker like mosquitto_sub (the fleet user).
FLEET_PORT=$((TEST_LCM_PORT + 6))
start fleet-page "$BUILD/services/cnc-fleet" --broker 127.0.0.1 --broker-port "$PORT" --ca-file "$WORK/ca.crt" \
  --user fleet --password-file "$WORK/fleet.pw" --port "$FLEET_PORT"
start mqtt-b "$MQTT" --machine "$WORK/sim3b.yaml"
start mqtt-c "$MQTT" --machine "$WORK/sim3c.yaml"

# lines TOPIC [PATTERN]: the fleet reader's lines on TOPIC (matching PATTERN)
lines() { awk -v t="$1" '$3 == t' "$WORK/fleet.log" | grep -c -- "${2:-.}" || true; }
wait_lines() {  # TOPIC COUNT PATTERN SECONDS
  local i
  for ((i = 0; i < ${4:-5} * 20; i++)); do [ "$(lines "$1" "$3")" -ge "$2" ] && return 0; sleep 0.05; done
  cat "$WORK/fleet.log" >&2; fail "the fleet's reader did not get $2 line(s) on $1 matching '$3'"
}
for c in sim3 sim3b sim3c; do wait_lines "cnc/$c/status" 1 '"status":"online"' 10; done
note "three cells online"
# The birth is retained: a reader that comes later gets it at once (retain flag 1).
mosquitto_sub "${SUB[@]}" -u fleet -P "$(cat "$WORK/fleet.pw")" -t cnc/sim3b/status -C 1 -W 3 -F '%r %p' >"$WORK/late.out" ||
  fail "a late reader got no retained status"
grep -q '^1 .*"status":"online"' "$WORK/late.out" || fail "the retained status: $(cat "$WORK/late.out")"

cat >"$WORK/short.ngc" <<'NGC'
G21 G90
G1 X100 Y50 F3000
G0 X0 Y0
M2
NGC
"$BUILD/tools/cnc-ctl" --machine "$M" --do override --value 0.8 --timeout 10 >"$WORK/ovr.out" 2>&1 ||
  { cat "$WORK/ovr.out" >&2; fail "the feed override was not taken"; }
PID=${TEST_PIDS[mqtt]}
cpu_ticks() { awk '{print $14 + $15}' "/proc/$PID/stat"; }
t0=$(cpu_ticks); w0=$(date +%s.%N)
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/short.ngc" --timeout 60 >"$WORK/ctl1.out" 2>&1 ||
  { cat "$WORK/ctl1.out" >&2; fail "the first program did not complete"; }
t1=$(cpu_ticks); w1=$(date +%s.%N)
RSS=$(awk '/VmRSS/ {print $2}' "/proc/$PID/status")
CPU=$(awk -v a="$t0" -v b="$t1" -v w0="$w0" -v w1="$w1" -v hz="$(getconf CLK_TCK)" 'BEGIN {printf "%.1f", 100 * (b - a) / hz / (w1 - w0)}')
note "cnc-mqtt while the program ran ($(awk -v a="$w0" -v b="$w1" 'BEGIN {printf "%.2f", b - a}') s): CPU $CPU % of a core, RSS $RSS kB"
wait_lines cnc/sim3/job/end 1 '"outcome":"done"' 5
JOB1=$(awk '$3 == "cnc/sim3/job/end"' "$WORK/fleet.log" | head -1 | sed 's/.*"job":"\([^"]*\)".*/\1/')
[ "$(lines cnc/sim3/job/start "\"job\":\"$JOB1\"")" -eq 1 ] || fail "job $JOB1: $(lines cnc/sim3/job/start "$JOB1") start records"
/usr/bin/python3 - "$WORK/fleet.log" "$JOB1" <<'PY' || fail "the job's summary"
import json, sys
for line in open(sys.argv[1]):
    f = line.split(" ", 3)
    if f[2] == "cnc/sim3/job/end":
        j = json.loads(f[3])
        if j["job"] == sys.argv[2]:
            break
print(f"# job end: program {j['program']}, {j['duration_s']:.3f} s, program time {j['program_time_s']:.3f} s, "
      f"{j['blocks_done']} blocks, {j['alarms']} alarms, largest following error {j['max_following_error_mm']:.4f} mm, log {j['log']}",
      file=sys.stderr)
ok = (j["program"] == "short.ngc" and 0.2 < j["duration_s"] < 30 and j["program_time_s"] > 0.2
      and j["max_following_error_mm"] is not None and 0 < j["max_following_error_mm"] < 1.0
      and j["log"] is not None and j["log"].startswith(sys.argv[1].rsplit("/", 1)[0] + "/run"))
sys.exit(0 if ok else 1)
PY

# The retained state after the run: the program done, the override, where the axes stand.
# The first is published as the program ends, while the drives settle (60 um off once on a
# fresh clone's run); the state is published again every mqtt.state_period_s, so the
# retained one comes to where they stand: wait for it, at most 4 s.
check_state() {
  awk '$3 == "cnc/sim3/state"' "$WORK/fleet.log" | tail -1 | cut -d' ' -f4- >"$WORK/state.json"
  /usr/bin/python3 - "$WORK/state.json" "$1" <<'PY'
import json, sys
try:
    s = json.load(open(sys.argv[1]))
except ValueError:
    sys.exit(1)
if sys.argv[2] == "say":
    print(f"# state: program {s['program']}, overrides {s['overrides']}, position {s['position_mm']}, actual {s['actual_mm']}",
          file=sys.stderr)
ok = (s["program"]["state"] == "done" and s["program"]["name"] == "short.ngc" and abs(s["overrides"]["feed"] - 0.8) < 1e-9
      and all(abs(s["position_mm"][a]) < 1e-3 and abs(s["actual_mm"][a]) < 0.05 for a in "XY") and s["job"] is None)
sys.exit(0 if ok else 1)
PY
}
for ((i = 0; i < 80; i++)); do check_state quiet && break; sleep 0.05; done
check_state say || fail "the state: $(cat "$WORK/state.json")"

# An alarm (the interpolator's on a reset) arrives once, outside any job.
"$BUILD/tools/cnc-ctl" --machine "$M" --do reset --timeout 10 >"$WORK/reset.out" 2>&1 || { cat "$WORK/reset.out" >&2; fail "reset"; }
wait_lines cnc/sim3/alarm 1 '"code":"reset"' 5
[ "$(lines cnc/sim3/alarm '"code":"reset"')" -eq 1 ] && [ "$(lines cnc/sim3/alarm '"job":null')" -ge 1 ] ||
  fail "the reset alarm: $(awk '$3 == "cnc/sim3/alarm"' "$WORK/fleet.log")"

# ---- a broker restart while a program runs: its records wait at the cell ---------------
printf 'G21 G90\nG1 X20 F3000\nG0 X0\nM2\n' >"$WORK/second.ngc"
stop broker TERM
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/second.ngc" --timeout 60 >"$WORK/ctl2.out" 2>&1 ||
  { cat "$WORK/ctl2.out" >&2; fail "the second program did not complete"; }
[ "$(lines cnc/sim3/job/end)" -eq 1 ] || fail "a job end arrived while the broker was down"
broker_up
wait_lines cnc/sim3/job/end 2 . 10
JOB2=$(awk '$3 == "cnc/sim3/job/end"' "$WORK/fleet.log" | sed -n 2p | sed 's/.*"job":"\([^"]*\)".*/\1/')
[ "$JOB2" != "$JOB1" ] || fail "the second job has the first's id"
sleep 0.5  # time for a duplicate to show
for t in start end; do
  [ "$(lines cnc/sim3/job/$t "\"job\":\"$JOB1\"")" -eq 1 ] && [ "$(lines cnc/sim3/job/$t "\"job\":\"$JOB2\"")" -eq 1 ] ||
    fail "job/$t: $(lines cnc/sim3/job/$t "$JOB1") records of $JOB1, $(lines cnc/sim3/job/$t "$JOB2") of $JOB2 (1 each)"
done
note "broker restart: job $JOB2 (run while the broker was down) arrived once, start and end"

# ---- a cell gone silent (SIGSTOP: a frozen PC, a cable pulled): its will when the broker
# has heard nothing for 1.5 keepalives (7.5 s); the next steps run meanwhile.
s0=$(date +%s.%N)
kill -STOP "${TEST_PIDS[mqtt-c]}"

# ---- a cell killed: its will marks it offline -----------------------------------------
# (A broker stopping publishes its clients' wills too: only a will after the kill counts.)
k0=$(date +%s.%N)
kill_hard mqtt-b
offline_after() { awk -v t0="$k0" '$1 > t0 && $2 == 0 && $3 == "cnc/sim3b/status" && /connection lost/ {print $1; exit}' "$WORK/fleet.log"; }
for ((i = 0; i < 300; i++)); do [ -n "$(offline_after)" ] && break; sleep 0.05; done
k1=$(offline_after)
[ -n "$k1" ] || fail "sim3b was not marked offline by its will within 15 s"
note "SIGKILL to offline at the reader: $(awk -v a="$k0" -v b="$k1" 'BEGIN {printf "%.3f", b - a}') s (keepalive 5 s)"

# ---- a cell writing outside its topics: the broker drops it ----------------------------
mosquitto_pub "${SUB[@]}" -u sim3c -P "$(cat "$WORK/sim3c.pw")" -i intruder -t cnc/sim3/job/end -m '{"job":"forged"}' ||
  fail "mosquitto_pub as sim3c"
mosquitto_pub "${SUB[@]}" -u sim3c -P "$(cat "$WORK/sim3c.pw")" -i intruder -t cnc/sim3c/probe -m '{"probe":1}' ||
  fail "mosquitto_pub as sim3c on its own topic"
wait_lines cnc/sim3c/probe 1 . 5  # its own topic arrives, so the other would have by now
[ "$(grep -c forged "$WORK/fleet.log" || true)" -eq 0 ] || fail "sim3c's record on sim3's topic reached the reader"
grep -q "Denied PUBLISH from intruder" "$WORK/broker.log" || fail "the broker did not log the denied publish"
note "sim3c on cnc/sim3/job/end: $(grep -m1 "Denied PUBLISH from intruder" "$WORK/broker.log" | cut -d' ' -f2-)"

# ---- the fleet page: the three cells, their state and last jobs -------------------------
/usr/bin/python3 - "$FLEET_PORT" "$JOB1" "$JOB2" <<'PY' || fail "the fleet page"
import json, sys, time, urllib.request
base = f"http://127.0.0.1:{sys.argv[1]}/"
page = urllib.request.urlopen(base, timeout=5).read().decode()
assert "fleet.js" in page, page
assert "refresh" in urllib.request.urlopen(base + "fleet.js", timeout=5).read().decode()
for _ in range(50):
    f = json.load(urllib.request.urlopen(base + "fleet.json", timeout=5))
    cells = {c["cell"]: c for c in f["cells"]}
    if (set(cells) == {"sim3", "sim3b", "sim3c"} and cells["sim3b"]["status"].get("status") == "offline"
            and [j["job"] for j in cells["sim3"]["jobs"]] == [sys.argv[3], sys.argv[2]]):
        break
    time.sleep(0.1)
else:
    print(json.dumps(f, indent=1), file=sys.stderr)
    sys.exit(1)
assert cells["sim3"]["status"]["status"] == "online"
assert cells["sim3"]["state"]["program"]["name"] == "second.ngc", cells["sim3"]["state"]
assert cells["sim3b"]["status"]["reason"] == "connection lost"
print(f"# fleet page: {len(cells)} cells, sim3's last jobs {[j['program'] + ' ' + j['outcome'] for j in cells['sim3']['jobs']]}, "
      f"{f['records']} records read", file=sys.stderr)
PY
# The page itself in headless Chromium: its script fills one row per cell with sim3's jobs.
flags=(--headless --no-sandbox --disable-gpu --disable-quic --no-first-run --disable-background-networking
       --disable-component-update --disable-sync --user-data-dir="$WORK/chromium-profile" --enable-logging=stderr --v=0
       --window-size=1280,420 --hide-scrollbars --virtual-time-budget=3000)
timeout 60 chromium "${flags[@]}" --dump-dom "http://127.0.0.1:$FLEET_PORT/" >"$WORK/fleet-dom.html" 2>"$WORK/chromium.log" ||
  { tail -20 "$WORK/chromium.log" >&2; fail "chromium could not load the fleet page"; }
for c in sim3 sim3b sim3c; do grep -q "data-cell=\"$c\"" "$WORK/fleet-dom.html" || fail "the page has no row for $c"; done
grep -q "data-job=\"$JOB2\"" "$WORK/fleet-dom.html" && grep -q "data-job=\"$JOB1\"" "$WORK/fleet-dom.html" ||
  fail "the page does not list sim3's jobs"
grep -q 'data-status="offline"' "$WORK/fleet-dom.html" || fail "the page does not show sim3b offline"
note "the fleet page in Chromium: 3 rows, sim3's 2 jobs, sim3b offline"
# CNC_FLEET_SCREENSHOT=FILE: the page's picture for docs/mqtt.md (docs/img/fleet.png).
if [ -n "${CNC_FLEET_SCREENSHOT:-}" ]; then
  timeout 60 chromium "${flags[@]}" --screenshot="$CNC_FLEET_SCREENSHOT" "http://127.0.0.1:$FLEET_PORT/" >>"$WORK/chromium.log" 2>&1 ||
    fail "chromium: no screenshot"
fi

# ---- the silent cell: offline by its will after 1.5 keepalives, back when it wakes -----
silent_after() { awk -v t0="$s0" '$1 > t0 && $2 == 0 && $3 == "cnc/sim3c/status" && /connection lost/ {print $1; exit}' "$WORK/fleet.log"; }
for ((i = 0; i < 300; i++)); do [ -n "$(silent_after)" ] && break; sleep 0.05; done
s1=$(silent_after)
kill -CONT "${TEST_PIDS[mqtt-c]}"
[ -n "$s1" ] || fail "sim3c, silent, was not marked offline within 15 s"
SILENT=$(awk -v a="$s0" -v b="$s1" 'BEGIN {printf "%.3f", b - a}')
# MQTT: 1.5 keepalives (7.5 s) of silence, the last state up to 1 s before the stop;
# mosquitto 2.0.11 takes longer: 11 s after the last packet seen (10.5 s from the stop).
awk -v s="$SILENT" 'BEGIN {exit !(s >= 6.4 && s <= 12.5)}' || fail "sim3c silent to offline: $SILENT s, expected 6.5-12.5 s"
note "SIGSTOP to offline at the reader: $SILENT s (keepalive 5 s; MQTT's 1.5 keepalives: 7.5 s)"
for ((i = 0; i < 100; i++)); do
  awk -v t0="$s1" '$1 > t0 && $3 == "cnc/sim3c/status" && /"status":"online"/ {f = 1} END {exit !f}' "$WORK/fleet.log" && break
  sleep 0.05
done
awk -v t0="$s1" '$1 > t0 && $3 == "cnc/sim3c/status" && /"status":"online"/ {f = 1} END {exit !f}' "$WORK/fleet.log" ||
  fail "sim3c did not come back online within 5 s of SIGCONT"

stop mqtt TERM
wait_lines cnc/sim3/status 1 '"reason":"stopped"' 5
grep -q "cnc-mqtt: stopped: 2 jobs started, 2 ended" "$WORK/mqtt.log" || { tail -3 "$WORK/mqtt.log" >&2; fail "cnc-mqtt's counts"; }
note "$(grep "cnc-mqtt: stopped" "$WORK/mqtt.log" | sed 's/.*cnc-mqtt: //')"
note "records at the reader: $(wc -l <"$WORK/fleet.log") ($(lines cnc/sim3/state) sim3 states, $(lines cnc/sim3/job/start) job starts, $(lines cnc/sim3/job/end) job ends, $(lines cnc/sim3/alarm) alarms)"
stop mqtt-c TERM
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
stop fleet TERM
stop fleet-page TERM
stop broker TERM
echo "mqtt test passed"
