#!/usr/bin/env bash
# integration.package_build: the Debian packages cnc and cnc-cam, built from this build
# by CPack into BUILD/package-test/pk, where integration.package installs them. No
# cell and no root needed: it runs beside the live-cell tests (cpack and lintian
# took their share of the live chain's time when they ran inside integration.package).
#
# lintian finds no error in either; neither ships build files; cnc ships the services,
# the unit, the cell file, the drive profiles, the report tool and the OPC UA server with
# its node modules (npm ci's, from the lock file); cnc-cam ships cnc-cam.
set -euo pipefail
BUILD="$(cd "$1" && pwd)"
SRC="$(cd "$2" && pwd)"
source "$SRC/tests/integration/lib.sh"
for t in cpack dpkg-deb dpkg-shlibdeps lintian; do
  command -v "$t" >/dev/null || fail "$t is missing (./cnc installs it: dpkg-dev, lintian)"
done
OUT="$BUILD/package-test"
rm -rf "$OUT"
mkdir -p "$OUT"
WORK="$(mktemp -d /tmp/cnc-package-build.XXXXXX)"
trap 'rm -rf "$WORK"' EXIT
t0=$SECONDS

# ---- build and check the packages ------------------------------------------------
(cd "$BUILD" && cpack -G DEB -B "$OUT/pk") >"$WORK/cpack.log" 2>&1 || { tail -30 "$WORK/cpack.log"; fail "cpack failed"; }
CELL_DEB="$(ls "$OUT"/pk/cnc_*.deb)"
CAM_DEB="$(ls "$OUT"/pk/cnc-cam_*.deb)"
VERSION="$(dpkg-deb -f "$CELL_DEB" Version)"
note "cpack: $((SECONDS - t0)) s, version $VERSION"
for deb in "$CELL_DEB" "$CAM_DEB"; do
  note "$(basename "$deb"): $(du -k "$deb" | cut -f1) kB, installed $(dpkg-deb -f "$deb" Installed-Size) kB"
  note "  Depends: $(dpkg-deb -f "$deb" Depends)"
  dpkg-deb -c "$deb" >"$WORK/contents.$(basename "$deb").txt"
  grep -qE '\./usr/(include|lib/.*\.a$)' "$WORK/contents.$(basename "$deb").txt" && fail "$(basename "$deb") ships build files"
  lintian --fail-on error "$deb" >"$WORK/lintian.$(basename "$deb").txt" 2>&1 ||
    { cat "$WORK/lintian.$(basename "$deb").txt"; fail "lintian reports errors in $(basename "$deb")"; }
  note "  lintian: $(grep -c '^E:' "$WORK/lintian.$(basename "$deb").txt" || true) errors, $(grep -c '^W:' "$WORK/lintian.$(basename "$deb").txt" || true) warnings"
done
for f in /usr/bin/cnc-interpolator /usr/bin/cnc-ctl /usr/lib/systemd/system/cnc@.service /etc/cnc/cell.yaml \
         /usr/share/cnc/config/drives/sim.yaml /usr/share/cnc/tools/report/make_report.py \
         /usr/bin/cnc-opcua /usr/share/cnc/services/opcua/server.js \
         /usr/share/cnc/services/opcua/node_modules/node-opcua/package.json \
         /usr/lib/systemd/system/cnc@opcua.service.d/restart.conf \
         /usr/bin/cnc-mqtt /usr/lib/systemd/system/cnc@mqtt.service.d/restart.conf \
         /usr/bin/cnc-fleet /usr/share/cnc/services/mqtt/www/fleet.html; do
  grep -q " \.$f\$" "$WORK/contents.$(basename "$CELL_DEB").txt" || fail "cnc does not ship $f"
done
grep -q ' \./usr/bin/cnc-cam$' "$WORK/contents.$(basename "$CAM_DEB").txt" || fail "cnc-cam does not ship /usr/bin/cnc-cam"

note "package_build: $((SECONDS - t0)) s"
