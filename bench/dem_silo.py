#!/usr/bin/env python3
"""2D DEM silo discharge against the Beverloo law (issue 17, item 7).

Runs examples/dem_silo.opts (a 0.3 m wide silo of disks, d = 8 mm +-15%, plate at y = 0)
for orifice widths D, measures the discharge rate W (grains/s, a linear fit of the removed
count over the steady part: from 0.3 s to the end), and fits the 2D Beverloo law
W = C (D - k d)^(3/2) (k and C by least squares over a grid of k). Writes
bench/results/dem_silo.csv and prints the fit.

With --mpm: the same comparison in the geometry of GranMPM's continuum silo
(examples/silo.opts: 0.4 m wide, plate at y = 0.1 m, filled 0.35 m above it, orifice at
the centre), side by side with that MPM run (the granmpm binary with examples/silo.opts
and -silo_orifice D; its rate is the one it prints). Rates as mass per second and metre of
depth; the Beverloo constant C of W = C rho_b sqrt(g) (D - k d)^(3/2) with each medium's
bulk density (DEM: the solid fraction of a band of the filled silo, y 0.2..0.3 m, at
t = 0.3 s, times 2500; MPM: its -rho). Writes bench/results/dem_silo_mpm.csv.

Usage: python3 bench/dem_silo.py [--widths 0.05,0.06,0.08,0.10] [--t_end 1.2] [--ranks 1]
       /usr/bin/python3 bench/dem_silo.py --mpm [--widths 0.04,0.06,0.08,0.10] (needs h5py)
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


def beverloo(res, d):
    """Least-squares W = C (D - k d)^1.5 over a grid of k; returns k, C."""
    best = None
    for i in range(0, 301):
        k = i * 0.01
        xs = [(D - k * d) ** 1.5 if D > k * d else 0 for D, _ in res]
        C = sum(x * W for x, (_, W) in zip(xs, res)) / max(sum(x * x for x in xs), 1e-300)
        err = sum((C * x - W) ** 2 for x, (_, W) in zip(xs, res))
        if best is None or err < best[0]:
            best = (err, k, C)
    return best[1], best[2]


def mpm_compare(a):
    import re

    import h5py

    RHO_S, R, SPREAD, G = 2500.0, 0.004, 0.15, 9.81
    m_mean = RHO_S * 3.141592653589793 * R * R * (1 + SPREAD ** 2 / 3)  # E[pi r^2] rho, r uniform +-15%
    tmp = tempfile.mkdtemp(prefix="dem-silo-mpm-")
    rows, dem, mpm = [], [], []
    for D in [float(x) for x in a.widths.split(",")]:
        out = os.path.join(tmp, f"D{D}")
        args = ["-dem", "-dem_dim", "2", "-dem_lo", "0,0", "-dem_hi", "0.4,0.6", "-dem_outlet", "ylo", "-dem_plate_y", "0.1", "-dem_orifice", repr(D),
                "-dem_orifice_x", "0.2", "-dem_gravity", "0,-9.81", "-dem_radius", repr(R), "-dem_radius_dist", "uniform", "-dem_radius_spread", repr(SPREAD),
                "-dem_kn", "2e5", "-dem_e", "0.5", "-dem_mu", "0.5", "-dem_block_lo", "0,0.105", "-dem_block_hi", "0.4,0.45", "-dem_jitter", "0.5",
                "-dem_skin", "0.002", "-dem_t_end", repr(a.t_end), "-dem_output_every", "200", "-dem_fields_every", "5000", "-dem_quiet",
                "-dem_output_dir", out, "-dem_output_overwrite"]
        p = subprocess.run(mpiexec_prefix(a.ranks) + [granmpm_binary()] + args, capture_output=True, text=True)
        if p.returncode != 0:
            sys.exit(p.stderr[-1000:])
        Wn = rate(os.path.join(out, "dem_summary.csv"), 0.3)
        # Bulk density: the solid fraction of the band y in [0.2, 0.3] of the snapshot nearest t = 0.3 s.
        best = None
        for f in sorted(os.listdir(out)):
            if f.startswith("grains_") and f.endswith(".h5"):
                with h5py.File(os.path.join(out, f), "r") as h:
                    t = float(h.attrs["time"])
                    if best is None or abs(t - 0.3) < abs(best[0] - 0.3):
                        x, r = h["grains/position"][...], h["grains/radius"][...].ravel()
                        band = (x[:, 1] >= 0.2) & (x[:, 1] < 0.3)
                        best = (t, float((3.141592653589793 * r[band] ** 2).sum() / (0.4 * 0.1)))
        phi = best[1]
        Wd = Wn * m_mean
        dem.append((D, Wd / (phi * RHO_S * G ** 0.5)))
        # The continuum silo at the same D.
        mo = os.path.join(tmp, f"M{D}")
        cmd = mpiexec_prefix(a.ranks) + [granmpm_binary(), "-options_file", os.path.join(REPO_ROOT, "examples", "silo.opts"), "-silo_orifice", f"{D:g}",
                                         "-output_interval", "0", "-output_final", "0", "-progress_interval", "0", "-output_dir", mo]
        q = subprocess.run(cmd, capture_output=True, text=True)
        m = re.search(r"discharge rate ([-+0-9.eE]+) kg/s", q.stdout)
        if q.returncode != 0 or not m:
            sys.exit("MPM silo failed: " + (q.stdout + q.stderr)[-1000:])
        Wm = float(m.group(1))
        RHO_MPM = 1500.0
        mpm.append((D, Wm / (RHO_MPM * G ** 0.5)))
        rows.append([D, D / D_GRAIN, f"{Wn:.1f}", f"{Wd:.3f}", f"{phi:.3f}", f"{Wm:.3f}"])
        print(f"D = {D:.3f} m: DEM {Wn:.0f} grains/s = {Wd:.2f} kg/s/m (solid fraction {phi:.3f}); MPM {Wm:.2f} kg/s/m", flush=True)
    write_mpm_csv(rows)


def write_mpm_csv(rows):
    """Fits and CSV from rows [D, D/d, grains/s, DEM kg/s/m, DEM solid fraction, MPM kg/s/m]. The DEM's bulk
    density is its static one: the solid fraction of the smallest orifice's run (larger orifices dilate the band)."""
    RHO_S, G = 2500.0, 9.81
    phi = float(rows[0][4])
    dem = [(float(r[0]), float(r[3]) / (phi * RHO_S * G ** 0.5)) for r in rows]
    mpm = [(float(r[0]), float(r[5]) / (1500.0 * G ** 0.5)) for r in rows]
    # The offset D0 = k d in metres, on a grid up to 0.9 of the smallest width (d differs: 8 mm grains, the MPM's 1 mm).
    kd, Cd = beverloo(dem, 0.9 * dem[0][0] / 3)
    km, Cm = beverloo(mpm, 0.9 * mpm[0][0] / 3)
    D0d, D0m = kd * 0.9 * dem[0][0] / 3, km * 0.9 * mpm[0][0] / 3
    print(f"Beverloo W = C rho_b sqrt(g) (D - D0)^1.5: DEM D0 = {D0d * 1e3:.1f} mm = {D0d / D_GRAIN:.2f} d, C = {Cd:.3f} (rho_b = {phi:.3f} x 2500); "
          f"MPM D0 = {D0m * 1e3:.1f} mm, C = {Cm:.3f} (rho_b = 1500)")
    os.makedirs(RESULTS_DIR, exist_ok=True)
    with open(os.path.join(RESULTS_DIR, "dem_silo_mpm.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["D_m", "D_over_d", "dem_grains_per_s", "dem_kg_per_s_m", "dem_solid_fraction", "mpm_kg_per_s_m", "dem_C_fit", "dem_D0_fit_m", "mpm_C_fit",
                    "mpm_D0_fit_m", "dem_fit_kg_per_s_m", "mpm_fit_kg_per_s_m"])
        for r in rows:
            D = float(r[0])
            fd = Cd * phi * RHO_S * G ** 0.5 * max(D - D0d, 0) ** 1.5
            fm = Cm * 1500.0 * G ** 0.5 * max(D - D0m, 0) ** 1.5
            w.writerow(list(r[:6]) + [f"{Cd:.4f}", f"{D0d:.4f}", f"{Cm:.4f}", f"{D0m:.4f}", f"{fd:.2f}", f"{fm:.2f}"])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--widths", default="0.05,0.06,0.08,0.10")
    ap.add_argument("--t_end", type=float, default=1.2)
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--mpm", action="store_true")
    ap.add_argument("--refit", action="store_true", help="with --mpm: redo the fits from bench/results/dem_silo_mpm.csv without running")
    a = ap.parse_args()
    if a.mpm and a.refit:
        with open(os.path.join(RESULTS_DIR, "dem_silo_mpm.csv")) as f:
            return write_mpm_csv([r[:6] for r in list(csv.reader(f))[1:]])
    if a.mpm:
        return mpm_compare(a)
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
    k, C = beverloo(res, D_GRAIN)
    print(f"Beverloo fit W = C (D - k d)^1.5: k = {k:.2f}, C = {C:.4g} grains/s/m^1.5")
    os.makedirs(RESULTS_DIR, exist_ok=True)
    with open(os.path.join(RESULTS_DIR, "dem_silo.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["D_m", "D_over_d", "W_grains_per_s", "beverloo_fit"])
        for D, W in res:
            w.writerow([D, D / D_GRAIN, f"{W:.2f}", f"{C * max(D - k * D_GRAIN, 0) ** 1.5:.2f}"])


if __name__ == "__main__":
    main()
