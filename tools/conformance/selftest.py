#!/usr/bin/env python3
"""Self-test of the conformance harness, with rs274 on both sides.

1. rs274 against itself must agree exactly (canon max 0, path max 0).
2. rs274 against a perturbed copy of itself (a wrapper that runs rs274 and then
   edits its output, or refuses) must be caught, each in the expected way:
   numbers beyond the print precision, a shifted arc, a renamed / dropped
   call, a changed argument format, a refusal, and a change of one unit of
   the last printed decimal that must still pass.

Exit 0 when every case behaves as expected; 77 when rs274 is not installed.
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
RS274_ARGS = "-g -i {ini} -t {tbl} -v {var} {file} {out}"


def perturb(mode, out):
    with open(out) as f:
        lines = f.read().splitlines(keepends=True)
    done = False

    def bump(line, k, delta):
        nums = list(re.finditer(r'-?\d+\.\d+', line))
        m = nums[k]
        v = float(m.group()) + delta
        return line[:m.start()] + f"{v:.4f}" + line[m.end():]

    for i, line in enumerate(lines):
        if done:
            break
        if mode.startswith('shift:') and 'STRAIGHT_FEED(' in line:
            lines[i] = bump(line, 0, float(mode.split(':')[1]))
            done = True
        elif mode == 'arc' and 'ARC_FEED(' in line:
            lines[i] = bump(line, 2, 0.05)        # first coordinate of the centre
            done = True
        elif mode == 'rename' and 'STRAIGHT_TRAVERSE(' in line:
            lines[i] = line.replace('STRAIGHT_TRAVERSE(', 'STRAIGHT_FEED(')
            done = True
        elif mode == 'drop' and 'STRAIGHT_FEED(' in line:
            del lines[i]
            done = True
        elif mode == 'format' and 'STRAIGHT_FEED(' in line:
            lines[i] = line.replace(', ', ',', 1)
            done = True
        elif mode == 'nlabel' and 'STRAIGHT_FEED(' in line:
            lines[i] = re.sub(r'^(\s*\d+ )N\S*\s*', r'\1N..... ', line)
            lines[i] = lines[i] if lines[i] != line else re.sub(r'^(\s*\d+ )N\.\.\.\.\. ', r'\1N1     ', line)
            done = True
    with open(out, 'w') as f:
        f.writelines(lines)


def wrap(argv):
    mode, exe, args = argv[0], argv[1], argv[2:]
    if mode == 'refuse':
        print('refused by the self-test wrapper', file=sys.stderr)
        return 1
    rc = subprocess.call([exe] + args)
    if mode != 'none' and len(args) >= 2 and os.path.exists(args[-1]):
        perturb(mode, args[-1])
    return rc


# mode -> (expected exit status, text that must appear in the output)
CASES = [
    ('none', 0, r'canon_max_diff=0 path_max_diff_mm=0 .*failures=0'),
    ('shift:0.0001', 0, r'canon_max_diff=1\.00e-04 .*failures=0'),       # one unit of the 4th decimal: tolerated
    ('shift:0.0003', 1, r'argument 1 differs by 0\.0003'),                 # canon difference, path within 0.01
    ('shift:0.05', 1, r'tool paths differ by 5\.00e-02 mm'),
    ('arc', 1, r'argument 3 differs by 0\.05'),
    ('rename', 1, r'call name differs'),
    ('drop', 1, r'call name differs|one side has'),
    ('format', 1, r'argument format differs'),
    ('nlabel', 1, r'N-field differs'),
    ('refuse', 1, r'rs274 accepts, ours refuses'),
]


def main():
    if len(sys.argv) > 1 and sys.argv[1] == '--wrap':
        return wrap(sys.argv[2:])
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--theirs', default='/usr/bin/rs274')
    ap.add_argument('--generate', type=int, default=8)
    ap.add_argument('--seed', type=int, default=7)
    ap.add_argument('--samples', default='/usr/share/linuxcnc/ncfiles')
    a = ap.parse_args()
    if not os.access(a.theirs, os.X_OK):
        print(f"selftest: {a.theirs} missing: skipped", file=sys.stderr)
        return 77
    failures = 0
    with tempfile.TemporaryDirectory(prefix='conformance-selftest-') as tmp:
        progs = []
        for s in ('arcspiral.ngc', 'systems.ngc', 'polar.ngc'):   # arcs, NURBS, offsets
            p = os.path.join(a.samples, s)
            if os.path.exists(p):
                progs += ['--program', p]
        for mode, want_rc, want_text in CASES:
            w = os.path.join(tmp, f"ours-{mode.replace(':', '_')}")
            with open(w, 'w') as f:
                f.write(f'#!/bin/sh\nexec "{sys.executable}" "{os.path.abspath(__file__)}" --wrap {mode} "{a.theirs}" "$@"\n')
            os.chmod(w, 0o755)
            cmd = [sys.executable, os.path.join(HERE, 'conformance.py'), '--ours', w, '--ours-args', RS274_ARGS,
                   '--theirs', a.theirs, '--generate', str(a.generate), '--seed', str(a.seed), '--quiet'] + progs
            if mode == 'none':
                cmd.append('--always-path')
            p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            ok = p.returncode == want_rc and re.search(want_text, p.stdout) is not None
            summary = [l for l in p.stdout.splitlines() if l.startswith('SUMMARY')]
            print(f"{'ok  ' if ok else 'FAIL'} {mode:14s} exit {p.returncode} (want {want_rc}); "
                  f"{summary[0] if summary else '(no summary)'}")
            if not ok:
                failures += 1
                print('\n'.join('    ' + l for l in p.stdout.splitlines()[-25:]))
    print(f"selftest: {len(CASES) - failures}/{len(CASES)} cases as expected")
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
