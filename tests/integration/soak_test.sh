#!/usr/bin/env bash
# The soak's short version (./cnc soak, tools/soak/soak.py): programs back to back on
# the simulated cell with operator actions and injected faults (every run here has one),
# in two epochs of 42 s (of a minute each, the suite took 14.6 of its 15 minutes on 2
# cores, the live cells one after another). Passes when every fault that stopped a run named its
# cause, the cell came back by RESET every time, every service exited 0 at each epoch's
# end, and every interpolator run in the logs replayed bit for bit.
#   soak_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
BUILD="$1"; SRC="$2"
unshare -n true 2>/dev/null || { echo "SKIP: needs a private network namespace (unshare -n)"; exit 0; }
command -v nft >/dev/null || fail "nft (Debian package nftables) is missing: ./cnc test installs it"
WORK="$(mktemp -d /tmp/cnc-soak-test.XXXXXX)"
trap 'cleanup' EXIT
rc=0
/usr/bin/python3 "$SRC/tools/soak/soak.py" --build "$BUILD" --src "$SRC" --minutes 1.4 --epoch-minutes 0.7 \
  --fault-share 1 --seed "${SOAK_SEED:-1}" --out "$WORK/soak" >"$WORK/soak.out" 2>&1 || rc=$?
cat "$WORK/soak.out" >&2
[ "$rc" -eq 0 ] || fail "the soak found a fault (above; its logs in $WORK/soak)"
grep -qE "replayed bit for bit ([1-9][0-9]*) of \1 interpolator runs" "$WORK/soak.out" || fail "no replayed run"
grep -qE "faults injected [1-9]" "$WORK/soak.out" || fail "no fault was injected"
echo "PASS"
