#!/usr/bin/env python3
"""DEM throughput, GranMPM against LAMMPS on the same scenes in the same run (issue 17).

Scenes: a dense packing settling under gravity, started on an fcc (3D) or hexagonal (2D)
lattice with nearest-neighbour gap 1% of the radius, periodic sideways, a frictional floor;
linear spring-dashpot (LAMMPS pair_style gran/hooke/history, fix wall/gran hooke/history),
the same k_n, k_t = 2/7 k_n, gamma_n, gamma_t = gamma_n / 2, mu, dt and skin. 2D: LAMMPS
`dimension 2` with spheres; GranMPM's disks get the density that gives the same masses.

Reported per case and rank count (CSV to stdout and bench/results/dem_throughput.csv):
grain-steps per second per core (loop time only, both codes), grain-steps per CPU-second
(user + system time of all processes of the run, set-up and MPI waiting included: less
sensitive to other jobs on a shared machine), pair contacts per grain at
the end, the GranMPM time split (neighbour search incl. migration, forces, communication,
integration) and resident bytes per grain (GranMPM: its arrays; LAMMPS: its own
"Per MPI rank memory" figure).

Usage: python3 bench/dem_throughput.py [--steps 2000] [--ranks 1,2] [--cases 3d,2d] [--big]
       [--base /work/base/build/granmpm] [--repeats 3] [--memory] [--no-orientation]
(--big adds a 3D case of ~3e5 spheres; --base runs a second granmpm binary, e.g. the old main,
interleaved with the others; --repeats: interleaved repeats, medians reported; --memory: the
marginal resident memory per grain, (RSS(N) - RSS(0.7^d N)) / dN from /usr/bin/time, one rank.)
2-rank efficiency: speed-up over 1 rank (median loop times) / the machine's 2-process
capacity 2 t1/t2 of bench/compute_loop.cpp measured in the same run (see bench/scaling.py).
Needs /usr/bin/lmp (apt-get install lammps).
"""
import argparse
import csv
import math
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import granmpm_binary, mpiexec_prefix, write_rows  # noqa: E402

R = 0.005
RHO = 2500.0
KN = 2e4
E = 0.5
MU = 0.5
SKIN = 0.3 * R
A = 2.02 * R  # nearest-neighbour distance of the lattice


def masses(dim):
    m = RHO * 4.0 / 3.0 * math.pi * R ** 3
    return m


def damping():
    le = math.log(E)
    return -2 * le / math.sqrt(math.pi ** 2 + le ** 2)  # GranMPM -dem_damping seed: gamma = damp sqrt(k m_eff)


def scene(dim, n):
    """Box and block for n lattice cells per horizontal direction."""
    if dim == 3:
        c = A * math.sqrt(2)
        nz = n - 1
        box = (n * c, n * c, nz * c + 0.02)
        count = 4 * n * n * nz
        return dict(cell=(c, c, c), ncell=(n, n, nz), box=box, count=count)
    c = (A, A * math.sqrt(3))
    ny = n // 2
    box = (n * c[0], ny * c[1] + 0.02)
    return dict(cell=c, ncell=(n, ny), box=box, count=2 * n * ny)


def dt_value():
    meff = masses(3) / 2
    return math.pi * math.sqrt(meff / KN) / 20


def cpu_children():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_granmpm(dim, sc, steps, np_, tmp, binary=None, extra=()):
    box = sc["box"]
    out = os.path.join(tmp, f"g{dim}_{np_}")
    rho = RHO if dim == 3 else RHO * 4.0 / 3.0 * R
    lo = ",".join(["0"] * (dim - 1) + ["-0.002"])  # the floor 2 mm below the lattice block
    hi = ",".join(f"{b:.9g}" for b in box)
    blo = ",".join(["0"] * dim)
    blk = [sc["ncell"][k] * sc["cell"][k] for k in range(dim)]
    bhi = ",".join(f"{b + 1e-9:.9g}" for b in blk)
    grav = "0,-9.81" if dim == 2 else "0,0,-9.81"
    per = "x" if dim == 2 else "xy"
    args = ["-dem", "-dem_dim", str(dim), "-dem_lo", lo, "-dem_hi", hi, "-dem_periodic", per, "-dem_gravity", grav,
            "-dem_radius", str(R), "-dem_density", repr(rho), "-dem_kn", str(KN), "-dem_kt_ratio", repr(2.0 / 7.0),
            "-dem_e", str(E), "-dem_damping", "seed", "-dem_gt_ratio", "0.5", "-dem_mu", str(MU), "-dem_skin", repr(SKIN),
            "-dem_lattice", "dense", "-dem_spacing", repr(A), "-dem_block_lo", blo, "-dem_block_hi", bhi,
            "-dem_dt", repr(dt_value()), "-dem_max_steps", str(steps), "-dem_output_every", str(steps), "-dem_fields", "0",
            "-dem_output_dir", out, "-dem_output_overwrite"] + list(extra)
    cmd = mpiexec_prefix(np_) + ["/usr/bin/time", "-f", "rss_kb %M", binary or granmpm_binary()] + args
    c0 = cpu_children()
    p = subprocess.run(cmd, capture_output=True, text=True)
    cpu = cpu_children() - c0
    if p.returncode != 0:
        sys.exit("granmpm failed: " + p.stderr[-2000:])
    rss = sum(int(v) for v in re.findall(r"rss_kb (\d+)", p.stderr)) * 1024
    m = re.search(r"dem: (\d+) steps, (\d+) rebuilds; time neighbour ([\d.e+-]+) s, force ([\d.e+-]+) s, comm ([\d.e+-]+) s, integrate ([\d.e+-]+) s; (\d+) bytes/grain", p.stdout)
    t = [float(m.group(i)) for i in (3, 4, 5, 6)]
    with open(os.path.join(out, "dem_summary.csv")) as f:
        rows = list(csv.DictReader(f))
    last = rows[-1]
    grains = int(last["grains"])
    return dict(cpu=cpu, loop=sum(t), neigh=t[0], force=t[1], comm=t[2], integ=t[3], rebuilds=int(m.group(2)), bytes=int(m.group(7)),
                grains=grains, contacts=int(last["contacts"]) / grains, rss=rss)


def run_lammps(dim, sc, steps, np_, tmp, lmp):
    box = sc["box"]
    m = masses(dim)
    meff = m / 2
    gn = damping() * math.sqrt(KN * meff) / meff  # LAMMPS: F = -m_eff gamma_n v_n
    kt = 2.0 / 7.0 * KN
    dt = dt_value()
    lines = ["units si", f"dimension {dim}", "atom_style sphere", "atom_modify map array",
             ("boundary p f p" if dim == 2 else "boundary p p f"), "newton off", "comm_modify vel yes"]
    if dim == 3:
        lines += [f"region box block 0 {box[0]!r} 0 {box[1]!r} -0.002 {box[2]!r} units box", "create_box 1 box",
                  f"lattice fcc {sc['cell'][0]!r} origin 0.25 0.25 0.25",
                  f"region blk block 0 {sc['ncell'][0]} 0 {sc['ncell'][1]} 0 {sc['ncell'][2]} units lattice"]
    else:
        lines += [f"region box block 0 {box[0]!r} -0.002 {box[1]!r} -0.5 0.5 units box", "create_box 1 box",
                  f"lattice hex {A!r} origin 0.25 0.25 0",
                  f"region blk block 0 {sc['ncell'][0]} 0 {sc['ncell'][1]} -0.5 0.5 units lattice"]
    lines += ["create_atoms 1 region blk", f"set type 1 diameter {2 * R!r}", f"set type 1 mass {m!r}",
              f"pair_style gran/hooke/history {KN!r} {kt!r} {gn!r} {0.5 * gn!r} {MU} 1", "pair_coeff * *",
              f"neighbor {SKIN!r} bin", "neigh_modify delay 0 every 1 check yes", f"timestep {dt!r}",
              "fix 1 all nve/sphere"]
    if dim == 3:
        lines += ["fix 2 all gravity 9.81 vector 0 0 -1",
                  f"fix 3 all wall/gran hooke/history {KN!r} {kt!r} {gn!r} {0.5 * gn!r} {MU} 1 zplane -0.002 NULL"]
    else:
        lines += ["fix 2 all gravity 9.81 vector 0 -1 0",
                  f"fix 3 all wall/gran hooke/history {KN!r} {kt!r} {gn!r} {0.5 * gn!r} {MU} 1 yplane -0.002 NULL", "fix 4 all enforce2d"]
    lines += ["compute c all contact/atom", "compute cs all reduce sum c_c", "thermo_style custom step atoms ke c_cs",
              f"thermo {steps}", f"run {steps}"]
    path = os.path.join(tmp, f"in.dem{dim}_{np_}")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    cmd = mpiexec_prefix(np_) + ["/usr/bin/time", "-f", "rss_kb %M", lmp, "-in", path, "-log", "none"]
    c0 = cpu_children()
    p = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp, env=dict(os.environ, OMP_NUM_THREADS="1"))
    cpu = cpu_children() - c0
    if p.returncode != 0:
        sys.exit("lmp failed: " + (p.stdout + p.stderr)[-2000:])
    rss = sum(int(v) for v in re.findall(r"rss_kb (\d+)", p.stderr)) * 1024
    o = p.stdout
    loop = float(re.search(r"Loop time of ([\d.e+-]+) on", o).group(1))
    atoms = int(re.search(r"for \d+ steps with (\d+) atoms", o).group(1))
    mem = re.search(r"Per MPI rank memory allocation \(min/avg/max\) = [\d.]+ \| ([\d.]+) \| [\d.]+ Mbytes", o)
    thermo = [l.split() for l in o.splitlines() if re.match(r"\s*\d+\s+\d+\s+[\d.e+-]+\s+[\d.e+-]+\s*$", l)]
    csum = float(thermo[-1][3])
    neigh = re.search(r"Ave neighs/atom = ([\d.]+)", o)
    return dict(cpu=cpu, loop=loop, grains=atoms, contacts=csum / 2 / atoms, bytes=(float(mem.group(1)) * 1048576 * np_ / atoms) if mem else float("nan"),
                neighs=float(neigh.group(1)) if neigh else float("nan"), rss=rss)


def median(v):
    v = sorted(v)
    return v[len(v) // 2] if len(v) % 2 else 0.5 * (v[len(v) // 2 - 1] + v[len(v) // 2])


def capacity(tmp, repeats):
    """2 t1 / t2 of bench/compute_loop (2.0 on two free cores): the machine's 2-process capacity now."""
    from scaling import compile_loop, run_loop

    exe = compile_loop(tmp)
    ratios = []
    for rep in range(repeats):
        t1 = run_loop(exe, 1, 400000, 20, rep)["loop_wall_s"]
        t2 = run_loop(exe, 2, 400000, 20, rep)["loop_wall_s"]
        if t1 and t2:
            ratios.append(2 * t1 / t2)
    return median(ratios) if ratios else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--ranks", default="1,2")
    ap.add_argument("--cases", default="3d,2d")
    ap.add_argument("--big", action="store_true")
    ap.add_argument("--base", help="a second granmpm binary (the old main) run in the same sequence")
    ap.add_argument("--repeats", type=int, default=1, help="interleaved repeats; medians are reported")
    ap.add_argument("--tag", default="", help="suffix of the results file (bench/results/dem_throughput<tag>.csv)")
    ap.add_argument("--memory", action="store_true", help="also the marginal RSS per grain: two sizes of each case, 100 steps")
    ap.add_argument("--no-orientation", action="store_true",
                    help="also GranMPM with -dem_orientation false (code granmpm-noorient: no orientation kept, as LAMMPS's atom_style sphere)")
    a = ap.parse_args()
    lmp = shutil.which("lmp")
    if not lmp:
        sys.exit("bench: lmp (LAMMPS) not found: apt-get install -y lammps")
    cases = []
    for c in a.cases.split(","):
        if c == "3d":
            cases.append(("3d", 3, 20))
        elif c == "2d":
            cases.append(("2d", 2, 172))
    if a.big:
        cases.append(("3d-big", 3, 42))
    tmp = tempfile.mkdtemp(prefix="dem-bench-")
    codes = [("granmpm", None, ())] + ([("granmpm-noorient", None, ("-dem_orientation", "false"))] if a.no_orientation else [])
    codes += ([("granmpm-base", a.base, ())] if a.base else []) + [("lammps", None, ())]
    rows = []
    w = csv.writer(sys.stdout)
    head = ["case", "ranks", "code", "grains", "steps", "repeats", "loop_s", "grain_steps_per_s_per_core", "grain_steps_per_cpu_s", "contacts_per_grain", "bytes_per_grain",
            "rss_bytes_per_grain_marginal", "neigh_s", "force_s", "comm_s", "integrate_s", "rebuilds", "efficiency_2_ranks", "capacity_2_processes"]
    w.writerow(head)
    cap = capacity(tmp, max(1, a.repeats)) if "2" in a.ranks.split(",") else float("nan")
    for name, dim, n in cases:
        sc = scene(dim, n)
        marg = {}
        if a.memory:  # (RSS(n) - RSS(n_small)) / (grains(n) - grains(n_small)), one rank
            small = scene(dim, int(n * 0.7))
            for code, binary, extra in codes:
                big_r = run_lammps(dim, sc, 100, 1, tmp, lmp) if code == "lammps" else run_granmpm(dim, sc, 100, 1, tmp, binary, extra)
                sm_r = run_lammps(dim, small, 100, 1, tmp, lmp) if code == "lammps" else run_granmpm(dim, small, 100, 1, tmp, binary, extra)
                marg[code] = (big_r["rss"] - sm_r["rss"]) / (big_r["grains"] - sm_r["grains"])
        per = {}
        for rep in range(a.repeats):
            for np_ in [int(x) for x in a.ranks.split(",")]:
                for code, binary, extra in codes:
                    d = run_lammps(dim, sc, a.steps, np_, tmp, lmp) if code == "lammps" else run_granmpm(dim, sc, a.steps, np_, tmp, binary, extra)
                    per.setdefault((np_, code), []).append(d)
        for np_ in [int(x) for x in a.ranks.split(",")]:
            for code, _, _ in codes:
                runs = per[(np_, code)]
                d = dict(runs[0])
                for k in ("cpu", "loop", "neigh", "force", "comm", "integ"):
                    if k in d:
                        d[k] = median([r[k] for r in runs])
                eff = float("nan")
                if np_ == 2 and (1, code) in per:
                    sp = median([r["loop"] for r in per[(1, code)]]) / d["loop"]
                    eff = sp / cap
                row = [name, np_, code, d["grains"], a.steps, a.repeats, f"{d['loop']:.4g}", f"{d['grains'] * a.steps / d['loop'] / np_:.4g}",
                       f"{d['grains'] * a.steps / d['cpu']:.4g}", f"{d['contacts']:.3g}", f"{d['bytes']:.0f}", f"{marg.get(code, float('nan')):.0f}",
                       f"{d.get('neigh', float('nan')):.3g}", f"{d.get('force', float('nan')):.3g}", f"{d.get('comm', float('nan')):.3g}",
                       f"{d.get('integ', float('nan')):.3g}", d.get("rebuilds", ""), f"{eff:.3f}", f"{cap:.3f}"]
                w.writerow(row)
                sys.stdout.flush()
                rows.append(row)
    write_rows("dem_throughput" + a.tag, head, rows, command=" ".join(sys.argv), loadavg_end=os.getloadavg()[0])


if __name__ == "__main__":
    main()
