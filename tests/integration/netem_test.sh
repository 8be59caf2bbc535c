#!/usr/bin/env bash
# cnc-netem, the loss-and-delay forwarder: two network namespaces A and B, each with
# multicast on its loopback and nothing between them but the forwarder. A probe in A
# sends numbered, time-stamped datagrams (3000 at 1 kHz, 100 bytes); a probe in B
# records what arrives and when. Checked (netem_probe.py check):
#   * without the forwarder nothing crosses;
#   * 5 % loss, 2 ± 1 ms, order not kept: measured loss within 4 sd + 0.3 points of
#     5 %, the forwarder's counters agree with the probe's, no datagram earlier than
#     1 ms, 90 % within [1, 3.5] ms, median within [1.5, 3.0] ms, interquartile range
#     0.6..1.6 ms (uniform: 1 ms), some datagrams reordered;
#   * no loss, 2 ± 1 ms, --keep-order: every datagram, none out of order;
#   * cnc-netem exits 0 on SIGTERM with its counters.
#   netem_test.sh BUILD_DIR SOURCE_DIR
source "$(dirname "$0")/lib.sh"
enter_private_netns "$@"
BUILD="$1"; SRC="$2"
[ -n "${CNC_IN_NETNS:-}" ] || { echo "SKIP: needs network namespaces (unshare -n)"; exit 0; }
WORK="$(mktemp -d /tmp/cnc-netem-test.XXXXXX)"
trap 'cleanup' EXIT
PROBE="$SRC/tests/integration/netem_probe.py"
GROUP=239.255.76.67
PORT=$(( (RANDOM % 2000) * 10 + 20005 ))
N=3000

netns_host a lo
netns_host b lo
# The probes at SCHED_FIFO 45 where permitted (below the forwarder's 50): under load a
# Python process at normal priority wakes late and the delays it measures are its own.
RT=()
chrt -f 45 true 2>/dev/null && RT=(chrt -f 45)

# probe_run NAME COUNT [RECV_ARGS...]: a receiver in B (joined before anything is sent), a sender in A.
probe_run() {
  local name="$1" count="$2"; shift 2
  rm -f "$WORK/$name.ready"
  start "recv-$name" ${HOST[b]} "${RT[@]}" /usr/bin/python3 "$PROBE" recv "$GROUP" "$PORT" "$WORK/$name.csv" "$WORK/$name.ready" "$@"
  local i
  for ((i = 0; i < 500; i++)); do [ -s "$WORK/$name.ready" ] && break; sleep 0.01; done
  [ -s "$WORK/$name.ready" ] || fail "the receiving probe did not join the group"
  ${HOST[a]} "${RT[@]}" /usr/bin/python3 "$PROBE" send "$GROUP" "$PORT" "$count" 1000 || fail "the sending probe failed"
  local pid="${TEST_PIDS[recv-$name]}" rc=0
  wait "$pid" || rc=$?
  unset "TEST_PIDS[recv-$name]"
  [ "$rc" -eq 0 ] || { cat "$WORK/recv-$name.log" >&2; fail "the receiving probe failed"; }
}

# start_netem NAME ARGS...: the forwarder A -> B; returns when its sockets are set up.
start_netem() {
  local name="$1"; shift
  start "$name" "$BUILD/tools/cnc-netem" --group "$GROUP:$PORT" --from "/proc/${NETNS_PID[a]}/ns/net" \
    --to "/proc/${NETNS_PID[b]}/ns/net" "$@"
  local i
  for ((i = 0; i < 500; i++)); do grep -q "queue" "$WORK/$name.log" 2>/dev/null && break; sleep 0.01; done
  grep -q "queue" "$WORK/$name.log" || { cat "$WORK/$name.log" >&2; fail "cnc-netem did not start"; }
}

# Bad arguments: exit 2, naming the flag.
rc=0; "$BUILD/tools/cnc-netem" --group "$GROUP:$PORT" --from . --to . --loss 120 2>"$WORK/bad.err" || rc=$?
[ "$rc" -eq 2 ] && grep -q -- "--loss" "$WORK/bad.err" || { cat "$WORK/bad.err" >&2; fail "--loss 120: exit $rc"; }
rc=0; "$BUILD/tools/cnc-netem" --group "10.0.0.1:$PORT" --from . --to . 2>"$WORK/bad.err" || rc=$?
[ "$rc" -eq 2 ] && grep -q -- "--group" "$WORK/bad.err" || { cat "$WORK/bad.err" >&2; fail "unicast --group: exit $rc"; }

# 1. No forwarder: the namespaces are apart.
probe_run isolated 200 --first-timeout 1.5
got=$(($(wc -l <"$WORK/isolated.csv") - 1))
[ "$got" -eq 0 ] || fail "$got datagrams crossed from A to B without the forwarder"
note "without the forwarder: 0 of 200 crossed"

# 2. 5 % loss, 2 ± 1 ms, reordering allowed.
start_netem netem-loss --loss 5 --delay 2 --jitter 1 --seed 11
probe_run loss "$N"
stop netem-loss TERM
grep "received" "$WORK/netem-loss.log" >&2
/usr/bin/python3 "$PROBE" check "$WORK/loss.csv" "$N" --loss 5 --delay 2 --jitter 1 \
  --forwarder-log "$WORK/netem-loss.log" || fail "loss or delay outside the tolerances (figures above)"
grep -qE "reordered [1-9]" "$WORK/netem-loss.log" || fail "no datagram reordered with a 2 ms spread at 1 ms spacing"

# 3. No loss, 2 ± 1 ms, order kept.
start_netem netem-fifo --delay 2 --jitter 1 --seed 12 --keep-order
probe_run fifo "$N"
stop netem-fifo TERM
grep "received" "$WORK/netem-fifo.log" >&2
/usr/bin/python3 "$PROBE" check "$WORK/fifo.csv" "$N" --loss 0 --delay 2 --jitter 1 --ordered \
  --forwarder-log "$WORK/netem-fifo.log" || fail "order or delay outside the tolerances (figures above)"
echo "PASS"
