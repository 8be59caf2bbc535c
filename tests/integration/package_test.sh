#!/usr/bin/env bash
# integration.package: the Debian packages, built from this build by CPack, installed
# on this machine with dpkg, and the cell run from the installed files alone.
#
#  1. The packages of cnc and cnc-cam, as integration.package_build made them from this
#     build (cpack) and checked them (lintian, contents): its fixture.
#  2. dpkg -i installs them: the cnc system user, /var/lib/cnc, the cell's key owned by
#     cnc with mode 0600, `--version` of every program = the package's version,
#     `systemd-analyze verify` of every unit, the host generator's wants.
#  3. With the source and build trees hidden (a mount namespace binds an empty
#     directory over them), the services run by the units' own ExecStart
#     (/usr/libexec/cnc/cnc-service NAME; logger and monitor as the cnc user, the
#     cyclic ones as root: see svc below), `cnc-ctl --do status` lists them
#     with host and version, reset enables the drives, and the demo's program runs
#     to its end (its end writes the parameters into program.var_file,
#     /var/lib/cnc/cell.var); the log verifies and names each service's version.
#  4. Restart policy (what systemd's Restart= does, done by hand: there is no systemd
#     here): a killed logger started again writes a new file, the cell runs on; a
#     killed interpolator started again refuses to run until RESET, then runs.
#  5. An upgrade in place keeps the edited cell file, the key and the parameters; removal keeps the
#     configuration, purge removes it with the state directory.
#
# Needs root (dpkg -i on this machine; CI's machine is fresh). Skipped (77) without it
# or when a cnc package is installed already (the test would replace it).
set -euo pipefail
BUILD="$(cd "$1" && pwd)"
SRC="$(cd "$2" && pwd)"
source "$SRC/tests/integration/lib.sh"

[ "$(id -u)" -eq 0 ] || { echo "skipped: needs root for dpkg -i"; exit 77; }
for t in dpkg-deb systemd-analyze unshare setpriv; do
  command -v "$t" >/dev/null || fail "$t is missing (./cnc installs it: dpkg-dev, systemd)"
done
if dpkg-query -W -f='${Status}' cnc 2>/dev/null | grep -q 'installed'; then
  echo "skipped: a cnc package is installed on this machine; this test would replace it"
  exit 77
fi
enter_private_netns "$@"

WORK="$(mktemp -d /tmp/cnc-package-test.XXXXXX)"
chmod 755 "$WORK"
purge() { dpkg -P cnc cnc-cam >/dev/null 2>&1 || true; }
trap 'cleanup; purge; rm -rf "$WORK"' EXIT
t0=$SECONDS

# ---- 1. the packages integration.package_build made and checked ------------------------
DEBS="$BUILD/package-test/pk"
CELL_DEB="$(ls "$DEBS"/cnc_*.deb 2>/dev/null || true)"
CAM_DEB="$(ls "$DEBS"/cnc-cam_*.deb 2>/dev/null || true)"
[ -f "$CELL_DEB" ] && [ -f "$CAM_DEB" ] || fail "no packages in $DEBS: integration.package_build makes them (ctest runs it first as this test's fixture)"
VERSION="$(dpkg-deb -f "$CELL_DEB" Version)"
note "packages of integration.package_build: $(basename "$CELL_DEB"), $(basename "$CAM_DEB")"

# ---- 2. install ----------------------------------------------------------------------
dpkg -i "$CELL_DEB" "$CAM_DEB" >"$WORK/dpkg-i.log" 2>&1 || { cat "$WORK/dpkg-i.log"; fail "dpkg -i failed"; }
note "installed: $(dpkg-query -W -f='${Package} ${Version} ${Status}\n' cnc cnc-cam | tr '\n' ';')"
getent passwd cnc >/dev/null || fail "the package made no cnc user"
[ "$(stat -c '%U %a' /etc/cnc/cell.key)" = "cnc 600" ] || fail "key: $(stat -c '%U %a' /etc/cnc/cell.key), expected 'cnc 600'"
[ "$(stat -c '%U' /var/lib/cnc)" = cnc ] || fail "/var/lib/cnc does not belong to cnc"
for p in cnc-logger cnc-interpolator cnc-drive-bridge cnc-monitor cnc-program-server cnc-servo-sim cnc-ctl; do
  v="$(/usr/bin/$p --version 2>&1 | awk '{print $2}')"
  [ "$v" = "$VERSION" ] || fail "$p --version says '$v', the package is $VERSION"
done
# The units: verified offline (systemd-analyze loads them, checks ExecStart, users, drop-ins).
for s in logger servo-sim drive-bridge monitor program-server interpolator; do
  systemd-analyze verify "cnc@$s.service" >"$WORK/verify.$s.txt" 2>&1 ||
    { cat "$WORK/verify.$s.txt"; fail "systemd-analyze verify cnc@$s.service"; }
  [ -s "$WORK/verify.$s.txt" ] && { cat "$WORK/verify.$s.txt" >&2; fail "systemd-analyze verify cnc@$s.service printed warnings"; }
done
systemd-analyze verify cnc.target >"$WORK/verify.target.txt" 2>&1 || { cat "$WORK/verify.target.txt"; fail "verify cnc.target"; }
note "systemd-analyze verify: cnc.target and 6 instances of cnc@.service, no message"
mkdir -p "$WORK/gen"
/usr/lib/systemd/system-generators/cnc-host-generator "$WORK/gen" "$WORK/gen" "$WORK/gen"
[ "$(ls "$WORK/gen/cnc.target.wants" | wc -l)" -eq 6 ] || fail "the generator made $(ls "$WORK/gen/cnc.target.wants") for host.conf"
for s in logger monitor; do
  grep -qx 'Restart=always' "/usr/lib/systemd/system/cnc@$s.service.d/restart.conf" || fail "cnc@$s: Restart=always expected"
done
for s in interpolator drive-bridge program-server servo-sim; do
  grep -qx 'Restart=on-failure' "/usr/lib/systemd/system/cnc@$s.service.d/restart.conf" || fail "cnc@$s: Restart=on-failure expected"
done

# ---- 3. run the cell from the installed files, the source tree hidden -----------------
# The cell file as installed, with the test's own ports (private namespace anyway).
mkdir -p "$WORK/empty"
cat >"$WORK/run.sh" <<'EOS'
set -euo pipefail
WORK="$1"; VERSION="$2"
source "$WORK/lib.sh"
export PATH=/usr/sbin:/usr/bin:/sbin:/bin
[ ! -e "$3/CMakeLists.txt" ] || fail "the source tree is still visible"
# svc NAME: a service as its unit starts it (ExecStart=cnc-service NAME, a clean
# environment). The logger and the monitor run as the cnc user (User=cnc: they read the
# key and write /var/lib/cnc/runs as it). The cyclic services run as root here: the
# unit's LimitRTPRIO gives the cnc user SCHED_FIFO, but this sandbox cannot raise that
# limit (prlimit: Operation not permitted), and at normal priority beside the suite's
# SCHED_FIFO tests a 50 ms stall trips the setpoint watchdog.
svc() {
  case "$1" in
    logger|monitor) start "$1" setpriv --reuid cnc --regid cnc --init-groups -- \
                      env -i PATH="$PATH" CNC_CELL=/etc/cnc/cell.yaml /usr/libexec/cnc/cnc-service "$1" ;;
    *) start "$1" env -i PATH="$PATH" CNC_CELL=/etc/cnc/cell.yaml /usr/libexec/cnc/cnc-service "$1" ;;
  esac
}
for s in logger servo-sim drive-bridge monitor program-server interpolator; do svc "$s"; done
trap 'CNC_KEEP_WORK=1 cleanup' EXIT  # the folder is the outer test's, which goes on in it
ctl() { /usr/bin/cnc-ctl --machine /etc/cnc/cell.yaml "$@"; }
sleep 1.5
ctl --do status >"$WORK/status.txt" 2>&1 || { cat "$WORK/status.txt"; fail "cnc-ctl --do status"; }
cat "$WORK/status.txt" >&2
for s in cnc-logger cnc-drive-bridge cnc-monitor cnc-program-server cnc-interpolator; do  # (the simulator is no LCM service)
  status_lists "$WORK/status.txt" "$s" "$(hostname)" "$VERSION" || fail "status does not list $s on $(hostname), $VERSION, running"
done
# The shipped cell file enables no drive by itself: a program is refused until reset.
rc=0; ctl --do run --program /usr/share/cnc/config/programs/lines.ngc --timeout 30 >"$WORK/refused.txt" 2>&1 || rc=$?
[ "$rc" -eq 3 ] || { cat "$WORK/refused.txt"; fail "run before reset: exit $rc, expected 3 (refused: drives disabled)"; }
note "before reset: $(tail -1 "$WORK/refused.txt")"
ctl --do reset --timeout 20 >&2 || fail "reset"
t=$SECONDS
ctl --do run --program /usr/share/cnc/config/programs/demo.ngc --timeout 120 >"$WORK/demo.txt" 2>&1 || { cat "$WORK/demo.txt"; fail "the demo's program did not run to its end"; }
note "demo.ngc from the installed files: done in $((SECONDS - t)) s ($(grep -o 'largest following error[^,]*' "$WORK/demo.txt" | head -1))"
# The HMI's program directory in the installed cell file holds the shipped programs.
hmi_dir=$(sed -n 's/^ *program_dir: *\([^ #]*\).*/\1/p' /etc/cnc/cell.yaml)
[ "$hmi_dir" = /usr/share/cnc/config/programs ] && [ -f "$hmi_dir/demo.ngc" ] \
  || fail "the installed cell file's hmi.program_dir ('$hmi_dir') does not hold the shipped programs"
# The installed cell keeps the interpreter's parameters (program.var_file): written at the program's end.
grep -q "^5221"$'\t' /var/lib/cnc/cell.var 2>/dev/null || fail "the demo's end wrote no parameter file /var/lib/cnc/cell.var (program.var_file)"
note "parameters kept: /var/lib/cnc/cell.var, $(wc -l </var/lib/cnc/cell.var) persistent parameters, owner $(stat -c %U /var/lib/cnc/cell.var)"

# Restart policy, by hand: the logger (Restart=always) comes back with a new file.
kill_hard logger
svc logger
sleep 1
[ "$(ls /var/lib/cnc/runs/*.lcmlog | wc -l)" -ge 2 ] || fail "the restarted logger wrote no new file: $(ls /var/lib/cnc/runs)"
# The interpolator (Restart=on-failure) comes back into a state where nothing moves until RESET.
# systemd starts it again RestartSec after the crash (the unit's 1 s): the drive bridge's
# watchdog has stopped the axes and faulted by then, so START is refused until RESET.
# Started again at once (no RestartSec), the new interpolator's stream came 44 ms after
# the old one's last setpoint, within the 50 ms watchdog, and the bridge joined it.
restart_s=$(sed -n 's/^RestartSec=//p' /usr/lib/systemd/system/cnc@.service)
[ -n "$restart_s" ] || fail "cnc@.service sets no RestartSec"
kill_hard interpolator
sleep "$restart_s"
svc interpolator
sleep 1.5
rc=0; ctl --do run --program /usr/share/cnc/config/programs/lines.ngc --timeout 30 >"$WORK/after-kill.txt" 2>&1 || rc=$?
[ "$rc" -ne 0 ] || fail "a restarted interpolator ran a program without RESET"
note "restarted interpolator, before reset: exit $rc: $(grep -m1 '^cnc-ctl:' "$WORK/after-kill.txt" || tail -1 "$WORK/after-kill.txt")"
ctl --do reset --timeout 20 >&2 || fail "reset after the restart"
ctl --do run --program /usr/share/cnc/config/programs/lines.ngc --timeout 60 >"$WORK/after-reset.txt" 2>&1 ||
  { cat "$WORK/after-reset.txt"; fail "after reset the program did not run"; }
note "after reset: lines.ngc ran to its end"
for s in interpolator program-server monitor drive-bridge servo-sim logger; do stop "$s" TERM; done
# The cnc command as installed (no build, files from /usr/share/cnc): a dry run.
(cd "$WORK" && /usr/bin/cnc plan /usr/share/cnc/config/programs/lines.ngc --csv "$WORK/plan.csv" >"$WORK/plan.txt" 2>&1) ||
  { cat "$WORK/plan.txt"; fail "cnc plan from the installed files"; }
note "cnc plan (installed): $(grep -m1 -iE 'time|setpoints' "$WORK/plan.txt" || true)"
EOS
cp "$SRC/tests/integration/lib.sh" "$WORK/lib.sh"
chmod -R a+rX "$WORK"
unshare -m bash -c 'mount --make-rprivate / && mount --bind "$1" "$2" && { [ "$3" = "${3#$2/}" ] && mount --bind "$1" "$3" || true; } && shift 3 && exec bash "$@"' \
  _ "$WORK/empty" "$SRC" "$BUILD" "$WORK/run.sh" "$WORK" "$VERSION" "$SRC" || fail "the installed cell (above)"
log="$(ls -t /var/lib/cnc/runs/*.lcmlog | tail -1)"
/usr/bin/cnc-logstat --log "$log" --summary --machine /etc/cnc/cell.yaml >"$WORK/logstat.txt" 2>&1 ||
  { cat "$WORK/logstat.txt"; fail "the installed cell's log does not verify"; }
grep -qF "cnc-interpolator $VERSION on $(hostname)" "$WORK/logstat.txt" || { cat "$WORK/logstat.txt"; fail "the log does not name the interpolator's version"; }
sed -n '/^  services/,/^  sequence/p' "$WORK/logstat.txt" | head -7 >&2

# ---- 5. upgrade, remove, purge -------------------------------------------------------
echo "# changed on this site" >>/etc/cnc/cell.yaml
key_sum="$(sha256sum /etc/cnc/cell.key | cut -d' ' -f1)"
dpkg-deb -R "$CELL_DEB" "$WORK/up"
NEXT="${VERSION}.1"
sed -i "s/^Version: .*/Version: $NEXT/" "$WORK/up/DEBIAN/control"
dpkg-deb -b "$WORK/up" "$WORK/cnc_next.deb" >/dev/null
dpkg -i "$WORK/cnc_next.deb" >"$WORK/dpkg-up.log" 2>&1 || { cat "$WORK/dpkg-up.log"; fail "upgrade failed"; }
[ "$(dpkg-query -W -f='${Version}' cnc)" = "$NEXT" ] || fail "upgrade: version $(dpkg-query -W -f='${Version}' cnc)"
tail -1 /etc/cnc/cell.yaml | grep -q 'changed on this site' || fail "the upgrade lost the site's change to cell.yaml"
[ -s /var/lib/cnc/cell.var ] || fail "the upgrade lost the parameter file /var/lib/cnc/cell.var"
[ "$(sha256sum /etc/cnc/cell.key | cut -d' ' -f1)" = "$key_sum" ] || fail "the upgrade changed the key"
[ "$(stat -c '%U %a' /etc/cnc/cell.key)" = "cnc 600" ] || fail "upgrade: key $(stat -c '%U %a' /etc/cnc/cell.key)"
note "upgrade $VERSION -> $NEXT: cell.yaml kept the site's change, key unchanged"
dpkg -r cnc-cam cnc >"$WORK/dpkg-r.log" 2>&1 || { cat "$WORK/dpkg-r.log"; fail "dpkg -r"; }
[ ! -e /usr/bin/cnc-interpolator ] || fail "remove left /usr/bin/cnc-interpolator"
[ -f /etc/cnc/cell.yaml ] && [ -f /etc/cnc/host.conf ] && [ -f /etc/cnc/cell.key ] || fail "remove took the configuration"
note "remove: programs gone, /etc/cnc kept ($(ls /etc/cnc | tr '\n' ' '))"
dpkg -P cnc cnc-cam >"$WORK/dpkg-p.log" 2>&1 || { cat "$WORK/dpkg-p.log"; fail "dpkg -P"; }
[ ! -e /etc/cnc ] || fail "purge left /etc/cnc: $(ls -A /etc/cnc)"
[ ! -e /var/lib/cnc ] || fail "purge left /var/lib/cnc"
note "purge: /etc/cnc and /var/lib/cnc gone; whole test $((SECONDS - t0)) s"
echo "PASS"
