#!/usr/bin/env bash
# The 10-million-line run (issue 32, item 3): a 3D finishing program of --lines lines
# (tools/bench/finishing_program.py) streamed through a live cell, program server ->
# interpolator -> drive bridge -> simulated drives, with the logger on; the resident
# memory of every service sampled over the run, each stage's throughput, the log's
# size and write rate, then cnc-replay of the whole log, timed. Not a test (the long
# run takes about 40 minutes): a bench, for the figures in docs/programs.md.
#
#   tools/bench/tenm/run.sh BUILD SRC [--lines N] [--program FILE] [--out DIR] [--keep-log] [--minutes M]
#
# --out DIR (default /tmp/cnc-tenm-LINES): the machine file, the services' output,
# rss.csv (sample.py), summary.txt, rss.png (analyze.py); the log is deleted at the
# end unless --keep-log (10 M lines: about 11 GB). --program reuses a program.
# --minutes M: the cell is stopped after M minutes if the program has not ended
# (what ran is measured and replayed all the same).
# Runs in a private network namespace as the live tests do (tests/integration/lib.sh),
# on tools/bench/tenm/machine.yaml. Exit 0 when the program ran to its end on its last
# point and the replay was identical.
source "$2/tests/integration/lib.sh"
enter_private_netns "$@"
BUILD="$(readlink -f "$1")"; SRC="$(readlink -f "$2")"; shift 2
LINES=10000000; PROGRAM=""; OUT=""; KEEP_LOG=0; MINUTES=180
while [ $# -gt 0 ]; do
  case "$1" in
    --lines) LINES="$2"; shift 2 ;;
    --program) PROGRAM="$2"; shift 2 ;;
    --out) OUT="$2"; shift 2 ;;
    --keep-log) KEEP_LOG=1; shift ;;
    --minutes) MINUTES="$2"; shift 2 ;;
    *) echo "run.sh: unknown argument '$1'" >&2; exit 2 ;;
  esac
done
WORK="${OUT:-/tmp/cnc-tenm-$LINES}"
mkdir -p "$WORK"
export CNC_KEEP_WORK=1
trap 'cleanup' EXIT
M="$WORK/machine.yaml"
make_machine "$SRC/tools/bench/tenm/machine.yaml" "$M"

if [ -z "$PROGRAM" ]; then
  PROGRAM="$WORK/finish.ngc"
  t0=$(date +%s.%N)
  /usr/bin/python3 "$SRC/tools/bench/finishing_program.py" --lines "$LINES" --out "$PROGRAM"
  note "wrote $PROGRAM ($LINES lines) in $(echo "$(date +%s.%N) - $t0" | bc) s"
fi
PROGRAM="$(readlink -f "$PROGRAM")"
# The program's last point, for the end check: its last G1 line.
read -r EX EY EZ < <(tail -n 2 "$PROGRAM" | head -n 1 | sed -E 's/.*X(-?[0-9.]+) Y(-?[0-9.]+) Z(-?[0-9.]+).*/\1 \2 \3/')

rm -f "$WORK/run.lcmlog"
start logger "$BUILD/services/cnc-logger" --machine "$M" --out "$WORK/run"
start servo-sim "$BUILD/tools/cnc-servo-sim" --machine "$M" --final-state "$WORK/final.json"
start_cell
sleep 1
procs=()
for s in logger servo-sim drive-bridge monitor program-server interpolator; do procs+=("$s=${TEST_PIDS[$s]}"); done
/usr/bin/python3 "$SRC/tools/bench/tenm/sample.py" --out "$WORK/rss.csv" --period 2 --log "$WORK/run.lcmlog" "${procs[@]}" &
SAMPLER=$!

t_run=$(date +%s.%N)
rc=0
"$BUILD/tools/cnc-ctl" --machine "$M" --do run --program "$PROGRAM" --timeout $((MINUTES * 60)) >"$WORK/ctl.out" 2>&1 || rc=$?
t_end=$(date +%s.%N)
cat "$WORK/ctl.out" >&2
sleep 1
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
kill -TERM "$SAMPLER" 2>/dev/null || true
wait "$SAMPLER" 2>/dev/null || true
ENDED=1
if [ "$rc" -eq 4 ]; then
  ENDED=0  # cnc-ctl's timeout: stopped after --minutes
  note "stopped after $MINUTES minutes, before the program's end"
else
  [ "$rc" -eq 0 ] || fail "the program did not complete (cnc-ctl exit $rc)"
  final_at "$WORK/final.json" "$EX" "$EY" "$EZ" || fail "the drives did not end on the program's last point"
fi

{
  echo "program: $PROGRAM, $(wc -l <"$PROGRAM") lines, $(stat -c %s "$PROGRAM") bytes"
  echo "run (cnc-ctl run: load, validation and the motion): $(echo "$t_end - $t_run" | bc) s$([ $ENDED -eq 1 ] || echo ", stopped after --minutes $MINUTES before the program's end")"
  echo "log: $(stat -c %s "$WORK/run.lcmlog") bytes"
} >"$WORK/summary.txt"
"$BUILD/tools/cnc-logstat" --log "$WORK/run.lcmlog" --summary --machine "$M" >"$WORK/logstat.out" 2>&1 || true
t0=$(date +%s.%N)
rrc=0
# At most 8 GB of address space: a replay that held the whole log would fail, not swap.
(ulimit -v 8000000; /usr/bin/time -v "$BUILD/tools/cnc-replay" --log "$WORK/run.lcmlog") >"$WORK/replay.out" 2>&1 || rrc=$?
echo "replay: exit $rrc in $(echo "$(date +%s.%N) - $t0" | bc) s, peak RSS $(sed -n 's/.*Maximum resident set size (kbytes): //p' "$WORK/replay.out") KiB" >>"$WORK/summary.txt"
tail -n 5 "$WORK/replay.out" >&2
/usr/bin/python3 "$SRC/tools/bench/tenm/analyze.py" --work "$WORK" --prefix "$TEST_PREFIX" >>"$WORK/summary.txt" || fail "analyze.py failed"
cat "$WORK/summary.txt"
[ "$KEEP_LOG" -eq 1 ] || rm -f "$WORK/run.lcmlog"
[ "$rrc" -eq 0 ] || fail "the replay was not identical (exit $rrc)"
echo "PASS"
