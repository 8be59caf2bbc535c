#!/usr/bin/env python3
"""Conformance of the project's RS274NGC interpreter (cnc-rs274) with LinuxCNC's
rs274: both run the same programs with the same fixture (INI, tool table, a
fresh copy of the var file, their own HOME); their canonical calls are compared
call by call and their tool paths (machine coordinates, mm) by Hausdorff
distance. See README.md for the figures and CANON_FORMAT.md for the format.

Exit status: 0 pass, 1 fail (see --help for the criterion), 2 usage / setup
error, 77 skip (--skip-if-missing and the interpreter under test is absent).
"""
import argparse
import hashlib
import concurrent.futures as cf
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import canon            # noqa: E402
import gen_programs     # noqa: E402

RS274_ARGS = "-g -i {ini} -t {tbl} -v {var} {file} {out}"
OURS_ARGS = "--spindle-sync --probe -i {ini} -t {tbl} -v {var} {file} {out}"
HARDWARE = re.compile(r'(?i)\bG\s*38\s*\.\s*[2-5]|\bM\s*66\b|#\s*5070\b|#\s*5399\b')


def args_for(exe, template):
    if template:
        return template
    return RS274_ARGS if os.path.basename(exe) == 'rs274' else OURS_ARGS


def make_ini(fixture, subpath, dest):
    with open(os.path.join(fixture, 'mill.ini')) as f:
        text = f.read()
    text = re.sub(r'(?m)^SUBROUTINE_PATH\s*=.*$', f'SUBROUTINE_PATH = {subpath}', text)
    with open(dest, 'w') as f:
        f.write(text)


def run_one(exe, template, prog, fixture, ini, subpath, workdir, timeout):
    """Run one interpreter on one program. Returns dict(accepted, status, out, err, secs)."""
    os.makedirs(workdir, exist_ok=True)
    var = os.path.join(workdir, 'run.var')
    shutil.copyfile(os.path.join(fixture, 'mill.var'), var)
    out = os.path.join(workdir, 'canon.txt')
    if os.path.exists(out):
        os.remove(out)
    home = os.path.join(workdir, 'home')
    os.makedirs(home, exist_ok=True)
    argv = [exe] + [a.format(ini=ini, tbl=os.path.join(fixture, 'mill.tbl'), var=var, file=prog,
                             out=out, subpath=subpath) for a in template.split()]
    env = dict(os.environ, HOME=home)
    t0 = time.time()
    try:
        p = subprocess.run(argv, cwd=os.path.dirname(prog) or '.', env=env, stdin=subprocess.DEVNULL,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, timeout=timeout)
        status = p.returncode
        err = p.stderr.decode('utf-8', 'replace')
    except subprocess.TimeoutExpired:
        status, err = 'timeout', f'timeout after {timeout} s'
    except OSError as e:
        status, err = 'exec', str(e)
    err = '\n'.join(l for l in err.splitlines() if l.strip() and l.strip() != 'executing').replace('executing', '', 1)
    return dict(accepted=(status == 0), status=status, out=out, err=err.strip(), secs=time.time() - t0)


def compare(prog, theirs, ours, canon_tol, path_tol, chord_tol, always_path):
    ca, ja = canon.parse_file(theirs['out'])
    cb, jb = canon.parse_file(ours['out'])
    r = canon.compare_calls(ca, cb, canon_tol)
    res = dict(calls_theirs=len(ca), calls_ours=len(cb), compared=r.compared,
               canon_max=r.max_diff, canon_ok=(r.first_diff is None), first_diff=None,
               path_max=None, path_ok=None, nurbs=0, junk_ours=len(jb))
    if r.first_diff:
        a, b = r.first_diff_calls
        res['first_diff'] = dict(what=r.first_diff,
                                 theirs=a.raw if a else '(no call)', ours=b.raw if b else '(no call)',
                                 where=(a or b).where())
    if r.identical_text and not always_path:
        res['path_max'], res['path_ok'] = 0.0, True
    else:
        pa, pb = canon.build_path(ca, chord_tol), canon.build_path(cb, chord_tol)
        d = canon.path_distance(pa, pb)
        res['path_max'], res['path_ok'] = d, d <= path_tol
        res['nurbs'] = pa.unknown_moves
    return res


def collect(args):
    """[(label, corpus kind, path)]"""
    progs = []
    for d in args.corpus or []:
        for root, _, files in os.walk(d):
            if os.path.basename(root) == 'subs':
                continue
            for f in sorted(files):
                if f.endswith('.ngc'):
                    progs.append(('corpus', os.path.abspath(os.path.join(root, f))))
    for f in args.program or []:
        progs.append(('corpus', os.path.abspath(f)))
    if args.samples:
        for root, _, files in os.walk(args.samples):
            for f in sorted(files):
                if f.endswith('.ngc'):
                    progs.append(('samples', os.path.abspath(os.path.join(root, f))))
    return sorted(set(progs), key=lambda x: (x[0], x[1]))


def load_expected(path):
    """Expected refusals: lines 'PROGRAM-BASENAME-OR-PATH  reason...'; '#' comments."""
    exp = {}
    if path:
        with open(path) as f:
            for line in f:
                line = line.split('#', 1)[0].strip()
                if line:
                    name, _, reason = line.partition(' ')
                    exp[name] = reason.strip() or '(no reason given)'
    return exp


def fmtd(x):
    if x is None:
        return '-'
    if x == math.inf:
        return 'inf'
    return f"{x:.2e}" if x else '0'


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--ours', required=True, help='interpreter under test (cnc-rs274)')
    ap.add_argument('--theirs', default='/usr/bin/rs274', help='the oracle (LinuxCNC rs274)')
    ap.add_argument('--ours-args', help=f'argument template for --ours (default "{OURS_ARGS}", '
                    f'or rs274\'s "{RS274_ARGS}" when --ours is named rs274)')
    ap.add_argument('--theirs-args', help='argument template for --theirs')
    ap.add_argument('--corpus', action='append', help='directory of .ngc programs (recursive; subs/ dirs are '
                    'subroutine libraries on the path); the project\'s own corpus')
    ap.add_argument('--program', action='append', help='single program (project corpus)')
    ap.add_argument('--generate', type=int, default=0, help='generate N random programs (kept: those rs274 accepts)')
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--samples', help='LinuxCNC sample directory, e.g. /usr/share/linuxcnc/ncfiles')
    ap.add_argument('--fixture', default=os.path.join(HERE, 'fixture'))
    ap.add_argument('--subroutine-path', default='', help='extra subroutine dirs (colon separated)')
    ap.add_argument('--canon-tol', type=float, default=1e-4 * (1 + 1e-9),
                    help='per-number tolerance of the printed calls (rs274 prints 4 decimals: default 1e-4 + ulp)')
    ap.add_argument('--path-tol', type=float, default=0.01, help='tool-path tolerance, mm (default 0.01)')
    ap.add_argument('--chord-tol', type=float, default=1e-3, help='arc sampling chord error, mm')
    ap.add_argument('--always-path', action='store_true', help='compute the path distance even for identical text')
    ap.add_argument('--expected-refusals', help='file: programs rs274 accepts and ours may refuse, with reasons')
    ap.add_argument('--expected-differences', default=os.path.join(HERE, 'expected-differences.txt'),
                    help='file: programs whose calls/paths differ for a documented reason (expected-differences.md); '
                         'reported as expected difference, not a failure (default: %(default)s; "" for none)')
    ap.add_argument('--require-all', action='store_true',
                    help='strict: every program rs274 accepts must be accepted by ours (samples too), '
                         'ours must refuse what rs274 refuses, and refused runs must agree up to the error')
    ap.add_argument('--include-hardware', action='store_true',
                    help='count programs that need probe/input hardware (G38.x, M66) in the verdict')
    ap.add_argument('--jobs', type=int, default=2)
    ap.add_argument('--timeout', type=float, default=60)
    ap.add_argument('--work', help='keep the work directory here (default: temporary, removed)')
    ap.add_argument('--json', help='write per-program results as JSON')
    ap.add_argument('--quiet', action='store_true', help='only differences and the summary')
    ap.add_argument('--skip-if-missing', action='store_true', help='exit 77 when --ours does not exist')
    a = ap.parse_args()

    if not (os.path.isfile(a.ours) and os.access(a.ours, os.X_OK)):
        print(f"conformance: interpreter under test {a.ours} does not exist (yet)", file=sys.stderr)
        return 77 if a.skip_if_missing else 2
    if not (os.path.isfile(a.theirs) and os.access(a.theirs, os.X_OK)):
        print(f"conformance: oracle {a.theirs} missing (apt-get install linuxcnc-uspace)", file=sys.stderr)
        return 77 if a.skip_if_missing else 2
    a.ours, a.theirs = os.path.abspath(a.ours), os.path.abspath(a.theirs)
    a.fixture = os.path.abspath(a.fixture)
    tpl_ours, tpl_theirs = args_for(a.ours, a.ours_args), args_for(a.theirs, a.theirs_args)

    work = a.work or tempfile.mkdtemp(prefix='conformance-')
    os.makedirs(work, exist_ok=True)
    t_start = time.time()
    try:
        progs = collect(a)
        generated_refused = 0
        gen_dir = os.path.join(work, 'generated')
        subdirs = []
        for d in (a.corpus or []):
            for root, dirs, _ in os.walk(d):
                if os.path.basename(root) == 'subs':
                    subdirs.append(os.path.abspath(root))
        if a.generate:
            gen_programs.generate(gen_dir, a.generate, a.seed)
            subdirs.append(os.path.join(gen_dir, 'subs'))
        if a.samples:
            subdirs += [os.path.abspath(r) for r, _, _ in os.walk(a.samples)]
        subdirs += [d for d in a.subroutine_path.split(':') if d]
        subpath = ':'.join(dict.fromkeys(subdirs))
        ini = os.path.join(work, 'mill.ini')
        make_ini(a.fixture, subpath, ini)

        if a.generate:
            gen = sorted(os.path.join(gen_dir, f) for f in os.listdir(gen_dir) if f.endswith('.ngc'))
            progs += [('generated', p) for p in gen]
        expected = load_expected(a.expected_refusals)
        expected_diff = load_expected(a.expected_differences if a.expected_differences and
                                      os.path.exists(a.expected_differences) else None)

        def job(item):
            kind, prog = item
            # Short: rs274 silently truncates a long var-file path (then reads no
            # parameters at all), and a program's path can be long.
            key = (re.sub(r'[^A-Za-z0-9_.-]', '_', os.path.basename(prog))[:48] + '-' +
                   hashlib.sha1(prog.encode()).hexdigest()[:10])
            wd = os.path.join(work, 'runs', key)
            th = run_one(a.theirs, tpl_theirs, prog, a.fixture, ini, subpath, os.path.join(wd, 'theirs'), a.timeout)
            if kind == 'generated' and not th['accepted']:
                return dict(kind=kind, program=prog, dropped=True, theirs=th)
            ou = run_one(a.ours, tpl_ours, prog, a.fixture, ini, subpath, os.path.join(wd, 'ours'), a.timeout)
            res = dict(kind=kind, program=prog, dropped=False, theirs=th, ours=ou)
            with open(prog, errors='replace') as f:
                res['hardware'] = bool(HARDWARE.search(f.read()))
            if th['accepted'] or ou['accepted'] or a.require_all:
                res.update(compare(prog, th, ou, a.canon_tol, a.path_tol, a.chord_tol, a.always_path))
            return res

        results = []
        with cf.ThreadPoolExecutor(max_workers=max(1, a.jobs)) as ex:
            for res in ex.map(job, progs):
                results.append(res)

        # ---------------------------------------------------------- verdicts
        fails = []
        n_cmp_calls = 0
        canon_max = 0.0
        path_max = 0.0
        acc = dict(theirs=0, ours=0, both=0, theirs_only=0, ours_only=0, neither=0)
        path_agree = 0
        hardware = []
        kept = [r for r in results if not r['dropped']]
        generated_refused = sum(1 for r in results if r['dropped'])
        for r in kept:
            th, ou = r['theirs']['accepted'], r['ours']['accepted']
            name = os.path.relpath(r['program'], a.samples) if r['kind'] == 'samples' else r['program']
            r['name'] = name
            verdict = []
            acc['theirs'] += th
            acc['ours'] += ou
            acc['both' if th and ou else 'theirs_only' if th else 'ours_only' if ou else 'neither'] += 1
            counts = not r['hardware'] or a.include_hardware
            if r['hardware']:
                hardware.append(name)
            if 'compared' in r:
                n_cmp_calls += r['compared']
                if th and ou:
                    canon_max = max(canon_max, r['canon_max'])
                    if r['path_max'] is not None:
                        path_max = max(path_max, r['path_max'])
                    if r['path_ok']:
                        path_agree += 1
                    differs = not r['canon_ok'] or not r['path_ok']
                    excused_diff = differs and (expected_diff.get(name) or
                                                expected_diff.get(os.path.basename(r['program'])))
                    if excused_diff:
                        r['excused_diff'] = excused_diff
                    elif counts and not r['canon_ok']:
                        verdict.append('canonical calls differ')
                    if counts and not r['path_ok'] and not excused_diff:
                        verdict.append(f"tool paths differ by {fmtd(r['path_max'])} mm")
                elif a.require_all and not th and not ou and not r['canon_ok']:
                    verdict.append('calls before the error differ')
            if th and not ou:
                base = os.path.basename(r['program'])
                excused = expected.get(name) or expected.get(base)
                if excused:
                    r['excused'] = excused
                elif counts and (r['kind'] != 'samples' or a.require_all):
                    verdict.append('rs274 accepts, ours refuses')
            if ou and not th and a.require_all and counts:
                verdict.append('ours accepts, rs274 refuses')
            r['verdict'] = verdict
            if verdict:
                fails.append(r)

        # ---------------------------------------------------------- report
        def yn(x):
            return 'yes' if x else 'no '
        print(f"{'program':58s} rs274 ours  calls  canon-max  path-max(mm)")
        for r in kept:
            th, ou = r['theirs'], r['ours']
            line = (f"{r['name'][-58:]:58s} {yn(th['accepted'])}   {yn(ou['accepted'])}  "
                    f"{r.get('compared', 0):5d}  {fmtd(r.get('canon_max')) if th['accepted'] and ou['accepted'] else '-':>9s}  "
                    f"{fmtd(r.get('path_max')) if th['accepted'] and ou['accepted'] else '-':>9s}")
            tags = []
            if r['hardware']:
                tags.append('needs-hardware')
            if r.get('nurbs'):
                tags.append(f"{r['nurbs']} NURBS (geometry not printed)")
            if r.get('excused'):
                tags.append(f"expected refusal: {r['excused']}")
            if r.get('excused_diff'):
                tags.append(f"expected difference: {r['excused_diff']}")
            if r['verdict']:
                tags.append('FAIL: ' + '; '.join(r['verdict']))
            if tags:
                line += '  [' + ', '.join(tags) + ']'
            if not a.quiet or r['verdict']:
                print(line)
            if r['verdict'] or (not a.quiet and th['accepted'] != ou['accepted']):
                if not th['accepted']:
                    print(f"    rs274 refuses: {th['err'][:300]}")
                if not ou['accepted']:
                    print(f"    ours refuses (status {ou['status']}): {ou['err'][:300]}")
            if r['verdict'] and r.get('first_diff'):
                fd = r['first_diff']
                print(f"    first difference at {fd['what']} ({fd['where']}):")
                print(f"      rs274: {fd['theirs']}")
                print(f"      ours : {fd['ours']}")
        if hardware:
            print(f"needs probe/input hardware (G38.x, M66; rs274 simulates them; "
                  f"{'counted' if a.include_hardware else 'not counted in the verdict'}): {len(hardware)}")
            for h in hardware:
                print(f"    {h}")
        secs = time.time() - t_start
        print(f"SUMMARY programs={len(kept)} generated_refused_by_rs274={generated_refused} "
              f"calls_compared={n_cmp_calls} canon_max_diff={fmtd(canon_max)} path_max_diff_mm={fmtd(path_max)} "
              f"rs274_accepts={acc['theirs']} ours_accepts={acc['ours']} both={acc['both']} "
              f"rs274_only={acc['theirs_only']} ours_only={acc['ours_only']} neither={acc['neither']} "
              f"path_agree={path_agree}/{acc['both']} "
              f"expected_differences={sum(1 for r in kept if r.get('excused_diff'))} "
              f"needs_hardware={len(hardware)} "
              f"failures={len(fails)} seconds={secs:.1f}")
        if a.json:
            with open(a.json, 'w') as f:
                json.dump(results, f, indent=1, default=str)
        return 1 if fails else 0
    finally:
        if not a.work:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == '__main__':
    sys.exit(main())
