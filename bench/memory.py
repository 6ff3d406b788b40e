#!/usr/bin/env python3
"""Memory per particle in 3D for every material (issue 16 goal 2: <= 300 B/particle).

For each material, the 3D block (examples/block_3d.opts, the grid fixed) runs a few steps at
two lattice densities (-ppc LO and HI: about 8x more particles at the same grid) on 1 rank.
Two measures per material:

  footprint_B   the run's own count ("particle data N bytes per particle": every swarm field
                and the per-particle step buffers), at the larger run;
  rss_delta_B   (peak RSS of the HI run - peak RSS of the LO run) / (particles HI - LO): what
                one more particle costs the process, PETSc's swarm buffers and the transient
                peaks of migration, sorting and the constitutive update included (the grid is
                the same in both runs, so it cancels).

Usage: python3 bench/memory.py [--materials a,b] [--ppc 3,6] [--steps 5] [--out memory]
Writes bench/results/<out>.csv. GRANMPM selects the binary (default build/granmpm).
"""

import argparse
import csv
import os
import re
import subprocess
import sys

import _common as C

MATERIALS = ["elastic", "hypoelastic", "mu_i", "drucker_prager", "nonlocal", "dynamic"]


def run(binary, material, ppc, steps):
    cmd = [binary, "-options_file", os.path.join(C.REPO_ROOT, "examples", "block_3d.opts"), "-material", material, "-ppc", str(ppc),
           "-max_steps", str(steps), "-output_interval", "0", "-output_final", "0", "-progress_interval", "0",
           "-output_dir", os.path.join("/tmp", "granmpm_memory_%d" % os.getpid()), "-output_overwrite"]
    p = subprocess.run(cmd, capture_output=True, text=True)
    out = p.stdout + p.stderr
    if p.returncode != 0:
        sys.exit("memory: %s failed: %s" % (" ".join(cmd), out.strip().splitlines()[-1:]))
    n = int(re.search(r"GranMPM: (\d+) particles", out).group(1))
    rss = float(re.search(r"peak memory ([\d.]+) MiB", out).group(1)) * 1024 * 1024
    fp = float(re.search(r"particle data ([\d.]+) bytes per particle", out).group(1))
    return n, rss, fp


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", default=",".join(MATERIALS))
    ap.add_argument("--ppc", default="3,6", help="the two lattice densities (particles per cell per direction)")
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--out", default="memory")
    a = ap.parse_args()
    binary = C.granmpm_binary()
    lo, hi = (int(x) for x in a.ppc.split(","))
    rows = []
    header = ["material", "footprint_B", "rss_delta_B", "particles_lo", "particles_hi", "rss_lo_MiB", "rss_hi_MiB"]
    print(",".join(header))
    for m in a.materials.split(","):
        n0, r0, _ = run(binary, m, lo, a.steps)
        n1, r1, fp = run(binary, m, hi, a.steps)
        row = [m, "%.0f" % fp, "%.0f" % ((r1 - r0) / (n1 - n0)), n0, n1, "%.1f" % (r0 / 2**20), "%.1f" % (r1 / 2**20)]
        rows.append(row)
        print(",".join(str(c) for c in row), flush=True)
    os.makedirs(C.RESULTS_DIR, exist_ok=True)
    path = os.path.join(C.RESULTS_DIR, a.out + ".csv")
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["# " + C.binary_provenance(binary) + "; block_3d, -ppc %d,%d, %d steps, 1 rank" % (lo, hi, a.steps)])
        w.writerow(header)
        w.writerows(rows)
    print("# wrote", path)


if __name__ == "__main__":
    main()
