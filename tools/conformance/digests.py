#!/usr/bin/env python3
"""Digests of what the interpreter and the dry run make of every program we know:
the shipped programs, the golden and cutter-compensation programs, LinuxCNC's
samples and the conformance generator's programs (fixed seed). A change that
means to keep behaviour compares two of these files: any line that differs names
the program and whether its canonical calls (cnc-rs274) or its setpoints
(cnc-plan on the machine file) changed.

  digests.py --build BUILD [--machine M] [--out FILE] [--generate N] [--jobs J]
  digests.py --compare A B
"""
import argparse
import concurrent.futures
import glob
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)


def sha(data):
    # Messages name files by absolute path: the same program in another checkout is the same.
    return hashlib.sha256(data.replace(ROOT.encode(), b'$SRC')).hexdigest()[:16]


def programs(generate, work):
    found = []
    for pattern in ('config/programs/*.ngc', 'tests/golden/programs/**/*.ngc', 'tests/unit/rs274_comp/*.ngc'):
        found += sorted(glob.glob(os.path.join(ROOT, pattern), recursive=True))
    found += sorted(p for p in glob.glob('/usr/share/linuxcnc/ncfiles/**/*.ngc', recursive=True)
                    if '/subs/' not in p)
    if generate:
        import gen_programs
        # A fixed folder: refusals name the file, and the digests must not depend on a temporary name.
        found += sorted(gen_programs.generate(os.path.join(tempfile.gettempdir(), 'cnc-digests-gen'), generate, 1))
    return found


def label(p):
    return os.path.relpath(p, ROOT) if p.startswith(ROOT) else p


def run(argv, timeout):
    try:
        r = subprocess.run(argv, capture_output=True, timeout=timeout)
        return r.returncode, r.stdout, r.stderr
    except subprocess.TimeoutExpired:
        return 'timeout', b'', b''


def digest_one(build, machine, prog, work, timeout):
    name = label(prog)
    d = tempfile.mkdtemp(dir=work)
    sub = ':'.join(x for x in (os.path.dirname(prog), os.path.join(os.path.dirname(prog), 'subs')) if os.path.isdir(x))
    fx = os.path.join(HERE, 'fixture')
    var = os.path.join(d, 'mill.var')
    shutil.copyfile(os.path.join(fx, 'mill.var'), var)
    ini = os.path.join(d, 'mill.ini')
    with open(os.path.join(fx, 'mill.ini')) as f, open(ini, 'w') as g:
        g.write(re.sub(r'(?m)^SUBROUTINE_PATH\s*=.*$', 'SUBROUTINE_PATH = ' + sub, f.read()))
    canon_out = os.path.join(d, 'canon.txt')
    rc, out, err = run([os.path.join(build, 'tools/rs274/cnc-rs274'), '-i', ini, '-t', os.path.join(fx, 'mill.tbl'),
                        '-v', var, prog, canon_out], timeout)
    canon = open(canon_out, 'rb').read() if os.path.exists(canon_out) else b''
    line_canon = f'{sha(canon + out + err)} rc={rc} canon {name}'
    csv = os.path.join(d, 'plan.csv')
    argv = [os.path.join(build, 'tools/cnc-plan'), '--machine', machine, '--program', prog, '--csv', csv]
    if sub:
        argv += ['--subroutine-path', sub]
    rc, out, err = run(argv, timeout)
    data = open(csv, 'rb').read() if os.path.exists(csv) else b''
    out = re.sub(rb', [0-9.]+ setpoints/s computed', b'', out)  # the wall clock's, not the plan's
    line_plan = f'{sha(data + out + err)} rc={rc} plan {name}'
    shutil.rmtree(d, ignore_errors=True)
    return [line_canon, line_plan]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--build')
    ap.add_argument('--machine', default=os.path.join(ROOT, 'config/machines/sim3.yaml'))
    ap.add_argument('--out')
    ap.add_argument('--generate', type=int, default=200)
    ap.add_argument('--jobs', type=int, default=2)
    ap.add_argument('--timeout', type=float, default=300)
    ap.add_argument('--compare', nargs=2)
    a = ap.parse_args()
    if a.compare:
        old = dict(reversed(l.rstrip('\n').split(' ', 1)) for l in open(a.compare[0]))
        new = dict(reversed(l.rstrip('\n').split(' ', 1)) for l in open(a.compare[1]))
        differ = [k for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]
        for k in differ:
            print(f'differs: {k}: {old.get(k)} -> {new.get(k)}')
        print(f'{len(set(old) & set(new))} digests compared, {len(differ)} differ')
        return 1 if differ else 0
    if not a.build:
        ap.error('--build or --compare')
    work = tempfile.mkdtemp(prefix='cnc-digests.')
    try:
        progs = programs(a.generate, work)
        with concurrent.futures.ThreadPoolExecutor(a.jobs) as ex:
            lines = [l for ls in ex.map(lambda p: digest_one(a.build, a.machine, p, work, a.timeout), progs) for l in ls]
    finally:
        shutil.rmtree(work, ignore_errors=True)
    text = ''.join(l + '\n' for l in lines)
    if a.out:
        open(a.out, 'w').write(text)
    else:
        sys.stdout.write(text)
    print(f'{len(progs)} programs, {len(lines)} digests', file=sys.stderr)


if __name__ == '__main__':
    main()
