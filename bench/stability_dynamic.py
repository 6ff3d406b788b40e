#!/usr/bin/env python3
"""Stability of the dynamical fluidity step: dt from 0.25x to 30x the explicit diffusion limit.

Scene: the seed-000 vertical chute with the dynamical nonlocal model (-material dynamic), 20 cells across, 1 PPC,
started from the steady shear stress (-chute_prestress -gravity_ramp 0), E = 1e8. The explicit fluidity step is
limited by the diffusion limit dt_diff = h^2 t0 / (2 dim A^2 d^2) (the solver also applies the local relaxation
limit); t0 is varied (1e-4, 1e-5, 1e-6 s) so that dt_diff lies below the CFL limit h/c = 1.7e-4 s. For each t0,
f = dt/dt_diff takes the values FACTORS (capped at 0.9 times the CFL limit) for both -fluidity_step explicit and
implicit, each run to the same physical time T = 10000 dt_diff (quick: 2000).

Classification: the run is first made as a user would; when the solver refuses the step (guard 'refused'), it is
repeated with -dt_allow_unstable. Outcome 'stable' if it completes and its column-averaged velocity profile is
within DEV_TOL (relative L2) of the implicit f = 0.25 run at the same T; 'inaccurate' if it completes within 100%
of it (a time-step error in the transient, not a blow-up); 'unstable' if it completes further off; otherwise the
guard or error that stopped it (nan, energy, runaway, error).

Writes bench/results/stability_dynamic.csv, docs/figures/stability_dynamic.png and a section of docs/stability.md
(with --quick: fewer cases, bench/results/quick/, docs untouched).
"""

import math
import os
import shutil
import sys

import _common as C

NAME = "stability_dynamic"
A, D = 0.48, 0.05
H = 1.0 / 20
CFL = 1.7e-4  # h / c at E = 1e8, nu = 0.3, rho = 1500 (c = 300 m/s); the solver prints its own
T0S = [1e-4, 1e-5, 1e-6]
FACTORS = [0.25, 0.5, 0.9, 1.1, 2.0, 4.0, 10.0, 30.0]
QUICK_FACTORS = [0.5, 1.1, 4.0, 30.0]
DEV_TOL = 0.05
COLUMNS = ["t0", "dt_diff", "step", "factor", "dt", "t_end", "guard", "outcome", "deviation", "steps", "wall_s", "message", "cmd"]


def dt_diff(t0):
    return H * H * t0 / (2 * 2 * A * A * D * D)


def base(t0, dt, T, step):
    return ["-material", "dynamic", "-cells", "20,4", "-domain_hi", "0.5,0.2", "-ppc", "1", "-chute_prestress", "-gravity_ramp", "0",
            "-t0", f"{t0:g}", "-fluidity_step", step, "-dt", f"{dt:.6g}", "-t_end", f"{T:.6g}", "-output_final", "0", "-progress_interval", "0"]


def profile(d):
    p = os.path.join(d, "profile.csv")
    if not os.path.exists(p):
        return None
    return [r["vy"] for r in C.read_csv(p)]


def classify(text):
    t = text.lower()
    if "non-finite" in t or "nan" in t:
        return "nan"
    if "kinetic energy" in t:
        return "energy"
    if "cells in one step" in t:
        return "runaway"
    return "error"


def run_case(t0, step, f, T, ref):
    dt = f * dt_diff(t0)
    args = base(t0, dt, T, step)
    r = C.run_granmpm(args, keep_dir=True, label=f"t0 {t0:g} {step} f {f:g}")
    guard = "accepted"
    if not r["ok"] and "exceeds the stability limit" in r["output"]:
        guard = "refused"
        shutil.rmtree(r.get("dir", ""), ignore_errors=True)
        r = C.run_granmpm(args + ["-dt_allow_unstable"], keep_dir=True, label=f"t0 {t0:g} {step} f {f:g} (allow unstable)")
    elif not r["ok"]:
        guard = classify(r["output"])
    dev = None
    if r["ok"]:
        v = profile(r["dir"])
        if ref is None:
            ref = v
        if v and ref and all(math.isfinite(x) for x in v):
            num = math.sqrt(sum((a - b) ** 2 for a, b in zip(v, ref)))
            den = math.sqrt(sum(b * b for b in ref)) or 1.0
            dev = num / den
        outcome = "stable" if dev is not None and dev < DEV_TOL else ("inaccurate" if dev is not None and dev < 1.0 else "unstable")
    else:
        outcome = classify(r["output"])
    shutil.rmtree(r.get("dir", ""), ignore_errors=True)
    return dict(t0=t0, dt_diff=dt_diff(t0), step=step, factor=f, dt=dt, t_end=T, guard=guard, outcome=outcome, deviation=dev,
                steps=r.get("steps"), wall_s=r.get("wall_s"), message="" if r["ok"] else C.error_line(r["output"]), cmd=r["cmd"]), ref


def run(quick):
    rows = []
    for t0 in (T0S[1:] if quick else T0S):
        T = (2000 if quick else 10000) * dt_diff(t0)
        _, ref = run_case(t0, "implicit", 0.25, T, None)  # the reference profile
        for step in ("explicit", "implicit"):
            for f in (QUICK_FACTORS if quick else FACTORS):
                if f * dt_diff(t0) > 0.9 * CFL:
                    continue
                row, _ = run_case(t0, step, f, T, ref)
                rows.append(row)
    return rows


def plot(rows, path):
    plt = C.pyplot()
    if not plt:
        return
    style = {"stable": ("o", "C2"), "inaccurate": ("s", "C1"), "unstable": ("P", "C3"), "nan": ("x", "C3"), "energy": ("^", "C3"), "runaway": ("v", "C3"), "error": ("D", "k")}
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for ax, step in zip(axes, ("explicit", "implicit")):
        seen = set()
        for r in rows:
            if r["step"] != step:
                continue
            mk, col = style.get(r["outcome"], ("D", "k"))
            lab = r["outcome"] if r["outcome"] not in seen else None
            seen.add(r["outcome"])
            ax.plot(r["factor"], r["t0"], mk, color=col, mfc=col if r["guard"] != "refused" else "none", ms=8, label=lab)
        ax.axvline(1.0, color="k", lw=1, label="explicit diffusion limit")
        ts = sorted({r["t0"] for r in rows})
        ax.plot([0.9 * CFL / dt_diff(t) for t in ts], ts, "k--", lw=1, label="0.9 x CFL limit")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("dt / dt_diff")
        ax.set_title(f"-fluidity_step {step}", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("t0 [s]")
    fig.suptitle("Dynamical fluidity, chute 20 cells: open markers = refused by the solver without -dt_allow_unstable", fontsize=9)
    fig.tight_layout()
    C.save_figure(fig, path)


def main():
    ap = C.common_argparser(__doc__.split("\n")[0])
    a = ap.parse_args()
    binary = C.granmpm_binary()
    path, png = C.output_paths(NAME, a.quick)
    if a.replot:
        rows = C.read_csv(path, strings=("step", "guard", "outcome", "message", "cmd"))
    else:
        rows = run(a.quick)
        C.write_csv(path, COLUMNS, rows)
        C.write_meta(path, binary)
    plot(rows, png)
    if a.quick or a.no_docs:
        return
    table = C.md_table(["t0 [s]", "dt_diff [s]", "step", "largest f that did not blow up", "first that did (outcome)", "refused above"],
                       [], ["r", "r", "l", "r", "l", "r"])
    lines = []
    for t0 in sorted({r["t0"] for r in rows}, reverse=True):
        for step in ("explicit", "implicit"):
            sel = sorted([r for r in rows if r["t0"] == t0 and r["step"] == step], key=lambda r: r["factor"])
            stable = None
            first = None
            for r in sel:
                if r["outcome"] in ("stable", "inaccurate") and first is None:
                    stable = r["factor"]
                elif first is None:
                    first = r
            refused = [r["factor"] for r in sel if r["guard"] == "refused"]
            lines.append(f"| {t0:g} | {dt_diff(t0):.3g} | {step} | {C.fmt(stable) or 'none'} | "
                         f"{(C.fmt(first['factor']) + ' (' + first['outcome'] + ')') if first else '-'} | {C.fmt(min(refused)) if refused else '-'} |")
    body = ("Produced by `bench/stability_dynamic.py` (see its docstring). The explicit fluidity step must stay below "
            "dt_diff = h^2 t0 / (2 dim A^2 d^2); the implicit step has no such limit. Each run goes to T = 10000 dt_diff; "
            f"'stable' = completed and within {DEV_TOL:g} (relative L2) of the implicit f = 0.25 profile at T, 'inaccurate' = within 100%, "
            "'unstable' = further off. Example command:\n\n```\n"
            + rows[0]["cmd"] + "\n```\n\n" + table + "\n" + "\n".join(lines) + "\n\n![dynamic](figures/stability_dynamic.png)\n")
    C.replace_doc_section("stability.md", "stability-dynamic", "Dynamical fluidity step (generated)", body, "GranMPM stability stress tests")


if __name__ == "__main__":
    main()
