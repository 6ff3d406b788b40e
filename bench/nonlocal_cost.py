#!/usr/bin/env python3
"""Cost of the steady nonlocal fluidity against the local mu(I) model on the 2D chute (issue 15 goal 1).

For each grid (N cells across, 4 high, square cells) the same binary runs, interleaved and repeated:
  local     examples/chute_local.opts (mu(I), no fluidity solve)
  nonlocal  examples/chute_nonlocal.opts with the defaults (adaptive solve interval, auto solver)
  every     the same with -fluidity_resolve_max 1 (a solve every step: the interval's effect)
and, with --base BINARY (e.g. a build of old main), "base": the nonlocal case run by that binary.
The dynamical model (seed 004, examples/chute_dynamic.opts, same grid) as the variants
  dynamic            implicit fluidity step (the example's default)
  dynamic_explicit   -fluidity_step explicit
  dynamic_A0         -A 0: the same hyperelastic model with the nonlocal term off
  base_dynamic       "dynamic" run by the --base binary
  tc3d_dynamic       a 3D flow: examples/taylor_couette_3d_dynamic.opts to t = --tc3d_t (its own grid; the
                     --cells value is only the row label; rel_err is empty, the run prints its torque)
Prints CSV (medians over --repeat runs of the wall time reported by granmpm, and of the CPU time of the
run, which a loaded machine inflates less) with the ratios to the local model of the same round, the relative L2 error against the 1D reference, the Fluidity stage's share of the
step stages (-log_view) and the number of fluidity solves. Writes bench/results/nonlocal_cost.csv.
"""

import os
import re
import sys

import _common as C

NAME = "nonlocal_cost"
COLUMNS = ["cells", "np", "variant", "wall_s", "ratio_to_local", "cpu_s", "cpu_ratio_to_local", "rel_err", "fluidity_share", "solves", "steps", "runs"]
STEP_STAGES = ["Migrate", "P2G", "GridUpdate", "G2P", "Constitutive", "Fluidity"]
RE_SOLVES = re.compile(r"^(?:FluiditySolve|KSPSolve)\s+(\d+)", re.M)  # the banded path has no KSPSolve


TC3D_T = 0.05


def args_for(variant, cells):
    v = variant[len("base_"):] if variant.startswith("base_") else variant
    if v == "tc3d_dynamic":
        return ["-options_file", os.path.join(C.REPO_ROOT, "examples", "taylor_couette_3d_dynamic.opts"), "-t_end", f"{TC3D_T:g}",
                "-output_final", "0", "-progress_interval", "0", "-log_view"]
    opts = "chute_local.opts" if v == "local" else "chute_dynamic.opts" if v.startswith("dynamic") else "chute_nonlocal.opts"
    a = ["-options_file", os.path.join(C.REPO_ROOT, "examples", opts), "-cells", f"{cells},4", "-domain_hi", f"0.5,{4.0 / cells:.12g}",
         "-output_final", "0", "-progress_interval", "0", "-log_view"]
    if v == "every":
        a += ["-fluidity_resolve_max", "1"]
    if v == "dynamic_explicit":
        a += ["-fluidity_step", "explicit"]
    if v == "dynamic_A0":
        a += ["-A", "0"]
    return a


def run(variant, cells, np_, base):
    env_old = os.environ.get("GRANMPM")
    on_base = variant == "base" or variant.startswith("base_")
    if on_base:
        os.environ["GRANMPM"] = base
    try:
        r = C.run_granmpm(args_for(variant, cells), np_=np_, label=f"{variant} {cells} cells np {np_}")
    finally:
        if on_base:
            if env_old is None:
                del os.environ["GRANMPM"]
            else:
                os.environ["GRANMPM"] = env_old
    st = r.get("stages", {})
    tot = sum(st.get(s, 0.0) for s in STEP_STAGES)
    m = RE_SOLVES.search(r["output"])
    return {"wall": r.get("wall_s"), "cpu": r.get("cpu_s"), "rel_err": r.get("rel_err"), "share": st.get("Fluidity", 0.0) / tot if tot > 0 else float("nan"),
            "solves": int(m.group(1)) if m else 0, "steps": r.get("steps"), "ok": r["ok"]}


def main():
    global TC3D_T
    ap = C.common_argparser(__doc__.split("\n")[0])
    ap.add_argument("--cells", default="40,80", help="comma-separated cells across (default 40,80)")
    ap.add_argument("--np", default="1", help="comma-separated rank counts (default 1)")
    ap.add_argument("--repeat", type=int, default=2, help="runs per case, interleaved (default 2)")
    ap.add_argument("--variants", default="local,nonlocal,every", help="comma-separated subset of local,nonlocal,every,base,dynamic,dynamic_explicit,dynamic_A0,tc3d_dynamic, and base_ + any of them")
    ap.add_argument("--base", default=None, help="granmpm binary of the baseline (adds the variant 'base')")
    ap.add_argument("--tc3d_t", type=float, default=0.05, help="end time of the tc3d_dynamic variant (default 0.05 s, 514 steps)")
    ap.add_argument("--out", default=NAME, help="result name: bench/results/OUT.csv (default nonlocal_cost)")
    a = ap.parse_args()
    TC3D_T = a.tc3d_t
    variants = a.variants.split(",")
    if a.base and not any(v == "base" or v.startswith("base_") for v in variants):
        variants.append("base")
    if any(v == "base" or v.startswith("base_") for v in variants) and not a.base:
        sys.exit("nonlocal_cost: the base variants need --base BINARY")
    rows = []
    print(",".join(COLUMNS))
    for np_ in [int(x) for x in a.np.split(",")]:
        for cells in [int(x) for x in a.cells.split(",")]:
            res = {v: [] for v in variants}
            for _ in range(a.repeat):
                for v in variants:
                    res[v].append(run(v, cells, np_, a.base))
            loc = C.median([r["wall"] for r in res.get("local", [])]) if "local" in res else float("nan")
            loc_cpu = C.median([r["cpu"] for r in res.get("local", [])]) if "local" in res else float("nan")
            for v in variants:
                ok = [r for r in res[v] if r["ok"]]
                w = C.median([r["wall"] for r in ok])
                cpu = C.median([r["cpu"] for r in ok])
                row = {"cells": cells, "np": np_, "variant": v, "wall_s": w, "ratio_to_local": w / loc if loc == loc and loc > 0 else float("nan"),
                       "cpu_s": cpu, "cpu_ratio_to_local": cpu / loc_cpu if loc_cpu == loc_cpu and loc_cpu > 0 else float("nan"),
                       "rel_err": ok[0]["rel_err"] if ok else float("nan"), "fluidity_share": C.median([r["share"] for r in ok]),
                       "solves": ok[0]["solves"] if ok else 0, "steps": ok[0]["steps"] if ok else 0, "runs": len(ok)}
                rows.append(row)
                print(",".join(C.fmt(row[c]) for c in COLUMNS), flush=True)
    csv_path, _ = C.output_paths(a.out, a.quick)
    C.write_csv(csv_path, COLUMNS, rows)
    C.write_meta(csv_path, C.granmpm_binary(), base=a.base or "")


if __name__ == "__main__":
    sys.exit(main())
