#!/usr/bin/env python3
"""Random RS274NGC programs for the conformance harness (fixed seed).

Every program exercises a random mix of: numbered / named local / named global
parameters, expressions with every operator and function, subroutines with
arguments and return values (in the file and in an external file found on the
subroutine path), while / do-while / repeat / if-elseif-else / break /
continue, G54-G59.3 with G10 L2 (incl. rotation) / G10 L20, G92 / G92.1-3,
G90/G91, G20/G21, arcs in G17/G18/G19 (I J K and R, helices, P turns),
G0/G1, G4, T M6, G43 H / G49, M3/M4/M5 S, M7/M8/M9, cutter compensation
(G41/G42 on closed contours with a valid entry and exit), canned cycles
G73 G81-G89 with G98/G99 and L, G80.

Each line carries N<source line> so that rs274's N-field names the source line.
Whether rs274 accepts a program is decided by running it (conformance.py
drops and counts the refused ones); the generator keeps them rare by
construction: expressions are domain-safe, arcs start from a known point.
"""
import argparse
import math
import os
import random
import re

OPS_ARITH = ['+', '-', '*', '/', 'MOD', '**']
OPS_CMP = ['EQ', 'NE', 'GT', 'GE', 'LT', 'LE']
OPS_LOGIC = ['AND', 'OR', 'XOR']
PREC = {'**': 6, '*': 5, '/': 5, 'MOD': 5, '+': 4, '-': 4,
        'EQ': 3, 'NE': 3, 'GT': 3, 'GE': 3, 'LT': 3, 'LE': 3, 'AND': 2, 'OR': 2, 'XOR': 2}


# LinuxCNC version difference (expected-differences.md, "TOLERANCE_EQUAL"): EQ/NE
# treat values closer than TOLERANCE_EQUAL as equal, 1e-4 in the rs274 oracle
# (2.9.0~pre1), 1e-6 since 2.9.0 (commit 014777a816, which also made LE/GE
# fuzzy), as cnc-rs274. Comparisons of values closer than this are not
# generated with EQ/NE/LE/GE (GT/LT are exact in both).
NEAR_TIE = 2e-4


def fmt(v):
    s = f"{v:.4f}".rstrip('0').rstrip('.')
    return '0' if s in ('-0', '') else s


class Expr:
    """Expression text plus its value as LinuxCNC computes it (degrees, MOD >= 0)."""

    def __init__(self, rng, params):
        self.rng = rng
        self.params = params      # name -> value, usable in expressions

    def leaf(self):
        r = self.rng
        if self.params and r.random() < 0.5:
            name = r.choice(sorted(self.params))
            return name, self.params[name]
        v = round(r.uniform(-20, 20), r.choice([0, 1, 2, 3]))
        return fmt(v), float(fmt(v))

    def safe(self, depth):
        """A bracketed expression [..] with its value; never a domain error."""
        r = self.rng
        if depth <= 0 or r.random() < 0.3:
            t, v = self.leaf()
            return t, v
        k = r.random()
        if k < 0.45:
            a, va = self.safe(depth - 1)
            b, vb = self.safe(depth - 1)
            op = r.choice(OPS_ARITH)
            if op == '/':
                b, vb = f"[ABS[{b}] + 0.5]", abs(vb) + 0.5
                return f"[{a} / {b}]", va / vb
            if op == 'MOD':
                b, vb = f"[ABS[{b}] + 1]", abs(vb) + 1
                m = math.fmod(va, vb)
                if m < 0:
                    m += abs(vb)
                return f"[{a} MOD {b}]", m
            if op == '**':
                m = math.fmod(abs(va), 3.0) + 0.5
                e = r.choice([0, 1, 2, 3, 0.5])
                return f"[[ABS[{a}] MOD 3 + 0.5] ** {fmt(e)}]", m ** e
            vv = {'+': va + vb, '-': va - vb, '*': va * vb}[op]
            if abs(vv) > 1e6:
                return f"[{a} - {b}]", va - vb
            return f"[{a} {op} {b}]", vv
        if k < 0.55:
            a, va = self.safe(depth - 1)
            b, vb = self.safe(depth - 1)
            op = r.choice(OPS_CMP)
            if op in ('EQ', 'NE', 'LE', 'GE') and 0 < abs(va - vb) < NEAR_TIE:
                op = 'GT' if op in ('NE', 'GE') else 'LT'
            vv = {'EQ': va == vb, 'NE': va != vb, 'GT': va > vb, 'GE': va >= vb,
                  'LT': va < vb, 'LE': va <= vb}[op]
            return f"[{a} {op} {b}]", 1.0 if vv else 0.0
        if k < 0.62:
            a, va = self.safe(depth - 1)
            b, vb = self.safe(depth - 1)
            op = r.choice(OPS_LOGIC)
            x, y = va != 0.0, vb != 0.0
            vv = {'AND': x and y, 'OR': x or y, 'XOR': x != y}[op]
            return f"[{a} {op} {b}]", 1.0 if vv else 0.0
        a, va = self.safe(depth - 1)
        f = r.choice(['ABS', 'ACOS', 'ASIN', 'COS', 'SIN', 'TAN', 'EXP', 'FIX', 'FUP', 'ROUND',
                      'LN', 'SQRT', 'ATAN', 'POW'])
        if f == 'ABS':
            return f"ABS[{a}]", abs(va)
        if f in ('ACOS', 'ASIN'):
            inner = f"[[{a} MOD 2] - 1]"
            m = math.fmod(va, 2.0)
            if m < 0:
                m += 2.0
            x = m - 1
            return f"{f}[{inner}]", math.degrees(math.acos(x) if f == 'ACOS' else math.asin(x))
        if f in ('COS', 'SIN'):
            return f"{f}[{a}]", (math.cos if f == 'COS' else math.sin)(math.radians(va))
        if f == 'TAN':
            inner = f"[{a} MOD 80]"
            m = math.fmod(va, 80.0)
            if m < 0:
                m += 80.0
            return f"TAN[{inner}]", math.tan(math.radians(m))
        if f == 'EXP':
            inner = f"[{a} MOD 5]"
            m = math.fmod(va, 5.0)
            if m < 0:
                m += 5.0
            return f"EXP[{inner}]", math.exp(m)
        if f == 'FIX':
            return f"FIX[{a}]", float(math.floor(va))
        if f == 'FUP':
            return f"FUP[{a}]", float(math.ceil(va))
        if f == 'ROUND':
            return f"ROUND[{a}]", float(int(va + (0.5 if va >= 0 else -0.5)))
        if f == 'LN':
            return f"LN[ABS[{a}] + 1]", math.log(abs(va) + 1)
        if f == 'SQRT':
            return f"SQRT[ABS[{a}]]", math.sqrt(abs(va))
        if f == 'ATAN':
            b, vb = self.safe(depth - 1)
            return f"ATAN[{a}]/[{b}]", math.degrees(math.atan2(va, vb))
        # POW: positive base, small exponent
        m = math.fmod(abs(va), 3.0) + 0.5
        e = r.choice([0, 1, 2, 3, 0.5])
        return f"[[ABS[{a}] MOD 3 + 0.5] ** {fmt(e)}]", m ** e

    def gen(self, depth=3):
        while True:
            t, v = self.safe(depth)
            if t is not None and v is not None and math.isfinite(v) and abs(v) < 1e6:
                return t, v

    def unbracketed_chain(self):
        """a op b op c ... without inner brackets: tests operator precedence."""
        r = self.rng
        n = r.randint(2, 4)
        terms = [self.leaf() for _ in range(n + 1)]
        ops = [r.choice(['+', '-', '*', 'MOD', 'EQ', 'GT', 'AND', 'OR', '**', '/']) for _ in range(n)]
        # make divisors / mod operands / power bases harmless: literals 1..9
        toks = [terms[0]]
        for i, op in enumerate(ops):
            if op in ('/', 'MOD', '**'):
                lit = r.randint(1, 9) if op != '**' else r.randint(1, 2)
                toks.append((str(lit), float(lit)))
                if op == '**':
                    # base must be positive: replace the previous term by a literal
                    lit2 = r.randint(1, 4)
                    toks[-2] = (str(lit2), float(lit2))
            else:
                toks.append(terms[i + 1])
        text = toks[0][0]
        for op, (t, _) in zip(ops, toks[1:]):
            text += f" {op} {t}"
        val = self._eval_chain([v for _, v in toks], ops)
        if val is None or not math.isfinite(val) or abs(val) > 1e6:
            return None, None
        return f"[{text}]", val

    @staticmethod
    def _eval_chain(vals, ops):
        # precedence climbing, left associative (as Interp::read_real_expression)
        def apply(op, a, b):
            if op == '+': return a + b
            if op == '-': return a - b
            if op == '*': return a * b
            if op == '/': return a / b
            if op == 'MOD':
                m = math.fmod(a, b)
                return m + abs(b) if m < 0 else m
            if op == '**':
                if a < 0 and b != int(b):
                    raise ValueError
                return a ** b
            if op == 'EQ':
                if 0 < abs(a - b) < NEAR_TIE:
                    raise ValueError(op)
                return 1.0 if a == b else 0.0
            if op == 'GT': return 1.0 if a > b else 0.0
            if op == 'AND': return 1.0 if (a != 0 and b != 0) else 0.0
            if op == 'OR': return 1.0 if (a != 0 or b != 0) else 0.0
            raise ValueError(op)
        vs, os_ = [vals[0]], []
        try:
            for op, v in zip(ops, vals[1:]):
                while os_ and PREC[os_[-1]] >= PREC[op]:
                    b = vs.pop(); a = vs.pop(); vs.append(apply(os_.pop(), a, b))
                os_.append(op)
                vs.append(v)
            while os_:
                b = vs.pop(); a = vs.pop(); vs.append(apply(os_.pop(), a, b))
        except (ValueError, ZeroDivisionError, OverflowError):
            return None
        return vs[0]


class Gen:
    def __init__(self, seed, ext_sub_name=None):
        self.r = random.Random(seed)
        self.lines = []
        self.params = {}          # parameters whose value the generator knows (main level, straight-line code)
        self.defined = {}         # parameters that certainly exist (value maybe not known)
        self.in_body = 0          # > 0 inside loops / branches: values assigned there are not known
        self.oword = 100
        self.units = 'mm'         # current units
        self.dist = 'G90'
        self.plane = 'G17'
        self.known = None         # known position (program frame, current units) or None
        self.tool = 0
        self.tlo = False          # a G43 may be active (no G49 since)
        self.sync_needed = False  # offsets changed since the last sync move (see sync_before_m6)
        self.cs = 1               # active coordinate system (G54 = 1)
        self.g92_on = False       # a G92 offset may be active
        self.spindle = False
        self.comp = False
        self.ext_sub = ext_sub_name
        self.subs = []            # (name, nargs, returns)
        self.gcount = 0
        self.loop_words = set()   # (o-word, 'break' / 'continue') emitted in that loop

    # -- helpers
    def emit(self, text, numbered=True):
        n = len(self.lines) + 1
        self.lines.append(f"N{n} {text}" if numbered else text)

    def insert(self, at, texts):
        """Insert numbered lines before index at; renumber the N-fields after them."""
        self.lines[at:at] = [f"N0 {t}" for t in texts]
        for i in range(at, len(self.lines)):
            if self.lines[i].startswith('N'):
                self.lines[i] = re.sub(r'^N\d+ ', f"N{i + 1} ", self.lines[i])

    def next_o(self):
        self.oword += 1
        return self.oword

    def num(self, lo, hi, nd=3):
        return round(self.r.uniform(lo, hi), nd)

    def scale(self):
        return 1.0 if self.units == 'mm' else 1 / 25.4

    def coord(self, v, exprs=True):
        """A coordinate value, sometimes written as an expression of that value."""
        r = self.r
        if exprs and r.random() < 0.25:
            e = Expr(r, self.params)
            t, ev = e.gen(2)
            return f"[{fmt(v)} + {t} - {fmt(ev)}]" if abs(ev) < 1e5 else fmt(v)
        return fmt(v)

    def position(self, x, y, z, rapid=True):
        word = 'G0' if rapid else 'G1'
        f = '' if rapid else f" F{fmt(self.num(50, 800, 0) * self.scale())}"
        self.emit(f"G90 {word} X{self.coord(x)} Y{self.coord(y)} Z{self.coord(z)}{f}")
        self.dist = 'G90'
        self.known = (x, y, z)

    def rnd_xyz(self, span=40):
        s = self.scale()
        return (round(self.num(-span, span) * s, 4), round(self.num(-span, span) * s, 4),
                round(self.num(-5, 20) * s, 4))

    # -- blocks
    def blk_params(self):
        r = self.r
        e = Expr(r, self.defined)
        kind = r.random()
        if kind < 0.35:
            name = f"#{r.randint(1, 30)}"
        elif kind < 0.7:
            name = f"#<v{r.randint(1, 9)}>"
        else:
            name = f"#<_gv{r.randint(1, 9)}>"
        if r.random() < 0.3:
            t, v = e.unbracketed_chain()
            if t is None:
                t, v = e.gen(3)
        else:
            t, v = e.gen(3)
        self.emit(f"{name} = {t}")
        self.defined[name] = v
        if self.in_body:
            self.params.pop(name, None)
        else:
            self.params[name] = v
        if r.random() < 0.2:
            self.emit(f"(DEBUG, {name} = {name})")

    def blk_moves(self):
        r = self.r
        for _ in range(r.randint(1, 4)):
            x, y, z = self.rnd_xyz()
            if r.random() < 0.3:
                self.emit(f"G0 X{self.coord(x)} Y{self.coord(y)} Z{self.coord(z)}" if self.dist == 'G90'
                          else f"G0 X{fmt(x / 4)} Y{fmt(y / 4)}")
            else:
                f = fmt(self.num(50, 1500, 0) * self.scale())
                if self.dist == 'G90':
                    self.emit(f"G1 X{self.coord(x)} Y{self.coord(y)} Z{self.coord(z)} F{f}")
                else:
                    self.emit(f"G1 X{fmt(x / 4)} Y{fmt(y / 4)} Z{fmt(z / 8)} F{f}")
        self.known = None if self.dist == 'G91' else self.known
        if self.dist == 'G90':
            self.known = None   # last move target is in the text; keep simple

    def blk_arc(self):
        r = self.r
        plane = r.choice(['G17', 'G17', 'G18', 'G19'])
        if plane != self.plane:
            self.emit(plane)
            self.plane = plane
        # axes (first, second, helix) and their letters/centre words
        ax = {'G17': ('X', 'Y', 'Z', 'I', 'J'), 'G18': ('Z', 'X', 'Y', 'K', 'I'),
              'G19': ('Y', 'Z', 'X', 'J', 'K')}[plane]
        s = self.scale()
        start = self.rnd_xyz(30)
        self.position(*start)
        idx = {'X': 0, 'Y': 1, 'Z': 2}
        p1, p2, p3 = start[idx[ax[0]]], start[idx[ax[1]]], start[idx[ax[2]]]
        rad = round(self.num(2, 25) * s, 4)
        a0 = r.uniform(0, 2 * math.pi)
        c1, c2 = p1 - rad * math.cos(a0), p2 - rad * math.sin(a0)
        a1 = a0 + r.uniform(0.2, 6.0) * r.choice([1, -1])
        e1, e2 = c1 + rad * math.cos(a1), c2 + rad * math.sin(a1)
        full = r.random() < 0.1
        if full:
            e1, e2 = p1, p2
        g = r.choice(['G2', 'G3'])
        helix = r.random() < 0.4
        e3 = p3 + (round(self.num(-5, 5) * s, 4) if helix else 0.0)
        f = fmt(self.num(100, 1000, 0) * s)
        incremental = r.random() < 0.3
        if incremental:
            self.emit("G91")
            self.dist = 'G91'
            w1, w2, w3 = e1 - p1, e2 - p2, e3 - p3
        else:
            w1, w2, w3 = e1, e2, e3
        hel = f" {ax[2]}{fmt(w3)}" if helix else ''
        use_r = (not full) and r.random() < 0.35
        if use_r:
            # R form: sign picks the short (+) or long (-) arc; end from the chord
            chord = math.hypot(e1 - p1, e2 - p2)
            if chord < 1e-3:
                use_r = False
        if use_r:
            rr = round(rad, 4)
            # which way does g go? pick the sign that matches: let rs274 decide geometry,
            # R must be >= chord/2 (it is: the end is on the circle of radius rad)
            sign = r.choice(['', '-'])
            self.emit(f"{g} {ax[0]}{fmt(w1)} {ax[1]}{fmt(w2)}{hel} R{sign}{fmt(rr + 0.0005 * s)} F{f}")
        else:
            turns = f" P{r.randint(2, 3)}" if (full or r.random() < 0.1) and r.random() < 0.5 else ''
            self.emit(f"{g} {ax[0]}{fmt(w1)} {ax[1]}{fmt(w2)}{hel} {ax[3]}{fmt(c1 - p1)} {ax[4]}{fmt(c2 - p2)}{turns} F{f}")
        if incremental:
            self.emit("G90")
            self.dist = 'G90'
        self.known = None

    def blk_offsets(self):
        r = self.r
        k = r.random()
        s = self.scale()
        self.sync_needed = True
        if k < 0.3:
            p = r.randint(1, 9)
            rot = f" R{fmt(self.num(-30, 30, 1))}" if r.random() < 0.15 else (" R0" if r.random() < 0.2 else '')
            if p == self.cs and self.g92_on:
                # LinuxCNC bug (expected-differences.md, "G10 L2 R with G92"):
                # convert_setup re-expresses the current point with the G92
                # offset left out of the rotation; the tool's position becomes
                # wrong in the interpreter when the active system's rotation
                # changes while a G92 offset is on.
                rot = ''
            self.emit(f"G10 L2 P{p} X{fmt(self.num(-20, 20) * s)} Y{fmt(self.num(-20, 20) * s)} Z{fmt(self.num(-5, 5) * s)}{rot}")
        elif k < 0.45:
            self.emit(f"G10 L20 P{r.randint(0, 9)} X{fmt(self.num(-20, 20) * s)} Y{fmt(self.num(-20, 20) * s)}")
        elif k < 0.7:
            g = r.choice(['G54', 'G55', 'G56', 'G57', 'G58', 'G59', 'G59.1', 'G59.2', 'G59.3'])
            self.emit(g)
            self.cs = ['G54', 'G55', 'G56', 'G57', 'G58', 'G59', 'G59.1', 'G59.2', 'G59.3'].index(g) + 1
        elif k < 0.85:
            self.emit(f"G92 X{fmt(self.num(-20, 20) * s)} Y{fmt(self.num(-20, 20) * s)} Z{fmt(self.num(-5, 5) * s)}")
            self.g92_on = True
        else:
            g = r.choice(['G92.1', 'G92.2', 'G92.3'])
            self.emit(g)
            self.g92_on = g == 'G92.3'
        self.known = None

    def blk_units(self):
        u = self.r.choice(['G20', 'G21'])
        if self.tlo and (u == 'G20') != (self.units == 'inch'):
            # rs274 artifact (expected-differences.md, "units change with G43"):
            # on a change of units the interpreter re-reads the tool length
            # offset from the canon (convert_length_units); rs274's canon
            # returns it in the units it was given, unconverted, so the active
            # offset becomes 25.4 times too large or small. No offset across it.
            self.emit("G49")
            self.tlo = False
            self.sync_needed = True
        self.emit(u)
        self.units = 'inch' if u == 'G20' else 'mm'
        self.known = None

    def blk_dist(self):
        d = self.r.choice(['G90', 'G91'])
        self.emit(d)
        self.dist = d
        self.known = None

    def blk_tool(self):
        r = self.r
        k = r.random()
        if k < 0.5:
            t = r.randint(1, 20)
            self.sync_before_m6()
            self.emit(f"T{t} M6" if r.random() < 0.5 else f"T{t}")
            if not self.lines[-1].endswith('M6'):
                self.emit("M6")
            self.tool = t
            self.spindle = False
            if r.random() < 0.7:
                self.emit("G43" if r.random() < 0.5 else f"G43 H{t}")
                self.tlo = True
        elif k < 0.8:
            self.emit(f"G43 H{r.randint(0, 20)}")
            self.tlo = True
        else:
            self.emit("G49")
            self.tlo = False
        self.sync_needed = True
        self.known = None

    def sync_before_m6(self):
        """A zero move before a tool change when an offset changed since the last move.

        rs274 artifact (expected-differences.md, "tool change re-reads the
        position"): at the block after M6 the interpreter re-reads its position
        from the canon (Interp::read_inputs -> refresh_actual_position). The
        standalone rs274's canon (saicanon.cc) returns the last programmed point,
        corrected for later G5x/G92/unit changes but not for tool length offset
        (G43/G49) or XY rotation changes, so such a change between the last move
        and M6 is lost from rs274's position (real LinuxCNC's canon computes the
        position from the machine's). A zero incremental traverse puts both in
        step; the G43 after M6 always comes on a later line.
        """
        if self.sync_needed:
            self.emit("G91 G0 X0 Y0 Z0")
            if self.dist == 'G90':
                self.emit("G90")
            self.sync_needed = False

    def blk_spindle(self):
        r = self.r
        k = r.random()
        sp = fmt(self.num(100, 12000, 0))
        if k < 0.4:
            self.emit(f"S{sp} M3"); self.spindle = True
        elif k < 0.7:
            self.emit(f"M4 S{sp}"); self.spindle = True
        else:
            self.emit("M5"); self.spindle = False

    def blk_coolant(self):
        self.emit(self.r.choice(['M7', 'M8', 'M9']))

    def blk_dwell(self):
        self.emit(f"G4 P{fmt(self.num(0, 2, 2))}")

    def blk_comment(self):
        r = self.r
        k = r.random()
        w = r.choice(['rough', 'finish pass', 'probe-free', 'check', 'x y z'])
        if k < 0.5:
            self.emit(f"({w})")
        else:
            self.emit(f"(MSG, {w})")

    def blk_comp(self):
        r = self.r
        if self.plane != 'G17':
            self.emit("G17"); self.plane = 'G17'
        s = self.scale()
        t = r.randint(1, 5)                       # D 0.02..0.1 in: radius <= 1.27 mm
        if self.tool != t and r.random() < 0.5:
            self.sync_before_m6()
            self.emit(f"T{t} M6"); self.tool = t; self.spindle = False
        w, h = self.num(15, 40) * s, self.num(15, 40) * s
        x0, y0 = self.num(-30, 10) * s, self.num(-30, 10) * s
        rc = round(self.num(3, 6) * s, 4)         # corner radius > tool radius
        z = round(self.num(-3, 3) * s, 4)
        side = r.choice(['G41', 'G42'])
        f = fmt(self.num(100, 800, 0) * s)
        # start outside the lower-left corner, enter to the middle of the bottom edge
        self.position(round(x0 + w / 2, 4), round(y0 - 8 * s, 4), z)
        dword = f" D{t}" if r.random() < 0.7 or self.tool != t else ''
        if self.tool != t and not dword:
            dword = f" D{t}"
        self.emit(f"{side}{dword} G1 X{fmt(x0 + w / 2)} Y{fmt(y0)} F{f}")
        # G41: contour clockwise keeps the tool outside; G42: counterclockwise.
        cw = side == 'G41'
        rounded = r.random() < 0.6
        xs = [x0, x0 + w]
        ys = [y0, y0 + h]
        if not cw:   # counterclockwise: bottom edge to the right
            pts = [(xs[1], ys[0], (xs[1], ys[1])), (xs[1], ys[1], (xs[0], ys[1])),
                   (xs[0], ys[1], (xs[0], ys[0])), (xs[0], ys[0], (x0 + w / 2, ys[0]))]
            g = 'G3'
        else:        # clockwise: bottom edge to the left
            pts = [(xs[0], ys[0], (xs[0], ys[1])), (xs[0], ys[1], (xs[1], ys[1])),
                   (xs[1], ys[1], (xs[1], ys[0])), (xs[1], ys[0], (x0 + w / 2, ys[0]))]
            g = 'G2'
        cur = (x0 + w / 2, y0)
        for cx, cy, nxt in pts:
            if rounded and nxt != (x0 + w / 2, ys[0]):
                # stop rc before the corner, arc to rc after it
                dx, dy = cx - cur[0], cy - cur[1]
                L = math.hypot(dx, dy)
                ax_, ay_ = cx - dx / L * rc, cy - dy / L * rc
                ndx, ndy = nxt[0] - cx, nxt[1] - cy
                nL = math.hypot(ndx, ndy)
                bx, by = cx + ndx / nL * rc, cy + ndy / nL * rc
                ccx, ccy = ax_ + ndx / nL * rc, ay_ + ndy / nL * rc
                self.emit(f"G1 X{fmt(ax_)} Y{fmt(ay_)}")
                self.emit(f"{g} X{fmt(bx)} Y{fmt(by)} I{fmt(ccx - ax_)} J{fmt(ccy - ay_)}")
                cur = (bx, by)
            else:
                self.emit(f"G1 X{fmt(cx)} Y{fmt(cy)}")
                cur = (cx, cy)
        self.emit(f"G1 X{fmt(x0 + w / 2)} Y{fmt(y0)}")
        self.emit(f"G40 G1 X{fmt(x0 + w / 2)} Y{fmt(y0 - 8 * s)}")
        self.known = None

    def blk_cycle(self):
        r = self.r
        # G88 ends at the bottom after PROGRAM_STOP (the operator retracts by
        # hand) while the interpreter's point is the retract plane; the
        # position re-read after a later M6 (rs274: the last programmed point)
        # would differ: a sync move before the next tool change.
        self.sync_needed = True
        if self.plane != 'G17':
            self.emit("G17"); self.plane = 'G17'
        s = self.scale()
        cyc = r.choice(['G81', 'G82', 'G83', 'G73', 'G84', 'G85', 'G86', 'G87', 'G88', 'G89'])
        if cyc in ('G84', 'G86', 'G87', 'G88') or r.random() < 0.3:
            self.emit(f"M3 S{fmt(self.num(200, 3000, 0))}"); self.spindle = True
        x, y, _ = self.rnd_xyz(30)
        self.position(x, y, round(self.num(5, 15) * s, 4))
        rp = round(self.num(1, 4) * s, 4)
        zb = round(self.num(-8, -1) * s, 4)
        f = fmt(self.num(50, 500, 0) * s)
        retract = r.choice(['G98', 'G99'])
        extra = ''
        if cyc in ('G82', 'G89', 'G86'):
            extra += f" P{fmt(self.num(0.1, 1, 2))}"
        if cyc in ('G83', 'G73'):
            extra += f" Q{fmt(self.num(0.5, 3) * s)}"
        if cyc == 'G87':
            extra += f" I{fmt(self.num(0.5, 2) * s)} J0 K{fmt(zb + 2 * s)}"
        if cyc == 'G88':
            extra += f" P{fmt(self.num(0.1, 1, 2))}"
        inc = cyc != 'G87' and r.random() < 0.3
        if inc:
            self.emit("G91")
            lw = f" L{r.randint(2, 4)}"
            self.emit(f"{retract} {cyc} X{fmt(self.num(2, 8) * s)} Y{fmt(self.num(-5, 5) * s)} "
                      f"Z{fmt(zb - rp)} R{fmt(rp - 5 * s)}{extra} F{f}{lw}")
            self.emit("G90")
        else:
            lw = f" L{r.randint(1, 2)}" if r.random() < 0.2 else ''
            self.emit(f"{retract} {cyc} X{fmt(x)} Y{fmt(y)} Z{fmt(zb)} R{fmt(rp)}{extra} F{f}{lw}")
            for _ in range(r.randint(0, 3)):
                self.emit(f"X{fmt(x + self.num(-10, 10) * s)} Y{fmt(y + self.num(-10, 10) * s)}")
        self.emit("G80")
        self.dist = 'G90'
        self.known = None

    def blk_call(self):
        r = self.r
        if not self.subs:
            return
        name, nargs, returns = r.choice(self.subs)
        e = Expr(r, self.defined)
        args = ' '.join(f"[{e.gen(2)[0]}]" for _ in range(nargs))
        self.emit(f"o<{name}> call {args}".rstrip())
        if returns:
            self.emit(f"#<_gret> = #<_value>")
            if not self.in_body:
                self.defined['#<_gret>'] = 0.0   # value not tracked
        self.known = None

    def blk_loop(self, depth):
        r = self.r
        o = self.next_o()
        k = r.random()
        var = f"#<i{o}>"
        if k < 0.35:
            n = r.randint(1, 4)
            self.emit(f"{var} = 0")
            self.emit(f"o{o} while [{var} LT {n}]")
            self.body(depth + 1, loop=(o, var, 'while'))
            self.emit(f"{var} = [{var} + 1]")
            self.emit(f"o{o} endwhile")
            if (o, 'break') in self.loop_words:
                # LinuxCNC bug (interp_o_word.cc): 'break' sets doing_break, which
                # only the end test of a do-while clears; left set by a while
                # loop, it makes the next do-while, anywhere later, stop after
                # one pass (expected-differences.md, "stale break"). A do-while
                # that runs once anyway clears it and is a no-op for us.
                rst = self.next_o()
                self.emit(f"o{rst} do")
                self.emit(f"o{rst} while [0]")
        elif k < 0.6:
            n = r.randint(1, 4)
            self.emit(f"{var} = 0")
            self.emit(f"o{o} do")
            at = len(self.lines)
            self.emit(f"{var} = [{var} + 1]")
            self.body(depth + 1, loop=(o, var, 'do'))
            self.emit(f"o{o} while [{var} LT {n}]")
            if (o, 'continue') in self.loop_words:
                # LinuxCNC bug (interp_o_word.cc): 'continue' sets doing_continue,
                # which only an endwhile/endrepeat reached by skipping clears; left
                # set by a do-while, the next while/repeat that ends by skipping
                # loops back once more (a repeat runs its count again, a while
                # 'break' acts as 'continue') (expected-differences.md, "stale
                # continue"). A while loop whose test is false clears it and is
                # a no-op for us: one at the top of the body (the continue
                # jumps to the test and may loop back) and one after the loop.
                rst = self.next_o()
                self.insert(at, [f"o{rst} while [0]", f"o{rst} endwhile"])
                rst = self.next_o()
                self.emit(f"o{rst} while [0]")
                self.emit(f"o{rst} endwhile")
        elif k < 0.75:
            self.emit(f"o{o} repeat [{r.randint(1, 3)}]")
            self.body(depth + 1, loop=None)
            self.emit(f"o{o} endrepeat")
        else:
            e = Expr(r, self.defined)
            self.emit(f"o{o} if [{e.gen(2)[0]} GT {fmt(self.num(-5, 5))}]")
            self.body(depth + 1, loop=None)
            for _ in range(r.randint(0, 2)):
                self.emit(f"o{o} elseif [{e.gen(2)[0]} LT {fmt(self.num(-5, 5))}]")
                self.body(depth + 1, loop=None)
            if r.random() < 0.6:
                self.emit(f"o{o} else")
                self.body(depth + 1, loop=None)
            self.emit(f"o{o} endif")
        self.known = None

    def body(self, depth, loop=None):
        self.in_body += 1
        try:
            self._body(depth, loop)
        finally:
            self.in_body -= 1

    def _body(self, depth, loop=None):
        r = self.r
        for _ in range(r.randint(1, 3)):
            k = r.random()
            if loop and k < 0.15:
                o, var, kind = loop
                oi = self.next_o()
                word = r.choice(['break', 'continue'])
                self.loop_words.add((o, word))
                if word == 'continue' and var is not None and self.lines and 'while [' in ''.join(self.lines[-50:]):
                    pass
                self.emit(f"o{oi} if [{var} GE {r.randint(1, 3)}]")
                if word == 'continue':
                    # while-loops increment at the end: make sure the counter moves first
                    self.emit(f"{var} = [{var} + 1]")
                self.emit(f"o{o} {word}")
                self.emit(f"o{oi} endif")
            elif k < 0.35:
                self.blk_params()
            elif k < 0.6 or depth >= 2:
                self.emit("G91")
                self.dist = 'G91'
                self.blk_moves()
                self.emit("G90")
                self.dist = 'G90'
            elif k < 0.8:
                self.blk_call()
            else:
                self.blk_loop(depth)

    def subroutines(self):
        r = self.r
        for i in range(r.randint(0, 3)):
            name = f"s{i}"
            nargs = r.randint(0, 3)
            returns = r.random() < 0.5
            self.emit(f"o<{name}> sub")
            saved = self.params, self.defined
            self.params = {}
            self.defined = {f"#{k + 1}": 1.0 for k in range(nargs)}
            self.emit(f"#<l{i}> = {Expr(r, self.defined).gen(2)[0]}")
            self.emit("G91")
            for _ in range(r.randint(1, 3)):
                a = f"#{r.randint(1, nargs)}" if nargs else fmt(self.num(-3, 3))
                self.emit(f"G1 X[{a} MOD 5] Y[{fmt(self.num(-3, 3))}] F{fmt(self.num(100, 500, 0))}")
            self.emit("G90")
            if returns and r.random() < 0.5:
                oi = self.next_o()
                self.emit(f"o{oi} if [#<l{i}> GT 0]")
                self.emit(f"o<{name}> return [#<l{i}> MOD 7]")
                self.emit(f"o{oi} endif")
            self.emit(f"o<{name}> endsub" + (f" [{fmt(self.num(-5, 5))}]" if returns else ''))
            self.params, self.defined = saved
            self.subs.append((name, nargs, returns))
        if self.ext_sub:
            self.subs.append((self.ext_sub, 2, True))

    def program(self):
        r = self.r
        self.emit(f"(conformance corpus program, generated)")
        self.subroutines()
        self.emit("G21 G17 G90 G40 G49 G80 G94 G54")
        for k in range(1, 10):
            for name in (f"#<v{k}>", f"#<_gv{k}>"):
                v = float(fmt(self.num(-10, 10, 2)))
                self.emit(f"{name} = {fmt(v)}")
                self.params[name] = self.defined[name] = v
        self.emit(f"F{fmt(self.num(100, 1000, 0))}")
        blocks = [(self.blk_params, 4), (self.blk_moves, 4), (self.blk_arc, 4), (self.blk_offsets, 2),
                  (self.blk_units, 1), (self.blk_dist, 1), (self.blk_tool, 2), (self.blk_spindle, 2),
                  (self.blk_coolant, 1), (self.blk_dwell, 1), (self.blk_comment, 1), (self.blk_comp, 2),
                  (self.blk_cycle, 3), (self.blk_call, 2), (lambda: self.blk_loop(0), 3)]
        funcs = [f for f, w in blocks for _ in range(w)]
        for _ in range(r.randint(8, 25)):
            r.choice(funcs)()
        self.emit(r.choice(["M2", "M30"]))
        return '\n'.join(self.lines) + '\n'


EXT_SUB = """o<{name}> sub
(external subroutine: two arguments, returns their mean)
#<m> = [[#1 + #2] / 2]
G91 G1 X[#<m> MOD 3] Y1 F300
G90
o<{name}> endsub [#<m>]
M2
"""


def generate(outdir, n, seed, start=0):
    """Write programs seed-<seed>-<k>.ngc for k in [start, start+n) and the
    external subroutine file subs/cg_mean.ngc. Returns the list of paths."""
    os.makedirs(os.path.join(outdir, 'subs'), exist_ok=True)
    with open(os.path.join(outdir, 'subs', 'cg_mean.ngc'), 'w') as f:
        f.write(EXT_SUB.format(name='cg_mean'))
    paths = []
    for k in range(start, start + n):
        g = Gen(seed * 1000003 + k, ext_sub_name='cg_mean')
        text = g.program()
        p = os.path.join(outdir, f"gen-{seed}-{k:04d}.ngc")
        with open(p, 'w') as f:
            f.write(text)
        paths.append(p)
    return paths


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--out', required=True)
    ap.add_argument('-n', type=int, default=20)
    ap.add_argument('--seed', type=int, default=1)
    a = ap.parse_args()
    for p in generate(a.out, a.n, a.seed):
        print(p)


if __name__ == '__main__':
    main()
