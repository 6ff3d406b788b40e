#!/usr/bin/env python3
"""Strong scaling 1 -> 2 ranks against the machine's capacity for two processes, and correctness to 8 ranks.

Scene: the elastic block of throughput.py (fully periodic box, bspline2, APIC, USL, 2 particles per cell per
direction, velocity (3, 2[, 1]) m/s plus a spin, fixed dt = 0.25 h/c, no output), 2D 500 x 500 cells and 3D
50^3 cells, both 1e6 particles (quick: 1e5), 30 steps (quick: 20), every run with -log_view.

Capacity: bench/compute_loop.cpp, compiled here with `mpicxx -O2` into a temporary directory, sweeps an array
of N/2 particle-like records (192 bytes each) with a fixed flop + streaming loop, as 1 process and as 2
simultaneous processes (mpiexec -n 2, same array size per process, no communication in the timed loop).
capacity = 2 t1 / t2: 2.0 on two idle cores with independent memory paths, less when the cores are shared
(another job, hyper-threads) or memory bandwidth saturates.

Each repeat (default 3) runs, interleaved: compute loop on 1 and 2 processes, then every size on 1 and 2 ranks.
Per repeat: speed-up = wall(1 rank) / wall(2 ranks) (time-loop wall printed by the solver), capacity from the
same repeat, fraction = speed-up / capacity. Reported: medians over the repeats.

Correctness (timings meaningless, the machine has 2 cores): the 2D block at 1e5 particles (quick: 1e4) on
1, 2, 4 and 8 ranks (oversubscribed); the particle count must match exactly and the final kinetic energy
(the "block: ..." line) to 1e-10 relative.

The model parameters (docs/scaling.md) are calibrated from the -log_view stage times: a (particle stages per
particle-step) and b (GridUpdate per node-step) from the 1-rank runs; c (effective halo cost per byte) and d
(migration cost per migrated particle) from the growth of GridUpdate and Migrate between 1 and 2 ranks.

Writes bench/results/scaling.csv (one row per run), scaling.meta.json, docs/figures/scaling.png and the
section "Measured strong scaling" of docs/scaling.md (with --quick: bench/results/quick/, docs untouched).
"""

import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

import _common as C
from throughput import block_args, wave_speed

NAME = "scaling"
STAGES = ["Migrate", "P2G", "GridUpdate", "G2P", "Constitutive", "Fluidity", "Output"]
PARTICLE_STAGES = ["P2G", "G2P", "Constitutive"]
SIZES_FULL = [(2, "1e6", (500, 500)), (3, "1e6", (50, 50, 50))]
SIZES_QUICK = [(2, "1e5", (250, 100)), (3, "1e5", (25, 25, 20))]
CHECK_FULL = (2, "1e5", (250, 100))
CHECK_QUICK = (2, "1e4", (50, 50))
CHECK_RANKS = [1, 2, 4, 8]
KE_TOL = 1e-9  # the energy is printed with 10 significant digits: one unit in the last digit is up to 1e-9 relative
RE_BLOCK = re.compile(rf"block: (\d+) particles, mass ({C._FLOAT}), kinetic energy ({C._FLOAT})")
RE_LOOP = re.compile(rf"compute_loop: ranks (\d+), particles per rank (\d+), iters (\d+), wall ({C._FLOAT}) s")
HALO_WIDTH = 2          # DMDA stencil width of GranMPM's grid (quadratic B-splines)
HALO_DOUBLES = 10       # assumed doubles per halo node and step: mass + momentum (reverse) and velocity old/new (forward), 3D
COLUMNS = ["kind", "dim", "size", "ranks", "repeat", "particles", "grid_nodes", "steps", "wall_s", "rate", "elapsed_s", "loadavg",
           "loop_n", "loop_iters", "loop_wall_s", "ke_printed", "ok"] + STAGES


def compile_loop(tmp):
    src = os.path.join(C.BENCH_DIR, "compute_loop.cpp")
    exe = os.path.join(tmp, "compute_loop")
    cxx = os.environ.get("MPICXX", "mpicxx")
    p = subprocess.run([cxx, "-O2", "-o", exe, src], capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"scaling: could not compile {src} with {cxx}:\n{p.stderr}")
    return exe


def run_loop(exe, np_, n, iters, rep):
    cmd = ([] if np_ == 1 else C.mpiexec_prefix(np_)) + [exe, str(n), str(iters)]
    la = C.loadavg()
    t0 = time.monotonic()
    p = subprocess.run(cmd, capture_output=True, text=True)
    el = time.monotonic() - t0
    m = RE_LOOP.search(p.stdout)
    ok = p.returncode == 0 and m is not None
    print(f"# compute_loop np {np_} rep {rep}: {'%.3f s' % float(m.group(4)) if ok else 'FAILED ' + p.stderr[-300:]}", file=sys.stderr, flush=True)
    return {"kind": "compute_loop", "ranks": np_, "repeat": rep, "loop_n": n, "loop_iters": iters, "loop_wall_s": float(m.group(4)) if ok else None,
            "elapsed_s": el, "loadavg": la, "ok": ok}


def run_block(kind, dim, label, cells, np_, rep, steps):
    r = C.run_granmpm(block_args(dim, cells, steps=steps, extra=["-log_view"]), np_=np_, label=f"{kind} {dim}D {label} np {np_} rep {rep}")
    if not r["ok"]:
        print(r["output"][-2000:], file=sys.stderr)
    m = RE_BLOCK.search(r["output"])
    row = {"kind": kind, "dim": dim, "size": label, "ranks": np_, "repeat": rep, "particles": r.get("particles"), "grid_nodes": r.get("grid_nodes"),
           "steps": r.get("steps"), "wall_s": r.get("wall_s"), "rate": r.get("rate"), "elapsed_s": r["elapsed"], "loadavg": r["loadavg"],
           "ke": float(m.group(3)) if m else None, "ke_printed": m.group(3) if m else None, "ok": r["ok"]}
    row["block_particles"] = int(m.group(1)) if m else None
    for s in STAGES:
        row[s] = r.get("stages", {}).get(s)
    return row


# --------------------------------------------------------------------------------------
# Analysis


def shares(row):
    tot = sum(row.get(s) or 0.0 for s in STAGES)
    return {s: (row.get(s) or 0.0) / tot if tot > 0 else float("nan") for s in STAGES}, tot


def halo_nodes_per_rank(dim, cells, split_dir_ranks):
    """Ghost nodes a rank receives per exchange for a periodic grid split into `split_dir_ranks` slabs along x
    (for the square/cubic grids here every direction gives the same halo)."""
    if split_dir_ranks <= 1:
        return 0
    other = 1
    for n in cells[1:]:
        other *= n  # periodic: n nodes per direction
    return 2 * HALO_WIDTH * other  # two faces


def migrated_per_step(dim, cells, ranks):
    """Estimated particles crossing rank faces per step: particle density x face area x mean |v_n| dt, summed over
    the two faces of a slab split along x (v_x = 3 m/s; the spin adds +-0.5 m/s on average across the face, ignored)."""
    if ranks <= 1:
        return 0.0
    h = 1.0 / max(cells)
    dt = 0.25 * h / wave_speed()
    ppc = 2 ** dim
    face_cells = 1
    for n in cells[1:]:
        face_cells *= n
    # particles within v dt of a face: ppc per cell x face cells x (v dt / h); each slab boundary is crossed
    # in one direction; 2 boundaries in the periodic 2-slab split
    return 2 * ppc * face_cells * (3.0 * dt / h)


def analyse(rows, sizes):
    loops = [r for r in rows if r["kind"] == "compute_loop" and r["ok"]]
    caps = {}
    for rep in sorted({r["repeat"] for r in loops}):
        t1 = next((r["loop_wall_s"] for r in loops if r["repeat"] == rep and r["ranks"] == 1), None)
        t2 = next((r["loop_wall_s"] for r in loops if r["repeat"] == rep and r["ranks"] == 2), None)
        if t1 and t2:
            caps[rep] = 2 * t1 / t2
    summary = {"capacity": C.median(list(caps.values())), "capacity_all": caps, "cases": []}
    for dim, label, cells in sizes:
        sc = [r for r in rows if r["kind"] == "strong" and r["dim"] == dim and r["size"] == label and r["ok"]]
        sp, fr = [], []
        for rep in sorted({r["repeat"] for r in sc}):
            w1 = next((r["wall_s"] for r in sc if r["repeat"] == rep and r["ranks"] == 1), None)
            w2 = next((r["wall_s"] for r in sc if r["repeat"] == rep and r["ranks"] == 2), None)
            if w1 and w2:
                sp.append(w1 / w2)
                if rep in caps:
                    fr.append(w1 / w2 / caps[rep])
        case = {"dim": dim, "size": label, "cells": cells, "speedup": C.median(sp), "speedups": sp, "fraction": C.median(fr), "fractions": fr}
        for np_ in (1, 2):
            rs = [r for r in sc if r["ranks"] == np_]
            if not rs:
                continue
            case[f"wall{np_}"] = C.median([r["wall_s"] for r in rs])
            case[f"rate{np_}"] = C.median([r["rate"] for r in rs])
            case[f"stage{np_}"] = {s: C.median([r.get(s) or 0.0 for r in rs]) for s in STAGES}
            case[f"share{np_}"] = {s: C.median([shares(r)[0][s] for r in rs]) for s in STAGES}
            case["particles"], case["nodes"], case["steps"] = rs[0]["particles"], rs[0]["grid_nodes"], rs[0]["steps"]
        if "stage1" in case:
            N, Nn, S = case["particles"], case["nodes"], case["steps"]
            st1 = case["stage1"]
            case["a"] = sum(st1[s] for s in PARTICLE_STAGES + ["Migrate"]) / (N * S)
            case["a_migrate_local"] = st1["Migrate"] / (N * S)
            case["b"] = st1["GridUpdate"] / (Nn * S)
            if "stage2" in case:
                st2 = case["stage2"]
                halo = halo_nodes_per_rank(dim, cells, 2)
                halo_bytes = halo * 8 * (HALO_DOUBLES if dim == 3 else 7)
                case["halo_bytes"] = halo_bytes
                extra_grid = st2["GridUpdate"] - st1["GridUpdate"] / 2
                case["c"] = extra_grid / S / halo_bytes if halo_bytes else float("nan")
                mig = migrated_per_step(dim, cells, 2)
                case["migrated_per_step"] = mig
                extra_mig = st2["Migrate"] - st1["Migrate"] / 2
                case["d"] = extra_mig / S / (mig / 2) if mig else float("nan")
                case["extra_grid_per_step"] = extra_grid / S
                case["extra_mig_per_step"] = extra_mig / S
        summary["cases"].append(case)
    checks = [r for r in rows if r["kind"] == "check"]
    ref = next((r for r in checks if r["ranks"] == 1 and r["ok"]), None)
    summary["checks"] = []
    for r in sorted(checks, key=lambda x: x["ranks"]):
        d = {"ranks": r["ranks"], "particles": r.get("block_particles") or r.get("particles"), "ke": r.get("ke"), "ok": r["ok"]}
        if ref and r.get("ke") is not None and ref.get("ke"):
            d["rel_ke"] = abs(r["ke"] - ref["ke"]) / abs(ref["ke"])
            d["same_n"] = d["particles"] == (ref.get("block_particles") or ref.get("particles"))
            d["pass"] = d["same_n"] and d["rel_ke"] <= KE_TOL
        summary["checks"].append(d)
    return summary


def weak_prediction(case, P, latency=1.5e-6, bandwidth=10e9, allreduces=4, per_rank_particles=1e6):
    """Predicted weak-scaling efficiency of the 3D explicit block at per_rank_particles per rank on P ranks
    (cubic rank blocks, 2 PPC per direction). Network numbers are assumptions, a and b measured."""
    a, b = case["a"], case["b"]
    cells = (per_rank_particles / 8) ** (1 / 3)  # cells per direction per rank block
    nodes = cells ** 3
    t_work = a * per_rank_particles + b * nodes
    halo_nodes = 6 * HALO_WIDTH * (cells + 1) ** 2
    halo_bytes = halo_nodes * 8 * HALO_DOUBLES
    neighbours = 26
    t_halo = 2 * (neighbours * latency) + halo_bytes / bandwidth
    mig = 6 * 8 * cells ** 2 * 0.025  # particles within v dt (0.025 h per step, as in the block) of the 6 faces
    t_mig = neighbours * latency + mig * 200 / bandwidth
    t_red = allreduces * math.log2(max(P, 2)) * latency
    t = t_work + t_halo + t_mig + t_red
    return {"P": P, "t_work": t_work, "t_halo": t_halo, "t_mig": t_mig, "t_red": t_red, "t_step": t, "eff": t_work / t,
            "halo_bytes": halo_bytes, "migrated": mig}


# --------------------------------------------------------------------------------------
# Figure and docs


def plot(summary, path):
    plt = C.pyplot()
    if plt is None:
        return
    cases = [c for c in summary["cases"] if "stage1" in c]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    labels = [f"{c['dim']}D {c['size']}" for c in cases]
    x = range(len(cases))
    ax1.bar([i - 0.2 for i in x], [c["speedup"] for c in cases], width=0.4, label="GranMPM speed-up 1 -> 2 ranks")
    ax1.bar([i + 0.2 for i in x], [summary["capacity"]] * len(cases), width=0.4, label="capacity 2 t1/t2 (compute loop)")
    ax1.axhline(2.0, color="k", lw=0.8, ls="--")
    for i, c in enumerate(cases):
        ax1.text(i - 0.2, c["speedup"] + 0.03, f"{100 * c['fraction']:.0f}%", ha="center", fontsize=9)
    ax1.set_xticks(list(x))
    ax1.set_xticklabels(labels)
    ax1.set_ylabel("speed-up / capacity (medians)")
    ax1.set_ylim(0, 2.3)
    ax1.legend(fontsize=8, loc="lower right")
    ax1.set_title("strong scaling 1 -> 2 ranks (% = fraction of capacity)", fontsize=10)
    names, bottoms = [], []
    for c in cases:
        for np_ in (1, 2):
            if f"share{np_}" in c:
                names.append(f"{c['dim']}D {c['size']}\n{np_} rank(s)")
                bottoms.append(c[f"share{np_}"])
    b = [0.0] * len(names)
    for s in STAGES:
        v = [100 * sh[s] for sh in bottoms]
        if max(v, default=0) <= 0:
            continue
        ax2.bar(range(len(names)), v, bottom=b, label=s)
        b = [p + q for p, q in zip(b, v)]
    ax2.set_xticks(range(len(names)))
    ax2.set_xticklabels(names, fontsize=8)
    ax2.set_ylabel("share of time-loop stages [%] (-log_view)")
    ax2.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.0, 0.5))
    ax2.set_title("stage split", fontsize=10)
    fig.tight_layout()
    C.save_figure(fig, path)


def write_docs(summary, meta, a):
    cap = summary["capacity"]
    caps = ", ".join(f"{v:.2f}" for _, v in sorted(summary["capacity_all"].items()))
    parts = [f"Run: `/usr/bin/python3 bench/scaling.py` ({meta['binary']}, {meta['host']}, {meta['date']}; "
             f"{meta.get('repeats')} interleaved repeats, {meta.get('steps')} steps, every run with `-log_view`). "
             f"Capacity of the machine for two processes (compute loop, 2 t1/t2): median {cap:.2f} (repeats: {caps}).\n"]
    rows = []
    for c in summary["cases"]:
        if "wall1" not in c:
            continue
        rows.append([f"{c['dim']}D {c['size']}", f"{c['particles']}", f"{c['wall1']:.2f}", f"{c.get('wall2', float('nan')):.2f}",
                     f"{c['speedup']:.2f} ({', '.join('%.2f' % s for s in c['speedups'])})", f"{cap:.2f}",
                     f"{100 * c['fraction']:.0f}% ({', '.join('%.0f%%' % (100 * f) for f in c['fractions'])})"])
    parts.append(C.md_table(["case", "particles", "wall 1 rank [s]", "wall 2 ranks [s]", "speed-up (repeats)", "capacity", "fraction of capacity (repeats)"], rows,
                            ["l", "r", "r", "r", "r", "r", "r"]))
    parts.append("\nWall times are the solver's time-loop wall (medians); speed-up and fraction are paired within each repeat, then the median "
                 "is taken. Target of the issue: fraction >= 90%.\n")
    parts.append("### Stage shares (-log_view, medians)\n")
    rows = []
    for c in summary["cases"]:
        for np_ in (1, 2):
            if f"share{np_}" not in c:
                continue
            sh, st = c[f"share{np_}"], c[f"stage{np_}"]
            per_step = sum(st.values()) / c["steps"]
            rows.append([f"{c['dim']}D {c['size']}", np_, f"{1e3 * per_step:.1f}"] + [f"{100 * sh[s]:.1f}" for s in STAGES[:5]])
    parts.append(C.md_table(["case", "ranks", "stages per step [ms]"] + [f"{s} [%]" for s in STAGES[:5]], rows, ["l"] + ["r"] * 7))
    parts.append("\nShares of the sum of the time-loop stages (Fluidity and Output are zero for the elastic block). GridUpdate contains the "
                 "halo exchange (reverse scatter of nodal mass and momentum, forward scatter of the velocities); Migrate contains the "
                 "ownership check of every particle and the exchange of the particles that left the rank.\n")
    parts.append("### Calibrated model parameters\n")
    rows = []
    for c in summary["cases"]:
        if "a" not in c:
            continue
        rows.append([f"{c['dim']}D {c['size']}", sci(c["a"]), sci(c["a_migrate_local"]), sci(c["b"]), f"{c.get('halo_bytes', 0) / 1e3:.0f}",
                     sci(c.get("extra_grid_per_step")), sci(c.get("c")), f"{c.get('migrated_per_step', float('nan')):.0f}", sci(c.get("extra_mig_per_step")), sci(c.get("d"))])
    parts.append(C.md_table(["case", "a [s/particle-step]", "of which Migrate", "b [s/node-step]", "halo per rank [kB]", "extra GridUpdate 2 ranks [s/step]",
                             "c [s/byte]", "migrated per step (est.)", "extra Migrate 2 ranks [s/step]", "d [s/particle]"], rows, ["l"] + ["r"] * 9))
    parts.append("\na = (P2G + G2P + Constitutive + Migrate) / (N steps) and b = GridUpdate / (nodes steps) on 1 rank; 'extra' = stage time on "
                 "2 ranks minus half the 1-rank time, per step; c = extra GridUpdate / halo bytes per rank (periodic slab split, width 2, "
                 f"{HALO_DOUBLES} doubles per node in 3D, 7 in 2D: an assumption about what the exchange carries); d = extra Migrate / (estimated "
                 "migrated particles per rank). On one shared-memory node these are upper bounds that include waiting for the slower rank "
                 "and the sharing of the cores; negative values mean the 2-rank stage was faster than half the 1-rank one (noise, cache).\n")
    if any((c.get("d") or 0) > 1e-6 for c in summary["cases"]):
        parts.append("The extra Migrate time is far more than moving a few hundred particles can cost (d above 1e-6 s per particle): "
                     "Migrate ends each step (stage order P2G, GridUpdate, G2P, Constitutive, Fluidity, Migrate) and holds the first "
                     "exchange and allreduce after the particle work of G2P and Constitutive, so it absorbs the wait for the slower rank; "
                     "GridUpdate (halo exchange and the allreduces of the instability guard) does the same for P2G. d here is a wait "
                     "time divided by a particle count, not a migration cost.\n")
    c3 = next((c for c in summary["cases"] if c["dim"] == 3 and "a" in c), None)
    if c3:
        parts.append("### Weak-scaling prediction (3D, 1e6 particles per rank)\n")
        rows = []
        for P in (8, 64, 1000, 4096, 32768):
            w = weak_prediction(c3, P)
            rows.append([P, f"{P * 1e6:.0e}", f"{1e3 * w['t_work']:.0f}", f"{1e6 * w['t_halo']:.0f}", f"{1e6 * w['t_mig']:.0f}", f"{1e6 * w['t_red']:.0f}",
                         f"{100 * w['eff']:.2f}%"])
        parts.append(C.md_table(["ranks P", "particles", "work a N/P + b nodes/P [ms]", "halo [us]", "migration [us]", "allreduces [us]",
                                 "efficiency"], rows))
        w = weak_prediction(c3, 1000)
        parts.append(f"\na = {sci(c3['a'])} s and b = {sci(c3['b'])} s measured here (3D, 1 rank); halo {w['halo_bytes'] / 1e6:.2f} MB per rank "
                     f"and step, about {w['migrated']:.0f} migrated particles per rank and step (200 bytes each); latency 1.5 us, bandwidth "
                     "10 GB/s per rank, 26 neighbours, 4 allreduces per step of log2(P) latencies: ASSUMED, not measured. See the model "
                     "section above for what this leaves out (memory bandwidth of a full node, imbalance, the fluidity solve).\n")
    parts.append("### Correctness on 1-8 ranks (oversubscribed: timings meaningless)\n")
    rows = []
    for d in summary["checks"]:
        rows.append([d["ranks"], d.get("particles"), f"{d['ke']:.9e}" if d.get("ke") is not None else "-",
                     sci(d.get("rel_ke"), 1) if "rel_ke" in d else "-", "yes" if d.get("pass") else ("-" if d["ranks"] == 1 else "NO")])
    parts.append(C.md_table(["ranks", "particles", "final kinetic energy [J]", "relative difference to 1 rank", "same N and KE to print precision"], rows))
    ck = CHECK_QUICK if a.quick else CHECK_FULL
    parts.append(f"\n2D block {ck[2][0]} x {ck[2][1]} cells, same arguments as above; the kinetic energy is printed with 10 significant digits, "
                 "so one unit in the last digit (up to 1e-9 relative) is the resolution of the comparison; a difference of 0 means the printed values agree in all 10 digits.\n")
    C.replace_doc_section("scaling.md", "scaling", "Measured strong scaling", "\n".join(parts), "Scaling")


def sci(v, digits=2):
    if v is None or (isinstance(v, float) and v != v):
        return "-"
    return f"{v:.{digits}e}"


def main():
    ap = C.common_argparser(__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=None, help="time steps per run (default 30; quick 20)")
    ap.add_argument("--dims", default="2,3", help="which block dimensions to time (default 2,3)")
    ap.add_argument("--loop-iters", type=int, default=None, help="sweeps of the compute loop (default: about 1-3 s on one idle core)")
    a = ap.parse_args()
    dims = [int(d) for d in a.dims.split(",")]
    sizes = [s for s in (SIZES_QUICK if a.quick else SIZES_FULL) if s[0] in dims]
    check = CHECK_QUICK if a.quick else CHECK_FULL
    steps = a.steps or (20 if a.quick else 30)
    csv_path, png_path = C.output_paths(NAME, a.quick)
    if a.replot:
        rows = C.read_csv(csv_path, strings=("size", "kind", "ke_printed"))
        rows = [dict(r, ke_printed=float(r["ke_printed"])) if r.get("ke_printed") else r for r in rows]
        for r in rows:
            r["block_particles"] = r.get("particles")
            r["ke"] = r.get("ke_printed")
        summary = analyse(rows, sizes)
        plot(summary, png_path)
        if not (a.quick or a.no_docs):
            write_docs(summary, C.read_meta(csv_path), a)
        return 0
    binary = C.granmpm_binary()
    tmp = tempfile.mkdtemp(prefix="granmpm-scaling-")
    try:
        exe = compile_loop(tmp)
        n_loop = max(s[2][0] * s[2][1] * (s[2][2] if len(s[2]) > 2 else 1) * 2 ** s[0] for s in sizes) // 2
        iters = a.loop_iters or max(4, int(2e7 / n_loop))
        rows = []
        for rep in range(1, a.repeats + 1):
            rows.append(run_loop(exe, 1, n_loop, iters, rep))
            rows.append(run_loop(exe, 2, n_loop, iters, rep))
            for dim, label, cells in sizes:
                for np_ in (1, 2):
                    rows.append(run_block("strong", dim, label, cells, np_, rep, steps))
        # Oversubscribed correctness runs: let idle ranks yield the core (Open MPI busy-polls by default).
        os.environ.setdefault("OMPI_MCA_mpi_yield_when_idle", "1")
        for np_ in CHECK_RANKS:
            rows.append(run_block("check", check[0], check[1], check[2], np_, 1, steps))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    C.write_csv(csv_path, COLUMNS, rows)
    meta = C.write_meta(csv_path, binary, repeats=a.repeats, steps=steps, loop_particles_per_rank=n_loop, loop_iters=iters,
                        command="/usr/bin/python3 bench/scaling.py" + (" --quick" if a.quick else ""))
    summary = analyse(rows, sizes)
    for c in summary["cases"]:
        print(f"# {c['dim']}D {c['size']}: speed-up {c['speedup']:.3f}, capacity {summary['capacity']:.3f}, fraction {c['fraction']:.3f}", file=sys.stderr)
    for d in summary["checks"]:
        print(f"# check np {d['ranks']}: N {d.get('particles')}, KE {d.get('ke')}, rel {d.get('rel_ke')}, pass {d.get('pass')}", file=sys.stderr)
    plot(summary, png_path)
    if not (a.quick or a.no_docs):
        write_docs(summary, meta, a)
    bad = [d for d in summary["checks"] if d["ranks"] > 1 and not d.get("pass")]
    return 1 if bad or not all(r["ok"] for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
