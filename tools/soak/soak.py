#!/usr/bin/python3
"""The soak: programs back to back on the simulated cell, random operator actions and
injected faults, every log replayed.

  soak.py --build BUILD --src SOURCE --minutes M [--seed S] [--out DIR] [--epoch-minutes E]

The cell runs in a private network namespace (the loss rule and the cut route must not
touch the host), in epochs of E minutes (default 5): each epoch is a fresh cell with a
log of its own; at its end every service gets SIGTERM (each must exit 0) and every
interpolator run in the log (a restart begins a new one) is replayed by cnc-replay,
which must find it identical bit for bit.

Within an epoch, runs of the shipped programs follow one another; during a run, at
random: operator actions (hold and resume, feed override, stop) and one fault at most
(kill -9 and restart of a service, a loss burst of 5-20 % for 1-4 s, a stall of a
process by SIGSTOP for 20-400 ms, the multicast route cut for 0.3-1.5 s, a drive fault,
the drives' Modbus server silent for 0.2-1 s). Between runs: a jog, an MDI line, or a
run from a line. A run ends done, stopped or in a fault; a fault must name its cause
(cnc-ctl's reason), and the cell must come back by RESET (at most 3 tries, else the
epoch ends as unrecovered).

Figures (stdout and summary.json in the output folder): runs by outcome, actions and
faults by kind, controlled stops, faults that named their cause, recoveries, services
that did not exit 0, interpolator runs replayed identical of all, lost inputs (a log
cnc-replay refuses), sequence gaps per epoch (cnc-logstat: expected under loss),
memory and file-descriptor growth per hour of each service instance that lived for a
minute or more, and disk use. Exit 0 when every check held.
"""
import argparse
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time

SERVICES = ["drive-bridge", "monitor", "program-server", "interpolator"]  # started after logger and servo-sim
PROGRAMS = ["demo.ngc", "lines.ngc", "butterfly.ngc", "fig11_valley.ngc"]
FAULTS = ["kill", "loss", "stall", "cut", "drive_fault", "sim_silent"]


def now():
    return time.monotonic()


class Soak:
    def __init__(self, a):
        self.a = a
        self.rng = random.Random(a.seed)
        self.build, self.src = a.build, a.src
        self.work = a.out
        self.fig = {"runs": {}, "actions": {}, "faults": {}, "stops_controlled": 0, "faults_named": 0,
                    "faults_unnamed": [], "recoveries": 0, "unrecovered": 0, "bad_exits": [],
                    "replays": {"identical": 0, "of": 0, "failed": []}, "gaps": {}, "growth": [], "epochs": 0}
        self.procs = {}
        self.started = {}
        self.logs = {}
        self.ok = True

    # ---- the cell ------------------------------------------------------------
    def exe(self, name):
        return {"logger": "services/cnc-logger", "servo-sim": "tools/cnc-servo-sim",
                "drive-bridge": "services/cnc-drive-bridge", "monitor": "services/cnc-monitor",
                "program-server": "services/cnc-program-server",
                "interpolator": "services/cnc-interpolator"}[name]

    def make_machine(self):
        base = self.rng.randrange(2000) * 10 + 20000
        self.port, self.prefix = base, f"S{base}."
        text = open(os.path.join(self.src, "config/machines/sim3.yaml")).read()
        text = text.replace("udpm://239.255.76.67:7667", f"udpm://239.255.76.67:{base}")
        text = text.replace("port: 1502", f"port: {base + 1}")
        text = text.replace('channel_prefix: "SIM3."', f'channel_prefix: "{self.prefix}"')
        self.machine = os.path.join(self.work, "machine.yaml")
        open(self.machine, "w").write(text)
        key = re.search(r"^\s*key_file:\s*([^\s#]+)", text, re.M)
        self.key = None
        if key:
            self.key = key.group(1) if key.group(1).startswith("/") else os.path.join(self.work, key.group(1))
            subprocess.run([self.bin("tools/cnc-key"), "gen", "--file", self.key, "--if-missing"], check=True,
                           stdout=subprocess.DEVNULL)

    def bin(self, rel):
        return os.path.join(self.build, rel)

    def start(self, name, extra=()):
        if name == "program-server" and not extra:  # as ./cnc up and the package start it
            extra = ["--state", os.path.join(self.epoch_dir, "program-server.state")]
        log = open(os.path.join(self.epoch_dir, f"{name}.log"), "a")
        p = subprocess.Popen([self.bin(self.exe(name)), "--machine", self.machine, *extra], stdout=log,
                             stderr=subprocess.STDOUT)
        self.procs[name] = p
        self.started[name] = {"t": now(), "base": None}

    def usage(self, pid):
        try:
            rss = int(re.search(r"VmRSS:\s+(\d+)", open(f"/proc/{pid}/status").read()).group(1))
            return rss, len(os.listdir(f"/proc/{pid}/fd"))
        except (OSError, AttributeError):
            return None

    def mark_baselines(self):
        # Each instance's baseline a minute into its life: its start-up allocations are not growth.
        for name, p in self.procs.items():
            st = self.started[name]
            if st["base"] is None and now() - st["t"] >= 60 and p.poll() is None:
                u = self.usage(p.pid)
                if u is not None:
                    st["base"] = (now(), u)

    def note_growth(self, name):
        p, st = self.procs.get(name), self.started.get(name)
        if p is None or st is None or st["base"] is None or p.poll() is not None:
            return
        t0, u0 = st["base"]
        u1 = self.usage(p.pid)
        if u1 is None or now() - t0 < 60:
            return
        hours = (now() - t0) / 3600
        self.fig["growth"].append({"service": name, "minutes": round((now() - t0) / 60, 1),
                                   "rss_kb_per_h": round((u1[0] - u0[0]) / hours),
                                   "fds_per_h": round((u1[1] - u0[1]) / hours, 1)})

    def start_cell(self):
        self.epoch_dir = os.path.join(self.work, f"epoch-{self.fig['epochs']:03d}")
        os.makedirs(self.epoch_dir)
        self.sim_ctl = os.path.join(self.epoch_dir, "sim.ctl")
        self.start("logger", ["--out", os.path.join(self.epoch_dir, "cell")])
        time.sleep(0.2)
        self.start("servo-sim", ["--control", self.sim_ctl])
        for s in SERVICES:
            self.start(s)
        time.sleep(1.0)

    def stop_cell(self):
        for name in reversed(["logger", "servo-sim"] + SERVICES):
            p = self.procs.pop(name, None)
            if p is None:
                continue
            self.note_growth(name)
            p.send_signal(signal.SIGTERM)
            try:
                rc = p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                rc = "did not exit within 10 s"
            if rc != 0:
                self.fig["bad_exits"].append(f"epoch {self.fig['epochs']}: {name} exit {rc}")
                self.ok = False

    # ---- operator -------------------------------------------------------------
    def ctl(self, verb, *args, timeout=10, wait=True):
        cmd = [self.bin("tools/cnc-ctl"), "--machine", self.machine, "--do", verb, *args]
        if verb in ("run", "enable", "reset", "status"):
            cmd += ["--timeout", str(timeout)]
        if not wait:
            return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=timeout + 15)
            return r.returncode, r.stdout
        except subprocess.TimeoutExpired:
            return 4, "cnc-ctl hung"

    def count(self, group, kind):
        self.fig[group][kind] = self.fig[group].get(kind, 0) + 1

    # ---- faults ---------------------------------------------------------------
    def inject(self):
        kind = self.rng.choice(FAULTS)
        self.count("faults", kind)
        if kind == "kill":
            name = self.rng.choice(SERVICES)
            self.note_growth(name)
            self.procs[name].kill()
            self.procs[name].wait()
            time.sleep(self.rng.uniform(0.2, 1.5))
            if name == "program-server" and self.rng.random() < 0.3:
                # Its state file lost too: the interpolator stops the program it runs (program_lost).
                self.start(name, ["--state", os.path.join(self.epoch_dir, "program-server.lost.state")])
                return "kill program-server, state lost"
            self.start(name)
            return f"kill {name}"
        if kind == "loss":
            pct, secs = self.rng.randint(5, 20), self.rng.uniform(1, 4)
            nft = ["nft", "add", "rule", "inet", "soak", "in", "udp", "dport", str(self.port), "numgen", "random",
                   "mod", "100", "<", str(pct), "drop"]
            subprocess.run(["nft", "add", "table", "inet", "soak"], check=True)
            subprocess.run(["nft", "add", "chain", "inet", "soak", "in", "{ type filter hook input priority 0; }"],
                           check=True)
            subprocess.run(nft, check=True)
            time.sleep(secs)
            subprocess.run(["nft", "delete", "table", "inet", "soak"], check=True)
            return f"loss {pct} % for {secs:.1f} s"
        if kind == "stall":
            name = self.rng.choice(SERVICES + ["servo-sim", "logger"])
            ms = self.rng.uniform(20, 400)
            os.kill(self.procs[name].pid, signal.SIGSTOP)
            time.sleep(ms / 1e3)
            os.kill(self.procs[name].pid, signal.SIGCONT)
            return f"stall {name} {ms:.0f} ms"
        if kind == "cut":
            secs = self.rng.uniform(0.3, 1.5)
            subprocess.run(["ip", "route", "del", "224.0.0.0/4", "dev", "lo"], check=True)
            time.sleep(secs)
            subprocess.run(["ip", "route", "add", "224.0.0.0/4", "dev", "lo"], check=True)
            return f"route cut {secs:.1f} s"
        if kind == "drive_fault":
            axis = self.rng.choice("XYZ")
            with open(self.sim_ctl, "w") as f:
                f.write(f"fault {axis}\n")
            return f"drive fault {axis}"
        secs = self.rng.uniform(0.2, 1.0)
        with open(self.sim_ctl, "w") as f:
            f.write(f"drop {secs:.2f}\n")
        return f"drives silent {secs:.1f} s"

    # ---- one run --------------------------------------------------------------
    def one_run(self):
        prog = os.path.join(self.src, "config/programs", self.rng.choice(PROGRAMS))
        frm = []
        if self.rng.random() < 0.15:
            frm = ["--from", str(self.rng.randint(2, 12)), "--confirm"]
            self.count("actions", "run_from_line")
        run = self.ctl("run", "--program", prog, *frm, timeout=300, wait=False)
        t_end = now() + self.rng.uniform(1, 12)
        injected = None
        fault_now = self.rng.random() < self.a.fault_share
        while run.poll() is None and now() < t_end:
            time.sleep(self.rng.uniform(0.2, 1.5))
            if run.poll() is not None:
                break
            r = self.rng.random()
            if r < 0.15:
                self.count("actions", "hold_resume")
                self.ctl("hold")
                time.sleep(self.rng.uniform(0.2, 1.5))
                self.ctl("resume")
            elif r < 0.35:
                self.count("actions", "override")
                self.ctl("override", "--value", f"{self.rng.uniform(0.3, 1.5):.2f}")
            elif r < 0.40:
                self.count("actions", "stop")
                self.ctl("stop")
            elif fault_now and injected is None:
                injected = self.inject()
        try:
            out, _ = run.communicate(timeout=330)
        except subprocess.TimeoutExpired:
            run.kill()
            out, _ = run.communicate()
        self.ctl("override", "--value", "1.0")
        rc = run.returncode
        outcome = {0: "done", 5: "fault", 3: "refused", 4: "timeout", 6: "stopped"}.get(rc, f"exit {rc}")
        self.count("runs", outcome)
        with open(os.path.join(self.work, "runs.txt"), "a") as f:
            last = out.strip().splitlines()[-1] if out.strip() else ""
            f.write(f"epoch {self.fig['epochs']} {os.path.basename(prog)}{' ' + ' '.join(frm) if frm else ''}: "
                    f"{outcome} (exit {rc}); fault injected: {injected or 'none'}; {last}\n")
        if rc not in (0, 6) or injected:
            if rc == 5:
                self.fig["stops_controlled"] += 1
                # Named: cnc-ctl's reason says what failed, after a colon.
                if re.search(r"(fault|lost|failed|stopped)[^\n]*:\s*\S", out):
                    self.fig["faults_named"] += 1
                else:
                    self.fig["faults_unnamed"].append(f"{injected}: {out.strip()[-200:]}")
            return self.recover(injected)
        return True

    def recover(self, injected):
        time.sleep(0.5)
        for attempt in range(3):
            rc, out = self.ctl("reset", timeout=20)
            if rc == 0:
                self.fig["recoveries"] += 1
                return True
            time.sleep(1.0)
        self.fig["unrecovered"] += 1
        self.fig.setdefault("unrecovered_after", []).append(f"{injected}: {out.strip()[-200:]}")
        self.ok = False
        return False

    def between_runs(self):
        r = self.rng.random()
        if r < 0.2:
            self.count("actions", "jog")
            self.ctl("jog", "--axis", self.rng.choice("XY"), "--value", f"{self.rng.uniform(1, 10):.2f}",
                     "--feed", "1200")
        elif r < 0.4:
            self.count("actions", "mdi")
            self.ctl("mdi", "--line", f"G0 X{self.rng.uniform(10, 100):.3f} Y{self.rng.uniform(10, 100):.3f}")

    # ---- epochs ---------------------------------------------------------------
    def replay_epoch(self):
        log = os.path.join(self.epoch_dir, "cell.lcmlog")
        k = 1
        while True:
            cmd = [self.bin("tools/cnc-replay"), "--log", log, "--run", str(k)]
            if self.key:
                cmd += ["--key", self.key]
            r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            runs = re.search(r"interpolator runs in the log: (\d+)", r.stdout)
            n = int(runs.group(1)) if runs else 0
            if k > max(n, 1):
                break
            self.fig["replays"]["of"] += 1
            if r.returncode == 0 and "\nidentical: " in "\n" + r.stdout:
                self.fig["replays"]["identical"] += 1
            else:
                self.fig["replays"]["failed"].append(f"epoch {self.fig['epochs']} run {k}: {r.stdout.strip()[-300:]}")
                self.ok = False
            k += 1
            if k > n:
                break
        st = subprocess.run([self.bin("tools/cnc-logstat"), "--log", log], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True).stdout
        size = os.path.getsize(log) if os.path.exists(log) else 0
        self.fig["log_mb"] = round(self.fig.get("log_mb", 0) + size / 1e6, 1)
        # A log that replayed is not kept unless asked (about 1 GB an hour); a failed one is.
        if not self.a.keep_logs and not any(x.startswith(f"epoch {self.fig['epochs']} ") for x in
                                            self.fig["replays"]["failed"]):
            os.remove(log)
        gaps = 0
        for line in st.split(" events in ")[0].splitlines():
            f = line.split()
            if len(f) >= 4 and f[0].startswith(self.prefix) and f[3].isdigit():
                gaps += int(f[3])
        self.fig["gaps"][f"epoch {self.fig['epochs']}"] = gaps

    def run(self):
        t_stop = now() + 60 * self.a.minutes
        while now() < t_stop:
            self.start_cell()
            t_epoch = min(t_stop, now() + 60 * self.a.epoch_minutes)
            while now() < t_epoch:
                self.mark_baselines()
                if not self.one_run():
                    break
                self.between_runs()
            self.stop_cell()
            self.replay_epoch()
            self.fig["epochs"] += 1
        self.fig["disk_mb"] = round(sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(self.work)
                                        for f in fs) / 1e6, 1)
        self.fig["minutes"] = self.a.minutes
        json.dump(self.fig, open(os.path.join(self.work, "summary.json"), "w"), indent=1)
        self.report()
        return 0 if self.ok else 1

    def report(self):
        f = self.fig
        print(f"soak: {f['minutes']:g} min, {f['epochs']} epoch(s), output in {self.work}")
        print(f"  runs            {sum(f['runs'].values())}: " + ", ".join(f"{k} {v}" for k, v in sorted(f['runs'].items())))
        print(f"  actions         " + ", ".join(f"{k} {v}" for k, v in sorted(f['actions'].items())))
        print(f"  faults injected {sum(f['faults'].values())}: " + ", ".join(f"{k} {v}" for k, v in sorted(f['faults'].items())))
        print(f"  controlled stops (runs ended in a fault) {f['stops_controlled']}, naming their cause "
              f"{f['faults_named']}; recoveries by RESET {f['recoveries']}, unrecovered {f['unrecovered']}")
        rp = f["replays"]
        print(f"  replayed bit for bit {rp['identical']} of {rp['of']} interpolator runs; services not exiting 0: "
              f"{len(f['bad_exits'])}")
        print(f"  sequence gaps in the logs (loss bursts, cuts, kills): {sum(f['gaps'].values())}")
        if f["growth"]:
            print(f"  growth per hour, largest: RSS {max(g['rss_kb_per_h'] for g in f['growth'])} kB/h, fds "
                  f"{max(g['fds_per_h'] for g in f['growth'])}/h over {len(f['growth'])} service lives of 1 min or more")
        print(f"  disk use {f['disk_mb']} MB left in the output folder; the cell's logs were {f.get('log_mb', 0)} MB")
        for k in ("faults_unnamed", "bad_exits"):
            for line in f[k]:
                print(f"  ! {k}: {line}")
        for line in rp["failed"] + f.get("unrecovered_after", []):
            print(f"  ! {line}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", required=True)
    ap.add_argument("--src", required=True)
    ap.add_argument("--minutes", type=float, default=10)
    ap.add_argument("--epoch-minutes", type=float, default=5)
    ap.add_argument("--seed", type=int, default=int(time.time()))
    ap.add_argument("--fault-share", type=float, default=0.5, help="share of runs with an injected fault")
    ap.add_argument("--out", default="")
    ap.add_argument("--keep-logs", action="store_true", help="keep every epoch's log (else only those that failed)")
    a = ap.parse_args()
    if not os.environ.get("CNC_IN_NETNS"):
        if os.geteuid() != 0 or subprocess.run(["unshare", "-n", "true"]).returncode != 0:
            sys.exit("soak: needs root and a private network namespace (unshare -n)")
        os.environ["CNC_IN_NETNS"] = "1"
        os.execvp("unshare", ["unshare", "-n", "/bin/sh", "-c",
                              'ip link set lo up && ip link set lo multicast on && '
                              'ip route add 224.0.0.0/4 dev lo && exec "$0" "$@"',
                              sys.executable, *sys.argv])
    a.build, a.src = os.path.abspath(a.build), os.path.abspath(a.src)
    a.out = a.out or f"/tmp/cnc-soak-{time.strftime('%Y%m%d-%H%M%S')}"
    os.makedirs(a.out, exist_ok=True)
    print(f"soak: seed {a.seed}")
    s = Soak(a)
    s.make_machine()
    try:
        rc = s.run()
    finally:
        for p in s.procs.values():
            if p.poll() is None:
                p.kill()
        subprocess.run(["nft", "delete", "table", "inet", "soak"], stderr=subprocess.DEVNULL)
    sys.exit(rc)


if __name__ == "__main__":
    main()
