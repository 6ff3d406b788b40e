#!/usr/bin/env python3
"""Regression harness (issue 13 acceptance): the same examples, two binaries, same final state.

Runs every example in examples/ (not dem_*: the DEM has its own tests) for a fixed number of
steps (-max_steps, default 200; examples that reach their -t_end earlier stop there) on 1 and
2 ranks with each of two granmpm binaries, writes a checkpoint at the last step (the full
particle state, gathered in rank order) and compares the two runs of each case:

  * every particle field, rows sorted by particle id (DMSwarm_pid);
  * the run state in the checkpoint (time, step count, vmax, plastic_limit, rigid-body state,
    nodal fluidity, fluidity schedule).

Each case is reported as "bitwise" (every value identical), "1e-12" (max relative
difference <= 1e-12, relative to the largest magnitude of the field) or "DIFFERS" (with the
field of the largest difference). Column old_np1_vs_np2 is the old binary's own difference
between its 1- and 2-rank runs (same measure): how far the example amplifies round-off.
Exit status 1 if any case differs beyond 1e-12 or failed.

Usage:
  /usr/bin/python3 bench/regress_examples.py NEW_BINARY [OLD_BINARY] [--steps N] [--ranks 1,2]
                                             [--only name,name] [--keep DIR]
OLD_BINARY defaults to /work/base/build/granmpm. Needs h5py and numpy (/usr/bin/python3 has them).
Writes bench/results/regress_examples.csv (one row per example and rank count).
"""

import csv
import glob
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

import _common as C

try:
    import h5py
except ImportError:
    sys.exit("regress_examples: needs h5py (use /usr/bin/python3)")

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
# Costly examples run fewer steps so that the whole comparison stays at a few minutes.
STEPS = {"taylor_couette_3d_local": 20, "taylor_couette_3d_nonlocal": 20, "silo_3d": 30, "collapse_3d": 30, "block_3d": 40}


def mpiexec(n):
    base = ["mpiexec", "--oversubscribe"]
    if os.geteuid() == 0:
        base.append("--allow-run-as-root")
    return base + ["-n", str(n)]


def examples(only):
    out = []
    for path in sorted(glob.glob(os.path.join(ROOT, "examples", "*.opts")) + glob.glob(os.path.join(ROOT, "examples", "*.yaml"))):
        base = os.path.basename(path)
        name = base.replace(".opts", "").replace(".yaml", "_yaml")
        if base.startswith("dem_"):
            continue
        if only and name not in only:
            continue
        out.append((name, path))
    return out


def run(binary, example, ranks, steps, outdir):
    os.makedirs(outdir, exist_ok=True)
    ck = os.path.join(outdir, "final.h5")
    flag = "-options_file_yaml" if example.endswith(".yaml") else "-options_file"
    cmd = mpiexec(ranks) + [binary, flag, example, "-output_dir", outdir, "-output_overwrite", "-output_interval", "0", "-output_final", "0",
                            "-progress_interval", "0", "-max_steps", str(steps), "-checkpoint_interval", str(steps), "-checkpoint_file", ck, "-quiet"]
    t0 = time.time()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.time() - t0
    if p.returncode != 0:
        return None, wall, (p.stdout + p.stderr).strip().splitlines()[-1:] or ["exit %d" % p.returncode]
    if not os.path.exists(ck):
        # -t_end came first: no checkpoint at -max_steps. Write one at the end instead.
        return None, wall, ["no checkpoint at step %d (t_end reached earlier?)" % steps]
    return ck, wall, None


def load(path):
    """Particle fields sorted by id, and the run-state arrays."""
    out = {}
    with h5py.File(path, "r") as f:
        pid = np.asarray(f["particles/DMSwarm_pid"]).reshape(-1)
        order = np.argsort(pid, kind="stable")
        for k in f["particles"]:
            if k == "counts":
                continue
            a = np.asarray(f["particles"][k])
            out["particles/" + k] = a[order]
        # A checkpoint of the F, Fp layout (before the dynamical model stored Be - I only):
        # compare through Be - I = Fe Fe^T - I, Fe = F Fp^-1 (round-off of the conversion).
        if "particles/F" in out and "particles/Fp" in out:
            F = out.pop("particles/F").reshape(-1, 3, 3)
            Fe = F @ np.linalg.inv(out.pop("particles/Fp").reshape(-1, 3, 3))
            B = np.einsum("pij,pkj->pik", Fe, Fe) - np.eye(3)
            out["particles/Be_minus_I"] = np.stack([B[:, 0, 0], B[:, 1, 1], B[:, 2, 2], B[:, 0, 1], B[:, 1, 2], B[:, 0, 2]], axis=1)
        if "fluidity_g" in f:
            out["fluidity_g"] = np.asarray(f["fluidity_g"])
        for k in ("time", "nsteps", "vmax", "plastic_limit", "bodies_state", "fluidity_schedule", "removed_total", "removed_mass_total"):
            if k in f.attrs:
                out["attr/" + k] = np.atleast_1d(np.asarray(f.attrs[k], dtype=float))
    return out


def compare(a, b, ignore=()):
    """('bitwise' | '1e-12' | 'DIFFERS', worst relative difference, detail)."""
    a = {k: v for k, v in a.items() if k not in ignore}
    b = {k: v for k, v in b.items() if k not in ignore}
    if sorted(a) != sorted(b):
        return "DIFFERS", float("inf"), "datasets differ: %s" % sorted(set(a) ^ set(b))
    worst, where, bitwise = 0.0, "", True
    for k in sorted(a):
        x, y = a[k], b[k]
        if x.shape != y.shape:
            return "DIFFERS", float("inf"), "%s: shape %s vs %s" % (k, x.shape, y.shape)
        if x.tobytes() == y.tobytes():
            continue
        bitwise = False
        xf, yf = x.astype(float), y.astype(float)
        scale = max(np.max(np.abs(xf)), np.max(np.abs(yf)), 1e-300)
        rel = float(np.max(np.abs(xf - yf)) / scale)
        if not np.isfinite(rel):
            rel = float("inf")
        if rel > worst or not where:
            worst, where = rel, k
    if bitwise:
        return "bitwise", 0.0, ""
    return ("1e-12" if worst <= 1e-12 else "DIFFERS"), worst, where


def main():
    ap = C.ab_argparser(__doc__)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--only", default="")
    ap.add_argument("--keep", default="")
    ap.add_argument("--csv", default=os.path.join(HERE, "results", "regress_examples.csv"))
    args = ap.parse_args()
    new, old = os.path.abspath(args.new), os.path.abspath(args.old)
    for b in (new, old):
        if not os.access(b, os.X_OK):
            sys.exit("regress_examples: no executable at %s" % b)
    only = set(filter(None, args.only.split(",")))
    work = args.keep or tempfile.mkdtemp(prefix="granmpm_regress_")
    rows, failed = [], 0
    t_all = time.time()
    header = ["example", "ranks", "steps", "result", "max_rel_diff", "where", "old_np1_vs_np2", "wall_new_s", "wall_old_s"]
    print(",".join(header))
    for name, path in examples(only):
        steps = min(args.steps, STEPS.get(name, args.steps))
        old_ck = {}
        for ranks in [int(r) for r in args.ranks.split(",")]:
            res = {}
            for tag, b in (("new", new), ("old", old)):
                res[tag] = run(b, path, ranks, steps, os.path.join(work, "%s_np%d_%s" % (name, ranks, tag)))
            (ckn, wn, en), (cko, wo, eo) = res["new"], res["old"]
            if en or eo:
                result, rel, where = "FAILED", float("nan"), "new: %s; old: %s" % (en and en[0], eo and eo[0])
            else:
                result, rel, where = compare(load(ckn), load(cko))
            failed += result in ("DIFFERS", "FAILED")
            # The old binary's own spread between rank counts: how much this example
            # amplifies round-off (a fluidity KSP converges to a partition-dependent iterate).
            spread = ""
            if cko:
                old_ck[ranks] = cko
                if len(old_ck) == 2:
                    s1, s2 = (load(c) for c in old_ck.values())
                    spread = "%.3g" % compare(s1, s2, ignore=("particles/DMSwarm_rank",))[1]
            row = [name, ranks, steps, result, "%.3g" % rel, where, spread, "%.2f" % wn, "%.2f" % wo]
            rows.append(row)
            print(",".join(str(c) for c in row), flush=True)
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    os.makedirs(os.path.dirname(args.csv), exist_ok=True)
    with open(args.csv, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    n_bit = sum(r[3] == "bitwise" for r in rows)
    n_tol = sum(r[3] == "1e-12" for r in rows)
    print("# %d cases: %d bitwise, %d within 1e-12, %d differ or failed; %.0f s" % (len(rows), n_bit, n_tol, failed, time.time() - t_all))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
