#!/usr/bin/python3
# fe_events.py SIMTRACE BRIDGETRACE [N]: the N largest following-error episodes of a
# run (CNC_SIM_DEBUG_TRACE's file, its .writes beside it, and CNC_BRIDGE_DEBUG_TRACE's
# file with its .setpoints), 50 ms apart at least, each with the 30 ms before it: the
# world's stalls, the simulator's and the bridge's loop gaps, the gaps between target
# writes, the bridge's held ticks and lead, late setpoints, and the error's course
# (t ms, fe um, ms of targets buffered ahead; negative: dry). README, Drives.
import csv, sys
import numpy as np

sim_f, br_f = sys.argv[1], sys.argv[2]
N = int(sys.argv[3]) if len(sys.argv) > 3 else 5
S = np.genfromtxt(sim_f, delimiter=",", names=True)
W = np.genfromtxt(sim_f + ".writes", delimiter=",", names=True)
B = np.genfromtxt(br_f, delimiter=",", names=True)
P = np.genfromtxt(br_f + ".setpoints", delimiter=",", names=True)

fe = np.vstack([S["fe0"], S["fe1"], S["fe2"]]).T
absfe = np.abs(fe).max(axis=1)
print(f"sim steps {len(S)}, max |fe| {absfe.max()*1e3:.1f} um, p99 {np.percentile(absfe,99)*1e3:.2f} um, p50 {np.percentile(absfe,50)*1e3:.2f} um")
# episodes: local maxima separated by >= 50 ms
order = np.argsort(-absfe)
picked = []
for i in order:
    if absfe[i] < 0.005: break
    if all(abs(S["mono"][i] - S["mono"][j]) > 0.05 for j in picked):
        picked.append(i)
    if len(picked) >= N: break

def gaps(t, lo, hi, thr):
    m = (t >= lo) & (t <= hi)
    tt = t[m]
    d = np.diff(tt)
    return [(tt[k] - lo, d[k]) for k in np.nonzero(d > thr)[0]]

for i in picked:
    t = S["mono"][i]
    ax = int(np.argmax(np.abs(fe[i])))
    lo, hi = t - 0.03, t + 0.005
    print(f"\n== |fe| {absfe[i]*1e3:.1f} um axis {ax} at mono {t:.4f}, vel {S['vel%d'%ax][i]:.1f} mm/s, ahead {S['ahead%d'%ax][i]*1e3:.2f} ms")
    m = (S["mono"] >= lo) & (S["mono"] <= hi)
    sh = S["shifted"][m]
    print("  sim world shifts (t-rel ms, lost ms):", [(round((a - lo) * 1e3, 1), round(b * 1e3, 2)) for a, b in zip(S["mono"][m][sh > 0], sh[sh > 0])])
    # catch-up: grid steps computed late
    late = S["mono"][m] - S["grid"][m]
    print(f"  sim step lateness max {late.max()*1e3:.2f} ms; min ahead {S['ahead%d'%ax][m].min()*1e3:.2f} ms (negative: buffer dry)")
    print("  sim loop gaps >1.5ms (t-rel ms, gap ms):", [(round(a * 1e3, 1), round(b * 1e3, 1)) for a, b in gaps(S["mono"], lo, hi, 0.0015)])
    wm = W["unit"] == ax + 1
    print("  write gaps >1.5ms:", [(round(a * 1e3, 1), round(b * 1e3, 1)) for a, b in gaps(W["mono"][wm], lo, hi, 0.0015)])
    print("  bridge tick gaps >1.5ms:", [(round(a * 1e3, 1), round(b * 1e3, 1)) for a, b in gaps(B["mono"], lo, hi, 0.0015)])
    bm = (B["mono"] >= lo) & (B["mono"] <= hi)
    print(f"  bridge held ticks: {int(B['held'][bm].sum())}; lead (last_cycle - tau) {np.min(B['last_cycle'][bm]-B['tau'][bm]):.2f}..{np.max(B['last_cycle'][bm]-B['tau'][bm]):.2f}")
    print("  setpoint arrival gaps >6ms:", [(round(a * 1e3, 1), round(b * 1e3, 1)) for a, b in gaps(P["mono"], lo, hi, 0.006)])
    # fe profile
    idx = np.nonzero(m)[0]
    prof = [(round((S['mono'][k] - lo) * 1e3, 1), round(fe[k, ax] * 1e3, 1), round(S['ahead%d'%ax][k]*1e3, 2)) for k in idx[::2]]
    print("  fe profile (t ms, fe um, ahead ms):", prof[-20:])
