#!/usr/bin/env bash
# A stranger on the cell's network (a plain UDP socket, no key: stranger.py) sends
# forged, unsigned, wrong-key, corrupted, replayed and delayed STOP, HOLD, OVERRIDE 1.5,
# LOAD /etc/shadow, setpoints 100 mm off, DISABLE, and captured blocks, requests and
# interpolator inputs to a running signing cell. The program completes unaffected
# (ctl "program done", end point within 1 µm, one START and no STOP/HOLD/OVERRIDE
# applied, /etc/shadow never loaded); every receiver counts, per channel and cause,
# exactly what was sent (heartbeats), 0 accepted; bus_* ALARMs come at most once a
# second per service and cause. Mid-program the key is rotated (cnc-key rotate):
# the services change keys without a stop, the log holds both keys and verifies.
# Before all that: a key file others may read is refused by every executable. After:
# the log replays bit for bit with its MACs verified; one bit changed in it is found.
#   stranger_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-stranger-test.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
[ -n "${TEST_KEY:-}" ] || fail "the machine config does not sign"
mkdir -p "$WORK/py"
lcm-gen --python --ppath "$WORK/py" "$SRC"/lcmtypes/*.lcm || fail "lcm-gen --python failed"

# End point: X 123.4567 Y 45.6789 Z -4; about 8 s.
cat >"$WORK/part.ngc" <<'NGC'
G21 G90
G0 X5 Y5 Z1
G1 Z-2 F600
G1 X150 Y20 F1500
G1 X150.5 Y45.6789 Z-4
G1 X123.4567 F1800
M30
NGC

# A key file others may read: every executable that signs refuses to start (exit 2),
# naming the file and its mode.
chmod 640 "$TEST_KEY"
for exe in services/cnc-logger services/cnc-drive-bridge services/cnc-monitor services/cnc-program-server \
           services/cnc-interpolator tools/cnc-ctl; do
  rc=0; timeout 10 "$BUILD/$exe" --machine "$M" >"$WORK/mode.out" 2>&1 || rc=$?
  { [ "$rc" -eq 2 ] && grep -q "key file $TEST_KEY has mode 0640" "$WORK/mode.out"; } \
    || { cat "$WORK/mode.out" >&2; fail "$exe with a key file of mode 0640: exit $rc"; }
done
note "a key file of mode 0640 is refused: $(head -1 "$WORK/mode.out")"
chmod 600 "$TEST_KEY"

start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --final-state "$WORK/final.json" --trace "$WORK/trace.csv"
start_cell
sleep 0.5

python3 "$SRC/tests/integration/stranger.py" attack --port "$TEST_LCM_PORT" --prefix "$TEST_PREFIX" --py "$WORK/py" \
  --out "$WORK/sent.json" >"$WORK/stranger.out" 2>&1 &
stranger=$!
for ((i = 0; i < 200; i++)); do grep -q "^stranger: listening" "$WORK/stranger.out" 2>/dev/null && break; sleep 0.05; done
grep -q "^stranger: listening" "$WORK/stranger.out" || { cat "$WORK/stranger.out" >&2; fail "the stranger did not start listening within 10 s"; }
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$WORK/part.ngc" --timeout 60 >"$WORK/ctl.out" 2>&1 &
ctl=$!
rc=0; wait "$stranger" || rc=$?
cat "$WORK/stranger.out" >&2
[ "$rc" -eq 0 ] || fail "the stranger could not attack (exit $rc)"
# Key rotation while the program runs: every service reads the file within a second.
sleep 0.5
"$BUILD/tools/cnc-key" rotate --file "$TEST_KEY" --grace 60 >"$WORK/rotate.out" || fail "cnc-key rotate failed"
cat "$WORK/rotate.out" >&2
rc=0; wait "$ctl" || rc=$?
cat "$WORK/ctl.out" >&2
[ "$rc" -eq 0 ] || fail "the program did not complete under attack (cnc-ctl exit $rc)"
grep -q "program done" "$WORK/ctl.out" || fail "no completion report"
sleep 1.2  # a last heartbeat period, so the counts include everything

settle_at "$WORK/trace.csv" 123.4567 45.6789 -4.0
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
for s in interpolator program-server monitor drive-bridge logger; do
  grep -q "key file .* read again: 2 key(s)" "$WORK/$s.log" || { cat "$WORK/$s.log" >&2; fail "$s did not take the rotated key"; }
done

final_at "$WORK/final.json" 123.4567 45.6789 -4.0 || fail "final positions differ from the end point by more than 1 µm"

python3 "$SRC/tests/integration/stranger.py" check --log "$WORK/run.lcmlog" --py "$WORK/py" --sent "$WORK/sent.json" \
  --prefix "$TEST_PREFIX" >&2 || fail "the stranger's messages were not all dropped and counted (above)"

# The log keeps the MACs: every message verifies under the rotated key file (both
# keys), none repeated, the setpoint stream whole across the rotation; messages
# under both keys are in it.
"$BUILD/tools/cnc-logstat" --log "$WORK/run.lcmlog" --summary --key "$TEST_KEY" --require-no-gaps "${TEST_PREFIX}SETPOINTS" \
  >"$WORK/logstat.out" 2>&1 \
  || { cat "$WORK/logstat.out" >&2; fail "the cell's log does not verify, or the rotation cost setpoints"; }
sed -n '/^signatures (key/,$p' "$WORK/logstat.out" >&2
grep -qE "^signatures: [0-9]+ verified, 0 bad" "$WORK/logstat.out" || fail "no verification verdict"
python3 - "$WORK/run.lcmlog" <<'PY' || fail "the log does not hold messages under both keys"
import struct, sys
data = open(sys.argv[1], "rb").read(); off = 0; ids = {}
while off + 28 <= len(data):
    _, _, _, clen, dlen = struct.unpack_from(">IqqII", data, off)
    p = data[off + 28 + clen:off + 28 + clen + dlen]; off += 28 + clen + dlen
    if p.endswith(b"CNM\x01"): ids[p[-40:-36].hex()] = ids.get(p[-40:-36].hex(), 0) + 1
print("# messages per key id in the log: %s" % ids, file=sys.stderr)
sys.exit(0 if len(ids) == 2 else 1)
PY
# A log changed afterwards (one bit of one setpoint): logstat and replay name it.
"$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" --key "$TEST_KEY" >"$WORK/replay.out" 2>&1 \
  || { cat "$WORK/replay.out" >&2; fail "the untouched log does not replay"; }
grep -q "^identical: " "$WORK/replay.out" || fail "no replay verdict"
python3 - "$WORK/run.lcmlog" "$WORK/tampered.lcmlog" <<'PY'
import struct, sys
data = bytearray(open(sys.argv[1], "rb").read()); off = 0
while off + 28 <= len(data):
    _, _, _, clen, dlen = struct.unpack_from(">IqqII", data, off)
    if data[off + 28:off + 28 + clen].endswith(b"SETPOINTS"):
        data[off + 28 + clen + 60] ^= 0x01  # a bit of the position
        break
    off += 28 + clen + dlen
open(sys.argv[2], "wb").write(data)
PY
rc=0; "$BUILD/tools/cnc-logstat" --log "$WORK/tampered.lcmlog" --key "$TEST_KEY" >"$WORK/t.out" 2>&1 || rc=$?
[ "$rc" -eq 1 ] && grep -qE "^signatures: [0-9]+ verified, 1 bad" "$WORK/t.out" \
  || { cat "$WORK/t.out" >&2; fail "cnc-logstat --key: a changed log exit $rc"; }
rc=0; "$BUILD/tools/cnc-replay" --log "$WORK/tampered.lcmlog" --key "$TEST_KEY" >"$WORK/t.out" 2>&1 || rc=$?
[ "$rc" -eq 2 ] && grep -q "SETPOINTS: 0 unsigned, 0 unknown key, 1 forged" "$WORK/t.out" \
  || { cat "$WORK/t.out" >&2; fail "cnc-replay --key: a changed log exit $rc, expected 2"; }
note "a changed log: $(grep 'does not verify' "$WORK/t.out")"
echo PASS
