#!/usr/bin/env python3
"""HTML report of `cnc-predict program --out DIR` (a start).

  make_predict_report.py DIR [--title T]  ->  DIR/index.html with
    force.png      mean force components and peak force over time (flat end mill)
    deflection.png tool-tip deflection and the wall's surface error over time, engagement arc
    surface.png    the stock after the cut, the path coloured by the predicted surface error
    rmax.png       R_max per block (ball end mill)
"""
import argparse
import csv
import html
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_matrix(path):
    rows, meta = [], {}
    for line in open(path):
        if line.startswith("#"):
            for tok in line[1:].replace(";", " ").split():
                if "=" in tok:
                    k, v = tok.split("=", 1)
                    try:
                        meta[k] = float(v)
                    except ValueError:
                        pass
            continue
        rows.append([float(v) for v in line.split(",")])
    return rows, meta


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--title", default="cnc predict")
    a = ap.parse_args()
    d = Path(a.dir)
    rows = list(csv.DictReader(open(d / "predict.csv")))
    flat = rows and "f_peak_N" in rows[0]
    t = [float(r["t_s"]) for r in rows]
    imgs = []
    if flat:
        fig, ax = plt.subplots(figsize=(11, 4))
        ax.plot(t, [float(r["fx_mean_N"]) for r in rows], lw=0.8, label="Fx (tooth-period mean)")
        ax.plot(t, [float(r["fy_mean_N"]) for r in rows], lw=0.8, label="Fy (tooth-period mean)")
        ax.plot(t, [float(r["f_peak_N"]) for r in rows], lw=0.8, label="|Fxy| peak")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("force on the tool [N]")
        ax.legend()
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(d / "force.png", dpi=100)
        imgs.append(("Cutting force (Kline model, VMCS 1999)", "force.png"))
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
        ax1.plot(t, [1e3 * float(r["deflection_peak_mm"]) for r in rows], lw=0.8, label="tool-tip deflection, peak")
        ax1.plot(t, [1e3 * float(r["surface_error_mm"]) for r in rows], lw=0.8, color="0.6",
                 label="wall surface error, walls a later pass removes")
        fin = [(ti, 1e3 * float(r["surface_error_mm"])) for ti, r in zip(t, rows) if r["final_wall"] == "1"]
        ax1.plot([f[0] for f in fin], [f[1] for f in fin], ".", ms=2, color="C1",
                 label="wall surface error, final walls (+ = material left)")
        ax1.set_ylabel("µm")
        ax1.legend()
        ax1.grid(alpha=0.3)
        ax2.plot(t, [float(r["arc_exit_deg"]) - float(r["arc_start_deg"]) for r in rows], lw=0.8, color="C3")
        ax2.set_ylabel("engaged arc [deg]")
        ax2.set_xlabel("t [s]")
        ax2.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(d / "deflection.png", dpi=100)
        imgs.append(("Deflection, surface error and engagement from the stock", "deflection.png"))
    m, meta = read_matrix(d / "stock.csv")
    p = meta.get("pitch_mm", 1.0)
    x0, y0 = meta.get("x0", 0.0), meta.get("y0", 0.0)
    ny, nx = len(m), len(m[0])
    # the figure's height follows the stock's aspect, so the colour bars span the map, not a tall empty frame
    fig, ax = plt.subplots(figsize=(11, min(9.0, max(3.5, 7.5 * ny / nx + 1.0))))
    im = ax.imshow(m, origin="lower", extent=(x0, x0 + nx * p, y0, y0 + ny * p), cmap="gray", aspect="equal")
    fig.colorbar(im, ax=ax, label="stock z [mm]", fraction=0.04, pad=0.1)
    if flat:
        fr = [r for r in rows if r["final_wall"] == "1"]
        sc = ax.scatter([float(r["x_mm"]) for r in fr], [float(r["y_mm"]) for r in fr], s=3,
                        c=[1e3 * float(r["surface_error_mm"]) for r in fr], cmap="coolwarm")
        fig.colorbar(sc, ax=ax, label="surface error [µm]", fraction=0.04, pad=0.02)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    fig.tight_layout()
    fig.savefig(d / "surface.png", dpi=100)
    imgs.append(("Stock after the cut" + (", tool path along the final walls coloured by their surface error"
                                          if flat else ""), "surface.png"))
    if (d / "rmax_map.csv").exists():
        rm, meta = read_matrix(d / "rmax_map.csv")
        fig, ax = plt.subplots(figsize=(9, 7))
        masked = [[v if v >= 0 else float("nan") for v in row] for row in rm]
        im = ax.imshow(masked, origin="lower", cmap="magma", aspect="equal")
        fig.colorbar(im, ax=ax, label="R_max [µm] per block")
        ax.set_title("R_max map (Z-map of the rotating edges, plane removed per block)")
        fig.tight_layout()
        fig.savefig(d / "rmax.png", dpi=100)
        imgs.append(("R_max map", "rmax.png"))
    worst = list(csv.DictReader(open(d / "worst_lines.csv"))) if (d / "worst_lines.csv").exists() else []
    out = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(a.title)}</title>",
           "<style>body{font-family:sans-serif;margin:2em}td,th{padding:2px 10px;text-align:left}"
           "img{max-width:100%}</style></head><body>",
           f"<h1>{html.escape(a.title)}</h1>"]
    if worst:
        out.append("<h2>Worst places (largest surface error of a final wall, per program line)</h2>"
                   "<table><tr><th>line</th>"
                   "<th>surface error [µm]</th><th>block</th></tr>")
        for w in worst:
            out.append(f"<tr><td>{w['line']}</td><td>{1e3 * float(w['surface_error_mm']):.1f}</td>"
                       f"<td><code>{html.escape(w['text'])}</code></td></tr>")
        out.append("</table>")
    for title, img in imgs:
        out.append(f"<h2>{html.escape(title)}</h2><img src='{img}'>")
    out.append("</body></html>")
    (d / "index.html").write_text("\n".join(out))
    print(d / "index.html")


if __name__ == "__main__":
    main()
