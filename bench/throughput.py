#!/usr/bin/env python3
"""Throughput (particle-steps/s) and memory per particle of the explicit MPM core.

Elastic block filling a fully periodic box (-scene block -material elastic, E = 1e6 Pa, nu = 0.3,
rho = 1500 kg/m^3: wave speed 29.96 m/s), quadratic B-splines, APIC, USL, gravity 0, 2 particles per cell per
direction, initial velocity (3, 2[, 1]) m/s plus a spin of 1 rad/s about z so that particles move (up to about
one cell over the run) and migrate between cells and ranks; fixed dt = 0.25 h / c (about a quarter of the CFL
limit h/(c + |v|max)); 40 steps; no output. Sizes about 1e5 and 1e6 particles in 2D and 3D, on 1 and 2 MPI
ranks, each case repeated (default 3 times, interleaved) and the median taken.

The rate is the solver's own "particle-steps/s" (global particles x steps / wall time of the time loop).
Memory is the peak RSS summed over ranks (getrusage, as the solver prints it). Per-particle and per-node
costs on 1 rank: marginal RSS between the two sizes, and between 2 and 1 particles per cell per direction
on the larger grid (which separates particles from grid nodes).
With -log_view, the split of the time-stepping stages is recorded for the 1e6 cases.

Writes bench/results/throughput.csv (medians per case), throughput_runs.csv (every run),
throughput_memory.csv, throughput_stages.csv, docs/figures/throughput.png and docs/performance.md
(with --quick: bench/results/quick/, docs untouched).
"""

import os
import re
import sys

import _common as C

RE_DATA = re.compile(r"particle data (\d+) bytes per particle .*, transfer grid (\d+) bytes per node")

NAME = "throughput"
E, NU, RHO = 1e6, 0.3, 1500.0
SPIN = 1.0
STAGES = ["Migrate", "P2G", "GridUpdate", "G2P", "Constitutive", "Fluidity", "Output"]
TARGET_3D_PER_CORE = 2.5e6
CASE_COLUMNS = ["dim", "size", "ranks", "particles", "grid_nodes", "steps", "repeats", "rate_median", "rate_min", "rate_max", "rate_per_rank",
                           "rate_per_cpu_s", "wall_median", "mem_mib", "bytes_per_particle_total", "data_bytes_per_particle", "data_bytes_per_node", "loadavg_mean"]
MEM_COLUMNS = ["dim", "small_particles", "small_nodes", "small_mib", "large_particles", "large_nodes", "large_mib", "ppc1_particles",
                                       "ppc1_mib", "marginal_bytes_per_particle", "bytes_per_particle_fixed_grid", "bytes_per_node", "baseline_mib",
                                       "marginal_bytes_per_particle_2ranks"]

# (dim, label, cells): 2 particles per cell per direction -> 4 (2D) or 8 (3D) per cell.
SIZES_FULL = [
    (2, "1e5", (250, 100)),
    (2, "1e6", (500, 500)),
    (3, "1e5", (25, 25, 20)),
    (3, "1e6", (50, 50, 50)),
]
SIZES_QUICK = [
    (2, "1e4", (50, 50)),
    (2, "1e5", (250, 100)),
    (3, "1e4", (12, 12, 9)),
    (3, "1e5", (25, 25, 20)),
]


def wave_speed():
    M = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
    return (M / RHO) ** 0.5


def block_args(dim, cells, ppc=2, steps=40, extra=()):
    h = 1.0 / max(cells)
    hi = [n * h for n in cells]
    dt = 0.25 * h / wave_speed()
    faces = ["x", "y", "z"][:dim]
    a = ["-dim", str(dim), "-scene", "block", "-material", "elastic", "-E", f"{E:g}", "-nu", f"{NU:g}", "-rho", f"{RHO:g}",
         "-domain_lo", ",".join(["0"] * dim), "-domain_hi", ",".join(f"{x:.12g}" for x in hi), "-cells", ",".join(str(n) for n in cells),
         "-ppc", str(ppc), "-shape", "bspline2", "-transfer", "apic", "-update", "usl",
         "-gravity", ",".join(["0"] * dim), "-gravity_ramp", "0", "-velocity", ",".join(["3", "2", "1"][:dim]), "-spin", f"{SPIN:g}",
         "-dt", f"{dt:.6g}", "-t_end", "1e9", "-max_steps", str(steps), "-output_final", "0", "-progress_interval", "0"]
    for f in faces:
        a += [f"-bc_{f}lo", "periodic", f"-bc_{f}hi", "periodic"]
    return a + list(extra)


def summarize(runs, sizes, ranks):
    """Median per (dim, size, ranks) over the successful repeats."""
    cases = []
    for dim, label, cells in sizes:
        for np_ in ranks:
            rs = [x for x in runs if x["dim"] == dim and x["size"] == label and x["ranks"] == np_ and x["ok"]]
            if not rs:
                continue
            rate = C.median([x["rate"] for x in rs])
            mem = C.median([x["mem_mib"] for x in rs])
            ps = rs[0]["particles"] * rs[0]["steps"]
            cases.append({"dim": dim, "size": label, "ranks": np_, "particles": rs[0]["particles"], "grid_nodes": rs[0]["grid_nodes"],
                          "steps": rs[0]["steps"], "repeats": len(rs), "rate_median": rate, "rate_min": min(x["rate"] for x in rs),
                          "rate_max": max(x["rate"] for x in rs), "rate_per_rank": rate / np_,
                          "rate_per_cpu_s": C.median([ps / x["cpu_s"] for x in rs if x.get("cpu_s")]),
                          "wall_median": C.median([x["wall_s"] for x in rs]),
                          "mem_mib": mem, "bytes_per_particle_total": mem * 2**20 / rs[0]["particles"],
                          "data_bytes_per_particle": rs[0].get("data_bytes_per_particle"), "data_bytes_per_node": rs[0].get("data_bytes_per_node"),
                          "loadavg_mean": sum(x["loadavg"] for x in rs) / len(rs),
                          "cmd": C.shown_cmd(block_args(dim, cells, steps=rs[0]["steps"]), np_)})
    return cases


def add_parallel_memory(mem_rows, cases, sizes):
    """Marginal RSS per particle between the two sizes on 2 ranks (sum over ranks), next to the 1-rank value."""
    for m in mem_rows:
        sz = [s for s in sizes if s[0] == m["dim"]]
        c = [next((c for c in cases if c["dim"] == m["dim"] and c["size"] == s[1] and c["ranks"] == 2), None) for s in sz[:2]]
        if all(c):
            m["marginal_bytes_per_particle_2ranks"] = (c[1]["mem_mib"] - c[0]["mem_mib"]) * 2**20 / (c[1]["particles"] - c[0]["particles"])
    return mem_rows


# --------------------------------------------------------------------------------------
# --kernels: GranMPM against the bare single-core kernels (issue 16 goal 1)

# The 3D yardstick lives outside the repository, in ../shared/bench (beside the main checkout; a worktree is one level deeper).
BARE_SOURCES = {3: next((p for p in (os.path.join(C.REPO_ROOT, *up, "shared", "bench", "bare_mpm3d.cpp") for up in (("..",), ("..", ".."))) if os.path.isfile(p)),
                        os.path.join(C.REPO_ROOT, "..", "shared", "bench", "bare_mpm3d.cpp")),
                2: os.path.join(C.BENCH_DIR, "bare_mpm2d.cpp")}
# (dim, material, cells, target ratio to the bare kernel)
KERNEL_CASES = [(3, "elastic", (40, 40, 40), 0.8), (3, "mu_i", (40, 40, 40), 0.7), (3, "dynamic", (40, 40, 40), 0.6),
                (2, "elastic", (360, 360), 0.8), (2, "mu_i", (360, 360), 0.7), (2, "dynamic", (360, 360), 0.6)]
KERNEL_COLUMNS = ["dim", "material", "particles", "steps", "repeats", "bare_rate", "granmpm_rate", "base_rate", "ratio_bare", "ratio_bare_min",
                  "ratio_bare_max", "ratio_base", "target", "loadavg_mean"]


def build_bare(dim, src, out_dir):
    import subprocess
    exe = os.path.join(out_dir, f"bare_mpm{dim}d")
    if not os.path.isfile(src):
        sys.exit(f"bench: bare kernel source not found: {src} (set BARE_MPM{dim}D_SOURCE)")
    subprocess.run(["g++", "-O3", "-march=native", "-std=c++17", src, "-o", exe], check=True)
    return exe


def run_bare(exe, n, steps):
    """(wall-time rate, CPU seconds of the process) of one bare-kernel run."""
    import resource
    import subprocess
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run([exe, str(n), str(steps)], capture_output=True, text=True, check=True).stdout
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return float(re.search(r"rate ([0-9.eE+-]+) p-steps/s", out).group(1)), (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)


def kernels(a):
    """Bare kernel, this build and (--base) another build, interleaved on the same cases, on 1 rank.

    The ratio of each repeat is taken within the repeat (the three runs follow each other), then the median."""
    import tempfile
    steps = a.steps
    tmp = tempfile.mkdtemp(prefix="bare-")
    bare = {d: build_bare(d, os.environ.get(f"BARE_MPM{d}D_SOURCE", BARE_SOURCES[d]), tmp) for d in (2, 3)}
    ours = C.granmpm_binary()
    cases = [c for c in KERNEL_CASES if not a.materials or c[1] in a.materials.split(",")]
    # Rates per CPU-second of the time loop: each code runs S and 2 S steps and the CPU time
    # difference is divided by S particle-steps (set-up cancels). On a loaded machine the
    # wall time mostly measures waiting for a core; the CPU time does not (cache sharing remains).
    runs = []
    for rep in range(a.repeats):
        for dim, mat, cells, target in cases:
            row = {"dim": dim, "material": mat, "repeat": rep + 1, "loadavg": C.loadavg()}
            cpu = {}
            for k in (1, 2):
                rate, cpu[k] = run_bare(bare[dim], cells[0], k * steps)
                if k == 2:
                    row["bare_wall_rate"] = rate
            for key, binary in (("granmpm", ours), ("base", a.base)):
                if not binary:
                    continue
                os.environ["GRANMPM"] = binary
                c = {}
                for k in (1, 2):
                    args = block_args(dim, cells, steps=k * steps)
                    args[args.index("-material") + 1] = mat
                    r = C.run_granmpm(args, label=f"kernels {dim}D {mat} {key} {k * steps} steps rep {rep + 1}")
                    c[k] = r["cpu_s"] if r["ok"] else None
                    row["particles"] = r.get("particles")
                    if k == 2:
                        row[key + "_wall_rate"] = r.get("rate")
                if c[1] is not None and c[2] is not None and c[2] > c[1]:
                    row[key + "_rate"] = row["particles"] * steps / (c[2] - c[1])
            os.environ["GRANMPM"] = ours
            if row.get("particles") and cpu[2] > cpu[1]:
                row["bare_rate"] = row["particles"] * steps / (cpu[2] - cpu[1])
            runs.append(row)
            print(f"# {dim}D {mat}: per CPU-s bare {row.get('bare_rate')}, granmpm {row.get('granmpm_rate')}, base {row.get('base_rate')}; "
                  f"wall bare {row['bare_wall_rate']:.3g} granmpm {row.get('granmpm_wall_rate')} base {row.get('base_wall_rate')}", file=sys.stderr)
    out = []
    for dim, mat, cells, target in cases:
        rs = [r for r in runs if r["dim"] == dim and r["material"] == mat and r.get("granmpm_rate") and r.get("bare_rate")]
        if not rs:
            continue
        rb = [r["granmpm_rate"] / r["bare_rate"] for r in rs]
        rbase = [r["granmpm_rate"] / r["base_rate"] for r in rs if r.get("base_rate")]
        out.append({"dim": dim, "material": mat, "particles": rs[0]["particles"], "steps": steps, "repeats": len(rs),
                    "bare_rate": C.median([r["bare_rate"] for r in rs]), "granmpm_rate": C.median([r["granmpm_rate"] for r in rs]),
                    "base_rate": C.median([r.get("base_rate") for r in rs]) if rbase else None, "ratio_bare": C.median(rb),
                    "ratio_bare_min": min(rb), "ratio_bare_max": max(rb), "ratio_base": C.median(rbase) if rbase else None, "target": target,
                    "loadavg_mean": sum(r["loadavg"] for r in rs) / len(rs)})
    csv_path = os.path.join(C.RESULTS_DIR, "throughput_kernels.csv")
    runs_path = os.path.join(C.RESULTS_DIR, "throughput_kernels_runs.csv")
    if a.materials:  # a subset: keep the other cases of the last run (their rows name their own repeats)
        done = {(o["dim"], o["material"]) for o in out}
        order = [(c[0], c[1]) for c in KERNEL_CASES]
        for path, rows in ((csv_path, out), (runs_path, runs)):
            if os.path.isfile(path):
                rows += [r for r in C.read_csv(path, strings=("material",)) if (r["dim"], r["material"]) not in done]
            rows.sort(key=lambda r: order.index((r["dim"], r["material"])))
    C.write_csv(csv_path, KERNEL_COLUMNS, out)
    meta = C.write_meta(csv_path, ours, base=a.base or "")
    if a.no_docs:
        return 0
    tab = [[f"{o['dim']}D", o["material"], f"{o['particles']:,}", f"{o['bare_rate']:.3g}", f"{o['granmpm_rate']:.3g}",
            f"{o['base_rate']:.3g}" if o.get("base_rate") else "-", f"{o['ratio_bare']:.2f} ({o['ratio_bare_min']:.2f}-{o['ratio_bare_max']:.2f})",
            f">= {o['target']}" + (" met" if o["ratio_bare"] >= o["target"] else " not met"), f"{o['ratio_base']:.2f}" if o.get("ratio_base") else "-",
            f"{o['loadavg_mean']:.1f}"] for o in out]
    C.write_csv(runs_path, ["dim", "material", "repeat", "particles", "bare_rate", "granmpm_rate", "base_rate", "bare_wall_rate", "granmpm_wall_rate",
                            "base_wall_rate", "loadavg"], runs)
    body = ("Produced by `bench/throughput.py --kernels --repeats " + str(a.repeats) + (" --base " + a.base if a.base else "") + "` (" + meta["binary"] + ", " +
            meta["date"] + ") on " + meta["host"] + ". Every repeat runs the bare single-core kernel (`../shared/bench/bare_mpm3d.cpp`, "
            "`bench/bare_mpm2d.cpp`, built with `g++ -O3 -march=native`), this GranMPM build and the base build one after the other on the "
            f"case of the throughput table (periodic elastic block, quadratic B-splines, APIC, USL, 2 particles per cell per direction, {steps} steps, 1 rank; "
            "GranMPM with the material of the row, the bare kernel always elastic and without the spin); ratios are taken within a repeat, "
            "then the median (min-max over repeats). Rates are particle-steps per CPU-second of the time loop: each code runs " + str(steps) +
            " and " + str(2 * steps) + " steps and the difference of the process CPU times (user + system) is divided by the extra particle-steps, "
            "so set-up cancels and waiting for a core on the loaded machine does not count (sharing of caches and memory bandwidth still does).\n\n" +
            C.md_table(["dim", "material", "particles", "bare kernel", "GranMPM", "base", "GranMPM / bare", "goal", "GranMPM / base", "load avg"], tab) + "\n")
    C.replace_doc_section("performance.md", "kernels", "Against the bare kernel (issue 16 goal 1)", body, "GranMPM performance")
    return 0


def main():
    ap = C.common_argparser(__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--ranks", default="1,2", help="comma-separated MPI rank counts (default 1,2)")
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--kernels", action="store_true", help="only the ratio to the bare kernels (issue 16 goal 1), see kernels()")
    ap.add_argument("--base", default=None, help="with --kernels: a second granmpm binary (e.g. old main) run in the same repeats")
    ap.add_argument("--materials", default=None, help="with --kernels: comma-separated subset of elastic,mu_i,dynamic")
    a = ap.parse_args()
    if a.kernels:
        if not a.quick and a.steps == 40:
            a.steps = 20
        return kernels(a)
    sizes = SIZES_QUICK if a.quick else SIZES_FULL
    ranks = [int(x) for x in a.ranks.split(",")]
    csv_path, png_path = C.output_paths(NAME, a.quick)
    base = os.path.splitext(csv_path)[0]
    if a.replot:
        runs = C.read_csv(base + "_runs.csv", strings=("size",))
        a.repeats = max(r["repeat"] for r in runs)
        a.steps = runs[0]["steps"]
        ranks = sorted({r["ranks"] for r in runs})
        cases = summarize(runs, sizes, ranks)
        mem_rows = C.read_csv(base + "_memory.csv")
        stage_rows = C.read_csv(base + "_stages.csv", strings=("size",))
        mem_rows = add_parallel_memory(mem_rows, cases, sizes)
        C.write_csv(csv_path, CASE_COLUMNS, cases)
        C.write_csv(base + "_memory.csv", MEM_COLUMNS, mem_rows)
        plot(cases, runs, stage_rows, png_path, ranks)
        if not (a.quick or a.no_docs):
            write_docs(cases, mem_rows, stage_rows, C.read_meta(csv_path), a, runs)
        return 0
    binary = C.granmpm_binary()

    runs = []
    for rep in range(a.repeats):  # interleave the repeats so that slow phases of a shared machine spread over all cases
        for dim, label, cells in sizes:
            for np_ in ranks:
                r = C.run_granmpm(block_args(dim, cells, steps=a.steps), np_=np_, label=f"throughput {dim}D {label} np {np_} rep {rep + 1}")
                if not r["ok"]:
                    print(r["output"][-2000:], file=sys.stderr)
                m = RE_DATA.search(r["output"])
                runs.append({"dim": dim, "size": label, "ranks": np_, "repeat": rep + 1, "particles": r.get("particles"),
                             "data_bytes_per_particle": int(m.group(1)) if m else None, "data_bytes_per_node": int(m.group(2)) if m else None,
                             "grid_nodes": r.get("grid_nodes"), "steps": r.get("steps"), "wall_s": r.get("wall_s"), "rate": r.get("rate"),
                             "elapsed_s": r["elapsed"], "cpu_s": r["cpu_s"], "mem_mib": r.get("mem_mib"), "loadavg": r["loadavg"], "ok": r["ok"], "cmd": r["cmd"]})

    cases = summarize(runs, sizes, ranks)

    # Memory model on 1 rank: RSS = base + b_p * particles + b_n * nodes, from the two sizes at 2 PPC and
    # the larger grid at 1 PPC.
    mem_rows = []
    for dim in (2, 3):
        sz = [s for s in sizes if s[0] == dim]
        small = next((c for c in cases if c["dim"] == dim and c["size"] == sz[0][1] and c["ranks"] == 1 and c.get("mem_mib")), None)
        large = next((c for c in cases if c["dim"] == dim and c["size"] == sz[1][1] and c["ranks"] == 1 and c.get("mem_mib")), None)
        if not (small and large):
            continue
        r1 = C.run_granmpm(block_args(dim, sz[1][2], ppc=1, steps=a.steps), label=f"memory {dim}D {sz[1][1]} grid, 1 PPC")
        row = {"dim": dim, "small_particles": small["particles"], "small_nodes": small["grid_nodes"], "small_mib": small["mem_mib"],
               "large_particles": large["particles"], "large_nodes": large["grid_nodes"], "large_mib": large["mem_mib"],
               "marginal_bytes_per_particle": (large["mem_mib"] - small["mem_mib"]) * 2**20 / (large["particles"] - small["particles"])}
        if r1["ok"] and r1.get("mem_mib"):
            bp = (large["mem_mib"] - r1["mem_mib"]) * 2**20 / (large["particles"] - r1["particles"])
            bn = ((large["mem_mib"] - small["mem_mib"]) * 2**20 - bp * (large["particles"] - small["particles"])) / (large["grid_nodes"] - small["grid_nodes"])
            base_mib = large["mem_mib"] - (bp * large["particles"] + bn * large["grid_nodes"]) / 2**20
            row.update({"ppc1_particles": r1["particles"], "ppc1_mib": r1["mem_mib"], "bytes_per_particle_fixed_grid": bp, "bytes_per_node": bn,
                        "baseline_mib": base_mib})
        mem_rows.append(row)

    mem_rows = add_parallel_memory(mem_rows, cases, sizes)

    # Stage split of the time loop from -log_view, for the larger sizes.
    stage_rows = []
    for dim, label, cells in sizes[1::2]:
        for np_ in ranks:
            r = C.run_granmpm(block_args(dim, cells, steps=a.steps, extra=["-log_view"]), np_=np_, label=f"log_view {dim}D {label} np {np_}")
            st = r.get("stages", {})
            tot = sum(st.get(s, 0.0) for s in STAGES)
            row = {"dim": dim, "size": label, "ranks": np_, "particles": r.get("particles"), "rate": r.get("rate"), "loop_stage_time_s": tot}
            for s in STAGES:
                row[s] = st.get(s, 0.0) / tot if tot > 0 else None
            row["main_stage_s"] = st.get("Main Stage")
            stage_rows.append(row)

    C.write_csv(csv_path, CASE_COLUMNS, cases)
    print()
    C.write_csv(base + "_runs.csv", ["dim", "size", "ranks", "repeat", "particles", "grid_nodes", "steps", "wall_s", "rate", "elapsed_s", "cpu_s", "mem_mib", "data_bytes_per_particle", "data_bytes_per_node", "loadavg", "ok"], runs)
    print()
    C.write_csv(base + "_memory.csv", MEM_COLUMNS, mem_rows)
    print()
    C.write_csv(base + "_stages.csv", ["dim", "size", "ranks", "particles", "rate", "loop_stage_time_s"] + STAGES + ["main_stage_s"], stage_rows)
    meta = C.write_meta(csv_path, binary)
    plot(cases, runs, stage_rows, png_path, ranks)
    if not (a.quick or a.no_docs):
        write_docs(cases, mem_rows, stage_rows, meta, a, runs)


def plot(cases, runs, stage_rows, path, ranks):
    plt = C.pyplot()
    if plt is None:
        return
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.8))
    labels, xs = [], []
    width = 0.8 / len(ranks)
    ok = [c for c in cases if c.get("repeats")]
    groups = []
    for c in ok:
        g = (c["dim"], c["size"])
        if g not in groups:
            groups.append(g)
    for j, np_ in enumerate(ranks):
        vals, errs_lo, errs_hi, pos = [], [], [], []
        for i, g in enumerate(groups):
            c = next((c for c in ok if (c["dim"], c["size"]) == g and c["ranks"] == np_), None)
            if c is None:
                continue
            pos.append(i + (j - (len(ranks) - 1) / 2) * width)
            vals.append(c["rate_median"] / np_)
            errs_lo.append((c["rate_median"] - c["rate_min"]) / np_)
            errs_hi.append((c["rate_max"] - c["rate_median"]) / np_)
        ax1.bar(pos, vals, width=width, yerr=[errs_lo, errs_hi], capsize=3, label=f"{np_} rank(s)")
    ax1.axhline(TARGET_3D_PER_CORE, color="k", linestyle="--", linewidth=0.8, label="3D target 2.5e6 per core")
    ax1.set_xticks(range(len(groups)))
    ax1.set_xticklabels([f"{d}D, {s} part." for d, s in groups])
    ax1.set_ylabel("particle-steps/s per rank (median, min-max bars)")
    load = [c["loadavg_mean"] for c in ok if c.get("loadavg_mean") is not None]
    ax1.set_title("bspline2 + APIC elastic block" + (f"; machine load avg {min(load):.1f}-{max(load):.1f} on {os.cpu_count()} cores" if load else ""),
                  fontsize=10)
    ax1.legend(fontsize=8)
    ax1.grid(True, axis="y", alpha=0.3)
    if stage_rows:
        bottom = [0.0] * len(stage_rows)
        names = [f"{r['dim']}D {r['size']}\n{r['ranks']} rank(s)" for r in stage_rows]
        for s in STAGES:
            v = [100 * (r.get(s) or 0.0) for r in stage_rows]
            if max(v) <= 0:
                continue
            ax2.bar(range(len(stage_rows)), v, bottom=bottom, label=s)
            bottom = [b + x for b, x in zip(bottom, v)]
        ax2.set_xticks(range(len(stage_rows)))
        ax2.set_xticklabels(names, fontsize=8)
        ax2.set_ylabel("share of time-loop stages [%] (-log_view)")
        ax2.set_title("stage split", fontsize=10)
        ax2.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    C.save_figure(fig, path)


def two_d_ratio(ok):
    r = []
    for size in sorted({c["size"] for c in ok}):
        c2 = next((c for c in ok if c["dim"] == 2 and c["size"] == size and c["ranks"] == 1), None)
        c3 = next((c for c in ok if c["dim"] == 3 and c["size"] == size and c["ranks"] == 1), None)
        if c2 and c3:
            r.append(f"{c2['rate_median'] / c3['rate_median']:.1f}x at {c2['particles']:,} particles")
    return ("On 1 rank, 2D is " + ", ".join(r) + " faster per particle-step than 3D (9 instead of 27 nodes per particle with "
            "quadratic B-splines).") if r else ""


def write_docs(cases, mem_rows, stage_rows, meta, a, runs):
    ok = [c for c in cases if c.get("repeats")]
    load = [c["loadavg_mean"] for c in ok]
    parts = [
        "Produced by `bench/throughput.py` (" + meta["binary"] + ", " + meta["date"] + ") on " + meta["host"] + ", a shared machine: "
        f"the 1-minute load average before the runs was {min(load):.1f}-{max(load):.1f} (other jobs were running), so absolute "
        "rates are noisy; each number is the median of " + str(a.repeats) + " interleaved repeats, with the min-max range.\n",
        "Case: elastic block filling a periodic box, quadratic B-splines, APIC, USL, 2 particles per cell per direction, "
        "E = 1e6 Pa, nu = 0.3, rho = 1500 kg/m^3, initial velocity (3, 2[, 1]) m/s plus spin 1 rad/s (particles move up to about "
        f"a cell and cross rank boundaries), dt = 0.25 h/c, {a.steps} steps, no output. "
        "The rate is the solver's printed particle-steps/s (global particles x steps / wall time of the time loop). "
        "'Per CPU-second' divides particles x steps by the user + system CPU time of all processes of the run (set-up and "
        "MPI busy-waiting included), which is less sensitive to other jobs than the wall time. "
        "Memory is the peak RSS summed over ranks. Command for the 3D 1e6 case on 2 ranks:\n",
        "```\n" + next((c["cmd"] for c in ok if c["dim"] == 3 and c["ranks"] == max(x["ranks"] for x in ok) and c["size"] == ok[-1]["size"]), ok[-1]["cmd"]) + "\n```\n",
    ]
    tab = []
    for c in ok:
        tab.append([f"{c['dim']}D", f"{c['particles']:,}", f"{c['grid_nodes']:,}", c["ranks"], f"{c['rate_median']:.3g}",
                    f"{c['rate_min']:.3g}-{c['rate_max']:.3g}", f"{c['rate_per_rank']:.3g}", f"{c['rate_per_cpu_s']:.3g}" if c.get("rate_per_cpu_s") else "-",
                    f"{c['wall_median']:.2f}", f"{c['mem_mib']:.0f}", f"{c['bytes_per_particle_total']:.0f}"])
    parts.append("### Throughput\n")
    parts.append(C.md_table(["dim", "particles", "grid nodes", "ranks", "particle-steps/s", "range", "per rank", "per CPU-second", "loop wall [s]",
                             "peak RSS [MiB]", "RSS / particle [B]"], tab) + "\n")
    # 2-rank speed-up measured in the same script run, and how much CPU the runs actually got
    sp = []
    for c in ok:
        if c["ranks"] == 1:
            c2 = next((x for x in ok if x["dim"] == c["dim"] and x["size"] == c["size"] and x["ranks"] == 2), None)
            if c2:
                sp.append(f"{c['dim']}D {c['particles']:,}: {c2['rate_median'] / c['rate_median']:.2f}")
    util = {}
    for np_ in sorted({c["ranks"] for c in ok}):
        u = [x["cpu_s"] / x["elapsed_s"] for x in runs if x["ranks"] == np_ and x.get("ok") and x.get("cpu_s") and x.get("elapsed_s")]
        if u:
            util[np_] = C.median(u)
    if sp:
        parts.append("Speed-up of 2 ranks over 1 (ratio of medians): " + "; ".join(sp) + ". " +
                     ("CPU-seconds used per elapsed second (median over runs): " + ", ".join(f"{u:.2f} on {n} rank(s)" for n, u in util.items()) +
                      ". A value well below the rank count means the ranks did not have a core each, so these ratios do not measure "
                      "parallel scaling; repeat on an idle machine for that." if util else "") + "\n")
    c3 = [c for c in ok if c["dim"] == 3]
    if c3:
        one = [c for c in c3 if c["ranks"] == 1]
        parts.append("### Against the 3D target\n")
        parts.append("Target: 3D >= 2.5e6 particle-steps/s per core. Measured on 1 rank (median wall-time rate / median per CPU-second): " +
                     "; ".join(f"{c['particles']:,} particles {c['rate_median']:.3g} / {c['rate_per_cpu_s']:.3g}, "
                               f"{c['rate_median'] / TARGET_3D_PER_CORE:.0%} / {c['rate_per_cpu_s'] / TARGET_3D_PER_CORE:.0%} of the target" for c in one) +
                     ". The target is " + ("met" if max(max(c["rate_median"], c["rate_per_cpu_s"]) for c in one) >= TARGET_3D_PER_CORE else "not met") +
                     " on this machine: even counting only the CPU time the run got, a 3D quadratic B-spline + APIC step costs about " +
                     f"{1e9 / max(c['rate_per_cpu_s'] for c in one):.0f} ns per particle, against the {1e9 / TARGET_3D_PER_CORE:.0f} ns the target allows. "
                     + two_d_ratio(ok) + "\n")
    if mem_rows:
        parts.append("### Memory\n")
        mt = []
        for m in mem_rows:
            mt.append([f"{m['dim']}D", f"{m['small_particles']:,} / {m['large_particles']:,}", f"{m['small_mib']:.0f} / {m['large_mib']:.0f}",
                       f"{m['marginal_bytes_per_particle']:.0f}", f"{m.get('ppc1_particles', 0):,}", f"{m['ppc1_mib']:.0f}" if m.get("ppc1_mib") else "-",
                       f"{m['bytes_per_particle_fixed_grid']:.0f}" if m.get("bytes_per_particle_fixed_grid") else "-",
                       f"{m['bytes_per_node']:.0f}" if m.get("bytes_per_node") is not None else "-",
                       f"{m['baseline_mib']:.0f}" if m.get("baseline_mib") is not None else "-",
                       f"{m['marginal_bytes_per_particle_2ranks']:.0f}" if m.get("marginal_bytes_per_particle_2ranks") else "-"])
        parts.append(C.md_table(["dim", "particles (2 sizes)", "RSS [MiB]", "marginal B/particle (incl. grid)", "particles at 1 PPC, large grid",
                                 "RSS [MiB]", "B/particle at fixed grid", "B/grid node", "fitted baseline [MiB]",
                                 "marginal B/particle on 2 ranks"], mt) + "\n")
        parts.append("1 rank unless stated. Marginal bytes per particle: RSS difference between the two sizes at 2 PPC divided by the "
                     "particle difference (the grid grows with the particles, so this includes the grid's share). At fixed grid: the larger "
                     "grid with 2 and 1 PPC. Per grid node: the rest of the size difference divided by the node difference. Last column: "
                     "the same as the first marginal value with the RSS summed over 2 ranks. Peak RSS includes set-up transients, so these "
                     "are upper estimates of the steady footprint.\n")
        dc = [c for c in ok if c.get("data_bytes_per_particle")]
        if dc:
            parts.append("Counted by the solver (its line 'particle data ... bytes per particle ..., transfer grid ... bytes per node'): " +
                         "; ".join(f"{c['dim']}D {c['particles']:,} on {c['ranks']} rank(s): {c['data_bytes_per_particle']} B/particle, "
                                   f"{c['data_bytes_per_node']} B/node" for c in dc) +
                         ". Particle data = the swarm's fields plus the per-particle step buffers; node = the transfer grid's global and "
                         "ghosted vectors (7 doubles per node in 3D, 5 in 2D, plus ghosts). Target: <= 400 B per particle in 3D.\n")
    if stage_rows:
        parts.append("### Stage split (-log_view)\n")
        st = []
        for r in stage_rows:
            st.append([f"{r['dim']}D", f"{r['particles']:,}" if r.get("particles") else "-", r["ranks"]] +
                      [f"{100 * r[s]:.1f}%" if r.get(s) is not None else "-" for s in ["P2G", "G2P", "GridUpdate", "Constitutive", "Migrate"]])
        parts.append(C.md_table(["dim", "particles", "ranks", "P2G", "G2P", "GridUpdate", "Constitutive", "Migrate"], st) + "\n")
        parts.append("Share of each stage in the sum of the time-loop stages (Migrate, P2G, GridUpdate, G2P, Constitutive, Fluidity, "
                     "Output; Fluidity and Output are zero here), from one extra run per row with `-log_view` (average over ranks).\n")
    parts.append("Figure: `docs/figures/throughput.png`. Raw runs: `bench/results/throughput_runs.csv`.\n")
    C.replace_doc_section("performance.md", "throughput", "Throughput and memory", "\n".join(parts), "GranMPM performance")


if __name__ == "__main__":
    sys.exit(main())
