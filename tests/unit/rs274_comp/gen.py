#!/usr/bin/env python3
"""Regenerates the literal data of tests/unit/rs274_comp_test.cc from LinuxCNC's rs274.

For every NAME.ngc here it runs the installed /usr/bin/rs274 twice:
  * on the program as written (G41/G42 ... G40): the expected canonical calls, and
    the refusal message if rs274 stops with one;
  * on the same program with compensation taken out (the driver): G41.1/G42.1 D..
    and G41/G42 D.. lines become (START L|R radius), G40 becomes (STOP), and a
    (FLUSH) comes before M2. These are the calls our uncompensated interpreter
    makes; the test replays them into CutterComp.
The tool table (T1 D6, T2 D1) is read by rs274 in inches (see
tools/conformance/CANON_FORMAT.md). Prints the C++ case table on stdout.
Usage: gen.py > cases.inc, then paste between the markers in the test.
"""
import glob, os, re, subprocess, sys, tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
TOOLS = {1: 6.0, 2: 1.0}  # diameters, inches
DROP = ("ON_RESET",)


def run(text):
    with tempfile.TemporaryDirectory() as d:
        ngc, out, tbl, var = (os.path.join(d, n) for n in ("p.ngc", "out.txt", "t.tbl", "v.var"))
        open(ngc, "w").write(text)
        open(tbl, "w").write("".join(f"T{t} P{t} Z0 D{dia}\n" for t, dia in TOOLS.items()))
        open(var, "w").write("")
        r = subprocess.run(["rs274", "-g", "-t", tbl, "-v", var, ngc, out], stdin=subprocess.DEVNULL,
                           capture_output=True, text=True, env=dict(os.environ, HOME=d))
        lines = [re.sub(r"^\s*\d+ N\S*\s*", "", l) for l in open(out).read().splitlines()]
        lines = lines[6:]  # rs274's own start-up calls
        lines = [l for l in lines if not l.startswith(DROP)]
        err = r.stderr.splitlines()
        error = err[1] if len(err) >= 2 and err[0] == "executing" else ""
        return lines, error


def driver(text):
    inch = "G20" in text
    out = []
    for line in text.splitlines():
        m = re.fullmatch(r"G4([12])(\.1)? D(\S+)", line.strip())
        if m:
            side = "L" if m.group(1) == "1" else "R"
            d = float(m.group(3))
            radius = d / 2 if m.group(2) else TOOLS[int(d)] / 2 * (1 if inch else 25.4)
            out.append(f"(START {side} {radius:g})")
        elif line.strip() == "G40":
            out.append("(STOP)")
        elif line.strip() == "M2":
            out += ["(FLUSH)", "M2"]
        else:
            out.append(line)
    return "\n".join(out) + "\n"


def lit(lines):
    return 'R"(' + "\n".join(lines) + ')"'


for path in sorted(glob.glob(os.path.join(HERE, "*.ngc"))):
    name = os.path.basename(path)[:-4]
    text = open(path).read()
    expected, error = run(text)
    drive, derr = run(driver(text))
    if derr:
        sys.exit(f"{name}: the uncompensated program fails: {derr}")
    print(f"    {{\"{name}\",\n     // rs274 on tests/unit/rs274_comp/{name}.ngc:\n     {lit(text.rstrip().splitlines())},")
    print(f"     {lit(drive)},\n     {lit(expected)},\n     \"{error}\"}},")
