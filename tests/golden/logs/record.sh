#!/usr/bin/env bash
# Records the golden log of this build's log format and motion revision
# (common/bus/log_format.h; name it format-N.lcmlog, or format-N-motion-R.lcmlog
# from motion revision 2 on):
# the live cell (logger, simulator, bridge, program server, interpolator; no
# monitor, to keep it small) runs golden.ngc once. Run it once per format change
# and per motion revision,
# by hand, and commit the file it names; the suite replays every golden log
# (tests/golden/logs/replay_golden.sh), so a later version that can no longer
# read a recorded format fails there.
#   record.sh BUILD_DIR SOURCE_DIR OUT.lcmlog
source "$2/tests/integration/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"; OUT="$3"
WORK="$(mktemp -d /tmp/cnc-golden-log.XXXXXX)"
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/config/machines/sim3.yaml" "$M"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
sleep 0.2
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M"
start_cell --no-monitor
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$SRC/tests/golden/logs/golden.ngc" --timeout 60 >&2 \
  || fail "golden.ngc did not complete"
for s in interpolator program-server drive-bridge servo-sim logger; do stop "$s" TERM; done
"$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog" >&2 || fail "the new log does not replay"
cp "$WORK/run.lcmlog" "$OUT"
note "recorded $OUT ($(stat -c %s "$OUT") bytes)"
