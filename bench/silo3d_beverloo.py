#!/usr/bin/env python3
"""3D silo discharge against orifice size (issue 20 item 4): the 3D Beverloo law.

Runs examples/silo_3d_beverloo.opts (square silo 0.16 x 0.16 m, fill 8 cm, rough plate,
smooth sides, local mu(I), 1 rank) for orifice diameters D at three resolutions h = 10,
6.67 and 5 mm, reads the discharge rate W (kg/s, slope of the discharged mass over the middle
60% of the discharge, silo_summary.csv) and fits W = C (D - k)^n by least squares in log W
over a grid of k, with n free and with n = 5/2 fixed (the 3D Beverloo law, where
C = C_B rho sqrt(g) and k = k_B d in its usual form). The rates at the three h show whether
the rate has converged. Prints the CSV on stdout; writes bench/results/silo3d_beverloo.csv,
docs/figures/silo3d_beverloo.png and the section `silo3d` of docs/scenes.md.
"""
import math
import os
import shutil
import sys

import _common as C
from scenes import fit_power, read_summary

RES = [(0.01, "16,14,16"), (0.02 / 3, "24,21,24"), (0.005, "32,28,32")]
DS = [0.025, 0.035, 0.045, 0.055, 0.065]
COLS = ["h", "D", "D_grid", "rate", "discharged_mass", "particles", "steps", "wall_s", "cpu_s", "ok"]
RHO, G = 1500.0, 9.81  # the bulk density of the example and gravity, for C_B = C / (rho sqrt g)


def d_area(h, D):
    """Diameter of the disc with the area of the open plate nodes, N h^2 (the rule of SiloPlate::open in
    include/granmpm/modules.hpp: strictly inside D/2 of the centre, which is a node here): the orifice the grid
    sees. The nominal D jumps between node rings (at h = 10 mm, D = 0.045 and 0.055 open the same 21 nodes)."""
    r2, m = 0.25 * D * D * (1 - 1e-9), int(D / h) + 2
    n = sum(1 for i in range(-m, m + 1) for k in range(-m, m + 1) if (i * h) ** 2 + (k * h) ** 2 < r2)
    return math.sqrt(4 * n * h * h / math.pi)


def args_for(cells, D, t_end):
    return ["-options_file", os.path.join(C.REPO_ROOT, "examples", "silo_3d_beverloo.opts"), "-cells", cells,
            "-silo_orifice", f"{D:g}", "-t_end", f"{t_end:g}", "-progress_interval", "0"]


def run(quick, path):
    rows = []
    res = RES[:2] if quick else RES
    for h, cells in res:
        for D in DS:
            r = C.run_granmpm(args_for(cells, D, 0.5), keep_dir=True, label=f"silo3d h = {h * 1e3:.3g} mm D = {D}")
            s = read_summary(r, "silo_summary.csv") if r["ok"] else {}
            rows.append(dict(h=h, D=D, D_grid=s.get("orifice_effective"), rate=s.get("discharge_rate"),
                             discharged_mass=s.get("discharged_mass"), particles=r.get("particles"), steps=r.get("steps"),
                             wall_s=r.get("wall_s"), cpu_s=r.get("cpu_s"), ok=r["ok"]))
            print(f"# h {h:.4g} D {D:g}: W {s.get('discharge_rate')} kg/s, cpu {r.get('cpu_s'):.1f} s", file=sys.stderr, flush=True)
            shutil.rmtree(r.get("dir", ""), ignore_errors=True)
            C.write_csv(path, COLS, rows)  # after every run: a stopped sweep keeps what it measured
    return rows


def fits(rows):
    out = {}
    for h in sorted({r["h"] for r in rows}):
        sel = [r for r in rows if r["h"] == h and r["ok"] in (True, "True", 1) and r["rate"]]
        if len(sel) < 3:
            continue
        D = [r["D"] for r in sel]
        W = [r["rate"] for r in sel]
        Da = [d_area(h, d) for d in D]
        out[h] = dict(free=fit_power(D, W), fixed=fit_power(D, W, 2.5), area_free=fit_power(Da, W), area_fixed=fit_power(Da, W, 2.5))
    return out


def plot(rows, fs, png):
    plt = C.pyplot()
    if plt is None:
        return
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for h in sorted({r["h"] for r in rows}, reverse=True):
        sel = [r for r in rows if r["h"] == h and r["rate"]]
        D = [r["D"] for r in sel]
        W = [r["rate"] for r in sel]
        l, = ax[0].plot(D, W, "o", label=f"h = {h * 1e3:.3g} mm")
        if h in fs:
            Cc, k, n, _ = fs[h]["fixed"]
            xs = [max(k, 0) + (max(D) * 1.05 - max(k, 0)) * i / 100 for i in range(101)]
            ax[0].plot(xs, [Cc * max(x - k, 0) ** 2.5 for x in xs], "-", color=l.get_color(), lw=0.8,
                       label=f"C (D - {k * 1e3:.1f} mm)^5/2")
        Da = [d_area(h, d) for d in D]
        ax[1].plot(Da, W, "o", color=l.get_color(), label=f"h = {h * 1e3:.3g} mm")
        if h in fs:
            Cc, k, n, _ = fs[h]["area_fixed"]
            xs = [max(k, 0) + (max(Da) * 1.05 - max(k, 0)) * i / 100 for i in range(101)]
            ax[1].plot(xs, [Cc * max(x - k, 0) ** 2.5 for x in xs], "-", color=l.get_color(), lw=0.8,
                       label=f"C (D_area - {k * 1e3:.1f} mm)^5/2")
    ax[0].set_xlabel("orifice D (nominal, -silo_orifice) [m]")
    ax[0].set_ylabel("discharge rate W [kg/s]")
    ax[0].legend(fontsize=7)
    ax[1].set_xlabel("D_area: diameter of the open plate nodes' area [m]")
    ax[1].set_ylabel("discharge rate W [kg/s]")
    ax[1].legend(fontsize=7)
    fig.suptitle("3D silo discharge (examples/silo_3d_beverloo.opts, local mu(I))")
    fig.tight_layout()
    C.save_figure(fig, png)


def main():
    ap = C.common_argparser(__doc__)
    a = ap.parse_args()
    path, png = C.output_paths("silo3d_beverloo", a.quick)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    if a.replot:
        rows = C.read_csv(path)
    else:
        rows = run(a.quick, path)
        C.write_meta(path, C.granmpm_binary())
    fs = fits(rows)
    ftxt = []
    for h, f in fs.items():
        Cc, k, n, rms = f["free"]
        C5, k5, _, rms5 = f["fixed"]
        line = (f"- h = {h * 1e3:.3g} mm: W = {C5:.4g} (D - {k5 * 1e3:.3g} mm)^(5/2) (rms log residual {rms5:.2g}; "
                f"C_B = C / (rho sqrt g) = {C5 / (RHO * math.sqrt(G)):.3g}); free exponent: W = {Cc:.4g} (D - {k * 1e3:.3g} mm)^{n:.2f} "
                f"(rms {rms:.2g})")
        ftxt.append(line)
        Ca, ka, _, rmsa = f["area_fixed"]
        Cf, kf, nf, rmsf = f["area_free"]
        line = (f"- h = {h * 1e3:.3g} mm, against D_area: W = {Ca:.4g} (D_area - {ka * 1e3:.3g} mm)^(5/2) (rms {rmsa:.2g}; C_B = "
                f"{Ca / (RHO * math.sqrt(G)):.3g}); free exponent: W = {Cf:.4g} (D_area - {kf * 1e3:.3g} mm)^{nf:.2f} (rms {rmsf:.2g})")
        ftxt.append(line)
    for line in ftxt:
        print("# " + line[2:], file=sys.stderr)
    plot(rows, fs, png)
    if a.quick or a.no_docs:
        return
    hs = sorted({r["h"] for r in rows}, reverse=True)
    tab = []
    for D in DS:
        cells = []
        for h in hs:
            r = next((r for r in rows if r["h"] == h and r["D"] == D), None)
            cells += [f"{d_area(h, D):.4g}", C.fmt(r["rate"]) if r else "-"]
        tab.append([f"{D:g}"] + cells)
    head = ["D [m]"] + sum(([f"D_area, h {h * 1e3:.3g} mm", f"W [kg/s], h {h * 1e3:.3g} mm"] for h in hs), [])
    body = ("Produced by `bench/silo3d_beverloo.py` (examples/silo_3d_beverloo.opts with -cells for h and -silo_orifice D, "
            "t_end 0.5 s, 1 rank). Example command:\n\n```\n" + C.shown_cmd(args_for(RES[0][1], 0.045, 0.5)) + "\n```\n\n"
            "Fits W = C (D - k)^n, least squares in log W:\n\n" + "\n".join(ftxt) + "\n\n" + C.md_table(head, tab) +
            "\n\n![silo3d](figures/silo3d_beverloo.png)\n")
    C.replace_doc_section("scenes.md", "silo3d", "3D silo: discharge rate against orifice size (Beverloo)", body,
                          "GranMPM scenes: column collapse, silo discharge")


if __name__ == "__main__":
    main()
