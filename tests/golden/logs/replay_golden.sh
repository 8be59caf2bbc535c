#!/usr/bin/env bash
# Every golden log (one per log format or motion revision, recorded by record.sh
# with the version of its time) is read in this build, names its format, and
# replays bit for bit, or (an older motion revision, common/bus/log_format.h) up to
# where it diverges by design, which the replay says; one of this build's motion
# revision replays bit for bit.
#   replay_golden.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
BUILD="$1"; SRC="$2"
n=0; same=0
# This build's motion revision: its own golden log (the newest) must replay identically.
motion="$(sed -n 's/^inline constexpr int kMotionRevision = \([0-9]*\);/\1/p' "$SRC/common/bus/log_format.h")"
[ -n "$motion" ] || { echo "FAIL: no kMotionRevision in common/bus/log_format.h" >&2; exit 1; }
for log in "$SRC"/tests/golden/logs/format-*.lcmlog; do
  [ -e "$log" ] || continue
  want="${log##*/format-}"; want="${want%%[.-]*}"  # format-N.lcmlog, format-N-motion-R.lcmlog
  rc=0; out="$("$BUILD/tools/cnc-replay" --log "$log" 2>&1)" || rc=$?
  echo "$out" | grep -q "^log format $want\b" || { echo "$out" >&2; echo "FAIL: $log is not read as format $want" >&2; exit 1; }
  # Every input decoded and applied up to the verdict: identical, or (a log of an
  # older motion revision) diverging by design, which the replay names.
  if [ "$rc" -eq 0 ]; then
    echo "$out" | grep -q "^identical: " || { echo "$out" >&2; echo "FAIL: $log: no verdict" >&2; exit 1; }
    echo "$out" | grep -q "^log format .*, motion revision $motion\$" && same=$((same + 1))
  else
    [ "$rc" -eq 2 ] && echo "$out" | grep -q "^expected: the log's motion revision [0-9]* is not this cnc's" \
      || { echo "$out" >&2; echo "FAIL: $log does not replay (exit $rc)" >&2; exit 1; }
  fi
  echo "$(basename "$log"): $(echo "$out" | grep -E '^(log format|identical|diverges|expected)' | tr '\n' ' ')"
  n=$((n + 1))
done
[ "$n" -ge 2 ] || { echo "FAIL: only $n golden logs" >&2; exit 1; }
[ "$same" -ge 1 ] || { echo "FAIL: no golden log of motion revision $motion replays identically (record one: record.sh)" >&2; exit 1; }
# A format this build does not know (the newest golden log's format event made
# 9): refused (exit 2), naming the format, the version that recorded it and what to do.
newest="$(ls "$SRC"/tests/golden/logs/format-*.lcmlog | sort -V | tail -n 1)"
tmp="$(mktemp /tmp/cnc-golden-future.XXXXXX.lcmlog)"
trap 'rm -f "$tmp"' EXIT
/usr/bin/python3 - "$newest" "$tmp" <<'PY'
import re, sys
data = open(sys.argv[1], "rb").read()
patched, n = re.subn(rb"cnc-log-format [0-9]+ ", b"cnc-log-format 9 ", data, count=1)
assert n == 1 and len(patched) == len(data), "no format event in " + sys.argv[1]
open(sys.argv[2], "wb").write(patched)
PY
rc=0; out="$("$BUILD/tools/cnc-replay" --log "$tmp" 2>&1)" || rc=$?
[ "$rc" -eq 2 ] || { echo "$out" >&2; echo "FAIL: a log of format 9 gave exit $rc, expected 2" >&2; exit 1; }
echo "$out" | grep -q "format 9 (recorded by cnc .*), newer than this cnc .* read it with the version that recorded it" \
  || { echo "$out" >&2; echo "FAIL: the refusal does not name the format, its version and what to do" >&2; exit 1; }
echo "format 9: refused: ${out#*: }"
# The report's tables of an older log: every message this build cannot decode (a
# status message that has gained fields since) is counted and said, never dropped unsaid.
exp="$(mktemp -d /tmp/cnc-golden-export.XXXXXX)"
trap 'rm -f "$tmp"; rm -rf "$exp"' EXIT
rc=0; out="$("$BUILD/tools/cnc-logexport" --machine "$SRC/config/machines/sim3.yaml" --log "$newest" --out "$exp" 2>&1)" || rc=$?
[ "$rc" -eq 0 ] || { echo "$out" >&2; echo "FAIL: cnc-logexport of $newest: exit $rc" >&2; exit 1; }
n_status="$(/usr/bin/python3 -c 'import sys; print(sum(1 for _ in open(sys.argv[1])) - 1)' "$exp/axis_status.csv")"
[ "$n_status" -gt 0 ] || echo "$out" | grep -q "AXIS_STATUS message(s) do not decode in this version" \
  || { echo "$out" >&2; echo "FAIL: $newest: no AXIS_STATUS row and no word why" >&2; exit 1; }
echo "export of $(basename "$newest"): $n_status AXIS_STATUS rows; $(echo "$out" | grep -c 'do not decode') channel(s) named as not decoded"
# The machine file the log recorded, as the cell loaded it: its relative paths beside
# the file it was loaded from (here a tool table and a var file: the newest golden log
# with its INTERP_CONFIG's machine file moved to $files and given both), and --program
# interpreted as the dry run does: read, never written. The program: golden.ngc with
# its two comment lines made G10s that the cell would write (a work offset, a tool's
# length), so its blocks and lines are the recorded ones.
files="$(mktemp -d /tmp/cnc-golden-files.XXXXXX)"
trap 'rm -f "$tmp"; rm -rf "$exp" "$files"' EXIT
printf 'T1 P1 Z+0.500000 D+6.000000 ;ball\n' >"$files/tool.tbl"
printf '5241\t0.000000\n' >"$files/params.var"
cp "$files/tool.tbl" "$files/tool.before"; cp "$files/params.var" "$files/params.before"
/usr/bin/python3 - "$newest" "$files/run.lcmlog" "$files/machine.yaml" \
  $'\nprogram:\n  tool_table: tool.tbl\n  var_file: params.var\n' <<'PY'
import struct, sys
src, dst, source_file, extra = sys.argv[1:5]
data = open(src, "rb").read()
out, i, n = bytearray(), 0, 0
while i < len(data):  # LCM log events: magic, number, time, channel and data lengths
    magic, num, ts, clen, dlen = struct.unpack_from(">IqqII", data, i)
    assert magic == 0xEDA1DA01, "not an LCM log event at byte %d" % i
    channel = data[i + 28:i + 28 + clen]
    body = data[i + 28 + clen:i + 28 + clen + dlen]
    i += 28 + clen + dlen
    if channel.endswith(b"INTERP_CONFIG"):  # lcmt_config: hash, utime, seq, sender, 3 strings, cycle
        p, strings = 28, []
        for _ in range(3):
            (k,) = struct.unpack_from(">i", body, p)
            strings.append(body[p + 4:p + 3 + k])
            p += 4 + k
        strings[1] = source_file.encode()
        strings[2] += extra.encode()
        # The cycle and the signature's trailer follow (not verified without --key).
        body = body[:28] + b"".join(struct.pack(">i", len(s) + 1) + s + b"\0" for s in strings) + body[p:]
        n += 1
    out += struct.pack(">IqqII", magic, num, ts, clen, len(body)) + channel + body
assert n > 0, "no INTERP_CONFIG in " + src
open(dst, "wb").write(out)
PY
rc=0; out="$("$BUILD/tools/cnc-replay" --log "$files/run.lcmlog" 2>&1)" || rc=$?
[ "$rc" -eq 0 ] && echo "$out" | grep -q "^identical: " \
  || { echo "$out" >&2; echo "FAIL: a log whose machine file names a tool table beside it does not replay (exit $rc)" >&2; exit 1; }
{ printf 'G10 L2 P2 X1\nG10 L1 P1 Z0.3\n'; tail -n +3 "$SRC/tests/golden/logs/golden.ngc"; } >"$files/golden.ngc"
rc=0; out="$("$BUILD/tools/cnc-replay" --log "$files/run.lcmlog" --program "$files/golden.ngc" 2>&1)" || rc=$?
[ "$rc" -eq 0 ] && echo "$out" | grep -q "^identical: " \
  || { echo "$out" >&2; echo "FAIL: --program with the G10s: exit $rc, expected identical" >&2; exit 1; }
cmp -s "$files/tool.tbl" "$files/tool.before" && cmp -s "$files/params.var" "$files/params.before" \
  || { cat "$files/tool.tbl" >&2; echo "FAIL: the replay wrote the machine's tool table or var file" >&2; exit 1; }
echo "recorded machine file with a tool table and a var file beside it: replays identically; with --program's G10s: $(echo "$out" | grep -o '^identical: [0-9]* setpoints'), the tool table and var file unchanged"
