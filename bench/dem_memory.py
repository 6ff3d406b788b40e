#!/usr/bin/env python3
"""DEM memory per grain, and the same results as another binary (issue 17, the 200 B/grain goal).

For each scene (examples/dem_block.opts: 3D, ~9.7e3 spheres settling, periodic in x and z;
examples/dem_silo.opts and dem_heap.opts: 2D) and each binary (this build, and --base, e.g.
the old main), one rank, --steps steps:
  - footprint: the run's own "dem: footprint" lines (bytes per owned grain of every container
    kept between steps: owned grain state, neighbour lists, springs (contact history) and
    ghosts (their copies, the exchange plan and buffer; older binaries count ghost copies in the
    state and not the exchange buffers), and per container) at the end of the run;
  - marginal RSS per grain (dem_block only, 100 steps): (RSS(N) - RSS(N_small)) / (N - N_small)
    from /usr/bin/time, for the block widened 3 x 3 in x and z (N ~ 5.5e4) and the same 0.7
    times as tall (PETSc and MPI cancel out); peak RSS, so it includes the rebuild's temporaries;
  - same results: the summary CSV (12 significant digits of the energies every 1% of the
    run) identical to the base binary's, and the final grain snapshot identical except for
    the HDF5 object timestamps (bytes differing counted).
CSV to stdout and bench/results/dem_memory.csv.

Usage: python3 bench/dem_memory.py [--steps 20000] [--base /work/base/build/granmpm] [--no-orientation]
"""
import argparse
import csv
import os
import re
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import granmpm_binary, write_rows  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(binary, opts, extra, out, steps):
    cmd = ["/usr/bin/time", "-f", "rss_kb %M", binary, "-options_file", os.path.join(ROOT, "examples", opts), "-dem_max_steps", str(steps),
           "-dem_output_dir", out, "-dem_output_overwrite", "-dem_fields_every", "0"] + extra
    env = dict(os.environ, HWLOC_COMPONENTS="-gl")  # no X display probing (a shared machine's Xvfb)
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        sys.exit("bench: %s failed: %s" % (" ".join(cmd), (p.stdout + p.stderr)[-1500:]))
    fp = re.search(r"dem: footprint (\d+) bytes/grain \(grain state (\d+), lists (\d+), springs (\d+)(?:, ghosts (\d+))?", p.stdout)
    per = re.search(r"dem: footprint per container \(bytes/grain\): (.*)", p.stdout)
    rss = int(re.search(r"rss_kb (\d+)", p.stderr).group(1)) * 1024
    with open(os.path.join(out, "dem_summary.csv")) as f:
        rows = list(csv.reader(f))
    grains = int(rows[1][rows[0].index("grains")])
    return {"footprint": [int(x) if x is not None else "" for x in fp.groups()], "containers": per.group(1).replace(",", ";") if per else "", "rss": rss, "grains": grains,
            "summary": rows}


def last_snapshot(out):
    h5 = sorted(x for x in os.listdir(out) if x.startswith("grains_") and x.endswith(".h5"))
    with open(os.path.join(out, h5[-1]), "rb") as f:
        return f.read()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--base", default="/work/base/build/granmpm")
    ap.add_argument("--no-orientation", action="store_true",
                    help="also this build with -dem_orientation false (code granmpm-noorient; its snapshots lack the orientation array)")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="dem-memory-")
    codes = [("granmpm", granmpm_binary(), [])] + ([("granmpm-noorient", granmpm_binary(), ["-dem_orientation", "false"])] if a.no_orientation else [])
    codes += [("base", a.base, [])]
    head = ["scene", "code", "grains", "steps", "footprint_bytes_per_grain", "grain_state", "lists", "springs", "ghosts", "rss_bytes_per_grain_marginal",
            "summary_identical_to_base", "snapshot_bytes_differing_from_base", "containers_bytes_per_grain"]
    w = csv.writer(sys.stdout)
    w.writerow(head)
    rows = []
    for scene in ("dem_block", "dem_silo", "dem_heap"):
        res, snap = {}, {}
        for code, binary, extra in codes:
            out = os.path.join(tmp, scene + "_" + code)
            res[code] = run(binary, scene + ".opts", extra, out, a.steps)
            snap[code] = last_snapshot(out)
            if scene == "dem_block":
                wide = ["-dem_hi", "0.6,0.4,0.6"]  # 9 times the grains: RSS noise << the difference
                small = run(binary, scene + ".opts", extra + wide + ["-dem_block_hi", "0.6,0.175,0.6"], out + "_small", 100)
                big = run(binary, scene + ".opts", extra + wide + ["-dem_block_hi", "0.6,0.25,0.6"], out + "_big", 100)
                res[code]["marginal"] = (big["rss"] - small["rss"]) / (big["grains"] - small["grains"])
        for code, _, _ in codes:
            r = res[code]
            same = r["summary"] == res["base"]["summary"]
            s0, s1 = snap[code], snap["base"]
            ndiff = sum(x != y for x, y in zip(s0, s1)) + abs(len(s0) - len(s1))
            row = [scene, code, r["grains"], a.steps] + r["footprint"] + ["%.0f" % r["marginal"] if "marginal" in r else "", int(same), ndiff, r["containers"]]
            w.writerow(row)
            sys.stdout.flush()
            rows.append(row)
    write_rows("dem_memory", head, rows, command=" ".join(sys.argv), loadavg_end=os.getloadavg()[0])


if __name__ == "__main__":
    main()
