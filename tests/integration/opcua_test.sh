#!/usr/bin/env bash
# The OPC UA server (cnc-opcua, OPC 40501-1 Machine Tools) on a live cell: sim3 with a
# spindle on the simulated drives, cnc-hmi with a users file, and two cnc-opcua
# servers as its clients in a private network namespace: a secure one (Basic256Sha256
# SignAndEncrypt only, HMI users, unknown client certificates refused) and an open
# one (anonymous: true, allow_security_none: true). node-opcua's client
# (opcua_client.js) checks the endpoints, refuses (SecurityPolicy None, an unknown
# client certificate, anonymous, a wrong password), browses the machine and reads
# the mandatory nodes, sees the channel state, the program's and job's states, the
# parts and the stack light change while a short program runs, and receives the
# cell's alarms as events; the open server takes an anonymous read over None and
# refuses its write. Before the cell: config errors exit 2 naming the key.
#   opcua_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-opcua-test.XXXXXX)"
trap 'cleanup $?' EXIT
OPCUA="$BUILD/services/cnc-opcua"
command -v node >/dev/null || fail "node is not installed (./cnc installs nodejs: PACKAGES)"
[ -d "$BUILD/services/opcua/node_modules/node-opcua" ] || fail "node-opcua is not in the build tree (npm ci: cnc_opcua_modules)"

# sim3 with a spindle that comes to speed in about 0.4 s.
sed 's/time_constant_s: 0.4/time_constant_s: 0.1/' "$SRC/config/machines/sim3_spindle.yaml" >"$WORK/src.yaml"
grep -q 'time_constant_s: 0.1' "$WORK/src.yaml" || fail "sim3_spindle.yaml's spindle time constant is no longer 0.4 s"
make_machine "$WORK/src.yaml" "$WORK/base.yaml"
CELL=$(sed -n 's/^  name: *\([^ ]*\).*/\1/p' "$WORK/base.yaml" | head -1)

# The HMI's users: the operator (who logs in to OPC UA) and cnc-opcua's own.
PASSWORD="swarf-$RANDOM-$RANDOM"
printf '%s\n' "$PASSWORD" | "$BUILD/services/cnc-hmi" --hash-password operator >"$WORK/users"
printf '%s\n' "opcua-$RANDOM-$RANDOM" >"$WORK/opcua.password"
tail -n 1 "$WORK/opcua.password" | "$BUILD/services/cnc-hmi" --hash-password opcua >>"$WORK/users"
chmod 600 "$WORK/users" "$WORK/opcua.password"
M="$WORK/machine.yaml"
{ cat "$WORK/base.yaml"; cat <<EOF
hmi:
  port: 8095
  users_file: users
opcua:
  port: 48401
  hmi_user: opcua
  hmi_password_file: opcua.password
  identification: {manufacturer: "Example Machine Works", model: "Sim 3 mill", serial_number: "SN-40501-7"}
EOF
} >"$M"
sed -e 's/port: 48401/port: 48402\n  anonymous: true\n  allow_security_none: true/' "$M" >"$WORK/open.yaml"
grep -q 'allow_security_none: true' "$WORK/open.yaml" || fail "open.yaml: no allow_security_none"

# ---- config errors name the key (exit 2); no section: exit 3 ---------------------------
expect_exit() {
  local want="$1" pattern="$2"; shift 2
  local rc=0
  "$@" >"$WORK/exit.out" 2>&1 || rc=$?
  [ "$rc" -eq "$want" ] && grep -q -- "$pattern" "$WORK/exit.out" ||
    { cat "$WORK/exit.out" >&2; fail "$*: exit $rc, expected $want with '$pattern'"; }
  note "exit $rc: $(grep -- "$pattern" "$WORK/exit.out" | head -1)"
}
grep -v 'manufacturer' "$M" | sed 's/^  port: 48401$/  port: 48401\n  identification: {model: m, serial_number: s}/' >"$WORK/bad1.yaml"
expect_exit 2 'opcua.identification.manufacturer' "$OPCUA" --machine "$WORK/bad1.yaml" --print-url
sed 's/^  hmi_user: opcua$//' "$M" >"$WORK/bad2.yaml"
expect_exit 2 'opcua.hmi_user: is required' "$OPCUA" --machine "$WORK/bad2.yaml" --print-url
expect_exit 3 'has no opcua: section' "$OPCUA" --machine "$WORK/base.yaml" --print-url
chmod 640 "$WORK/opcua.password"
expect_exit 2 'opcua.hmi_password_file .* has mode 0640' "$OPCUA" --machine "$M" --state "$WORK"
chmod 600 "$WORK/opcua.password"
[ "$("$OPCUA" --machine "$M" --print-url)" = "opc.tcp://127.0.0.1:48401" ] || fail "--print-url: $("$OPCUA" --machine "$M" --print-url)"

# ---- the cell, the HMI, the two servers -------------------------------------------------
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start_cell
start hmi "$BUILD/services/cnc-hmi" --machine "$M"
start opcua "$OPCUA" --machine "$M" --state "$WORK"
start opcua-open "$OPCUA" --machine "$WORK/open.yaml" --state "$WORK"
for name in opcua opcua-open; do
  for _ in $(seq 1 300); do grep -q "cnc-opcua: open opc.tcp" "$WORK/$name.log" && break; sleep 0.1; done
  grep -q "cnc-opcua: open opc.tcp" "$WORK/$name.log" || { cat "$WORK/$name.log" >&2; fail "$name did not start"; }
  for _ in $(seq 1 100); do grep -q "connected to the HMI" "$WORK/$name.log" && break; sleep 0.1; done
  grep -q "connected to the HMI" "$WORK/$name.log" || { cat "$WORK/$name.log" >&2; fail "$name did not reach the HMI"; }
done
grep -q "connected to the HMI at http://127.0.0.1:8095 as opcua" "$WORK/opcua.log" || fail "cnc-opcua did not log in to the HMI as opcua"
"$BUILD/tools/cnc-ctl" --machine "$M" --do enable --timeout 30 >"$WORK/enable.out" 2>&1 ||
  { cat "$WORK/enable.out" >&2; fail "the drives did not enable"; }

cat >"$WORK/short.ngc" <<'NGC'
G21 G90
M3 S6000
G1 X10 Y5 F3000
M5
M2
NGC
SETTINGS=$(/usr/bin/python3 -c 'import json, sys; a = sys.argv; print(json.dumps({
  "secure": "opc.tcp://127.0.0.1:48401", "open": "opc.tcp://127.0.0.1:48402",
  "server_pki": a[1] + "/machine.opcua/pki", "client_pki": a[1] + "/client-pki",
  "user": "operator", "password": a[2], "ctl": [a[3], "--machine", a[1] + "/machine.yaml"],
  "program": a[1] + "/short.ngc", "cell": a[4],
  "identification": {"manufacturer": "Example Machine Works", "model": "Sim 3 mill", "serial_number": "SN-40501-7"}}))' \
  "$WORK" "$PASSWORD" "$BUILD/tools/cnc-ctl" "$CELL")
rc=0
NODE_PATH="$BUILD/services/opcua/node_modules" timeout 90 node "$SRC/tests/integration/opcua_client.js" "$SETTINGS" \
  >"$WORK/client.log" 2>&1 || rc=$?
cat "$WORK/client.log" >&2
[ "$rc" -eq 0 ] || { tail -20 "$WORK/opcua.log" >&2; fail "the OPC UA client's checks failed (exit $rc)"; }

# The HMI checked the OPC UA logins: the operator's taken, the wrong password refused.
grep -q "OPC UA login of 'operator' accepted by the HMI" "$WORK/opcua.log" || fail "no accepted OPC UA login in the log"
grep -q "OPC UA login of 'operator' refused by the HMI" "$WORK/opcua.log" || fail "no refused OPC UA login in the log"
stop opcua TERM
stop opcua-open TERM
grep -q "cnc-opcua: stopped (.* events raised, 1 parts counted)" "$WORK/opcua.log" ||
  { tail -5 "$WORK/opcua.log" >&2; fail "cnc-opcua did not count 1 part"; }
grep -q '"parts":1' "$WORK/machine.opcua/counters.json" || fail "counters.json: $(cat "$WORK/machine.opcua/counters.json")"
# The hour meter counted the seconds the drive bridge ran while the server did (some 10-30 s).
/usr/bin/python3 - "$WORK/machine.opcua/counters.json" <<'PY' || fail "the power-on seconds: $(cat "$WORK/machine.opcua/counters.json")"
import json, sys
s = json.load(open(sys.argv[1]))["power_on_s"]
print(f"# power-on seconds counted: {s}", file=sys.stderr)
sys.exit(0 if 3 <= s <= 90 else 1)
PY
[ "$(stat -c %a "$WORK/machine.opcua/pki/own/private/private_key.pem")" = 600 ] ||
  fail "the server's private key has mode $(stat -c %a "$WORK/machine.opcua/pki/own/private/private_key.pem"), not 600"
for s in hmi interpolator program-server monitor drive-bridge servo-sim; do stop "$s" TERM; done
echo "opcua test passed"
