#!/usr/bin/env bash
# Every executable refuses a malformed machine config with exit status 2 and a
# message that names the key path, before it touches the network or a drive.
#   bad_input_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
BUILD="$1"; SRC="$2"
WORK="$(mktemp -d /tmp/cnc-bad-input.XXXXXX)"
trap 'rm -rf "$WORK"' EXIT

# case NAME SED-EXPRESSION EXPECTED-TEXT
check_case() {
  local name="$1" expr="$2" expected="$3"
  sed -e "$expr" "$SRC/config/machines/sim3.yaml" >"$WORK/$name.yaml"
  cmp -s "$WORK/$name.yaml" "$SRC/config/machines/sim3.yaml" && fail "$name: the edit changed nothing"
  for exe in services/cnc-program-server services/cnc-interpolator services/cnc-drive-bridge services/cnc-monitor \
             services/cnc-logger tools/cnc-servo-sim; do
    local rc=0
    timeout 10 "$BUILD/$exe" --machine "$WORK/$name.yaml" >"$WORK/out" 2>&1 || rc=$?
    [ "$rc" -eq 2 ] || { cat "$WORK/out" >&2; fail "$name: $exe exited $rc, expected 2"; }
    grep -qF -- "$expected" "$WORK/out" || { cat "$WORK/out" >&2; fail "$name: $exe did not say '$expected'"; }
  done
  note "$name: all six refuse with '$expected'"
}

check_case unknown_key 's/^  ipo_period_s: 0.004 .*/  ipo_period_s: 0.004\n  ipo_perod_s: 0.002/' \
  "timing.ipo_perod_s: unknown key"
check_case wrong_type '0,/max_velocity_mm_s: 250/{s/max_velocity_mm_s: 250/max_velocity_mm_s: fast/}' \
  "axes[0].max_velocity_mm_s: expected a number, got 'fast'"
check_case out_of_range 's/unit_id: 2,/unit_id: 300,/' "axes[1].drive.unit_id: out of range: 300 not in [1, 247]"
check_case bad_transport 's/transport: modbus_tcp, host: 127.0.0.1, port: 1502, unit_id: 3/transport: carrier_pigeon, host: 127.0.0.1, port: 1502, unit_id: 3/' \
  "axes[2].drive.transport: 'carrier_pigeon' is not one of"
check_case servo_period 's/servo_period_s: 0.001 /servo_period_s: 0.003 /' \
  "timing.servo_period_s: timing.ipo_period_s must be a whole multiple of it"

# A missing file, an unknown flag.
rc=0; "$BUILD/services/cnc-interpolator" --machine "$WORK/nope.yaml" >"$WORK/out" 2>&1 || rc=$?
[ "$rc" -eq 2 ] && grep -q "nope.yaml: (top level): cannot open the file" "$WORK/out" || fail "missing config: exit $rc"
rc=0; "$BUILD/services/cnc-interpolator" --machine "$SRC/config/machines/sim3.yaml" --bogus 1 >"$WORK/out" 2>&1 || rc=$?
[ "$rc" -eq 2 ] && grep -q "cnc-interpolator: The following arguments were not expected:.*--bogus" "$WORK/out" || { cat "$WORK/out"; fail "unknown flag: exit $rc"; }
rc=0; "$BUILD/services/cnc-interpolator" --machine >"$WORK/out" 2>&1 || rc=$?
[ "$rc" -eq 2 ] && grep -q "cnc-interpolator: --machine: 1 required FILE missing" "$WORK/out" || { cat "$WORK/out"; fail "flag without its value: exit $rc"; }
echo "PASS"
