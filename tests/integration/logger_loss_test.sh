#!/usr/bin/env bash
# The logger loses nothing on loopback: cnc-bench-logger publishes lcmt_setpoint and
# lcmt_axis_status at 1 kHz each for 10 s to a cnc-logger in a private network
# namespace and counts what reached the log. Allowed loss: LOGGER_LOSS_MAX_LOST
# messages (default 0) of the 20,000.
#   logger_loss_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"
[ -n "${CNC_IN_NETNS:-}" ] || note "multicast must reach the logger on this host's routes"
"$BUILD/tools/bench/cnc-bench-logger" --seconds 10 --rate-hz 1000 --logger "$BUILD/services/cnc-logger" \
  --max-lost "${LOGGER_LOSS_MAX_LOST:-0}" || fail "the logger lost messages on loopback (figures above)"
echo "PASS"
