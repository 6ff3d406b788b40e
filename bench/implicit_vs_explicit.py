#!/usr/bin/env python3
"""Implicit against explicit time integration: error and wall time at several dt.

Elastic bar (examples/bar.opts with -update usl, 100 cells, CFL limit h/c = 0.025 s): explicit at dt below
its limit; implicit backward Euler (-implicit_theta 1) and implicit midpoint (-implicit_theta 0.5) at fixed
dt from 1x to 20x the CFL limit. Error: max over one period of the rms velocity error / amplitude.
Local mu(I) chute (examples/chute_local.opts with -shape gimp, 20 cells, CFL limit 1.67e-4 s): explicit with
its automatic CFL-0.5 step; implicit backward Euler at fixed dt from 10x to 200x the CFL limit. Error:
relative L2 error of v_y(x) at t = 1.25 s against the analytic profile.
Nonlocal chute (examples/chute_nonlocal.opts, 20 and 40 cells, square cells): explicit (the staggered scheme of
seed 000: explicit stress, then the fluidity solve) with its automatic CFL-0.5 step, and -time_integrator
implicit_coupled (velocity and fluidity in one SNES system) with adaptive dt (-implicit_dt_adapt 1, the default;
fixed large steps fail at the onset of flow) starting from 10x to 100x the CFL limit. Error: relative L2 error of
v_y(x) at t = 1.25 s against the nonlocal 1D reference; wall time of the whole run (to steady state).
Implicit runs of the bar and the local chute use -implicit_dt_adapt 0 and the default solver (Newton line search,
GMRES, ILU). Runs are sequential on 1 rank.

Prints the CSV and writes bench/results/implicit_vs_explicit.csv and docs/figures/implicit_vs_explicit.png
(with --quick: bench/results/quick/).
"""

import os
import re
import sys

import _common as C

NAME = "implicit_vs_explicit"
COLUMNS = ["scene", "integrator", "theta", "dt", "dt_over_cfl_limit", "steps", "wall_s", "error", "newton_per_step", "krylov_per_step",
           "retries", "status"]
RE_IMPL = re.compile(r"implicit(?:_coupled)?: (\d+) steps, (\d+) Newton and (\d+) Krylov iterations.*?(\d+) failed solves retried")
BAR_CFL = 0.025
CHUTE_CFL = 1.66905e-4


def bar_args(integrator, dt, theta=1.0):
    a = ["-options_file", os.path.join(C.REPO_ROOT, "examples", "bar.opts"), "-update", "usl", "-output_final", "0", "-progress_interval", "0",
         "-dt", f"{dt:g}"]
    if integrator == "implicit":
        a += ["-time_integrator", "implicit", "-implicit_theta", f"{theta:g}", "-implicit_dt_adapt", "0"]
    return a


def chute_args(integrator, dt, theta=1.0):
    a = ["-options_file", os.path.join(C.REPO_ROOT, "examples", "chute_local.opts"), "-shape", "gimp", "-cells", "20,4", "-domain_hi", "0.5,0.2",
         "-output_final", "0", "-progress_interval", "0"]
    if integrator == "implicit":
        a += ["-dt", f"{dt:g}", "-time_integrator", "implicit", "-implicit_theta", f"{theta:g}", "-implicit_dt_adapt", "0"]
    return a


def nonlocal_args(integrator, dt, cells=20):
    a = ["-options_file", os.path.join(C.REPO_ROOT, "examples", "chute_nonlocal.opts"), "-cells", f"{cells},4", "-domain_hi",
         f"0.5,{4.0 / cells:.12g}", "-output_final", "0", "-progress_interval", "0"]
    if integrator == "implicit_coupled":
        a += ["-dt", f"{dt:g}", "-time_integrator", "implicit_coupled"]
    return a


def main():
    ap = C.common_argparser(__doc__.split("\n")[0])
    ap.add_argument("--timeout", type=float, default=1800, help="per-run timeout [s]")
    a = ap.parse_args()
    csv_path, png_path = C.output_paths(NAME, a.quick)
    if a.replot:
        plot(C.read_csv(csv_path), png_path)
        return 0
    binary = C.granmpm_binary()
    bar_mult = [1, 5, 10, 20] if a.quick else [1, 2, 5, 10, 20]
    chute_mult = [10, 50] if a.quick else [10, 25, 50, 100, 200]
    runs = [("bar", "explicit", 1.0, BAR_CFL * f) for f in (0.5, 0.9)]
    runs += [("bar", "implicit", th, BAR_CFL * f) for th in (1.0, 0.5) for f in bar_mult]
    runs += [("chute", "explicit", 1.0, None)]
    runs += [("chute", "implicit", 1.0, CHUTE_CFL * f) for f in chute_mult]
    nl_mult = [25, 50] if a.quick else [10, 25, 50, 100]
    runs += [("nonlocal20", "explicit", 1.0, None)]
    runs += [("nonlocal20", "implicit_coupled", 1.0, CHUTE_CFL * f) for f in nl_mult]
    if not a.quick:
        runs += [("nonlocal40", "explicit", 1.0, None), ("nonlocal40", "implicit_coupled", 1.0, CHUTE_CFL / 2 * 50)]
    rows = []
    for scene, integ, theta, dt in runs:
        if scene.startswith("nonlocal"):
            args = nonlocal_args(integ, dt, int(scene[8:]))
        else:
            args = (bar_args if scene == "bar" else chute_args)(integ, dt, theta)
        label = f"{scene} {integ}" + (f" theta {theta:g}" if integ == "implicit" else "") + (f" dt {dt:g}" if dt else " dt auto")
        r = C.run_granmpm(args, timeout=a.timeout, label=label)
        err = r.get("v_err_max") if scene == "bar" else r.get("rel_err")
        m = RE_IMPL.search(r["output"])
        steps = r.get("steps")
        cfl = BAR_CFL if scene == "bar" else CHUTE_CFL / 2 if scene == "nonlocal40" else CHUTE_CFL
        if integ == "implicit_coupled":
            dt = None  # adaptive: report the mean step (the first one was dt)
        dt_used = dt if dt else (1.25 / steps if steps else None)
        rows.append({"scene": scene, "integrator": integ, "theta": theta if integ != "explicit" else "", "dt": dt_used,
                     "dt_over_cfl_limit": dt_used / cfl if dt_used else None, "steps": steps, "wall_s": r.get("wall_s"), "error": err,
                     "newton_per_step": int(m.group(2)) / int(m.group(1)) if m else None,
                     "krylov_per_step": int(m.group(3)) / int(m.group(1)) if m else None, "retries": int(m.group(4)) if m else None,
                     "status": "ok" if r["ok"] and err is not None else f"failed: {C.error_line(r['output'])}"})
    C.write_csv(csv_path, COLUMNS, rows)
    C.write_meta(csv_path, binary)
    plot(rows, png_path)
    return 0


def plot(rows, path):
    plt = C.pyplot()
    if plt is None:
        return
    fig, axes = plt.subplots(1, 3, figsize=(17, 4.8))
    styles = {("explicit", ""): ("k", "o", "explicit"), ("implicit", 1.0): ("tab:red", "s", "implicit backward Euler"),
              ("implicit", 0.5): ("tab:blue", "^", "implicit midpoint (theta 0.5)")}
    for ax, scene, ylabel in ((axes[0], "bar", "max rms velocity error / amplitude"), (axes[1], "chute", "relative L2 error of v_y(x)")):
        for (integ, theta), (col, mk, name) in styles.items():
            sel = sorted([r for r in rows if r["scene"] == scene and r["integrator"] == integ and (integ == "explicit" or r["theta"] == theta)
                          and r["status"] == "ok"], key=lambda r: r["dt_over_cfl_limit"])
            if not sel:
                continue
            ax.loglog([r["dt_over_cfl_limit"] for r in sel], [r["error"] for r in sel], color=col, marker=mk, linewidth=0.9, label=name)
            for r in sel:
                ax.annotate(f"{r['wall_s']:.1f} s", (r["dt_over_cfl_limit"], r["error"]), fontsize=6.5, xytext=(3, 3), textcoords="offset points")
        ax.axvline(1.0, color="grey", linestyle=":", linewidth=0.8)
        ax.set_xlabel("dt / explicit CFL limit h/c")
        ax.set_ylabel(ylabel)
        ax.set_title("elastic bar, 100 cells, one period" if scene == "bar" else "local mu(I) chute, 20 cells, t = 1.25 s", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    ax = axes[2]
    for scene, col in (("nonlocal20", "tab:green"), ("nonlocal40", "tab:purple")):
        for integ, mk in (("explicit", "o"), ("implicit_coupled", "D")):
            sel = sorted([r for r in rows if r["scene"] == scene and r["integrator"] == integ and r["status"] == "ok"], key=lambda r: float(r["wall_s"]))
            if not sel:
                continue
            ax.loglog([float(r["wall_s"]) for r in sel], [float(r["error"]) for r in sel], color=col, marker=mk, linestyle="-" if integ != "explicit" else "none",
                      label=f"{scene[8:]} cells, {integ}")
            for r in sel:
                ax.annotate(f"{float(r['dt_over_cfl_limit']):.2g}x", (float(r["wall_s"]), float(r["error"])), fontsize=6.5, xytext=(3, 3), textcoords="offset points")
    ax.set_xlabel("wall time to t = 1.25 s [s]")
    ax.set_ylabel("relative L2 error of v_y(x)")
    ax.set_title("nonlocal chute (labels: mean dt / CFL limit)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.suptitle("Implicit vs explicit time integration (labels: wall time, 1 rank)")
    fig.tight_layout()
    C.save_figure(fig, path)


if __name__ == "__main__":
    sys.exit(main())
