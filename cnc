#!/usr/bin/env bash
# Entry point of the project. On a fresh Debian 12 machine, as root:
#   ./cnc demo     install what is missing, build, run the whole cell on this PC once
#   ./cnc test     install what is missing, build, run the test suite (ctest)
#                  [--sanitize address,undefined|thread]: the suite under the sanitizers
# and, once built:
#   ./cnc up --machine FILE [--only SERVICE,...]   start a cell's services in the foreground
#   ./cnc ctl --machine FILE --do run --program P  operator commands (see cnc-ctl --help)
#   ./cnc logstat --log FILE [--summary]           statistics of a recorded run
#   ./cnc replay LOG [--machine F] [--program P]   re-run the interpolator from a log, bit for bit
#   ./cnc plan PROGRAM [--machine FILE] --csv OUT [--plot PNG]  dry run: setpoints, time, feed plot
#   ./cnc report LOG --out DIR [--tolerance-um U] [--target-rmax-um U]  run report to open in a browser
#   ./cnc predict PROGRAM --tool F [--material F] --out DIR  force, deflection, surface along a dry run
#   ./cnc predict slot|wall|zmap|zmap-check|calibrate ...    one model at a time (cnc-predict --help)
#   ./cnc cam drop --stl MESH --tool ball:D|flat:D|bull:D:r --points XY.csv --out XYZ.csv [--threads N]
#                                                  offline CAM: drop-cutter CL heights (cnc-cam --help)
#   ./cnc cam rough --stl MESH --stock box|margin[:MM] --tool SPEC --cusp H --out rough.ngc [--compare T,T] [--png F]
#                                                  offline CAM: z-level roughing, cusp-limited levels (Shin et al.)
#   ./cnc conformance [conformance.py options]     our interpreter against LinuxCNC's rs274
#   ./cnc bench latency [--load N] [--out DIR]     cycle timing of the demo, idle and with N busy loops
#   ./cnc bench machining-time [--modes main,asis] [--only NAMES] [--out DIR] [--no-linuxcnc] [--reuse]
#                                                  CAM programs on our planner and LinuxCNC 2.9's: times, stops,
#                                                  path deviation, jerk (tools/bench/machining_time.py)
#   ./cnc bench interpreter [--lines N] [--runs N]  LinuxCNC's rs274 against our interpreter and program server
#                                                  on a finishing program of N lines (default 10 M), like for like
#   ./cnc bench ten-million [--lines N] [--out DIR] [--keep-log]  the program through a live cell: memory,
#                                                  throughput, log rate, replay (tools/bench/tenm/run.sh)
#   ./cnc soak --minutes M [--seed S] [--out DIR]  programs back to back with operator actions and injected
#                                                  faults, every log replayed (tools/soak/soak.py)
#   ./cnc experiment table1 [--size tiny|reduced|full] [--out DIR]
#                                                  Choi et al. 2005's Table 1 in a live cell: fixed feed
#                                                  against the roughness law, Z-map, report (docs/experiment.md)
#   ./cnc key gen|rotate|show [--machine FILE] [--grace S] [--activate-in S]  the cell's signing key
#   ./cnc package                                  Debian packages (cnc, cnc-cam) into build/packages, lintian-checked
#   ./cnc build                                    set up and build only
set -euo pipefail

SELF="$(readlink -f "${BASH_SOURCE[0]}")"
ROOT="$(dirname "$SELF")"
if [ -f "$ROOT/CMakeLists.txt" ]; then
  INSTALLED=0  # the source tree: builds into $BUILD and runs from there
  BUILD="${CNC_BUILD_DIR:-$ROOT/build}"
else
  # Installed from the Debian package (/usr/bin/cnc): the programs beside it, the
  # run-time files in /usr/share/cnc (laid out as the source tree), nothing to build.
  INSTALLED=1
  BINDIR="$ROOT"
  ROOT="$(cd "$BINDIR/../share/cnc" && pwd)" || { echo "cnc: neither a source tree nor an installed share/cnc beside $SELF" >&2; exit 2; }
  BUILD=""
fi
DEFAULT_MACHINE="$ROOT/config/machines/sim3.yaml"
DEFAULT_PROGRAM="$ROOT/config/programs/demo.ngc"

# bin NAME: the path of program NAME (cnc-ctl, cnc-logger, ...), built or installed.
bin() {
  if [ "$INSTALLED" -eq 1 ]; then echo "$BINDIR/$1"; return; fi
  case "$1" in
    cnc-logger|cnc-interpolator|cnc-drive-bridge|cnc-monitor|cnc-program-server|cnc-hmi|cnc-opcua|cnc-mqtt|cnc-fleet) echo "$BUILD/services/$1" ;;
    cnc-cam) echo "$BUILD/tools/cam/$1" ;;
    cnc-rs274) echo "$BUILD/tools/rs274/$1" ;;
    *) echo "$BUILD/tools/$1" ;;
  esac
}

# Debian packages the project needs to build, test and run.
PACKAGES=(
  g++ make cmake pkg-config
  liblcm-dev liblcm-bin libglib2.0-dev   # LCM 1.3.1; its lcm.pc needs glib
  libyaml-cpp-dev libmodbus-dev libspdlog-dev libeigen3-dev libgtest-dev
  libsodium-dev                          # crypto_auth (HMAC-SHA-512-256): the cell's signed channels
  python3 python3-matplotlib             # plots of feed profiles and run reports
  chromium                               # renders the run report headless in its test
  iproute2 util-linux procps             # ip, unshare: private network namespaces in tests
  nftables                               # random datagram loss on an input chain (loss test)
  dpkg-dev lintian                       # ./cnc package: CPack's dependencies (dpkg-shlibdeps), the packages' check
  adduser                                # the cnc package's postinst (integration.package installs it)
  systemd                                # systemd-analyze verify of the packages' units (package test)
  socat                                  # pseudo-terminal pairs standing in for RS-485 (Modbus RTU tests)
  python3-pymodbus python3-serial python3-serial-asyncio python3-yaml  # drive emulated with pymodbus (interop test)
  mbpoll                                 # reads the simulator's registers and I/O module coils (interop and io tests)
  linuxcnc-uspace                        # rs274: LinuxCNC's interpreter, the conformance oracle (tools/conformance)
  libcli11-dev                           # command-line flags (CLI11): every service, cnc-ctl, cnc-cam, ...
  libpolyclipping-dev                    # Clipper: polygon offsets of cnc-cam rough's levels
  libcgal-dev                            # CGAL's AABB tree, the baseline of cnc-cam-index-bench (optional)
  libboost-dev nlohmann-json3-dev        # cnc-hmi: Boost.Beast (HTTP, WebSocket), JSON
  chromium-driver python3-selenium       # integration.hmi drives the page in headless Chromium
  nodejs npm                             # cnc-opcua: node-opcua (npm ci from services/opcua/package-lock.json at build)
  libmosquitto-dev                       # cnc-mqtt: the MQTT client library
  mosquitto mosquitto-clients            # integration.mqtt: the broker and a third-party subscriber (mosquitto_sub)
  openssl                                # integration.mqtt: the test's CA and the broker's TLS certificate
  clang libclang-rt-14-dev               # libFuzzer with ASan and UBSan: tests/fuzz/run (optional)
)

# Service name -> executable, in start order (config/services.txt, the one list);
# OPTIONAL: the services started only when the config has their section.
SERVICES=()
declare -A EXE=() OPTIONAL=()
while read -r _svc _exe _opt; do
  case "$_svc" in ''|'#'*) continue ;; esac
  SERVICES+=("$_svc")
  EXE[$_svc]="$_exe"
  [ "${_opt%% *}" = optional ] && OPTIONAL[$_svc]=1
done <"$ROOT/config/services.txt"
unset _svc _exe _opt

say() { printf '%s\n' "cnc: $*" >&2; }
die() { say "$*"; exit 2; }

# run_child CMD...: runs CMD as a child and hands SIGTERM and SIGINT on to it (as
# SIGTERM: a background child of a script ignores SIGINT), so that `timeout` or
# Ctrl-C on ./cnc ends what it runs; returns the child's status.
run_child() {
  "$@" &
  local pid=$! rc=0
  trap "kill -TERM $pid 2>/dev/null || true" TERM INT
  while :; do
    rc=0
    wait "$pid" || rc=$?
    kill -0 "$pid" 2>/dev/null || break  # wait was only interrupted by a signal: wait on
  done
  trap - TERM INT
  return "$rc"
}

install_missing() {
  local missing=() provided
  # A package another one provides counts as there: NodeSource's nodejs provides npm
  # (and conflicts with Debian's npm, which apt would otherwise try to install).
  provided=" $(dpkg-query -W -f='${db:Status-Abbrev} ${Provides}\n' 2>/dev/null | awk '$1 == "ii" {$1 = ""; print}' |
              sed -e 's/([^)]*)//g' -e 's/,/ /g' | tr -s ' \n' '  ') "
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' ||
      [[ "$provided" == *" $p "* ]] || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  if [ "$(id -u)" -ne 0 ]; then
    die "missing Debian packages: ${missing[*]} (run as root, or: sudo apt-get install ${missing[*]})"
  fi
  say "installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}

build() {
  if [ "$INSTALLED" -eq 1 ]; then return 0; fi  # installed: the programs are there
  install_missing
  if [ ! -f "$BUILD/CMakeCache.txt" ]; then
    cmake -S "$ROOT" -B "$BUILD" -DCMAKE_BUILD_TYPE=Release >/dev/null
  fi
  mkdir -p "$BUILD"
  if ! cmake --build "$BUILD" -j "$(nproc)" >"$BUILD/last-build.log" 2>&1; then
    grep -E 'error|Error' -A5 "$BUILD/last-build.log" | head -60 >&2
    die "build failed (whole output in $BUILD/last-build.log)"
  fi
}

# up --machine FILE [--only a,b] [--log-out BASE] [--sim-final-state FILE] [--sim-trace CSV]
#    [--sim-control FIFO]: the simulator reads commands from FIFO ("input clamp_closed 1", cnc-servo-sim --help)
# Runs in the foreground; SIGINT/SIGTERM stop every service in reverse start order.
# Exit status: 0 when every service exited 0.
cmd_up() {
  local machine="" only="" log_out="" final_state="" sim_trace="" sim_control=""
  while [ $# -gt 0 ]; do
    case "$1" in
      --machine) machine="$2"; shift 2 ;;
      --only) only="$2"; shift 2 ;;
      --log-out) log_out="$2"; shift 2 ;;
      --sim-final-state) final_state="$2"; shift 2 ;;
      --sim-trace) sim_trace="$2"; shift 2 ;;
      --sim-control) sim_control="$2"; shift 2 ;;
      *) die "up: unknown argument '$1' (expected --machine FILE [--only SERVICE,...])" ;;
    esac
  done
  [ -n "$machine" ] || die "up: --machine FILE is required"
  [ -f "$machine" ] || die "up: no machine config at '$machine'"
  # The whole cell on this PC: its signing key is made on the first run. A part of
  # a cell (--only) needs the key of the PC that made it: copied, never made anew.
  if [ -z "$only" ]; then
    "$(bin cnc-key)" gen --machine "$machine" --if-missing || die "up: cannot make the cell's key"
  fi
  local chosen=()
  if [ -n "$only" ]; then
    IFS=',' read -r -a wanted <<<"$only"
    for w in "${wanted[@]}"; do
      [ -n "${EXE[$w]:-}" ] || die "up: unknown service '$w' (one of: ${SERVICES[*]})"
    done
    for s in "${SERVICES[@]}"; do
      for w in "${wanted[@]}"; do [ "$s" = "$w" ] && chosen+=("$s"); done
    done
  else
    chosen=("${SERVICES[@]}")
  fi
  declare -A pids=()
  local rc=0
  stop_all() {
    trap '' INT TERM
    for ((i = ${#chosen[@]} - 1; i >= 0; i--)); do
      local s="${chosen[$i]}" pid="${pids[${chosen[$i]}]:-}"
      [ -n "$pid" ] || continue
      kill -TERM "$pid" 2>/dev/null || true
      local code=0
      wait "$pid" || code=$?
      if [ "$code" -ne 0 ]; then say "$s exited with status $code"; rc=1; else say "$s stopped"; fi
    done
  }
  trap 'stop_all; exit $rc' INT TERM
  for s in "${chosen[@]}"; do
    local args=(--machine "$machine") url=""
    # An optional service runs when its program finds its section in the config
    # (--print-url answers its address; 3: no section).
    if [ -n "${OPTIONAL[$s]:-}" ]; then
      if ! url="$("$(bin "${EXE[$s]##*/}")" --machine "$machine" --print-url 2>/dev/null)"; then
        [ -z "$only" ] || say "$s: $machine does not configure it (no $s: section): not started"
        continue
      fi
    fi
    [ "$s" = logger ] && [ -n "$log_out" ] && args+=(--out "$log_out")
    [ "$s" = servo-sim ] && [ -n "$final_state" ] && args+=(--final-state "$final_state")
    [ "$s" = servo-sim ] && [ -n "$sim_trace" ] && args+=(--trace "$sim_trace")
    [ "$s" = servo-sim ] && [ -n "$sim_control" ] && args+=(--control "$sim_control")
    # The loaded program survives a restart of the program server (README, Killed
    # processes): its state file beside the machine config (like its key; git-ignored),
    # or in $CNC_STATE_DIR.
    if [ "$s" = program-server ]; then
      local sdir="${CNC_STATE_DIR:-$(dirname "$machine")}"
      mkdir -p "$sdir" && args+=(--state "$sdir/$(basename "$machine" .yaml).program-server.state")
    fi
    # The OPC UA server's certificate and counters: MACHINE.opcua/ in the same folder.
    if [ "$s" = opcua ]; then
      local sdir="${CNC_STATE_DIR:-$(dirname "$machine")}"
      mkdir -p "$sdir" && args+=(--state "$sdir")
    fi
    "$(bin "${EXE[$s]##*/}")" "${args[@]}" &
    pids[$s]=$!
    say "started $s (pid ${pids[$s]})"
    if [ "$s" = hmi ]; then say "the operator's page: $("$(bin cnc-hmi)" --machine "$machine" --print-url 2>/dev/null)"; fi
    if [ "$s" = opcua ]; then say "the OPC UA endpoint: $url"; fi
    if [ "$s" = mqtt ]; then say "the MQTT topics: $url/..."; fi
    sleep 0.1
  done
  # A service that ends on its own does not end the others: stopping them would take
  # the axes down with it (the drive bridge disables the drives on SIGTERM). The
  # services that depend on it raise a peer_lost ALARM naming it, the drive bridge
  # stops the axes when setpoints stop; restart it (./cnc up --only NAME), or stop
  # the cell with SIGINT/SIGTERM. When the last one has ended, exit 1.
  while [ ${#pids[@]} -gt 0 ]; do
    local code=0 ended=""
    wait -n -p ended "${pids[@]}" 2>/dev/null || code=$?
    if [ -z "$ended" ]; then
      # A child that ended between two waits can be reaped by bash already: `wait -n`
      # then says "no such job" for it (a killed monitor went unnoticed so, 1 of 3
      # suite runs). Find it by its pid; wait on a pid still gives its saved status.
      for s in "${!pids[@]}"; do
        if ! kill -0 "${pids[$s]}" 2>/dev/null; then
          ended="${pids[$s]}"; code=0; wait "$ended" 2>/dev/null || code=$?
          break
        fi
      done
      [ -n "$ended" ] || { sleep 0.1; continue; }
    fi
    for s in "${!pids[@]}"; do
      if [ "${pids[$s]}" = "$ended" ]; then
        unset "pids[$s]"
        say "$s ended by itself (status $code): the rest of the cell goes on; restart it with ./cnc up --machine $machine --only $s"
      fi
    done
  done
  exit 1
}

cmd_demo() {
  local machine="$DEFAULT_MACHINE" program="$DEFAULT_PROGRAM"
  while [ $# -gt 0 ]; do
    case "$1" in
      --machine) machine="$2"; shift 2 ;;
      --program) program="$2"; shift 2 ;;
      *) die "demo: unknown argument '$1'" ;;
    esac
  done
  build
  local runs="$ROOT/runs"
  if [ "$INSTALLED" -eq 1 ]; then
    # Installed: the run goes to ./runs (or $CNC_RUN_DIR), with a copy of the machine
    # file and its own key beside it (the shipped files in /usr/share/cnc stay as they are).
    runs="${CNC_RUN_DIR:-$PWD/runs}"
    local copy_dir
    copy_dir="$runs/demo-machine"
    mkdir -p "$copy_dir"
    cp "$machine" "$copy_dir/" && machine="$copy_dir/$(basename "$machine")"
  fi
  # The cell's signing key, made on the first run (before cnc-ctl, which signs too).
  "$(bin cnc-key)" gen --machine "$machine" --if-missing || die "demo: cannot make the cell's key"
  local run_dir="$runs/demo-$(date -u +%Y%m%d-%H%M%S)"
  mkdir -p "$run_dir"
  say "starting the cell ($machine), output in $run_dir"
  say "the operator's page while the demo runs: $("$(bin cnc-hmi)" --machine "$machine" --print-url 2>/dev/null)"
  # Each cyclic service writes its cycle timing into $run_dir/latency at the end (./cnc report shows it).
  CNC_LATENCY_DIR="$run_dir/latency" \
    "$SELF" up --machine "$machine" --log-out "$run_dir/cell" --sim-final-state "$run_dir/final-positions.json" \
    >"$run_dir/services.log" 2>&1 &
  local up_pid=$!
  # A signal to the demo stops the cell (up stops its services in reverse order).
  trap "kill -TERM $up_pid 2>/dev/null || true" TERM INT
  local ctl_rc=0
  run_child "$(bin cnc-ctl)" --machine "$machine" --do run --program "$program" --timeout 300 || ctl_rc=$?
  kill -TERM "$up_pid"
  local up_rc=0
  wait "$up_pid" || up_rc=$?
  echo
  echo "== summary =="
  # With the machine's key: every logged message's MAC verified (signing cells).
  local stat
  stat="$("$(bin cnc-logstat)" --log "$run_dir/cell.lcmlog" --summary --machine "$machine" 2>&1 || true)"
  sed -n '/^run summary/,$p' <<<"$stat"
  sed -n 's/^signatures: /  signatures (MAC)    /p' <<<"$stat"
  echo "  final positions     $(cat "$run_dir/final-positions.json" 2>/dev/null || echo '(simulator did not report)')"
  echo "  services            $( [ $up_rc -eq 0 ] && echo 'all exited 0 on SIGTERM' || echo "a service failed, see $run_dir/services.log")"
  echo "  log                 $run_dir/cell.lcmlog"
  echo "  play it back with   lcm-logplayer $run_dir/cell.lcmlog"
  if [ -d "$run_dir/latency" ]; then
    echo "  cycle timing (µs)   $run_dir/latency"
    /usr/bin/python3 "$ROOT/tools/bench/latency_plot.py" --run "demo=$run_dir/latency" 2>&1 | sed -n '/^service/,/^$/p' | sed 's/^/      /' || true
  fi
  [ $ctl_rc -eq 0 ] && [ $up_rc -eq 0 ]
}

# plan PROGRAM [--machine FILE] [--csv OUT] [--plot PNG] [other cnc-plan options]
cmd_plan() {
  [ $# -gt 0 ] || die "plan: PROGRAM is required"
  local program="$1"; shift
  local machine="$DEFAULT_MACHINE" csv="" plot="" rest=()
  while [ $# -gt 0 ]; do
    case "$1" in
      --machine) machine="$2"; shift 2 ;;
      --csv) csv="$2"; shift 2 ;;
      --plot) plot="$2"; shift 2 ;;
      *) rest+=("$1"); shift ;;
    esac
  done
  [ -n "$csv" ] || { [ -z "$plot" ] || csv="${plot%.png}.csv"; }
  local plan=("$(bin cnc-plan)" --machine "$machine" --program "$program" ${csv:+--csv "$csv"} "${rest[@]}")
  # Without a plot the dry run is the whole command: it takes the script's place and its signals.
  [ -n "$plot" ] || exec "${plan[@]}"
  run_child "${plan[@]}"
  run_child /usr/bin/python3 "$ROOT/tools/report/plot_plan.py" "$csv" --out "$plot" --title "$(basename "$program")"
}

# predict PROGRAM --tool FILE [--material FILE] --out DIR [--machine FILE] [cnc-predict program options]
# runs the dry run (cnc-plan) into DIR/setpoints.csv, predicts along it and writes DIR/index.html;
# predict slot|wall|zmap|zmap-check|calibrate ...: cnc-predict itself.
cmd_predict() {
  if [ $# -eq 0 ] || [ ! -f "$1" ]; then exec "$(bin cnc-predict)" "$@"; fi
  local program="$1"; shift
  local machine="$DEFAULT_MACHINE" out="" rest=()
  while [ $# -gt 0 ]; do
    case "$1" in
      --machine) machine="$2"; shift 2 ;;
      --out) out="$2"; shift 2 ;;
      *) rest+=("$1"); shift ;;
    esac
  done
  [ -n "$out" ] || die "predict: --out DIR is required"
  mkdir -p "$out"
  say "predict: dry run of $program"
  run_child "$(bin cnc-plan)" --machine "$machine" --program "$program" --csv "$out/setpoints.csv" >&2
  run_child "$(bin cnc-predict)" program --csv "$out/setpoints.csv" --program "$program" --out "$out" "${rest[@]}"
  run_child /usr/bin/python3 "$ROOT/tools/predict/make_predict_report.py" "$out" --title "$(basename "$program")"
}

# report LOG --out DIR [--tolerance-um U] [--target-rmax-um U] [--title T]
# cnc-logexport writes the run's tables into DIR, make_report.py plots them into DIR/index.html.
cmd_report() {
  [ $# -gt 0 ] || die "report: LOG is required (report LOG --out DIR)"
  local log="$1"; shift
  local out="" rest=()
  while [ $# -gt 0 ]; do
    case "$1" in
      --out) out="$2"; shift 2 ;;
      *) rest+=("$1"); shift ;;
    esac
  done
  [ -n "$out" ] || die "report: --out DIR is required"
  run_child "$(bin cnc-logexport)" --log "$log" --out "$out"
  # The cycle timing the services wrote beside the log (./cnc demo: RUN_DIR/latency), when there is some.
  local lat
  lat="$(dirname "$log")/latency"
  compgen -G "$lat/*.json" >/dev/null && rest+=(--latency-dir "$lat")
  run_child /usr/bin/python3 "$ROOT/tools/report/make_report.py" "$out" "${rest[@]}"
  say "open $out/index.html in a browser"
}

# conformance [--generate N] [--samples] [--corpus DIR] [conformance.py options]
# Our interpreter (cnc-rs274) against LinuxCNC's rs274; see tools/conformance/README.md.
# Without options: 200 random programs, the project's programs and LinuxCNC's samples.
cmd_conformance() {
  local ours="$(bin cnc-rs274)" conf="$ROOT/tools/conformance"
  [ -x "$ours" ] || die "conformance: $ours is not built yet"
  [ -x /usr/bin/rs274 ] || die "conformance: /usr/bin/rs274 missing (apt-get install linuxcnc-uspace)"
  if [ $# -eq 0 ]; then
    set -- --generate 200 --seed 1 --samples /usr/share/linuxcnc/ncfiles \
      --corpus "$ROOT/config/programs" --corpus "$ROOT/tests/golden/programs/valid" \
      --corpus "$ROOT/tests/unit/rs274_comp" --expected-refusals "$conf/expected-refusals.txt"
  fi
  python3 "$conf/conformance.py" --ours "$ours" --theirs /usr/bin/rs274 "$@"
}

# bench latency [latency_bench.sh options]: see tools/bench/latency_bench.sh.
# bench machining-time [machining_time.py options]: see tools/bench/machining_time.py.
# bench interpreter [--lines N] [cnc-bench-program-server options]: a finishing program of
#   N lines (default 10,000,000; tools/bench/finishing_program.py) and the bench's own
#   200,000-line program through LinuxCNC's rs274 and ours, like for like.
# bench ten-million [run.sh options]: tools/bench/tenm/run.sh, the program through a live cell.
cmd_bench() {
  local what="${1:-}"
  [ $# -gt 0 ] && shift
  case "$what" in
    latency) build; run_child "$ROOT/tools/bench/latency_bench.sh" "$@" ;;
    machining-time)
      [ "$INSTALLED" -eq 0 ] || die "bench machining-time: runs from the source tree (it needs the build's cnc-path-deviation)"
      build
      run_child /usr/bin/python3 "$ROOT/tools/bench/machining_time.py" --build "$BUILD" "$@" ;;
    interpreter)
      [ "$INSTALLED" -eq 0 ] || die "bench interpreter: runs from the source tree (it needs the build's cnc-bench-program-server)"
      build
      local lines=10000000
      if [ "${1:-}" = --lines ]; then lines="$2"; shift 2; fi
      local dir
      dir="$(mktemp -d /tmp/cnc-bench-interpreter.XXXXXX)"
      /usr/bin/python3 "$ROOT/tools/bench/finishing_program.py" --lines "$lines" --out "$dir/finish.ngc"
      local rc=0
      "$BUILD/tools/bench/cnc-bench-program-server" --only lines --lines 200000 --program "$dir/finish.ngc" \
        --canon-dir "$dir" "$@" || rc=$?
      rm -rf "$dir"
      return $rc ;;
    ten-million)
      [ "$INSTALLED" -eq 0 ] || die "bench ten-million: runs from the source tree"
      build
      run_child "$ROOT/tools/bench/tenm/run.sh" "$BUILD" "$ROOT" "$@" ;;
    *) die "bench: expected 'latency', 'machining-time', 'interpreter' or 'ten-million' (bench latency [--machine F] [--program P] [--out DIR] [--load N]; bench machining-time [--modes main,asis] [--only NAMES] [--out DIR] [--no-linuxcnc] [--reuse])" ;;
  esac
}

# experiment table1 [--size tiny|reduced|full] [--out DIR] [--machine FILE] [--host-network]:
# Choi et al. 2005's Table 1 in a live cell, fixed feed against the roughness law, and its
# report (tools/experiment/table1.py; docs/experiment.md). The cell runs in a network
# namespace of its own when this PC permits one (as root), so that no other cell on the
# PC hears it or is heard; --host-network runs it on the PC's network (an HMI can watch).
cmd_experiment() {
  [ "$INSTALLED" -eq 0 ] || die "experiment: runs from the source tree"
  local what="${1:-}"
  [ $# -gt 0 ] && shift
  [ "$what" = table1 ] || die "experiment: expected 'table1' (experiment table1 [--size tiny|reduced|full] [--out DIR])"
  local size=reduced out="" machine="$ROOT/config/machines/sim3_table1.yaml" host=0
  while [ $# -gt 0 ]; do
    case "$1" in
      --size) size="$2"; shift 2 ;;
      --out) out="$2"; shift 2 ;;
      --machine) machine="$2"; shift 2 ;;
      --host-network) host=1; shift ;;
      *) die "experiment table1: unknown argument '$1' (expected --size tiny|reduced|full, --out DIR, --machine FILE, --host-network)" ;;
    esac
  done
  case "$size" in tiny|reduced|full) ;; *) die "experiment table1: --size is tiny, reduced or full, not '$size'" ;; esac
  build
  [ -n "$out" ] || out="$ROOT/runs/table1-$size-$(date -u +%Y%m%d-%H%M%S)"
  "$(bin cnc-key)" gen --machine "$machine" --if-missing || die "experiment: cannot make the cell's key"
  local run=(/usr/bin/python3 "$ROOT/tools/experiment/table1.py" --build "$BUILD" --machine "$machine" --size "$size" --out "$out")
  if [ "$host" -eq 0 ] && unshare -n true 2>/dev/null; then
    say "experiment table1: size $size in a private network namespace, output in $out"
    run_child unshare -n bash -c 'ip link set lo up && ip route add 224.0.0.0/4 dev lo && exec "$0" "$@"' "${run[@]}"
  else
    say "experiment table1: size $size on this PC's network, output in $out"
    run_child "${run[@]}"
  fi
}

# soak --minutes M [soak.py options]: see tools/soak/soak.py.
cmd_soak() {
  build
  run_child python3 "$ROOT/tools/soak/soak.py" --build "$BUILD" --src "$ROOT" "$@"
}

# key gen|rotate|show [--machine FILE | --file KEYFILE] [...]: see tools/key/main.cc.
cmd_key() {
  [ -x "$(bin cnc-key)" ] || build
  local args=("$@") has_target=0
  for a in "$@"; do case "$a" in --machine|--file) has_target=1 ;; esac; done
  [ "$has_target" -eq 1 ] || args+=(--machine "$DEFAULT_MACHINE")
  exec "$(bin cnc-key)" "${args[@]}"
}

# package: Debian packages of this tree (CPack; packaging/CMakeLists.txt) into
# $BUILD/packages, each checked by lintian; prints their names, sizes and dependencies.
cmd_package() {
  [ "$INSTALLED" -eq 0 ] || die "package: packages are built from the source tree"
  build
  cmake "$BUILD" >/dev/null  # configure again: the packages' version is the repository's now
  cmake --build "$BUILD" -j "$(nproc)" >"$BUILD/last-build.log" 2>&1 || die "build failed (see $BUILD/last-build.log)"
  rm -rf "$BUILD/packages" && mkdir -p "$BUILD/packages"
  (cd "$BUILD" && cpack -G DEB -B "$BUILD/packages" >"$BUILD/packages/cpack.log" 2>&1) ||
    { tail -20 "$BUILD/packages/cpack.log" >&2; die "cpack failed (see $BUILD/packages/cpack.log)"; }
  rm -rf "$BUILD/packages/_CPack_Packages"
  local rc=0 deb
  for deb in "$BUILD"/packages/*.deb; do
    echo "$deb  $(du -k "$deb" | cut -f1) kB, installed $(dpkg-deb -f "$deb" Installed-Size) kB"
    echo "  Depends: $(dpkg-deb -f "$deb" Depends)"
    if command -v lintian >/dev/null; then
      lintian --fail-on error "$deb" | sed 's/^/  lintian: /' || rc=1
    fi
  done
  return $rc
}

# test [--sanitize address,undefined|thread] [ctest options]: the suite; with --sanitize
# in its own build folder (build-sanitize-LIST) built with those sanitizers, every
# process writing its reports to build-sanitize-LIST/sanitizer-reports/ (counted at the end).
cmd_test() {
  [ "$INSTALLED" -eq 0 ] || die "test: the test suite runs in the source tree (git clone, then ./cnc test)"
  local sanitize="" args=()
  while [ $# -gt 0 ]; do
    case "$1" in
      --sanitize) [ $# -ge 2 ] || die "test: --sanitize needs a list (address,undefined or thread)"; sanitize="$2"; shift 2 ;;
      --sanitize=*) sanitize="${1#--sanitize=}"; shift ;;
      *) args+=("$1"); shift ;;
    esac
  done
  local reports=""
  if [ -n "$sanitize" ]; then
    case "$sanitize" in
      address | undefined | address,undefined | undefined,address | thread | thread,undefined | undefined,thread) ;;
      *) die "test: --sanitize $sanitize: expected address,undefined or thread (ASan and TSan do not mix)" ;;
    esac
    BUILD="${CNC_BUILD_DIR:-$ROOT/build}-sanitize-${sanitize//,/-}"
    mkdir -p "$BUILD"
    # Warnings are not errors here: GCC's manual warns that sanitizers raise the rate of
    # false warnings (GCC 12: -Wmaybe-uninitialized inside libstdc++'s <regex>,
    # -Wrestrict on a string assignment); the plain build keeps the code warning-free.
    cmake -S "$ROOT" -B "$BUILD" -DCMAKE_BUILD_TYPE=Release -DCNC_SANITIZE="$sanitize" -DCNC_WERROR=OFF >/dev/null
    reports="$BUILD/sanitizer-reports"
    rm -rf "$reports" && mkdir -p "$reports"
    # Each process's reports in its own file (a service's stderr is often a log nobody reads).
    export ASAN_OPTIONS="log_path=$reports/asan:detect_leaks=1:halt_on_error=1:strict_string_checks=1"
    export UBSAN_OPTIONS="log_path=$reports/ubsan:print_stacktrace=1:halt_on_error=1"
    export TSAN_OPTIONS="log_path=$reports/tsan:halt_on_error=1:second_deadlock_stack=1"
    # Suppressions, each justified where it is written: tests/sanitizer/{lsan,tsan,ubsan}.supp.
    local kind var
    for kind in lsan tsan ubsan; do
      var="$(echo "$kind" | tr a-z A-Z)_OPTIONS"
      [ -f "$ROOT/tests/sanitizer/$kind.supp" ] && export "$var=${!var:+${!var}:}suppressions=$ROOT/tests/sanitizer/$kind.supp"
    done
  fi
  build
  cd "$BUILD"
  local start=$SECONDS rc=0
  run_child ctest --output-on-failure -j "$(nproc)" --timeout 900 ${args[@]+"${args[@]}"} || rc=$?
  if [ -n "$reports" ]; then
    local n
    n=$(find "$reports" -type f | wc -l)
    say "sanitizers ($sanitize): $n report file(s) in $reports"
    [ "$n" -eq 0 ] || { find "$reports" -type f | head -20 >&2; rc=1; }
  fi
  [ "$rc" -eq 0 ] || { say "the test suite failed (exit $rc) after $((SECONDS - start)) s"; exit "$rc"; }
  say "test suite passed in $((SECONDS - start)) s"
}

main() {
  local cmd="${1:-}"
  [ $# -gt 0 ] && shift
  case "$cmd" in
    demo) cmd_demo "$@" ;;
    test) cmd_test "$@" ;;
    build) build ;;
    package) cmd_package "$@" ;;
    up) [ -x "$(bin cnc-logger)" ] || build; cmd_up "$@" ;;
    ctl) exec "$(bin cnc-ctl)" "$@" ;;
    logstat) exec "$(bin cnc-logstat)" "$@" ;;
    replay) [ $# -gt 0 ] || die "replay: LOG is required"; log="$1"; shift; exec "$(bin cnc-replay)" --log "$log" "$@" ;;
    plan) [ -x "$(bin cnc-plan)" ] || build; cmd_plan "$@" ;;
    report) [ -x "$(bin cnc-logexport)" ] || build; cmd_report "$@" ;;
    cam) [ -x "$(bin cnc-cam)" ] || build; exec "$(bin cnc-cam)" "$@" ;;
    predict) { [ -x "$(bin cnc-predict)" ] && [ -x "$(bin cnc-plan)" ]; } || build; cmd_predict "$@" ;;
    conformance) [ -x "$(bin cnc-rs274)" ] || build; cmd_conformance "$@" ;;
    bench) cmd_bench "$@" ;;
    soak) cmd_soak "$@" ;;
    experiment) cmd_experiment "$@" ;;
    key) cmd_key "$@" ;;
    --version) [ -x "$(bin cnc-ctl)" ] || die "--version: not built yet (./cnc build)"
               echo "cnc $("$(bin cnc-ctl)" --version | cut -d' ' -f2)" ;;
    -h|--help) awk 'NR > 1 && /^#/ {sub(/^# ?/, ""); print; next} NR > 1 {exit}' "$0" ;;
    *) [ -z "$cmd" ] || say "unknown command '$cmd' (see cnc --help)"
       awk 'NR > 1 && /^#/ {sub(/^# ?/, ""); print; next} NR > 1 {exit}' "$0"; [ -z "$cmd" ] || exit 2 ;;
  esac
}

main "$@"
