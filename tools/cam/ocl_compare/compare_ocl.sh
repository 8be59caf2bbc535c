#!/usr/bin/env bash
# OpenCAMLib's BatchDropCutter and `cnc-cam drop` side by side on the same mesh, points
# and threads: CL points per second (best of REPEATS, index/kd-tree build excluded on
# both sides) and the largest |dz| between their results.
#
#   compare_ocl.sh --ocl /path/to/opencamlib [--ocl-build DIR] --stl MESH --points XY.csv
#                  [--tools "ball:2 flat:6 bull:6:1"] [--threads "1 2"] [--repeats 3] [--cnc-cam EXE]
#
# OpenCAMLib is not part of this project: build it yourself (its CMake, Debian's
# libboost-dev, OpenMP, -DBUILD_CXX_LIB=ON; with CMake 3.25 drop the
# `cmake_policy(SET CMP0144 NEW)` line of its src/CMakeLists.txt). This script only
# compiles ocl_drop.cc (ours) against that build. cnc-cam-bench --out-dir DIR writes a
# generated terrain STL and the grid points of each mesh for this.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../../.." && pwd)"
OCL="" OCL_BUILD="" STL="" POINTS="" TOOLS="ball:2 flat:6 bull:6:1" THREADS="1 2" REPEATS=3
CNC_CAM="${CNC_BUILD_DIR:-$ROOT/build}/tools/cam/cnc-cam"
while [ $# -gt 0 ]; do
  case "$1" in
    --ocl) OCL="$2"; shift 2 ;;
    --ocl-build) OCL_BUILD="$2"; shift 2 ;;
    --stl) STL="$2"; shift 2 ;;
    --points) POINTS="$2"; shift 2 ;;
    --tools) TOOLS="$2"; shift 2 ;;
    --threads) THREADS="$2"; shift 2 ;;
    --repeats) REPEATS="$2"; shift 2 ;;
    --cnc-cam) CNC_CAM="$2"; shift 2 ;;
    *) echo "compare_ocl.sh: unknown argument $1" >&2; exit 2 ;;
  esac
done
[ -n "$OCL" ] && [ -n "$STL" ] && [ -n "$POINTS" ] || { sed -n '2,14p' "$0" >&2; exit 2; }
OCL_BUILD="${OCL_BUILD:-$OCL/build}"
[ -f "$OCL_BUILD/libocl.so" ] || { echo "compare_ocl.sh: no $OCL_BUILD/libocl.so (build OpenCAMLib with -DBUILD_CXX_LIB=ON)" >&2; exit 2; }
[ -x "$CNC_CAM" ] || { echo "compare_ocl.sh: no $CNC_CAM (cmake --build BUILD --target cnc-cam)" >&2; exit 2; }

WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
inc=()
for d in "" geo cutters algo dropcutter common; do inc+=(-I "$OCL/src/$d"); done
g++ -std=c++17 -O2 -fopenmp "${inc[@]}" "$HERE/ocl_drop.cc" -o "$WORK/ocl_drop" \
  -L "$OCL_BUILD" -locl -Wl,-rpath,"$OCL_BUILD"

rate() { sed -n 's/.*pts_per_s=\([0-9.]*\).*/\1/p'; }
printf '%-10s %3s %12s %12s %7s  %s\n' tool T ours_pts/s ocl_pts/s ratio "agreement (ours vs OpenCAMLib)"
for tool in $TOOLS; do
  for t in $THREADS; do
    ours=0
    for _ in $(seq "$REPEATS"); do
      r=$("$CNC_CAM" drop --stl "$STL" --tool "$tool" --points "$POINTS" --out "$WORK/ours.csv" --threads "$t" 2>/dev/null | rate)
      ours=$(python3 -c "print(max($ours, $r))")
    done
    ocl=$("$WORK/ocl_drop" "$STL" "$POINTS" "$tool" "$t" "$REPEATS" "$WORK/ocl.csv" | rate)
    agree=$(python3 "$HERE/compare_xyz.py" "$WORK/ours.csv" "$WORK/ocl.csv")
    printf '%-10s %3s %12.0f %12.0f %6.1fx  %s\n' "$tool" "$t" "$ours" "$ocl" "$(python3 -c "print($ours / $ocl)")" "$agree"
  done
done
