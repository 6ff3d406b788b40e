#!/usr/bin/env python3
"""Force-chain output of `granmpm -dem -dem_force_chains` (issue 17): a 3D block of spheres
settling under gravity (periodic in x and z, so contacts cross the periodic faces and, on 2
and 3 ranks, the rank cuts) writes a snapshot every 800 steps with a summary row at the same
steps. For 1, 2 and 3 ranks:
  - every snapshot's contact network (chains_NNNNN.xmf) has as many lines as the summary's
    force-carrying contacts at that step (more than 200 of ~520 grains at the end);
  - 2 and 3 ranks write the same line counts as 1 rank;
  - ParaView (pvpython, under xvfb-run -a when there is one) opens chains.xmf with its XDMF
    reader: one time step per snapshot; at the last, as many cells as contacts, each a 2-point
    line no longer than two of the largest radii, normal_force > 0 on every cell; and grains.xmf
    with the spheres' orientations: a 4-component array of unit quaternions that the 3D
    Glyphs representation takes in its Quaternion orientation mode without an error.
The ParaView part is skipped (said so, not failed) when pvpython is not installed."""
import argparse
import csv
import os
import re
import shutil
import subprocess
import sys
import tempfile

import _cli

STEPS, EVERY = 4000, 800
ARGS = ["-dem", "-dem_dim", "3", "-dem_lo", "0,0,0", "-dem_hi", "0.06,0.2,0.06", "-dem_periodic", "xz", "-dem_gravity", "0,-9.81,0",
        "-dem_radius", "0.005", "-dem_radius_dist", "uniform", "-dem_radius_spread", "0.15", "-dem_kn", "2e4", "-dem_e", "0.5", "-dem_mu", "0.5",
        "-dem_block_lo", "0,0.002,0", "-dem_block_hi", "0.06,0.15,0.06", "-dem_jitter", "0.5", "-dem_velocity_random", "0.1",
        "-dem_steps_per_contact", "10", "-dem_max_steps", str(STEPS), "-dem_output_every", str(EVERY), "-dem_fields_every", str(EVERY),
        "-dem_force_chains", "-dem_quiet", "-dem_output_overwrite"]
RMAX = 0.005 * 1.15

PV = r"""
import sys
from paraview.simple import XDMFReader, Xdmf3ReaderS, UpdatePipeline
from paraview import servermanager as sm
r = Xdmf3ReaderS(FileName=[sys.argv[1]])
times = list(r.TimestepValues) if r.TimestepValues else []
UpdatePipeline(times[-1] if times else 0, r)
d = sm.Fetch(r)
b = d.GetBlock(0) if d.IsA("vtkMultiBlockDataSet") else d
cells = b.GetNumberOfCells()
two = all(b.GetCell(k).GetNumberOfPoints() == 2 for k in range(cells))
longest = 0.0
for k in range(cells):
    p = b.GetCell(k).GetPoints()
    a, c = p.GetPoint(0), p.GetPoint(1)
    longest = max(longest, sum((a[i] - c[i]) ** 2 for i in range(3)) ** 0.5)
fn = b.GetCellData().GetArray("normal_force")
fmin = min(fn.GetValue(k) for k in range(cells)) if fn and cells else -1
print("RESULT %d %d %d %.9g %.9g" % (len(times), cells, int(two), longest, fmin))
"""

# The grains' orientations as ParaView sees them (the last snapshot), glyphs oriented by them.
PV_ORIENT = r"""
import math, sys
from paraview.simple import XDMFReader, Show, Render
from paraview import servermanager as sm
r = XDMFReader(FileNames=[sys.argv[1]])
r.UpdatePipeline(r.TimestepValues[-1])
d = sm.Fetch(r)
a = d.GetPointData().GetArray("orientation")
n = a.GetNumberOfTuples()
err = max(abs(math.sqrt(sum(c * c for c in a.GetTuple(k))) - 1) for k in range(n))
turned = max(2 * math.acos(min(1.0, abs(a.GetTuple(k)[0]))) for k in range(n))
rep = Show(r)
rep.SetRepresentationType("3D Glyphs")
rep.Orient = 1
rep.OrientationMode = "Quaternion"
rep.SelectOrientationVectors = "orientation"
Render()
print("ORIENT %d %d %.3g %.6g" % (a.GetNumberOfComponents(), n, err, turned))
"""


def summary_contacts(out):
    with open(os.path.join(out, "dem_summary.csv")) as f:
        rows = list(csv.DictReader(f))
    return {int(r["step"]): int(r["contacts"]) for r in rows}


def xmf_lines(out):
    got = []
    for name in sorted(x for x in os.listdir(out) if re.match(r"chains_\d+\.xmf$", x)):
        with open(os.path.join(out, name)) as f:
            got.append(int(re.search(r'Polyline" NumberOfElements="(\d+)"', f.read()).group(1)))
    return got


def main():
    ap = _cli.arguments(__doc__)
    ap.add_argument("--pvpython", default=shutil.which("pvpython"))
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="granmpm-dem-chains-")
    failures, counts = 0, {}
    for n in (1, 2, 3):
        out = os.path.join(tmp, "np%d" % n)
        rc, _, err = _cli.run(_cli.command(a, n, ARGS + ["-dem_output_dir", out]), a.timeout)
        if rc != 0:
            print("FAIL run on %d ranks: rc %s %s" % (n, rc, err[-500:]))
            failures += 1
            continue
        lines, contacts = xmf_lines(out), summary_contacts(out)
        want = [contacts[s] for s in range(0, STEPS + 1, EVERY)]
        ok = lines == want and want[-1] > 200
        print("%s %d ranks: lines per snapshot %s, summary contacts %s" % ("ok  " if ok else "FAIL", n, lines, want))
        failures += not ok
        counts[n] = lines
    for n in (2, 3):
        ok = n in counts and counts[n] == counts.get(1)
        print("%s %d ranks write the line counts of 1 rank" % ("ok  " if ok else "FAIL", n))
        failures += not ok
    if not a.pvpython or not shutil.which(a.pvpython):
        print("SKIP ParaView check: pvpython not found (apt-get install paraview python3-paraview)")
    else:
        script = os.path.join(tmp, "pv.py")
        with open(script, "w") as f:
            f.write(PV)
        pre = ["xvfb-run", "-a"] if shutil.which("xvfb-run") else []
        p = subprocess.run(pre + [a.pvpython, "--no-mpi", "--disable-registry", script, os.path.join(tmp, "np2", "chains.xmf")], capture_output=True, text=True,
                           timeout=600)
        m = re.search(r"RESULT (\d+) (\d+) (\d+) (\S+) (\S+)", p.stdout)
        last = counts.get(2, [0])[-1]
        ok = bool(m) and int(m.group(1)) == STEPS // EVERY + 1 and int(m.group(2)) == last and m.group(3) == "1" and float(m.group(4)) <= 2 * RMAX \
            and float(m.group(5)) > 0
        print("%s ParaView reads chains.xmf: %s (want %d steps, %d two-point cells no longer than %.4g, normal_force > 0)%s" %
              ("ok  " if ok else "FAIL", m.group(0) if m else "no result", STEPS // EVERY + 1, last, 2 * RMAX, "" if ok else ": " + (p.stdout + p.stderr)[-1500:]))
        failures += not ok
        with open(script, "w") as f:
            f.write(PV_ORIENT)
        p = subprocess.run(pre + [a.pvpython, "--disable-registry", script, os.path.join(tmp, "np2", "grains.xmf")], capture_output=True, text=True, timeout=600)
        m = re.search(r"ORIENT (\d+) (\d+) (\S+) (\S+)", p.stdout)
        bad = "expecting an orientation array" in p.stdout + p.stderr
        ok = bool(m) and m.group(1) == "4" and int(m.group(2)) > 200 and float(m.group(3)) < 1e-12 and float(m.group(4)) > 0.01 and not bad
        print("%s ParaView reads the orientations in grains.xmf and orients glyphs by them: %s (want 4 components, unit norm, turned > 0.01 rad)%s" %
              ("ok  " if ok else "FAIL", m.group(0) if m else "no result", "" if ok else ": " + (p.stdout + p.stderr)[-1500:]))
        failures += not ok
    print("%d failures" % failures)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
