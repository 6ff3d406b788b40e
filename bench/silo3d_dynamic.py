#!/usr/bin/env python3
"""3D silo with the dynamical nonlocal model (seed 004's) beside local mu(I), and 1 against 2 ranks (issue 20).

examples/silo_3d_beverloo.opts at h = 10 mm (16K particles, 0.5 s, the same material: mu_s 0.3, b 18.754,
d 1 mm), for the orifices of bench/silo3d_beverloo.py: -material mu_i (local) and -material dynamic
-A 0.48 -t0 1e-4 -fluidity_step implicit (the seed's A and t0) on 1 rank; the dynamical model again on
2 ranks for --parallel orifices. Per run: the discharge rate W (silo_summary.csv) and the discharged mass
against time (silo.csv). The dynamical / local difference of W, the 3D Beverloo fit (exponent 5/2, against
D_area) of both, and for the 2-rank runs the largest difference from the 1-rank run of the discharged mass
(kg), its particle count and the step times.

Writes bench/results/silo3d_dynamic.csv (+ .meta.json), the section 'silo3d_dynamic' of docs/scenes.md.
--replot runs nothing.
"""
import math
import os
import shutil
import sys

import _common as C
from scenes import fit_power
from silo3d_beverloo import DS, RHO, G, d_area

H, CELLS = 0.01, "16,14,16"
MODELS = {"local": ["-material", "mu_i"], "dynamic": ["-material", "dynamic", "-A", "0.48", "-t0", "1e-4", "-fluidity_step", "implicit"]}
COLS = ["model", "ranks", "D", "rate", "discharged_mass", "discharged_particles", "steps", "cpu_s", "wall_s", "max_dmass_vs_np1", "max_dparticles_vs_np1",
        "max_dt_vs_np1", "ok", "cmd"]


def args_for(model, D):
    return (["-options_file", os.path.join(C.REPO_ROOT, "examples", "silo_3d_beverloo.opts"), "-cells", CELLS, "-silo_orifice", f"{D:g}", "-t_end", "0.5",
             "-progress_interval", "0"] + MODELS[model])


def one(model, D, np_):
    r = C.run_granmpm(args_for(model, D), np_=np_, keep_dir=True, label=f"silo3d {model} D = {D} on {np_} rank(s)")
    row = dict(model=model, ranks=np_, D=D, ok=r["ok"], steps=r.get("steps"), cpu_s=r["cpu_s"], wall_s=r["elapsed"], cmd=r["cmd"])
    series = []
    if r["ok"]:
        s = C.read_csv(os.path.join(r["dir"], "silo_summary.csv"))[0]
        row.update(rate=s["discharge_rate"], discharged_mass=s["discharged_mass"], discharged_particles=s["discharged_particles"])
        series = C.read_csv(os.path.join(r["dir"], "silo.csv"))
    shutil.rmtree(r.get("dir", ""), ignore_errors=True)
    return row, series


def main():
    ap = C.common_argparser(__doc__)
    ap.add_argument("--parallel", default="0.035,0.045", help="orifices also run on 2 ranks")
    a = ap.parse_args()
    path = os.path.join(C.RESULTS_DIR, "silo3d_dynamic.csv")
    if a.replot:
        rows = C.read_csv(path, strings=("model", "cmd"))
    else:
        rows, ser = [], {}
        for D in DS:
            for m in MODELS:
                row, ser[(m, D)] = one(m, D, 1)
                rows.append(row)
                C.write_csv(path, COLS, rows)
        for D in [float(x) for x in a.parallel.split(",") if x]:
            row, s2 = one("dynamic", D, 2)
            s1 = ser.get(("dynamic", D), [])
            if s1 and s2:
                n = min(len(s1), len(s2))
                row.update(max_dmass_vs_np1=max(abs(p["discharged_mass"] - q["discharged_mass"]) for p, q in zip(s1[:n], s2[:n])),
                           max_dparticles_vs_np1=max(abs(p["discharged_particles"] - q["discharged_particles"]) for p, q in zip(s1[:n], s2[:n])),
                           max_dt_vs_np1=max(abs(p["t"] - q["t"]) for p, q in zip(s1[:n], s2[:n])) if len(s1) == len(s2) else float("inf"))
            rows.append(row)
            C.write_csv(path, COLS, rows)
        C.write_meta(path, C.granmpm_binary(), h=H)
    fits = {}
    for m in MODELS:
        sel = [r for r in rows if r["model"] == m and r["ranks"] == 1 and r.get("rate")]
        if len(sel) >= 3:
            fits[m] = fit_power([d_area(H, r["D"]) for r in sel], [r["rate"] for r in sel], 2.5)
    for m, (Cc, k, n, rms) in fits.items():
        print(f"# {m}: W = {Cc:.4g} (D_area - {k * 1e3:.3g} mm)^(5/2), rms {rms:.2g}, C_B {Cc / (RHO * math.sqrt(G)):.3g}", file=sys.stderr)
    if a.no_docs:
        return
    tab = []
    for D in DS:
        lo = next((r for r in rows if r["model"] == "local" and r["ranks"] == 1 and r["D"] == D), None)
        dy = next((r for r in rows if r["model"] == "dynamic" and r["ranks"] == 1 and r["D"] == D), None)
        if not (lo and dy and lo.get("rate") and dy.get("rate")):
            continue
        tab.append([f"{D:g}", f"{d_area(H, D):.4g}", C.fmt(lo["rate"]), C.fmt(dy["rate"]), f"{dy['rate'] / lo['rate'] - 1:+.2%}",
                    C.fmt(lo["cpu_s"]), C.fmt(dy["cpu_s"]), f"{dy['cpu_s'] / lo['cpu_s']:.2f}"])
    par = [[f"{r['D']:g}", C.fmt(r.get("rate")), C.fmt(next((q.get("rate") for q in rows if q["model"] == "dynamic" and q["ranks"] == 1 and q["D"] == r["D"]), None)),
            C.fmt(r.get("max_dmass_vs_np1")), C.fmt(r.get("max_dparticles_vs_np1")), C.fmt(r.get("max_dt_vs_np1"))] for r in rows if r["ranks"] == 2]
    ftxt = "\n".join(f"- {m}: W = {Cc:.4g} (D_area - {k * 1e3:.3g} mm)^(5/2) (rms of log W {rms:.2g}; C_B = {Cc / (RHO * math.sqrt(G)):.3g})"
                     for m, (Cc, k, n, rms) in fits.items())
    body = ("Produced by `bench/silo3d_dynamic.py` (h = 10 mm, 16K particles, t_end 0.5 s). Command (dynamical model):\n\n```\n"
            + C.shown_cmd(args_for("dynamic", 0.045)) + "\n```\n\nFits against D_area, exponent 5/2:\n\n" + ftxt + "\n\n"
            + C.md_table(["D [m]", "D_area [m]", "W local [kg/s]", "W dynamical [kg/s]", "dynamical / local - 1", "CPU local [s]", "CPU dynamical [s]",
                          "CPU ratio"], tab)
            + "\n\n1 against 2 ranks (dynamical model; largest differences over the whole discharged-mass series):\n\n"
            + C.md_table(["D [m]", "W, 2 ranks", "W, 1 rank", "max |d mass| [kg]", "max |d particles|", "max |d t| of the steps [s]"], par) + "\n")
    C.replace_doc_section("scenes.md", "silo3d_dynamic", "3D silo: the dynamical model beside local mu(I), 1 and 2 ranks", body, "GranMPM scenes")


if __name__ == "__main__":
    main()
