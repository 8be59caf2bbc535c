#!/usr/bin/env bash
# Latency bench in the spirit of cyclictest: runs `./cnc demo` twice, once on an idle
# PC and once with busy loops (`while :; do :; done`, one per core by default)
# loading every core, and compares the cycle timing every cyclic service recorded
# (wake-up latency and compute: min, mean, p99, p99.9, max; cycles, overruns).
#
#   tools/bench/latency_bench.sh [--machine FILE] [--program P] [--out DIR] [--load N] [--cpus LIST]
#   ./cnc bench latency [same options]
#
# --cpus "1" runs with timing.realtime_cpus: [1] (a copy of the machine config beside
# it, removed at the end). Beside the figures the table's header gives, per run, the
# hypervisor's steal time (from /proc/stat) and how many SCHED_FIFO cnc-* processes
# were seen (this cell has 5: more means another cell shared the PC).
#
# Writes into DIR (default runs/latency-bench-YYYYmmdd-HHMMSS): table.txt (also
# printed), latency.png (the histograms, idle and loaded overlaid), idle/ and
# loaded/ (the services' JSON files) and each demo's output. Each demo's own run
# directory (runs/demo-*) keeps its latency/ files too, so `./cnc report` on its
# log shows them. The busy loops are ordinary (SCHED_OTHER) processes; they are
# ended by their process ids when the loaded run ends, or when the bench is stopped.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
machine="$ROOT/config/machines/sim3.yaml"
program="$ROOT/config/programs/demo.ngc"
out=""
load="$(nproc)"
cpus=""
while [ $# -gt 0 ]; do
  case "$1" in
    --machine) machine="$2"; shift 2 ;;
    --program) program="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --load) load="$2"; shift 2 ;;
    --cpus) cpus="$2"; shift 2 ;;
    -h|--help) awk 'NR > 1 && /^#/ {sub(/^# ?/, ""); print; next} NR > 1 {exit}' "$0"; exit 0 ;;
    *) echo "latency_bench: unknown argument '$1'" >&2; exit 2 ;;
  esac
done
[ -n "$out" ] || out="$ROOT/runs/latency-bench-$(date -u +%Y%m%d-%H%M%S)"
mkdir -p "$out"

tmp_machine=""
if [ -n "$cpus" ]; then
  grep -q '^  realtime_cpus:' "$machine" || { echo "latency_bench: $machine has no realtime_cpus line" >&2; exit 2; }
  tmp_machine="$(dirname "$machine")/.latency-bench-$$.yaml"
  sed "s/^  realtime_cpus:.*/  realtime_cpus: [$cpus]/" "$machine" >"$tmp_machine"
  machine="$tmp_machine"
fi

busy=()
sampler=""
stop_busy() {
  for pid in "${busy[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${busy[@]}"; do wait "$pid" 2>/dev/null || true; done
  busy=()
}
cleanup() {
  stop_busy
  [ -z "$sampler" ] || { kill -TERM "$sampler" 2>/dev/null || true; wait "$sampler" 2>/dev/null || true; }
  [ -z "$tmp_machine" ] || rm -f "$tmp_machine"
}
trap 'cleanup' EXIT
trap 'cleanup; exit 130' INT TERM

steal_ticks() { awk '/^cpu / {print $9}' /proc/stat; }

# run_demo LABEL: one demo; its latency files are copied into $out/LABEL.
run_demo() {
  local label="$1" rc=0 steal0 t0
  echo "== $label run: ./cnc demo (load average $(cut -d' ' -f1-3 /proc/loadavg), ${#busy[@]} busy loop(s))" >&2
  steal0="$(steal_ticks)"
  t0="$(date +%s.%N)"
  # The SCHED_FIFO cnc-* processes on the PC, every second.
  (while :; do ps -eo pid=,cls=,comm= | awk '$2 == "FF" && $3 ~ /^cnc-/ {print $1, $3}'; sleep 1; done) \
    >"$out/$label-fifo.txt" 2>/dev/null &
  sampler=$!
  "$ROOT/cnc" demo --machine "$machine" --program "$program" >"$out/$label-demo.txt" 2>&1 || rc=$?
  kill -TERM "$sampler" 2>/dev/null || true
  wait "$sampler" 2>/dev/null || true
  sampler=""
  echo "$label: $(awk -v s0="$steal0" -v s1="$(steal_ticks)" -v hz="$(getconf CLK_TCK)" -v t0="$t0" -v t1="$(date +%s.%N)" \
    'BEGIN {printf "%.1f s, hypervisor steal %.0f ms (all CPUs)", t1 - t0, (s1 - s0) * 1000 / hz}'), \
$(sort -u "$out/$label-fifo.txt" | wc -l) SCHED_FIFO cnc-* processes seen, load average at the end $(cut -d' ' -f1-3 /proc/loadavg)" \
    >>"$out/header.txt"
  local run_dir
  run_dir="$(sed -n 's/.*output in \(.*\)$/\1/p' "$out/$label-demo.txt" | head -1)"
  if [ -z "$run_dir" ] || [ ! -d "$run_dir/latency" ]; then
    echo "latency_bench: the $label demo left no latency files (exit $rc); its output: $out/$label-demo.txt" >&2
    tail -20 "$out/$label-demo.txt" >&2
    return 1
  fi
  mkdir -p "$out/$label"
  cp "$run_dir"/latency/*.json "$out/$label/"
  echo "$run_dir" >"$out/$label-run-dir.txt"
  [ "$rc" -eq 0 ] || echo "latency_bench: the $label demo exited $rc (see $out/$label-demo.txt); its timing is kept" >&2
  sed -n '/^  program time/p;/^  services/p' "$out/$label-demo.txt" | sed "s/^/  $label: /" >&2
}

{
  echo "latency bench $(date -u +%Y-%m-%dT%H:%M:%SZ) on $(uname -n): $(nproc) CPU(s), kernel $(uname -r)"
  echo "machine $machine${cpus:+ (realtime_cpus: [$cpus])}, program $program; loaded run: $load busy loop(s)"
} >"$out/header.txt"

run_demo idle
for ((i = 0; i < load; i++)); do
  bash -c 'while :; do :; done' &
  busy+=($!)
done
sleep 1
run_demo loaded
stop_busy

{
  cat "$out/header.txt"
  echo
  /usr/bin/python3 "$ROOT/tools/bench/latency_plot.py" --run "idle=$out/idle" --run "loaded=$out/loaded" \
    --png "$out/latency.png" --title "cycle timing, idle and with $load busy loop(s)"
} | tee "$out/table.txt"
echo "latency_bench: $out/table.txt, $out/latency.png" >&2
