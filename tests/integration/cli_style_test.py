#!/usr/bin/python3
"""Every installed executable's command line in one style (common/util/cli.h).

  cli_style_test.py EXE...

For each executable, from the build tree (nothing is started: each run ends at its flags):
  --help     exit 0, nothing on stderr; "NAME: summary" first, "Usage: NAME", -h,--help and
             --version listed, every option, positional and subcommand with a description
             (and so for each subcommand's --help);
  --version  exit 0, one line "NAME VERSION" (0.1.0+COMMITS.gHASH[.dirty]);
  a bad flag exit 2, nothing on stdout, one line "NAME: ... --no-such-flag ... (see NAME --help)";
  a malformed number (the first option whose value is a number, in the program or its
             first subcommand that has one): exit 2, the line names that option.
"""
import os
import re
import subprocess
import sys

VERSION = re.compile(r"^\d+\.\d+\.\d+\+\d+\.g[0-9a-f]+(\.dirty)?$")
NUMBER = re.compile(r"^(--[a-z0-9-]+) \S*(NUMBER|INT|FLOAT|UINT|POSITIVE|NONNEGATIVE)")
failures = []


def fail(exe, what):
    failures.append(f"{os.path.basename(exe)}: {what}")


def run(args):
    p = subprocess.run(args, capture_output=True, text=True, timeout=20, stdin=subprocess.DEVNULL)
    return p.returncode, p.stdout, p.stderr


def sections(text):
    """{section: [(entry, description)]} of a CLI11 help text."""
    out, name, lines = {}, None, text.splitlines()
    for i, line in enumerate(lines):
        if re.match(r"^[A-Z][a-z]+:$", line):
            name = line[:-1]
            out[name] = []
        elif not line.strip():
            name = None
        elif name and re.match(r"^  \S", line):
            # CLI11: the entry padded to column 30, then its description; a longer entry
            # alone on its line, the description on the next at column 30.
            if len(line) > 30 and line[29] == " ":
                entry, desc = line[:30].strip(), line[30:].strip()
            else:
                entry, desc = line.strip(), ""
                if i + 1 < len(lines) and re.match(r"^ {30}\S", lines[i + 1]):
                    desc = lines[i + 1].strip()
            out[name].append((entry, desc))
    return out


def check_help(exe, name, cmd, top):
    rc, out, err = run([exe] + cmd + ["--help"])
    where = " ".join([name] + cmd)
    if rc != 0 or err:
        fail(exe, f"{where} --help: exit {rc}, stderr {err!r}")
        return {}
    if top and not out.startswith(f"{name}: "):
        fail(exe, f"--help does not start with '{name}: ': {out.splitlines()[0]!r}")
    if f"Usage: {where}" not in out:
        fail(exe, f"{where} --help has no 'Usage: {where}'")
    s = sections(out)
    opts = s.get("Options", [])
    if not any(o.startswith("-h,--help") for o, _ in opts):
        fail(exe, f"{where} --help lists no -h,--help")
    if top and not any(o.startswith("--version") for o, _ in opts):
        fail(exe, "--help lists no --version")
    for sec in ("Options", "Positionals", "Subcommands"):
        for entry, desc in s.get(sec, []):
            if not desc:
                fail(exe, f"{where} --help: {sec} entry '{entry}' has no description")
    return s


def check(exe):
    name = os.path.basename(exe)
    s = check_help(exe, name, [], True)
    subs = [e.split()[0] for e, _ in s.get("Subcommands", [])]
    numeric = [(m.group(1), []) for e, _ in s.get("Options", []) if (m := NUMBER.match(e))]
    for sub in subs:
        ss = check_help(exe, name, [sub], False)
        numeric += [(m.group(1), [sub]) for e, _ in ss.get("Options", []) if (m := NUMBER.match(e))]

    rc, out, err = run([exe, "--version"])
    words = out.split()
    if rc != 0 or err or len(out.splitlines()) != 1 or len(words) != 2 or words[0] != name or not VERSION.match(words[1]):
        fail(exe, f"--version: exit {rc}, stdout {out!r}, stderr {err!r}")

    for args, flag in ((["--no-such-flag"], "--no-such-flag"),) + (
            ((numeric[0][1] + [numeric[0][0], "x1y"], numeric[0][0]),) if numeric else ()):
        rc, out, err = run([exe] + args)
        line = err.strip()
        if rc != 2 or out or len(line.splitlines()) != 1 or not line.startswith(f"{name}: ") \
                or flag not in line or not line.endswith(f"(see {name} --help)"):
            fail(exe, f"{' '.join(args)}: exit {rc} (want 2), stdout {out!r}, stderr {err!r}")
    return len(subs), (" ".join(numeric[0][1] + [numeric[0][0]]) if numeric else "-"), words[1] if len(words) == 2 else "?"


def main():
    exes = sys.argv[1:]
    if not exes:
        sys.exit("usage: cli_style_test.py EXE...")
    for exe in exes:
        subs, num, version = check(exe)
        print(f"# {os.path.basename(exe):20s} version {version}  subcommands {subs}  malformed number checked on: {num}")
    for f in failures:
        print("FAIL: " + f)
    if failures:
        sys.exit(1)
    print(f"PASS ({len(exes)} executables)")


main()
