#!/usr/bin/env python3
"""2D DEM silo discharge against the Beverloo law (issue 17, item 7).

Runs examples/dem_silo.opts (a 0.3 m wide silo of disks, d = 8 mm +-15%, plate at y = 0)
for orifice widths D, measures the discharge rate W (grains/s, a linear fit of the removed
count over the steady part: from 0.3 s to the end), and fits the 2D Beverloo law
W = C (D - k d)^(3/2) (k and C by least squares over a grid of k). Writes
bench/results/dem_silo.csv and prints the fit.

Usage: python3 bench/dem_silo.py [--widths 0.05,0.06,0.08,0.10] [--t_end 1.2] [--ranks 1]
"""
import argparse
import csv
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import REPO_ROOT, RESULTS_DIR, granmpm_binary, mpiexec_prefix  # noqa: E402

D_GRAIN = 0.008


def rate(csvfile, t0):
    rows = [r for r in csv.DictReader(open(csvfile)) if float(r["t"]) >= t0]
    t = [float(r["t"]) for r in rows]
    n = [float(r["removed"]) for r in rows]
    if len(t) < 3:
        return float("nan")
    mt, mn = sum(t) / len(t), sum(n) / len(n)
    return sum((a - mt) * (b - mn) for a, b in zip(t, n)) / sum((a - mt) ** 2 for a in t)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--widths", default="0.05,0.06,0.08,0.10")
    ap.add_argument("--t_end", type=float, default=1.2)
    ap.add_argument("--ranks", type=int, default=1)
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="dem-silo-")
    res = []
    for D in [float(x) for x in a.widths.split(",")]:
        out = os.path.join(tmp, f"D{D}")
        cmd = mpiexec_prefix(a.ranks) + [granmpm_binary(), "-options_file", os.path.join(REPO_ROOT, "examples", "dem_silo.opts"), "-dem_orifice", repr(D),
                                         "-dem_t_end", repr(a.t_end), "-dem_output_every", "200", "-dem_fields", "0", "-dem_quiet", "-dem_output_dir", out]
        p = subprocess.run(cmd, capture_output=True, text=True)
        if p.returncode != 0:
            sys.exit(p.stderr[-1000:])
        W = rate(os.path.join(out, "dem_summary.csv"), 0.3)
        res.append((D, W))
        print(f"D = {D:.3f} m ({D / D_GRAIN:.1f} d): W = {W:.1f} grains/s", flush=True)
    best = None
    for i in range(0, 301):
        k = i * 0.01
        xs = [(D - k * D_GRAIN) ** 1.5 if D > k * D_GRAIN else 0 for D, _ in res]
        C = sum(x * W for x, (_, W) in zip(xs, res)) / max(sum(x * x for x in xs), 1e-300)
        err = sum((C * x - W) ** 2 for x, (_, W) in zip(xs, res))
        if best is None or err < best[0]:
            best = (err, k, C)
    _, k, C = best
    print(f"Beverloo fit W = C (D - k d)^1.5: k = {k:.2f}, C = {C:.4g} grains/s/m^1.5")
    os.makedirs(RESULTS_DIR, exist_ok=True)
    with open(os.path.join(RESULTS_DIR, "dem_silo.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["D_m", "D_over_d", "W_grains_per_s", "beverloo_fit"])
        for D, W in res:
            w.writerow([D, D / D_GRAIN, f"{W:.2f}", f"{C * max(D - k * D_GRAIN, 0) ** 1.5:.2f}"])


if __name__ == "__main__":
    main()
