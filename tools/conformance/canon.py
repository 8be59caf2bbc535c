"""Canonical-call text of rs274 -g (see CANON_FORMAT.md): parser, call-by-call
comparison and tool paths in machine coordinates (mm).

Only the Python standard library is used.
"""
import math
import re
from dataclasses import dataclass, field

# "%5d " counter, then the N-field ("N..... " or "N<digits>" padded to 7 chars,
# no pad with 6+ digits), then NAME(ARGS).
_LINE = re.compile(r'^\s*(\d+) (N\.\.\.\.\. |N\d* *|)([A-Za-z_][A-Za-z0-9_.]*)\((.*)\)\s*$')
_NUM = re.compile(r'^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$')


@dataclass
class Call:
    index: int            # the printed counter (1-based)
    nlabel: str           # "" or the N word digits as printed ("0090")
    name: str
    nums: list            # numeric arguments, in order
    texts: list           # non-numeric arguments (quoted strings without quotes, enum words)
    skeleton: str         # argument text with every number replaced by '#': the exact format
    raw: str              # the whole line as printed
    lineno: int           # line of the output file (1-based)

    def where(self):
        return f"N{self.nlabel}" if self.nlabel else "N....."


def _split_args(argtext):
    """Tokens of an argument list: quoted strings whole, else split on ',' and blanks."""
    if argtext.startswith('"') and argtext.endswith('"') and len(argtext) >= 2:
        return [('s', argtext[1:-1])]
    toks = []
    for t in re.split(r'[,\s]+', argtext.strip()):
        if t == '':
            continue
        toks.append(('n', float(t)) if _NUM.match(t) else ('s', t))
    return toks


def parse_line(line, lineno=0):
    m = _LINE.match(line.rstrip('\n'))
    if not m:
        return None
    counter, nfield, name, args = m.groups()
    nlabel = nfield.strip()[1:] if nfield.startswith('N') and not nfield.startswith('N.....') else ''
    nums, texts = [], []
    if args.startswith('"') and args.endswith('"'):
        texts.append(args[1:-1])
        skeleton = '"' + '$' + '"'
    else:
        for kind, v in _split_args(args):
            (nums if kind == 'n' else texts).append(v)
        skeleton = re.sub(r'[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?', '#', args)
    return Call(int(counter), nlabel, name, nums, texts, skeleton, line.rstrip('\n'), lineno)


def parse_text(text):
    """Calls of an output text; lines that are not calls are returned apart."""
    calls, junk = [], []
    for i, line in enumerate(text.splitlines(), 1):
        c = parse_line(line, i)
        if c is None:
            if line.strip():
                junk.append((i, line))
        else:
            calls.append(c)
    return calls, junk


def parse_file(path):
    try:
        with open(path, encoding='utf-8', errors='replace') as f:
            return parse_text(f.read())
    except FileNotFoundError:
        return [], []


# ---------------------------------------------------------------- comparison

@dataclass
class CanonResult:
    compared: int = 0                 # calls compared (pairs)
    max_diff: float = 0.0             # largest |a-b| over all numeric args of matched calls
    max_diff_at: tuple = None         # (call A, call B, arg index)
    first_diff: str = None            # human-readable first difference, None if equal
    first_diff_calls: tuple = None    # (call A or None, call B or None)
    count_a: int = 0
    count_b: int = 0
    identical_text: bool = False


def compare_calls(a, b, tol):
    """Call-by-call comparison of two call lists. Numbers equal within tol;
    names, text arguments, the argument format (skeleton) and the N-field must
    be identical. Stops describing at the first difference but keeps
    measuring numeric differences while the call names still line up."""
    r = CanonResult(count_a=len(a), count_b=len(b))
    r.identical_text = [c.raw for c in a] == [c.raw for c in b]
    n = min(len(a), len(b))
    for i in range(n):
        ca, cb = a[i], b[i]
        r.compared += 1
        problem = None
        if ca.name != cb.name:
            problem = f"call name differs"
        elif ca.skeleton != cb.skeleton or len(ca.nums) != len(cb.nums):
            problem = "argument format differs"
        elif ca.texts != cb.texts:
            problem = "text argument differs"
        elif ca.nlabel != cb.nlabel:
            problem = "N-field differs"
        else:
            for k, (x, y) in enumerate(zip(ca.nums, cb.nums)):
                d = abs(x - y)
                if d > r.max_diff:
                    r.max_diff, r.max_diff_at = d, (ca, cb, k)
                if d > tol and problem is None:
                    problem = f"argument {k + 1} differs by {d:.6g} (> {tol:g})"
        if problem and r.first_diff is None:
            r.first_diff = f"call {i + 1}: {problem}"
            r.first_diff_calls = (ca, cb)
        if ca.name != cb.name:
            # sequences are out of step: numbers further on mean nothing
            r.max_diff = math.inf
            break
    if r.first_diff is None and len(a) != len(b):
        i = n
        r.first_diff = f"call {i + 1}: one side has {len(a)} calls, the other {len(b)}"
        r.first_diff_calls = (a[i] if i < len(a) else None, b[i] if i < len(b) else None)
        r.max_diff = math.inf
    return r


# ---------------------------------------------------------------- tool paths

MOTION = {'STRAIGHT_TRAVERSE', 'STRAIGHT_FEED', 'STRAIGHT_PROBE', 'ARC_FEED', 'RIGID_TAP', 'NURBS_FEED'}


@dataclass
class Path:
    """Polylines in machine coordinates (mm). A new polyline starts wherever the
    position becomes unknown (after NURBS_FEED: rs274 does not print its
    geometry)."""
    polylines: list = field(default_factory=list)
    unknown_moves: int = 0     # NURBS_FEED calls (geometry not in the text)
    moves: int = 0

    def segments(self):
        for pl in self.polylines:
            if len(pl) == 1:
                yield pl[0], pl[0]      # an isolated point (e.g. the end of a move after a NURBS)
            for i in range(len(pl) - 1):
                yield pl[i], pl[i + 1]

    def points(self):
        for pl in self.polylines:
            yield from pl


def _rot(x, y, deg):
    if deg == 0.0:
        return x, y
    t = math.radians(deg)
    c, s = math.cos(t), math.sin(t)
    return x * c - y * s, x * s + y * c


def build_path(calls, chord_tol=1e-3):
    """Replay the calls like LinuxCNC's canon: machine = rotate(p + g92) + g5x + tool,
    all lengths scaled by the current units. Arcs (and helices) are sampled with
    a chord error <= chord_tol mm."""
    unit = 1.0
    g5x = [0.0, 0.0, 0.0]
    g92 = [0.0, 0.0, 0.0]
    tool = [0.0, 0.0, 0.0]
    rot = 0.0
    plane = 'XY'
    path = Path()
    cur = None          # machine position (mm), None = unknown
    line = None

    def to_machine(p):   # p: program frame, mm
        x, y = _rot(p[0] + g92[0], p[1] + g92[1], rot)
        return (x + g5x[0] + tool[0], y + g5x[1] + tool[1], p[2] + g92[2] + g5x[2] + tool[2])

    def to_program(m):   # inverse of to_machine
        x, y = _rot(m[0] - g5x[0] - tool[0], m[1] - g5x[1] - tool[1], -rot)
        return (x - g92[0], y - g92[1], m[2] - g5x[2] - tool[2] - g92[2])

    def go(m):
        nonlocal cur, line
        if cur is None or line is None:
            line = [m]
            path.polylines.append(line)
        else:
            line.append(m)
        cur = m

    for c in calls:
        n, v = c.name, c.nums
        if n == 'USE_LENGTH_UNITS':
            unit = 25.4 if c.texts and c.texts[0] == 'CANON_UNITS_INCHES' else 1.0
        elif n == 'SET_G5X_OFFSET' and len(v) >= 4:
            g5x = [v[1] * unit, v[2] * unit, v[3] * unit]
        elif n == 'SET_G92_OFFSET' and len(v) >= 3:
            g92 = [v[0] * unit, v[1] * unit, v[2] * unit]
        elif n == 'SET_XY_ROTATION' and v:
            rot = v[0]
        elif n == 'USE_TOOL_LENGTH_OFFSET' and len(v) >= 3:
            tool = [v[0] * unit, v[1] * unit, v[2] * unit]
        elif n == 'SELECT_PLANE' and c.texts:
            plane = c.texts[0].replace('CANON_PLANE_', '')
        elif n in ('STRAIGHT_TRAVERSE', 'STRAIGHT_FEED', 'STRAIGHT_PROBE') and len(v) >= 3:
            path.moves += 1
            go(to_machine((v[0] * unit, v[1] * unit, v[2] * unit)))
        elif n == 'RIGID_TAP' and len(v) >= 3:
            path.moves += 1
            start = cur
            go(to_machine((v[0] * unit, v[1] * unit, v[2] * unit)))
            if start is not None:
                go(start)
        elif n == 'NURBS_FEED':
            path.moves += 1
            path.unknown_moves += 1
            cur, line = None, None
        elif n == 'ARC_FEED' and len(v) >= 6:
            path.moves += 1
            fe, se, fc, sc, turns, ae = (x * unit for x in v[:6])
            turns = int(round(v[4]))
            # (first, second, axis) index order in (x, y, z)
            idx = {'XY': (0, 1, 2), 'YZ': (1, 2, 0), 'XZ': (2, 0, 1)}.get(plane, (0, 1, 2))
            endp = [0.0, 0.0, 0.0]
            endp[idx[0]], endp[idx[1]], endp[idx[2]] = fe, se, ae
            if cur is None:
                go(to_machine(tuple(endp)))
                continue
            sp = to_program(cur)
            s1, s2, s3 = sp[idx[0]], sp[idx[1]], sp[idx[2]]
            a0 = math.atan2(s2 - sc, s1 - fc)
            a1 = math.atan2(se - sc, fe - fc)
            r0 = math.hypot(s1 - fc, s2 - sc)
            r1 = math.hypot(fe - fc, se - sc)
            if turns > 0:
                sweep = a1 - a0
                while sweep <= 1e-12:
                    sweep += 2 * math.pi
                sweep += 2 * math.pi * (turns - 1)
            elif turns < 0:
                sweep = a1 - a0
                while sweep >= -1e-12:
                    sweep -= 2 * math.pi
                sweep -= 2 * math.pi * (-turns - 1)
            else:
                sweep = 0.0
            rmax = max(r0, r1, 1e-9)
            dth = 2 * math.acos(max(-1.0, min(1.0, 1 - chord_tol / rmax))) if chord_tol < rmax else math.pi / 2
            steps = max(1, min(20000, int(math.ceil(abs(sweep) / max(dth, 1e-6)))))
            for k in range(1, steps + 1):
                t = k / steps
                ang = a0 + sweep * t
                rr = r0 + (r1 - r0) * t
                q = [0.0, 0.0, 0.0]
                q[idx[0]] = fc + rr * math.cos(ang)
                q[idx[1]] = sc + rr * math.sin(ang)
                q[idx[2]] = s3 + (ae - s3) * t
                if k == steps:
                    q = endp
                go(to_machine(tuple(q)))
    return path


# ------------------------------------------------- distance between two paths

def _seg_dist(p, a, b):
    ax, ay, az = a
    dx, dy, dz = b[0] - ax, b[1] - ay, b[2] - az
    px, py, pz = p[0] - ax, p[1] - ay, p[2] - az
    L2 = dx * dx + dy * dy + dz * dz
    t = 0.0 if L2 == 0.0 else max(0.0, min(1.0, (px * dx + py * dy + pz * dz) / L2))
    ex, ey, ez = px - t * dx, py - t * dy, pz - t * dz
    return math.sqrt(ex * ex + ey * ey + ez * ez)


class _Grid:
    """Segments bucketed in a 3-D grid: each segment is registered in the cells
    of points sampled along it every half cell, so every point of a segment is
    within a quarter cell of a registered sample."""

    def __init__(self, segs):
        self.segs = segs
        self.cells = {}
        if not segs:
            self.cell, self.maxring = 1.0, 0
            return
        lo = [min(min(a[k], b[k]) for a, b in segs) for k in range(3)]
        hi = [max(max(a[k], b[k]) for a, b in segs) for k in range(3)]
        span = max(max(h - l for h, l in zip(hi, lo)), 1e-3)
        lens = sorted(math.dist(a, b) for a, b in segs)
        typical = lens[len(lens) // 2]
        self.cell = c = min(max(2 * typical, span / 512.0, 1e-3), max(span / 8.0, 1e-3))
        cells = self.cells
        for i, (a, b) in enumerate(segs):
            n = int(math.dist(a, b) / (c / 2)) + 1
            last = None
            for k in range(n + 1):
                t = k / n
                key = (int(math.floor((a[0] + (b[0] - a[0]) * t) / c)),
                       int(math.floor((a[1] + (b[1] - a[1]) * t) / c)),
                       int(math.floor((a[2] + (b[2] - a[2]) * t) / c)))
                if key != last:
                    lst = cells.setdefault(key, [])
                    if not lst or lst[-1] != i:
                        lst.append(i)
                    last = key
        self.maxring = int(math.ceil(span / c)) + 2

    def dist(self, p):
        """(distance, segment index) from p to the union of segments (ring search)."""
        if not self.segs:
            return math.inf, -1
        c = self.cell
        ci, cj, ck = (int(math.floor(p[0] / c)), int(math.floor(p[1] / c)), int(math.floor(p[2] / c)))
        best, besti = math.inf, -1
        seen = set()
        segs, cells = self.segs, self.cells
        for ring in range(0, self.maxring + 1):
            for i in range(ci - ring, ci + ring + 1):
                ei = abs(i - ci) == ring
                for j in range(cj - ring, cj + ring + 1):
                    ej = ei or abs(j - cj) == ring
                    ks = range(ck - ring, ck + ring + 1) if ej else ((ck - ring, ck + ring) if ring else (ck,))
                    for k in ks:
                        lst = cells.get((i, j, k))
                        if not lst:
                            continue
                        for s in lst:
                            if s in seen:
                                continue
                            seen.add(s)
                            d = _seg_dist(p, *segs[s])
                            if d < best:
                                best, besti = d, s
            # any segment not seen yet has all its samples outside this cube
            if best + c / 4 <= ring * c:
                break
        if besti < 0:  # far away from everything: brute force
            for s, sg in enumerate(segs):
                d = _seg_dist(p, *sg)
                if d < best:
                    best, besti = d, s
        return best, besti


def directed_hausdorff(A, B, eps=1e-4, max_depth=30):
    """sup over the segments of A of the distance to the polyline set B, to
    within eps. Uses convexity: on a piece [p, q] of a segment of A the
    distance to one segment b is convex, so max(d_b(p), d_b(q)) bounds the
    distance to B from above on the whole piece (b = the segment nearest to p
    or to q); pieces are halved until that bound meets the exact distance at
    their ends (or is below the largest distance found so far)."""
    segsB = list(dict.fromkeys(B.segments()))   # repeated moves (probing) once
    if not any(True for _ in A.points()):
        return 0.0
    if not segsB:
        bp = list(B.points())
        if not bp:
            return math.inf
        return max(min(math.dist(p, q) for q in bp) for p in A.points())
    exact = set()
    for a, b in segsB:
        exact.add((a, b))
        exact.add((b, a))
    grid = _Grid(segsB)
    best = 0.0
    cache = {}

    def d(p):
        r = cache.get(p)
        if r is None:
            r = cache[p] = grid.dist(p)
        return r

    stack = []
    for pl in A.polylines:
        if len(pl) == 1:
            best = max(best, d(pl[0])[0])
        for i in range(len(pl) - 1):
            if (pl[i], pl[i + 1]) in exact:
                continue          # the same segment is in B: distance 0 all along
            stack.append((pl[i], pl[i + 1], 0))
    while stack:
        p, q, depth = stack.pop()
        (dp, ip), (dq, iq) = d(p), d(q)
        lo = max(dp, dq)
        if lo > best:
            best = lo
        L = math.dist(p, q)
        if L <= eps:
            continue
        ub = math.inf
        for s in (ip, iq):
            a, b = segsB[s]
            ub = min(ub, max(_seg_dist(p, a, b), _seg_dist(q, a, b)))
        if ub <= best + eps:
            continue
        if depth >= max_depth:
            best = max(best, min(ub, lo + L / 2))
            continue
        m = ((p[0] + q[0]) / 2, (p[1] + q[1]) / 2, (p[2] + q[2]) / 2)
        stack.append((p, m, depth + 1))
        stack.append((m, q, depth + 1))
    return best


def path_distance(A, B, eps=1e-4):
    """Symmetric Hausdorff distance between two tool paths (mm)."""
    return max(directed_hausdorff(A, B, eps), directed_hausdorff(B, A, eps))
