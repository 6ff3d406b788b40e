#!/usr/bin/python3
"""Angle of repose of a poured DEM heap, GranMPM against LAMMPS (issue 17, item 6).

A block of grains (d = 8 mm, radii uniform +-20%; 2D: height 0.3 of its width, 3D: a
0.12 m cube) is released onto a rough floor (wall mu 0.8) and slumps into a heap; grains reaching the side faces leave (outlets). The
angle of repose is read from the final surface: the highest grain top per bin of width
2 d along x (2D) or of the distance from the axis (3D), a straight line fitted to the
flank between 25% and 75% of the peak height, angle = atan(slope).

Both codes start from the same grains (LAMMPS reads GranMPM's first snapshot: positions,
radii; 2D masses equal through per-grain densities, discs' moments of inertia with
`fix nve/sphere disc`), the same linear spring-dashpot (k_n, k_t = 2/7 k_n, gamma_t =
gamma_n / 2, mu, the same dt and skin) and no attractive normal force (LAMMPS
`limit_damping`). Damping: GranMPM -dem_damping seed (gamma_n = c sqrt(k_n m_eff), c from
e) and LAMMPS gamma_n = c sqrt(k_n / m_eff) for the mean-size pair (LAMMPS's damping is
per unit m_eff), so contacts of other sizes are damped slightly differently.
Rolling resistance (-dem_mu_roll) is GranMPM-only here: LAMMPS's gran/* styles have none
(its `pair granular` rolling model is a spring-dashpot, not GranMPM's constant torque).

--pour: a poured heap instead: the grains start in a hopper above a plate at y = 0.3 m
(GranMPM -dem_plate_y) with a slot of 7.5 d (2D) or a round hole of 10 d (3D, under a
0.1 x 0.25 x 0.1 m column) at the axis (-dem_orifice) and pour through it onto the floor;
LAMMPS has the same plate (2D: two flat blocks of 2 um thickness either side of the slot;
3D: the intersection of a 2-um slab and the outside of a cylinder; fix wall/gran/region,
side out: the grains touch their nearest surface point, as GranMPM's plate; the 3D rim is
the one place the two differ: LAMMPS's compound region offers a grain over the rim either
the slab's top inside the slab's extent or the hole's wall at the plate's height, not the
rim's edge), with the plate's own wall law. The angle is read from the grains below the
plate at rest (|v| < 5 cm/s). --seeds: realisations (-dem_seed: radii, jitter).

Writes bench/results/dem_heap.csv (--pour: dem_heap_pour.csv). Needs /usr/bin/lmp and h5py
(Debian python3-h5py).
Usage: /usr/bin/python3 bench/dem_heap.py [--dims 2,3] [--mus 0.2,0.4,0.6,0.8] [--rolls 0,0.1] [--no-lammps] [--pour]
"""
import argparse
import csv
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import REPO_ROOT, RESULTS_DIR, granmpm_binary, mpiexec_prefix, pyplot, save_figure, write_rows  # noqa: E402

R = 0.004
RHO = 2500.0
E = 0.3
WALL_MU = 0.8


POUR = False  # --pour
T_END = None  # --t-end: overrides the scene's (quick checks)
PLATE_Y, ORIFICE, ORIFICE3 = 0.3, 0.06, 0.08  # the hopper's plate, its slot (2D: 7.5 d) and round hole (3D: 10 d)


def setup(dim):
    s = scene(dim)
    if T_END:
        s["t_end"] = T_END
    return s


def scene(dim):
    if POUR and dim == 2:  # a hopper of 0.24 x 0.2 m above the plate (its side grains stay on the plate): it drains in ~1 s
        return dict(kn=2e5, lo=[0, 0], hi=[1.2, 0.55], blo=[0.48, PLATE_Y + 0.002], bhi=[0.72, PLATE_Y + 0.2], t_end=4.0, centre=[0.6])
    if POUR:  # 3D: a 0.1 x 0.25 x 0.1 m column on the plate over a round hole of 10 d (ORIFICE3): ~2600 spheres, most drain
        return dict(kn=2e4, lo=[0, 0, 0], hi=[0.6, 0.6, 0.6], blo=[0.25, PLATE_Y + 0.002, 0.25], bhi=[0.35, PLATE_Y + 0.252, 0.35], t_end=2.0,
                    centre=[0.3, 0.3])
    # A low, wide block (height / width 0.3): it slumps at low speed and keeps a cone whose
    # flanks stand at the angle of repose (a tall column's grains arrive too fast and spread).
    if dim == 2:
        return dict(kn=2e5, lo=[0, 0], hi=[1.2, 0.3], blo=[0.4, 0.002], bhi=[0.8, 0.122], t_end=2.0, centre=[0.6])
    # 3D: a cube (height / width 1), so that the spheres' heap is more than a few grains high.
    return dict(kn=2e4, lo=[0, 0, 0], hi=[0.6, 0.25, 0.6], blo=[0.24, 0.002, 0.24], bhi=[0.36, 0.122, 0.36], t_end=1.5, centre=[0.3, 0.3])


def damping():
    le = math.log(E)
    return -2 * le / math.sqrt(math.pi ** 2 + le ** 2)


def run_granmpm(dim, mu, roll, tmp, seed=1):
    s = setup(dim)
    out = os.path.join(tmp, f"g{dim}_{mu}_{roll}_{seed}")
    j = lambda v: ",".join(repr(x) for x in v)  # noqa: E731
    grav = "0,-9.81" if dim == 2 else "0,-9.81,0"
    outl = "xlo,xhi" if dim == 2 else "xlo,xhi,zlo,zhi"
    args = ["-dem", "-dem_dim", str(dim), "-dem_lo", j(s["lo"]), "-dem_hi", j(s["hi"]), "-dem_outlet", outl, "-dem_gravity", grav, "-dem_radius", repr(R),
            "-dem_radius_dist", "uniform", "-dem_radius_spread", "0.2", "-dem_density", repr(RHO), "-dem_kn", repr(s["kn"]), "-dem_e", repr(E),
            "-dem_damping", "seed", "-dem_mu", repr(mu), "-dem_mu_roll", repr(roll), "-dem_wall_mu", repr(WALL_MU), "-dem_block_lo", j(s["blo"]),
            "-dem_block_hi", j(s["bhi"]), "-dem_jitter", "0.5", "-dem_t_end", repr(s["t_end"]), "-dem_output_every", "2000",
            "-dem_output_dir", out, "-dem_output_overwrite", "-dem_seed", str(seed)]
    if POUR:
        args += ["-dem_plate_y", repr(PLATE_Y), "-dem_orifice", repr(ORIFICE if dim == 2 else ORIFICE3), "-dem_orifice_x", repr(s["centre"][0])]
        if dim == 3:
            args += ["-dem_orifice_z", repr(s["centre"][1])]
    p = subprocess.run(mpiexec_prefix(1) + [granmpm_binary()] + args, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit("granmpm failed: " + p.stderr[-2000:])
    dt = float(p.stdout.split("dem: dt ")[1].split()[0])
    snaps = sorted(f for f in os.listdir(out) if f.startswith("grains_") and f.endswith(".h5"))

    def load(name):
        with h5py.File(os.path.join(out, name), "r") as f:
            return f["grains/position"][...], f["grains/radius"][...].ravel(), f["grains/id"][...].ravel(), f["grains/velocity"][...]

    return dt, load(snaps[0]), load(snaps[-1])


def run_lammps(dim, mu, init, dt, tmp, lmp, seed=1):
    s = setup(dim)
    x, r, ids = init[:3]
    kn, c = s["kn"], damping()
    mass2d = lambda rr: RHO * math.pi * rr ** 2  # noqa: E731
    m_mean = mass2d(R) if dim == 2 else RHO * 4 / 3 * math.pi * R ** 3
    gn = c * math.sqrt(kn / (0.5 * m_mean))  # pair with two mean grains
    gw = c * math.sqrt(kn / m_mean)  # a mean grain on the wall
    kt = 2.0 / 7.0 * kn
    d = os.path.join(tmp, f"l{dim}_{mu}_{seed}")
    os.makedirs(d, exist_ok=True)
    lo, hi = s["lo"], s["hi"]
    with open(os.path.join(d, "grains.data"), "w") as f:
        f.write(f"GranMPM heap grains\n\n{len(r)} atoms\n1 atom types\n\n")
        if dim == 2:
            f.write(f"{lo[0]} {hi[0]} xlo xhi\n{lo[1]} {hi[1]} ylo yhi\n-0.5 0.5 zlo zhi\n\nAtoms\n\n")
        else:
            f.write(f"{lo[0]} {hi[0]} xlo xhi\n{lo[1]} {hi[1]} ylo yhi\n{lo[2]} {hi[2]} zlo zhi\n\nAtoms\n\n")
        for k in range(len(r)):
            rho = RHO if dim == 3 else mass2d(r[k]) / (4 / 3 * math.pi * r[k] ** 3)  # the disc's mass per unit thickness
            f.write(f"{int(ids[k]) + 1} 1 {2 * r[k]!r} {rho!r} {x[k, 0]!r} {x[k, 1]!r} {x[k, 2] if dim == 3 else 0.0!r}\n")
    steps = int(round(s["t_end"] / dt))
    lines = ["units si", f"dimension {dim}", "atom_style sphere", "atom_modify map array", "boundary f f p" if dim == 2 else "boundary f f f",
             "newton off", "comm_modify vel yes", "read_data grains.data",
             f"pair_style gran/hooke/history {kn!r} {kt!r} {gn!r} {0.5 * gn!r} {mu!r} 1 limit_damping", "pair_coeff * *",
             f"neighbor {0.3 * 1.2 * R!r} bin", "neigh_modify delay 0 every 1 check yes", f"timestep {dt!r}",
             "fix 1 all nve/sphere" + (" disc" if dim == 2 else ""), "fix 2 all gravity 9.81 vector 0 -1 0",
             f"fix 3 all wall/gran hooke/history {kn!r} {kt!r} {gw!r} {0.5 * gw!r} {WALL_MU!r} 1 limit_damping yplane {lo[1]!r} NULL"]
    if dim == 2:
        lines.append("fix 4 all enforce2d")
    if POUR and dim == 3:  # the plate: a 2-um slab less a cylinder of the hole's radius, touched from outside
        xo, zo, h, eps = s["centre"][0], s["centre"][1], 0.5 * ORIFICE3, 1e-6
        lines += [f"region slab block {lo[0] - 0.1!r} {hi[0] + 0.1!r} {PLATE_Y - eps!r} {PLATE_Y + eps!r} {lo[2] - 0.1!r} {hi[2] + 0.1!r} units box",
                  f"region hole cylinder y {xo!r} {zo!r} {h!r} {PLATE_Y - 0.01!r} {PLATE_Y + 0.01!r} side out units box",
                  "region plate intersect 2 slab hole side out",
                  f"fix 5 all wall/gran/region hooke/history {kn!r} {kt!r} {gw!r} {0.5 * gw!r} {WALL_MU!r} 1 limit_damping region plate"]
    elif POUR:  # the plate either side of the slot: flat blocks whose outside the grains touch
        xo, h, eps = s["centre"][0], 0.5 * ORIFICE, 1e-6
        lines += [f"region pl1 block {lo[0] - 0.1!r} {xo - h!r} {PLATE_Y - eps!r} {PLATE_Y + eps!r} -0.5 0.5 side out units box",
                  f"region pl2 block {xo + h!r} {hi[0] + 0.1!r} {PLATE_Y - eps!r} {PLATE_Y + eps!r} -0.5 0.5 side out units box",
                  f"fix 5 all wall/gran/region hooke/history {kn!r} {kt!r} {gw!r} {0.5 * gw!r} {WALL_MU!r} 1 limit_damping region pl1",
                  f"fix 6 all wall/gran/region hooke/history {kn!r} {kt!r} {gw!r} {0.5 * gw!r} {WALL_MU!r} 1 limit_damping region pl2"]
    lines += ["thermo 10000", "thermo_modify lost ignore", f"run {steps}", "write_dump all custom final.txt id x y z radius vx vy vz modify sort id"]
    with open(os.path.join(d, "in.heap"), "w") as f:
        f.write("\n".join(lines) + "\n")
    p = subprocess.run(mpiexec_prefix(1) + [lmp, "-in", "in.heap", "-log", "none"], capture_output=True, text=True, cwd=d, env=dict(os.environ, OMP_NUM_THREADS="1"))
    if p.returncode != 0:
        sys.exit("lmp failed: " + (p.stdout + p.stderr)[-2000:])
    rows = []
    with open(os.path.join(d, "final.txt")) as f:
        body = f.read().split("ITEM: ATOMS")[1].splitlines()[1:]
    for ln in body:
        q = ln.split()
        rows.append([float(v) for v in q[1:8]])
    a = np.array(rows)
    return a[:, :3], a[:, 3], a[:, 4:7]


def angle(dim, x, r, v=None):
    """Angle of repose [deg] from the final grains: surface height per bin against the distance from the heap axis."""
    s = setup(dim)
    c = s["centre"]
    if POUR:  # the heap below the plate, without the grains still falling or rolling down its flanks
        keep = (x[:, 1] < PLATE_Y) & (np.linalg.norm(v, axis=1) < 0.05)
        x, r = x[keep], r[keep]
        if len(r) == 0:
            return float("nan"), 0.0, 0
    rho = np.abs(x[:, 0] - c[0]) if dim == 2 else np.hypot(x[:, 0] - c[0], x[:, 2] - c[1])
    top = x[:, 1] + r
    w = 4 * R
    nb = int(rho.max() / w) + 1
    h = np.full(nb, np.nan)
    b = (rho / w).astype(int)
    for k in range(nb):
        sel = top[b == k]
        if len(sel) >= (2 if dim == 2 else 3):
            h[k] = sel.max()
    centres = (np.arange(nb) + 0.5) * w
    peak = np.nanmax(h)
    ok = np.isfinite(h) & (h > 0.25 * peak) & (h < 0.75 * peak)
    if ok.sum() < 3:
        return float("nan"), peak, len(r)
    slope = np.polyfit(centres[ok], h[ok], 1)[0]
    return math.degrees(math.atan(-slope)), peak, len(r)


def spread(dim, x):
    """Pour: grains left on the plate, grains below it, and their median distance from the axis [m]."""
    if not POUR:
        return "", "", ""
    c = setup(dim)["centre"]
    below = x[:, 1] < PLATE_Y
    rho = np.abs(x[:, 0] - c[0]) if dim == 2 else np.hypot(x[:, 0] - c[0], x[:, 2] - c[1])
    return int((~below).sum()), int(below.sum()), f"{np.median(rho[below]):.4f}" if below.any() else "nan"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dims", default="2,3")
    ap.add_argument("--mus", default="0.2,0.4,0.6,0.8")
    ap.add_argument("--rolls", default="0,0.1")
    ap.add_argument("--no-lammps", action="store_true")
    ap.add_argument("--pour", action="store_true", help="a heap poured through a hopper's slot (2D) or round hole (3D)")
    ap.add_argument("--seeds", default="1", help="realisations: -dem_seed values (radii, jitter); LAMMPS starts from each one's grains")
    ap.add_argument("--t-end", type=float, help="simulated time instead of the scene's (quick checks)")
    ap.add_argument("--tag", default="", help="suffix of the results file (dem_heap_pour<tag>.csv)")
    ap.add_argument("--plot", help="only draw docs/figures/dem_heap_pour.png from these results files (comma-separated names in bench/results)")
    a = ap.parse_args()
    if a.plot:
        plot(a.plot.split(","))
        return
    global POUR, T_END
    POUR, T_END = a.pour, a.t_end
    lmp = None if a.no_lammps else shutil.which("lmp")
    tmp = tempfile.mkdtemp(prefix="dem-heap-")
    head = ["dim", "mu", "mu_roll", "seed", "code", "grains_start", "grains_left", "heap_grains", "peak_height_m", "angle_deg", "tan_angle", "cpu_s",
            "on_plate", "below_plate", "median_axis_distance_below_m"]
    w = csv.writer(sys.stdout)
    w.writerow(head)
    rows = []
    for dim in [int(v) for v in a.dims.split(",")]:
        for mu in [float(v) for v in a.mus.split(",")]:
            for roll in [float(v) for v in a.rolls.split(",")]:
                for seed in [int(v) for v in a.seeds.split(",")]:
                    c0 = cpu()
                    dt, init, fin = run_granmpm(dim, mu, roll, tmp, seed)
                    c1 = cpu()
                    th, pk, nh = angle(dim, fin[0], fin[1], fin[3])
                    rows.append([dim, mu, roll, seed, "granmpm", len(init[1]), len(fin[1]), nh, f"{pk:.4f}", f"{th:.2f}", f"{math.tan(math.radians(th)):.3f}", f"{c1 - c0:.1f}",
                                 *spread(dim, fin[0])])
                    w.writerow(rows[-1])
                    sys.stdout.flush()
                    if roll == 0 and lmp:
                        xl, rl, vl = run_lammps(dim, mu, init, dt, tmp, lmp, seed)
                        th, pk, nh = angle(dim, xl, rl, vl)
                        rows.append([dim, mu, 0.0, seed, "lammps", len(init[1]), len(rl), nh, f"{pk:.4f}", f"{th:.2f}", f"{math.tan(math.radians(th)):.3f}", f"{cpu() - c1:.1f}",
                                     *spread(dim, xl)])
                        w.writerow(rows[-1])
                        sys.stdout.flush()
    write_rows(("dem_heap_pour" if POUR else "dem_heap") + a.tag, head, rows, command=" ".join(sys.argv), loadavg_end=os.getloadavg()[0])


def plot(files):
    """docs/figures/dem_heap_pour.png: the poured heaps' angle against mu (2D: mean and standard
    deviation over the realisations, 3D), GranMPM and LAMMPS, from the result CSVs."""
    plt = pyplot()
    if plt is None:
        return
    rows = []
    for name in files:
        with open(os.path.join(RESULTS_DIR, name)) as f:
            rows += list(csv.DictReader(f))
    dims = sorted({int(r["dim"]) for r in rows})
    fig, axes = plt.subplots(1, len(dims), figsize=(5 * len(dims), 3.6), squeeze=False)
    for ax, dim in zip(axes[0], dims):
        for code, roll, style in (("granmpm", 0.0, "o-"), ("lammps", 0.0, "s--"), ("granmpm", 0.1, "^:")):
            sel = [r for r in rows if int(r["dim"]) == dim and r["code"] == code and float(r["mu_roll"]) == roll and r["angle_deg"] != "nan"]
            mus = sorted({float(r["mu"]) for r in sel})
            if not mus:
                continue
            m = [np.mean([float(r["angle_deg"]) for r in sel if float(r["mu"]) == mu]) for mu in mus]
            sd = [np.std([float(r["angle_deg"]) for r in sel if float(r["mu"]) == mu]) for mu in mus]
            n = len(sel) // len(mus)
            ax.errorbar(mus, m, yerr=sd if n > 1 else None, fmt=style, capsize=3, label=f"{'GranMPM' if code == 'granmpm' else 'LAMMPS'} mu_r {roll:g}" + (f" ({n} runs)" if n > 1 else ""))
        ax.set_xlabel("contact friction mu")
        ax.set_ylabel("angle of the poured heap [deg]")
        ax.set_title(f"{dim}D poured heap (d = 8 mm, hopper through a hole)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, os.path.join(REPO_ROOT, "docs", "figures", "dem_heap_pour.png"))


def cpu():
    """CPU seconds (user + system) of the finished child processes so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


if __name__ == "__main__":
    main()
