#!/usr/bin/env python3
"""Run time per simulated second of seed 004's four 3D scenes at the seed's particle count and
resolution, on 2 ranks, beside the seed's Table 2 figure (4 cores, issue 20).

Each scene runs twice on --ranks ranks: N0 steps and N0 + W steps (defaults 10 and 30), with the
time step GranMPM's stability limits choose (-dt 0: cfl times the elastic CFL limit h/c; the
dynamical fluidity's implicit step has no step limit of its own). The difference of the two runs
is the cost of W steps after start-up (set-up, first-step transients and output excluded): wall
and CPU (user + system of all ranks) per step, and run time per simulated second = wall per
step / dt. Also printed: the explicit fluidity step's diffusion limit h^2 t0 / (2 dim A^2 d^2),
which the implicit step removes.

The scenes (examples/*.opts with overrides to the seed's resolution):
  taylor_couette  examples/taylor_couette_3d_dynamic.opts -cells 110,110,15 (h = 4 mm = d, 471K)
  excavation      examples/excavation_3d.opts -E 15e6 -cells 78,30,20 (h = 3.33 mm, 225K)
  excavation_rel  examples/excavation_3d.opts -E 1.5e5 -cells 78,30,20 -ppc 1 (the seed's
                  relaxed-modulus Excavation*: 1 particle per cell; 28K, the seed 15K at 4 mm)
  wheel           examples/wheel_3d.opts -E 15e6 (h = 3.33 mm, 57.6K; a 4-cell periodic slice)
  silo            examples/silo_3d_seed.opts (h = 4 mm, 32K)

Writes bench/results/seed004_runtime.csv (+ .meta.json) and the section 'seed004_runtime' of
docs/scenes.md. --only NAME[,NAME] runs some scenes; --steps N0,W changes the window.
"""

import argparse
import math
import os
import re
import sys

import _common as C

EX = os.path.join(C.REPO_ROOT, "examples")

SCENES = {
    "taylor_couette": dict(opts="taylor_couette_3d_dynamic.opts", extra=["-cells", "110,110,15"], seed_particles="500K (4 ppc)", seed_dx=4.0e-3,
                           seed_dt=1.0e-4, seed_rt=1565, h=0.44 / 110),
    "excavation": dict(opts="excavation_3d.opts", extra=["-E", "15e6", "-cells", "78,30,20"], seed_particles="230K (8 ppc)", seed_dx=3.3e-3, seed_dt=4.0e-5,
                       seed_rt=770, h=0.26 / 78),
    "excavation_rel": dict(opts="excavation_3d.opts", extra=["-E", "1.5e5", "-cells", "78,30,20", "-ppc", "1"], seed_particles="15K (1 ppc)", seed_dx=4.0e-3,
                           seed_dt=3.5e-4, seed_rt=11, h=0.26 / 78),
    "wheel": dict(opts="wheel_3d.opts", extra=["-E", "15e6"], seed_particles="50K (4 ppc)", seed_dx=3.3e-3, seed_dt=1.0e-5, seed_rt=2522, h=0.4 / 120),
    "silo": dict(opts="silo_3d_seed.opts", extra=[], seed_particles="32K (8 ppc)", seed_dx=4.0e-3, seed_dt=1.0e-4, seed_rt=857, h=0.004),
}

RE_STEP = re.compile(r"step\s+(\d+)\s+t\s+(\S+)\s+dt\s+(\S+).*wall\s+(\S+) s")
A, T0 = 0.48, 1e-4
D = {"taylor_couette": 4e-3}


def run(name, steps, ranks, lever=()):
    s = SCENES[name]
    args = ["-options_file", os.path.join(EX, s["opts"])] + s["extra"] + list(lever) + ["-dt", "0", "-max_steps", str(steps), "-t_end", "100", "-progress_interval", "1",
                                                                         "-output_final", "0", "-output_interval", "0", "-bodies_interval", "1000000"]
    r = C.run_granmpm(args, np_=ranks, label=f"{name}, {steps} steps")
    dts = [float(m.group(3)) for m in RE_STEP.finditer(r["output"])]
    r["dt_last"] = dts[-1] if dts else None
    r["dt_mean_tail"] = sum(dts[-10:]) / len(dts[-10:]) if dts else None
    r["wall_at"] = {int(m.group(1)): float(m.group(4)) for m in RE_STEP.finditer(r["output"])}
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", default=",".join(SCENES))
    ap.add_argument("--steps", default="10,30", help="N0,W: start-up steps and window")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--no-docs", action="store_true")
    ap.add_argument("--replot", action="store_true", help="run nothing: the docs section from the existing CSV")
    ap.add_argument("--lever", default="", help="options of a second variant, run interleaved with the baseline per scene (e.g. '-cfl 0.9'); "
                    "writes seed004_runtime_lever.csv and the section 'seed004_lever' instead")
    a = ap.parse_args()
    n0, w = (int(x) for x in a.steps.split(","))
    if a.lever:
        return lever_main(a, n0, w)
    rows = []
    path = os.path.join(C.RESULTS_DIR, "seed004_runtime.csv")
    for name in ([] if a.replot else a.only.split(",")):
        s = SCENES[name]
        r0 = run(name, n0, a.ranks)
        r1 = run(name, n0 + w, a.ranks)
        ok = r0["ok"] and r1["ok"]
        # Wall: from the progress lines of the longer run (step n0 to n0 + w, 0.1 s resolution),
        # free of the run-to-run noise of a shared machine; CPU: the difference of the runs.
        wa = r1.get("wall_at", {})
        wall = (wa[n0 + w] - wa[n0]) / w if ok and n0 in wa and n0 + w in wa else None
        cpu = (r1["cpu_s"] - r0["cpu_s"]) / w if ok else None
        dt = r1["dt_mean_tail"]
        d = D.get(name, 3e-4)
        fl_limit = s["h"] ** 2 * T0 / (2 * 3 * A * A * d * d)
        rows.append(dict(scene=name, particles=r1.get("particles"), h=s["h"], ranks=a.ranks, steps_window=w, dt=dt, cfl_limit=r1.get("cfl_limit"),
                         explicit_fluidity_limit=fl_limit, wall_per_step=wall, cpu_per_step=cpu,
                         runtime_per_sim_s=wall / dt if ok and dt else None, cpu_per_sim_s=cpu / dt if ok and dt else None,
                         seed_particles=s["seed_particles"], seed_dx=s["seed_dx"], seed_dt=s["seed_dt"], seed_runtime_per_sim_s=s["seed_rt"],
                         ratio_to_seed=(wall / dt) / s["seed_rt"] if ok and dt else None, loadavg=r1["loadavg"], ok=ok, cmd=r1["cmd"],
                         message="" if ok else C.error_line(r1["output"] if not r1["ok"] else r0["output"])))
    if a.replot:
        rows = C.read_csv(path, strings=("scene", "seed_particles", "cmd", "message"))
    else:
        C.write_csv(path, list(rows[0].keys()), rows)
        C.write_meta(path, C.granmpm_binary(), ranks=a.ranks, steps=a.steps, host=C.host_description())
    if a.no_docs:
        return
    # On a loaded machine the wall time measures the load; the CPU time of the ranks (user +
    # system, MPI waiting included) divided by the rank count is what an idle machine's wall
    # time would be at most.
    for r in rows:
        r["idle_equiv_per_sim_s"] = r["cpu_per_sim_s"] / r["ranks"] if r.get("cpu_per_sim_s") else None
    table = C.md_table(["scene", "particles", "h [mm]", "dt [s] (CFL limit)", "explicit fluidity limit [s]", "wall / step [s]", "CPU / step [s] (all ranks)",
                        "wall / sim. s [s]", "CPU / ranks / sim. s [s]", "seed: particles, dx, dt", "seed run time / sim. s [s]", "CPU / ranks vs seed"],
                       [[r["scene"], r["particles"], f"{r['h'] * 1e3:.3g}", f"{C.sci(r['dt'])} ({C.sci(r['cfl_limit'])})", C.sci(r["explicit_fluidity_limit"]),
                         C.fmt(r["wall_per_step"]), C.fmt(r["cpu_per_step"]), C.fmt(r["runtime_per_sim_s"]), C.fmt(r["idle_equiv_per_sim_s"]),
                         f"{r['seed_particles']}, {r['seed_dx'] * 1e3:.2g} mm, {r['seed_dt']:.2g} s", r["seed_runtime_per_sim_s"],
                         f"{r['idle_equiv_per_sim_s'] / r['seed_runtime_per_sim_s']:.3g}x" if r["idle_equiv_per_sim_s"] else "-"]
                        for r in rows], align=["l"] + ["r"] * 11)
    body = (f"Produced by `bench/seed004_runtime.py` on {a.ranks} ranks of this 2-core machine (the seed: a 4-core i7-6700): per scene two runs, "
            f"{n0} and {n0 + w} steps, and their difference (the {w} steps after start-up). dt is GranMPM's choice (-dt 0: -cfl 0.5 of the elastic CFL "
            "limit; the implicit fluidity step sets no limit). Load average at the runs: "
            + ", ".join(f"{r['scene']} {r['loadavg']:.1f}" for r in rows) + ". Commands:\n\n```\n" + "\n".join(r["cmd"] for r in rows) + "\n```\n\n" + table + "\n")
    C.replace_doc_section("scenes.md", "seed004_runtime", "Seed 004's scenes: run time per simulated second against its Table 2", body,
                          "GranMPM scenes")


def measure(name, n0, w, ranks, lever=()):
    """Wall and CPU per step over the w steps after n0 (difference of an n0 and an n0 + w run), dt, CFL limit."""
    r0 = run(name, n0, ranks, lever)
    r1 = run(name, n0 + w, ranks, lever)
    ok = r0["ok"] and r1["ok"]
    wa = r1.get("wall_at", {})
    return dict(ok=ok, dt=r1["dt_mean_tail"], cfl_limit=r1.get("cfl_limit"), particles=r1.get("particles"), loadavg=r1["loadavg"], cmd=r1["cmd"],
                wall_per_step=(wa[n0 + w] - wa[n0]) / w if ok and n0 in wa and n0 + w in wa else None,
                cpu_per_step=(r1["cpu_s"] - r0["cpu_s"]) / w if ok else None,
                message="" if ok else C.error_line(r1["output"] if not r1["ok"] else r0["output"]))


def lever_main(a, n0, w):
    """Baseline and lever interleaved per scene on the same machine state: CPU per simulated second of each, and their ratio."""
    lever = a.lever.split()
    path = os.path.join(C.RESULTS_DIR, "seed004_runtime_lever.csv")
    rows = []
    if a.replot:
        rows = C.read_csv(path, strings=("scene", "lever", "cmd_base", "cmd_lever", "message"))
    for name in ([] if a.replot else a.only.split(",")):
        b = measure(name, n0, w, a.ranks)
        l = measure(name, n0, w, a.ranks, lever)
        row = dict(scene=name, lever=a.lever, particles=b["particles"], ranks=a.ranks, steps_window=w, cfl_limit=b["cfl_limit"], dt_base=b["dt"], dt_lever=l["dt"],
                   cpu_per_step_base=b["cpu_per_step"], cpu_per_step_lever=l["cpu_per_step"], seed_runtime_per_sim_s=SCENES[name]["seed_rt"],
                   loadavg=b["loadavg"], ok=b["ok"] and l["ok"], cmd_base=b["cmd"], cmd_lever=l["cmd"], message=b["message"] or l["message"])
        for k in ("base", "lever"):
            cps, dt = row[f"cpu_per_step_{k}"], row[f"dt_{k}"]
            row[f"cpu_ranks_per_sim_s_{k}"] = cps / dt / a.ranks if cps and dt else None
        rb, rl = row["cpu_ranks_per_sim_s_base"], row["cpu_ranks_per_sim_s_lever"]
        row["lever_gain"] = rb / rl if rb and rl else None
        rows.append(row)
        C.write_csv(path, list(row.keys()), rows)
    if not a.replot:
        C.write_meta(path, C.granmpm_binary(), ranks=a.ranks, steps=a.steps, lever=a.lever, host=C.host_description())
    if a.no_docs or not rows:
        return
    table = C.md_table(["scene", "particles", "CFL limit [s]", "dt base / lever [s]", "CPU / step base / lever [s]", "CPU / ranks / sim. s base [s]",
                        "lever [s]", "gain", "lever vs seed's Table 2"],
                       [[r["scene"], r["particles"], C.sci(r["cfl_limit"]), f"{C.sci(r['dt_base'])} / {C.sci(r['dt_lever'])}",
                         f"{C.fmt(r['cpu_per_step_base'])} / {C.fmt(r['cpu_per_step_lever'])}", C.fmt(r["cpu_ranks_per_sim_s_base"]),
                         C.fmt(r["cpu_ranks_per_sim_s_lever"]), f"{r['lever_gain']:.3g}x" if r["lever_gain"] else "-",
                         f"{r['cpu_ranks_per_sim_s_lever'] / r['seed_runtime_per_sim_s']:.3g}x" if r["cpu_ranks_per_sim_s_lever"] else "-"] for r in rows],
                       align=["l"] + ["r"] * 8)
    body = (f"Produced by `bench/seed004_runtime.py --lever '{rows[0]['lever']}' --steps {a.steps}` on {rows[0]['ranks']} ranks: per scene the baseline "
            "(the commands of the table above) and the same with the lever, interleaved, each as the difference of two runs. CPU = user + system of all "
            "ranks; CPU / ranks / sim. s bounds an idle machine's wall time per simulated second. Load average at the runs: "
            + ", ".join(f"{r['scene']} {r['loadavg']:.1f}" for r in rows) + ".\n\n" + table + "\n")
    C.replace_doc_section("scenes.md", "seed004_lever", "Seed 004's scenes: one measured lever on the run time", body, "GranMPM scenes")


if __name__ == "__main__":
    main()
