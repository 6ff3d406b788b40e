#!/usr/bin/python3
"""2D granular column collapse with the DEM, against Lube et al. (2005) and GranMPM's MPM
(issue 17, item 8).

DEM: a column of half-width L0 = 0.2 m and height H0 = a L0, centred at x = 0 (the mirror
image of the MPM's column against a slip wall: the symmetry plane is a frictionless wall),
disks d = 8 mm +-20% (L0 = 25 d), contact mu = 0.5 with rolling resistance mu_r (disks
without it roll away), a rough floor (wall mu 0.8), side faces open. Runout
(L_f - L0)/L0 at t = 6 sqrt(H0/g), as the MPM reports it, with L_f the 99% mass front and
the tip (furthest grain) of |x|, averaged over the two sides.

MPM: bench/scenes.py's collapse set-up (local mu(I), h = L0/20) at its calibrated
mu_s = 0.3 and at the DEM's macroscopic friction, mu_s = tan(angle of repose) of the DEM
heap at the same contact parameters (bench/dem_heap.py, given by --mu-s-dem).

Writes bench/results/dem_collapse.csv. Needs h5py (Debian python3-h5py).
Usage: /usr/bin/python3 bench/dem_collapse.py [--aspects 0.5,1,2] [--mu-roll 0.1] [--mu-s-dem 0.25]
"""
import argparse
import csv
import math
import os
import subprocess
import sys
import tempfile

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402
from scenes import L0, collapse_args, lube, read_summary  # noqa: E402

R = 0.004
G = 9.81


def run_dem(a, roll, tmp):
    H0 = a * L0
    W = L0 * (1 + 1.6 * max(1.2 * a, 1.9 * a ** (2 / 3))) + 0.1
    out = os.path.join(tmp, f"dem_a{a}")
    args = ["-dem", "-dem_dim", "2", "-dem_lo", f"{-W!r},0", "-dem_hi", f"{W!r},{1.2 * H0 + 0.05!r}", "-dem_outlet", "xlo,xhi", "-dem_gravity", "0,-9.81",
            "-dem_radius", repr(R), "-dem_radius_dist", "uniform", "-dem_radius_spread", "0.2", "-dem_density", "2500", "-dem_kn", "2e5", "-dem_e", "0.3",
            "-dem_mu", "0.5", "-dem_mu_roll", repr(roll), "-dem_wall_mu", "0.8", "-dem_block_lo", f"{-L0!r},0.002", "-dem_block_hi", f"{L0!r},{H0!r}",
            "-dem_jitter", "0.5", "-dem_t_end", f"{6 * math.sqrt(H0 / G):.6g}", "-dem_output_every", "2000", "-dem_quiet",
            "-dem_output_dir", out, "-dem_output_overwrite"]
    p = subprocess.run(C.mpiexec_prefix(1) + [C.granmpm_binary()] + args, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit("granmpm -dem failed: " + p.stderr[-2000:])
    snaps = sorted(f for f in os.listdir(out) if f.startswith("grains_") and f.endswith(".h5"))
    with h5py.File(os.path.join(out, snaps[-1]), "r") as f:
        x, r = f["grains/position"][...], f["grains/radius"][...].ravel()
    with h5py.File(os.path.join(out, snaps[0]), "r") as f:
        n0 = len(f["grains/radius"][...].ravel())
    fronts, tips = [], []
    for side in (1, -1):
        s = side * x[:, 0] > 0
        ext = np.sort(side * x[s, 0] + r[s])
        m = np.pi * r[s] ** 2
        cm = np.cumsum(m[np.argsort(side * x[s, 0] + r[s])])
        fronts.append(ext[np.searchsorted(cm, 0.99 * cm[-1])])
        tips.append(ext[-1])
    removed = n0 - len(r)
    return dict(front=np.mean(fronts), tip=np.mean(tips), grains=n0, removed=removed, height=float((x[:, 1] + r).max()))


def run_mpm(a, mu_s):
    args = collapse_args(a, L0 / 20)
    k = args.index("-mu_s")
    args[k + 1] = f"{mu_s:g}"
    r = C.run_granmpm(args, keep_dir=True, label=f"MPM collapse a = {a}, mu_s = {mu_s}")
    s = read_summary(r, "collapse_summary.csv") if r["ok"] else {}
    if "dir" in r:
        import shutil

        shutil.rmtree(r["dir"], ignore_errors=True)
    if not s:
        sys.exit("MPM collapse failed: " + r["output"][-1500:])
    return float(s["runout"]), float(s["runout_99"])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--aspects", default="0.5,1,2")
    ap.add_argument("--mu-roll", type=float, default=0.1)
    ap.add_argument("--mu-s-dem", type=float, default=0.25, help="tan of the DEM heap's angle of repose (bench/dem_heap.py, 2D, mu 0.5)")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="dem-collapse-")
    head = ["a", "lube", "dem_runout_99", "dem_runout_tip", "dem_grains", "dem_removed", "mpm_mu_s_0.3_tip", "mpm_mu_s_0.3_99", f"mpm_mu_s_{a.mu_s_dem:g}_tip",
            f"mpm_mu_s_{a.mu_s_dem:g}_99"]
    w = csv.writer(sys.stdout)
    w.writerow(head)
    rows = []
    for asp in [float(v) for v in a.aspects.split(",")]:
        d = run_dem(asp, a.mu_roll, tmp)
        m1 = run_mpm(asp, 0.3)
        m2 = run_mpm(asp, a.mu_s_dem)
        rows.append([asp, f"{lube(asp):.3f}", f"{(d['front'] - L0) / L0:.3f}", f"{(d['tip'] - L0) / L0:.3f}", d["grains"], d["removed"], f"{m1[0]:.3f}", f"{m1[1]:.3f}",
                     f"{m2[0]:.3f}", f"{m2[1]:.3f}"])
        w.writerow(rows[-1])
        sys.stdout.flush()
    C.write_rows("dem_collapse", head, rows, command=" ".join(sys.argv))


if __name__ == "__main__":
    main()
