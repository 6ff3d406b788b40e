#!/usr/bin/env python3
"""Hybrid against DEM-only and MPM-only (issue 18; docs/hybrid.md): --case silo (default),
the "steady silo with a fixed band" scene, or --case collapse, a 2D column collapse.

--case silo:
Runs examples/hybrid_silo.opts three ways on the same geometry, material and gravity, with the
continuum of --mu_s/--b/--d (the collapse's calibration) and, by default (--silo_grains
collapse), the collapse's disks (r 2 mm +-20%, e 0.3, mu_roll 0.1) that calibration is of:
  hybrid    the file as it is: MPM above y = 0.2 m, DEM below y = 0.15 m, the band between;
  DEM-only  granmpm -dem with the file's -dem_* options and the grains filling the silo to
            y = 0.5 m (the box, outlet and gravity of the MPM options);
  MPM-only  the file's MPM options with the material points filling the silo from the plate.
Discharge: the mass through the orifice against time (MPM: silo.csv; DEM-only: the removed
count of dem_summary.csv times the mean grain mass; hybrid: the grains' removed mass of
dem_summary.csv plus the material points' silo.csv), the rate a linear fit over
[--fit_from, t_end]. Wall and CPU time (user + system) of each run. Writes
bench/results/hybrid.csv, docs/figures/hybrid_silo.png (/usr/bin/python3 has matplotlib).

--case collapse: a column L0 = 0.1 m wide, H0 = 0.2 m high (a = 2) against the slip wall at
x = 0 on a rough floor, disks r = 2 mm +-20% (L0 = 25 d), h = 1 cm, t_end = 6 sqrt(H0/g), four
ways: DEM-only, MPM-only (local mu(I) calibrated to these disks by --case mu_i: mu_s 0.274,
b 0.921, d = 4 mm), hybrid with a fixed band (material points below
y = 0.11 m, grains above y = 0.09 m, the band between) and hybrid zoned (the same start,
-hybrid_zone_every 10 with homogenisation and enrichment). From the last snapshots of both
species: the runout (L_f - L0)/L0 (L_f the 99% mass front, and the tip), the deposit profile
(the highest grain top or material point per 1 cm column) and its mean difference to the
DEM's, the front over time, the mass balance; CPU times. Writes bench/results/hybrid_collapse.csv
and docs/figures/hybrid_collapse.png.

--case mu_i: the DEM's own mu(I): the collapse's disks in steady inclined-plane flows
(periodic in x, a layer ~14 d deep on a flat floor of the collapse's floor friction) at
--angles; per layer gdot, the overburden p and I = gdot d / sqrt(p / rho_s) (d the mean
diameter), mu = tan(theta); a linear fit mu = mu_s + b I over the steady runs (mean velocity
drifting by <= 5% of g sin theta) gives the local model's -mu_s and -b. Writes
bench/results/hybrid_mu_i.csv and docs/figures/hybrid_mu_i.png.

Usage: /usr/bin/python3 bench/hybrid.py [--case silo|collapse|mu_i] [--t_end 0.8] [--fit_from 0.3] [--ranks 1]
       silo:     [--silo_grains collapse|file] [--mu_s 0.274] [--b 0.921] [--d 0.004] [--tag _variant]
       collapse: [--mu_s 0.274] [--b 0.921] [--d 0.004] [--floor_mu MU] [--cell 0.01] [--mpm_dt 1e-4]
                 [--zone_every 10] [--band_distance 0] [--scale 1] [--methods a,b] [--repeats 1] [--tag _variant]
       mu_i:     [--angles 16,17,18,19] [--chute_t_end 4]
"""
import argparse
import bisect
import csv
import math
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import FIGURES_DIR, REPO_ROOT, granmpm_binary, mpiexec_prefix, pyplot, save_figure, write_rows  # noqa: E402

OPTS = os.path.join(REPO_ROOT, "examples", "hybrid_silo.opts")


def read_opts(path):
    out = []
    for line in open(path):
        line = line.split("#", 1)[0].split()
        if line:
            out.append((line[0], line[1] if len(line) > 1 else None))
    return out


def flat(pairs):
    args = []
    for k, v in pairs:
        args += [k] + ([v] if v is not None else [])
    return args


def run(args, ranks, out_flag, label):
    """Runs granmpm with args and out_flag <fresh dir>: (dir, wall s, CPU s of the processes)."""
    d = tempfile.mkdtemp(prefix="granmpm-hybrid-")
    full = [granmpm_binary()] + args + [out_flag, d]
    if ranks > 1:
        full = mpiexec_prefix(ranks) + full
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    p = subprocess.run(full, capture_output=True, text=True)
    wall = time.monotonic() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        sys.exit("bench/hybrid.py: the %s run failed: %s" % (label, (p.stdout + p.stderr)[-600:]))
    print("# %s: %.1f s wall" % (label, wall), file=sys.stderr, flush=True)
    return d, wall, (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime), p.stdout


def series(path, tcol, mcol, scale=1.0):
    rows = list(csv.DictReader(open(path)))
    return [float(r[tcol]) for r in rows], [scale * float(r[mcol]) for r in rows]


def interp(t, ts, ms):
    if not ts:
        return 0.0
    i = bisect.bisect_left(ts, t)
    if i <= 0:
        return ms[0] if t >= ts[0] else 0.0
    if i >= len(ts):
        return ms[-1]
    f = (t - ts[i - 1]) / (ts[i] - ts[i - 1])
    return ms[i - 1] + f * (ms[i] - ms[i - 1])


def fit_rate(ts, ms, t0):
    pts = [(t, m) for t, m in zip(ts, ms) if t >= t0]
    if len(pts) < 3:
        return float("nan")
    mt = sum(p[0] for p in pts) / len(pts)
    mm = sum(p[1] for p in pts) / len(pts)
    return sum((t - mt) * (m - mm) for t, m in pts) / sum((t - mt) ** 2 for t, _ in pts)


# The collapse's disks' grain properties (DEM_GRAINS without its walls and fixed step): the grains
# the continuum's mu(I) was calibrated to (--case mu_i), for the silo's --silo_grains collapse.
SILO_COLLAPSE_GRAINS = [("-dem_radius", "0.002"), ("-dem_radius_spread", "0.2"), ("-dem_e", "0.3"), ("-dem_mu", "0.5"), ("-dem_mu_roll", "0.1")]


def silo(a):
    opts = read_opts(OPTS)
    # The continuum calibrated to the collapse's disks (--mu_s, --b, --d), and with
    # --silo_grains collapse those disks instead of the file's r = 4 mm ones (no rolling
    # resistance, e 0.5), so that the grains and the continuum are the same material.
    over = {"-mu_s": repr(a.mu_s), "-b": repr(a.b), "-d": repr(a.d)}
    if a.silo_grains == "collapse":
        over.update(SILO_COLLAPSE_GRAINS)
    opts = [(k, over.get(k, v)) for k, v in opts] + [(k, v) for k, v in over.items() if k not in dict(opts)]
    mpm = [(k, v) for k, v in opts if not (k.startswith("-dem_") or k.startswith("-hybrid_")) and k not in ("-output_dir", "-t_end")]
    dem = dict((k, v) for k, v in opts if k.startswith("-dem_"))
    fill_top = dict(opts)["-body_hi"].split(",")[1]
    width, y_plate = dict(opts)["-domain_hi"].split(",")[0], dem["-dem_plate_y"]
    r0, spread, rho = float(dem["-dem_radius"]), float(dem["-dem_radius_spread"]), 2500.0
    grain_mass = rho * math.pi * r0 * r0 * (1 + spread * spread / 3)  # mean of pi r^2 for r uniform in r0 (1 +- s)
    runs = {
        "hybrid": (flat([(k, v) for k, v in opts if k not in ("-output_dir", "-t_end")] + [("-t_end", str(a.t_end))]), "-output_dir"),
        # MPM-only: the material points from the plate to the fill height
        "MPM-only": (flat([(k, v) if k != "-body_lo" else (k, "0," + y_plate) for k, v in mpm] + [("-t_end", str(a.t_end))]), "-output_dir"),
    }
    # DEM-only: the grains to the fill height, with the MPM's box, outlet face and gravity
    d = dict(dem)
    d["-dem_block_hi"] = width + "," + fill_top
    o = dict(opts)
    runs["DEM-only"] = (["-dem"] + flat(list(d.items())) + ["-dem_lo", o["-domain_lo"], "-dem_hi", o["-domain_hi"], "-dem_outlet", "ylo", "-dem_gravity", o["-gravity"],
                                                            "-dem_t_end", str(a.t_end), "-dem_fields", "0", "-dem_quiet", "-dem_output_every", "100"], "-dem_output_dir")
    res, out = {}, {}
    for name in ("DEM-only", "hybrid", "MPM-only"):
        args, flag = runs[name]
        dd, wall, cpu, text = run(args, a.ranks, flag, name)
        if name == "DEM-only":
            ts, ms = series(os.path.join(dd, "dem_summary.csv"), "t", "removed", grain_mass)
        elif name == "MPM-only":
            ts, ms = series(os.path.join(dd, "silo.csv"), "t", "discharged_mass")
        else:
            tg, mg = series(os.path.join(dd, "dem_summary.csv"), "t", "removed_mass")
            tm, mm = series(os.path.join(dd, "silo.csv"), "t", "discharged_mass")
            ts, ms = tg, [g + interp(t, tm, mm) for t, g in zip(tg, mg)]
            res["hybrid (grains)"] = (tg, mg)
            res["hybrid (points)"] = (tm, mm)
        res[name] = (ts, ms)
        out[name] = {"rate": fit_rate(ts, ms, a.fit_from), "mass_end": ms[-1] if ms else 0.0, "elapsed": wall, "cpu_s": cpu, "cmd": " ".join(args)}
        shutil.rmtree(dd, ignore_errors=True)
    runs = out
    ref = runs["DEM-only"]["rate"]
    rows = []
    print("method,discharge_rate_kg_per_s_per_m,rel_to_dem,discharged_mass_kg_per_m,wall_s,cpu_s,wall_ratio_dem_over_this,cpu_ratio_dem_over_this")
    for name in ("DEM-only", "hybrid", "MPM-only"):
        r = runs[name]
        row = [name, "%.4g" % r["rate"], "%.4f" % (r["rate"] / ref - 1), "%.4g" % r["mass_end"], "%.2f" % r["elapsed"], "%.2f" % r["cpu_s"],
               "%.3f" % (runs["DEM-only"]["elapsed"] / r["elapsed"]), "%.3f" % (runs["DEM-only"]["cpu_s"] / r["cpu_s"])]
        rows.append(row)
        print(",".join(row))
    write_rows("hybrid" + a.tag, ["method", "discharge_rate", "rel_to_dem", "discharged_mass", "wall_s", "cpu_s", "wall_ratio_dem_over_this", "cpu_ratio_dem_over_this"], rows,
               t_end=a.t_end, fit_from=a.fit_from, ranks=a.ranks, opts="examples/hybrid_silo.opts", mu_s=a.mu_s, b=a.b, d=a.d, silo_grains=a.silo_grains,
               commands={k: v["cmd"] for k, v in runs.items()})
    plt = pyplot()
    if plt:
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        style = {"DEM-only": ("k", "-"), "hybrid": ("C3", "-"), "MPM-only": ("C0", "-"), "hybrid (grains)": ("C3", ":"), "hybrid (points)": ("C3", "--")}
        for name, (ts, ms) in res.items():
            c, ls = style[name]
            rate = runs[name]["rate"] if name in runs else None
            ax.plot(ts, ms, color=c, ls=ls, label=name + (" (%.3g kg/s/m)" % rate if rate else ""))
        ax.axvline(a.fit_from, color="0.7", lw=0.8)
        ax.set_xlabel("t [s]")
        ax.set_ylabel("discharged mass [kg per m depth]")
        ax.set_title("2D silo, D = 5 cm: hybrid (fixed band y 0.15-0.2 m) vs DEM-only, MPM-only")
        ax.legend(fontsize=8)
        save_figure(fig, os.path.join(FIGURES_DIR, "hybrid_silo" + a.tag + ".png"))


# The collapse: geometry, grains and the MPM's material (see the docstring).
L0, H0, R, RHO = 0.1, 0.2, 0.002, 2500.0
WIDTH, HEIGHT, CELL = 0.6, 0.25, 0.01
BAND = (0.09, 0.11)
DEM_GRAINS = ["-dem_dim", "2", "-dem_radius", repr(R), "-dem_radius_dist", "uniform", "-dem_radius_spread", "0.2", "-dem_density", repr(RHO),
              "-dem_kn", "2e5", "-dem_e", "0.3", "-dem_mu", "0.5", "-dem_mu_roll", "0.1", "-dem_wall_mu", "0.8", "-dem_wall_mu_xlo", "0",
              "-dem_jitter", "0.5", "-dem_dt", "2.5e-5"]
MPM_COLUMN = ["-scene", "collapse", "-material", "mu_i", "-mu_s", "0.274", "-b", "0.921", "-d", repr(2 * R), "-rho_s", repr(RHO),
              "-rho", "2050", "-rho_c", "1845", "-E", "1e6", "-nu", "0.3", "-domain_lo", "0,0", "-domain_hi", "%r,%r" % (WIDTH, HEIGHT),
              "-cells", "%d,%d" % (round(WIDTH / CELL), round(HEIGHT / CELL)), "-bc_xlo", "slip", "-bc_xhi", "slip", "-bc_ylo", "sticky", "-bc_yhi", "free",
              "-gravity", "0,-9.81", "-gravity_ramp", "0", "-geostatic", "-p0", "0", "-ppc", "2", "-shape", "gimp", "-transfer", "apic",
              "-progress_interval", "100000"]


def snapshots(d, prefix):
    return sorted(os.path.join(d, f) for f in os.listdir(d) if f.startswith(prefix) and f.endswith(".h5"))


def species(d):
    """(time, x, y top, mass) of every snapshot pair in d: material points (snap_*) and grains
    (grains_*) of the same index are the same time."""
    import h5py
    import numpy as np
    out = []
    pts, grs = snapshots(d, "snap_"), snapshots(d, "grains_")
    n = max(len(pts), len(grs))
    for k in range(n):
        xs, ys, ms, t = [], [], [], None
        if k < len(pts):
            with h5py.File(pts[k], "r") as f:
                t = float(f.attrs["time"])
                x = f["particles/position"][...]
                m = f["particles/mass"][...].ravel()
                xs.append(x[:, 0])
                ys.append(x[:, 1] + 0.25 * CELL)  # the top of a material point's share of the cell (2 per cell and direction)
                ms.append(m)
        if k < len(grs):
            with h5py.File(grs[k], "r") as f:
                tg = float(f.attrs["time"])
                if t is not None and abs(tg - t) > 1e-9:
                    sys.exit("bench/hybrid.py: %s and %s are not the same time (%g, %g)" % (pts[k], grs[k], t, tg))
                t = tg
                x = f["grains/position"][...]
                r = f["grains/radius"][...].ravel()
                w = f["grains/mass_share"][...].ravel() if "grains/mass_share" in f else np.ones_like(r)
                xs.append(x[:, 0] + r)
                ys.append(x[:, 1] + r)
                ms.append(w * RHO * math.pi * r * r)
        out.append((t, np.concatenate(xs), np.concatenate(ys), np.concatenate(ms)))
    return out


def front(x, m, q=0.99):
    import numpy as np
    o = np.argsort(x)
    c = np.cumsum(m[o])
    return float(x[o][np.searchsorted(c, q * c[-1])])


def profile(x, y, nbin):
    import numpy as np
    top = np.zeros(nbin)
    b = np.clip((x / CELL).astype(int), 0, nbin - 1)
    np.maximum.at(top, b, y)
    return top


def collapse(a):
    import numpy as np
    over = {"-mu_s": repr(a.mu_s), "-b": repr(a.b), "-d": repr(a.d), "-bc_ylo": "slip" if a.floor_mu is not None else "sticky"}
    column_mpm = [v if k == 0 or MPM_COLUMN[k - 1] not in over else over[MPM_COLUMN[k - 1]] for k, v in enumerate(MPM_COLUMN)]
    if a.floor_mu is not None:
        column_mpm += ["-wall_friction", repr(a.floor_mu)]
    t_end = 6 * math.sqrt(H0 / 9.81)
    # Fixed steps (MPM 1e-4 s, DEM 2.5e-5 s = t_c/28 of the smallest grain; the hybrid takes 4
    # DEM sub-steps per MPM step): snapshots of all four runs at the same times, every 0.04 s.
    every = round(0.04 / a.mpm_dt)
    if abs(every * a.mpm_dt - 0.04) > 1e-12:
        sys.exit("bench/hybrid.py: --mpm_dt must divide the snapshot interval 0.04 s")
    mpm_end = ["-t_end", "%.6g" % t_end, "-dt", repr(a.mpm_dt), "-output_interval", "%d" % every]
    column = ["-body_lo", "0,0", "-body_hi", "%r,%r" % (L0, H0)]
    hyb = column_mpm + ["-body_lo", "0,0", "-body_hi", "%r,%r" % (L0, BAND[1])] + mpm_end + ["-hybrid_dem"] + DEM_GRAINS + [
        "-dem_block_lo", "0,%r" % BAND[0], "-dem_block_hi", "%r,%r" % (L0, H0), "-hybrid_band", "%r,%r" % BAND, "-hybrid_continuum", "lo"]
    runs = {
        "DEM-only": (["-dem"] + DEM_GRAINS + ["-dem_lo", "0,0", "-dem_hi", "%r,%r" % (WIDTH, HEIGHT), "-dem_gravity", "0,-9.81", "-dem_outlet", "xhi",
                                              "-dem_block_lo", "0,0.002", "-dem_block_hi", "%r,%r" % (L0, H0), "-dem_t_end", "%.6g" % t_end,
                                              "-dem_fields_every", "1600", "-dem_quiet"], "-dem_output_dir"),
        "MPM-only": (column_mpm + column + mpm_end, "-output_dir"),
        "hybrid fixed band": (hyb, "-output_dir"),
        "hybrid zoned": (hyb + ["-hybrid_zone_every", "%d" % a.zone_every] + (["-hybrid_band_distance", repr(a.band_distance)] if a.band_distance else []), "-output_dir"),
    }
    res, rows = {}, []
    for name, (args, flag) in runs.items():
        if a.methods and name != "DEM-only" and name not in a.methods:
            continue
        dd, wall, cpu, text = run(args, a.ranks, flag, name)
        # Repeats (the runs are deterministic: the same result, another CPU time): the medians
        # of the wall and CPU times and of the modules' CPU counters below.
        walls, cpus, texts = [wall], [cpu], [text]
        for _ in range(a.repeats - 1):
            d2, w2, c2, t2 = run(args, a.ranks, flag, name)
            shutil.rmtree(d2, ignore_errors=True)
            walls.append(w2)
            cpus.append(c2)
            texts.append(t2)
        wall, cpu = float(np.median(walls)), float(np.median(cpus))
        snaps = species(dd)
        t, x, y, m = snaps[-1]
        t0, x0, y0, m0 = snaps[0]
        fronts = [(s[0], front(s[1], s[3])) for s in snaps]
        summary = [l for l in text.splitlines() if "shares from the zones" in l or "hybrid coupling" in l]
        bal = re.search(r"mass balance of the zone updates ([-+0-9.e]+) kg", text)
        # Where the CPU goes (rank 0's process; the modules' summaries): DEM sub-steps and their
        # per-step summaries, the coupling's hooks, the zone updates; the rest is the MPM.
        def cpu_parts(text):
            dem_cpu = re.search(r"([-+0-9.e]+) s in the DEM sub-steps, ([-+0-9.e]+) s in their per-step summaries", text)
            hyb_cpu = re.search(r"([-+0-9.e]+) s in the coupling \(grains to the grid, ghosts, FLIP update\), ([-+0-9.e]+) s in the zone updates", text)
            parts = [float(dem_cpu.group(1)), float(dem_cpu.group(2))] if dem_cpu else [float("nan")] * 2
            return parts + ([float(hyb_cpu.group(1)), float(hyb_cpu.group(2))] if hyb_cpu else [float("nan")] * 2)
        parts = [float(v) for v in np.median([cpu_parts(t) for t in texts], axis=0)]
        res[name] = dict(t=t, front99=front(x, m), tip=float(x.max()), profile=profile(x, y, round(WIDTH / CELL)), fronts=fronts, wall=wall, cpu=cpu,
                         mass0=float(m0.sum()), mass1=float(m.sum()), parts=parts, balance=float(bal.group(1)) if bal else 0.0, summary=summary[-1] if summary else "",
                         cmd=" ".join(args))
        shutil.rmtree(dd, ignore_errors=True)
    ref = res["DEM-only"]
    head = ["method", "runout_99", "rel_to_dem_99", "runout_tip", "rel_to_dem_tip", "profile_mean_abs_diff_over_H0", "mass_change_rel", "zone_mass_balance_kg",
            "wall_s", "cpu_s", "cpu_ratio_dem_over_this", "cpu_dem_substeps_s", "cpu_dem_step_summaries_s", "cpu_coupling_s", "cpu_zone_updates_s"]
    print(",".join(head))
    for name, r in res.items():
        ro, rt = (r["front99"] - L0) / L0, (r["tip"] - L0) / L0
        ro_ref, rt_ref = (ref["front99"] - L0) / L0, (ref["tip"] - L0) / L0
        dprof = float(np.mean(np.abs(r["profile"] - ref["profile"]))) / H0
        row = [name, "%.4f" % ro, "%.4f" % (ro / ro_ref - 1), "%.4f" % rt, "%.4f" % (rt / rt_ref - 1), "%.4f" % dprof,
               "%.3g" % ((r["mass1"] - r["mass0"]) / r["mass0"]), "%.3g" % r["balance"], "%.2f" % r["wall"], "%.2f" % r["cpu"], "%.3f" % (ref["cpu"] / r["cpu"])] + ["%.3g" % v for v in r["parts"]]
        rows.append(row)
        print(",".join(row))
        if r["summary"]:
            print("# %s: %s" % (name, r["summary"][-600:]), file=sys.stderr)
    out_name = "hybrid_collapse" + a.tag
    write_rows(out_name, head, rows, t_end=t_end, ranks=a.ranks, repeats=a.repeats, mu_s=a.mu_s, b=a.b, d=a.d, floor_mu=a.floor_mu, scale=a.scale, mpm_dt=a.mpm_dt, zone_every=a.zone_every, L0=L0, H0=H0, band_distance=a.band_distance, cell=CELL, commands={k: v["cmd"] for k, v in res.items()})
    plt = pyplot()
    if plt:
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
        colour = {"DEM-only": "k", "MPM-only": "C0", "hybrid fixed band": "C2", "hybrid zoned": "C3"}
        xc = (np.arange(round(WIDTH / CELL)) + 0.5) * CELL
        for name, r in res.items():
            ax1.plot(xc / L0, r["profile"] / L0, color=colour[name], label="%s (runout %.2f)" % (name, (r["front99"] - L0) / L0))
            ts, fs = zip(*r["fronts"])
            ax2.plot(ts, (np.array(fs) - L0) / L0, color=colour[name], label=name)
        ax1.set_xlabel("x / L0")
        ax1.set_ylabel("deposit height / L0")
        ax1.legend(fontsize=8)
        ax2.set_xlabel("t [s]")
        ax2.set_ylabel("99% mass front (x - L0) / L0")
        ax2.set_title("front over time")
        ax1.set_title("2D column collapse, a = 2, MPM mu_s %g, h = %g cm" % (a.mu_s, 100 * CELL))
        save_figure(fig, os.path.join(FIGURES_DIR, out_name + ".png"))


# --case mu_i: the DEM's own mu(I), from steady inclined-plane flows of the collapse's disks.
CHUTE_W, CHUTE_H = 0.1, 0.08


def chute_profile(d, theta, t_from):
    """Time-averaged I and mu = tan(theta) of the bulk of one chute run (grains_* snapshots
    from t_from on): per layer of one mean diameter, the mean vx, its y-gradient gdot, the
    overburden p (the grains' weight above, per width, times cos theta: sigma_yy of the steady
    flow) and I = gdot d / sqrt(p / rho_s); layers more than 3 d from the floor and the
    surface. Returns (I per layer, y per layer, surface height, mean vx at the surface)."""
    import h5py
    import numpy as np
    dm = 2 * R
    nb = int(CHUTE_H / dm) + 2
    vs, ns, area_above, tops, means = np.zeros(nb), np.zeros(nb), np.zeros(nb), [], []
    nsnap = 0
    for path in snapshots(d, "grains_"):
        with h5py.File(path, "r") as f:
            t = float(f.attrs["time"])
            if t < t_from - 1e-9:
                continue
            x = f["grains/position"][...]
            v = f["grains/velocity"][...]
            r = f["grains/radius"][...].ravel()
        b = np.clip((x[:, 1] / dm).astype(int), 0, nb - 1)
        np.add.at(vs, b, v[:, 0])
        np.add.at(ns, b, 1)
        a = np.zeros(nb)
        np.add.at(a, b, math.pi * r * r)
        area_above += np.cumsum(a[::-1])[::-1] - 0.5 * a  # the layer's own half counts
        tops.append(float(np.percentile(x[:, 1] + r, 99)))
        means.append((t, float(np.sum(r * r * v[:, 0]) / np.sum(r * r))))
        nsnap += 1
    if nsnap == 0:
        sys.exit("bench/hybrid.py: no chute snapshot after t = %g" % t_from)
    vx = np.where(ns > 0, vs / np.maximum(ns, 1), 0.0)
    top = float(np.mean(tops))
    p = RHO * 9.81 * math.cos(theta) * area_above / nsnap / CHUTE_W
    yc = (np.arange(nb) + 0.5) * dm
    gd = np.gradient(vx, dm)
    keep = (yc > 3 * dm) & (yc < top - 3 * dm) & (p > 0)
    I = gd[keep] * dm / np.sqrt(p[keep] / RHO)
    ts, ms = zip(*means)
    accel = float(np.polyfit(ts, ms, 1)[0]) if len(ts) > 2 else float("nan")  # the mean velocity's drift: ~0 when steady
    return I, yc[keep], top, float(vx[max(0, int(top / dm) - 2)]), accel


def mu_i(a):
    """DEM chute flows at --angles (degrees) on a flat floor of the collapse's floor friction,
    periodic in x: mu = tan(theta) against the bulk's median I; a linear fit mu = mu_s + b I
    gives the local mu(I) model's -mu_s and -b for -d = the mean diameter. Writes
    bench/results/hybrid_mu_i.csv and docs/figures/hybrid_mu_i.png."""
    import numpy as np
    rows, pts = [], []
    for deg in a.angles:
        th = math.radians(deg)
        g = "%r,%r" % (9.81 * math.sin(th), -9.81 * math.cos(th))
        grains = [v for k, v in enumerate(DEM_GRAINS) if v != "-dem_wall_mu_xlo" and (k == 0 or DEM_GRAINS[k - 1] != "-dem_wall_mu_xlo")]
        args = ["-dem"] + grains + ["-dem_lo", "0,0", "-dem_hi", "%r,%r" % (CHUTE_W, 2 * CHUTE_H), "-dem_periodic", "x", "-dem_gravity", g,
                                        "-dem_block_lo", "0,0.002", "-dem_block_hi", "%r,%r" % (CHUTE_W, CHUTE_H), "-dem_t_end", repr(a.chute_t_end),
                                        "-dem_fields_every", "2000", "-dem_quiet"]
        dd, wall, cpu, _ = run(args, a.ranks, "-dem_output_dir", "chute %g deg" % deg)
        I, y, top, vsurf, accel = chute_profile(dd, th, a.chute_t_end / 2)
        shutil.rmtree(dd, ignore_errors=True)
        Im = float(np.median(I)) if len(I) else float("nan")
        steady = abs(accel) <= 0.05 * 9.81 * math.sin(th) and Im > 1e-3  # flowing, its mean velocity drifting by <= 5% of g sin(theta)
        pts.append((deg, Im, math.tan(th), I, y, steady))
        rows.append(["%g" % deg, "%.4f" % math.tan(th), "%.4g" % Im, "%.4g" % (float(np.percentile(I, 25)) if len(I) else float("nan")),
                     "%.4g" % (float(np.percentile(I, 75)) if len(I) else float("nan")), "%d" % len(I), "%.4f" % top, "%.4g" % vsurf, "%.3g" % accel, "%.3g" % (accel / (9.81 * math.sin(th))), "%d" % steady, "%.2f" % cpu])
    ok = [(Im, mu) for _, Im, mu, _, _, st in pts if st]
    if len(ok) >= 2:
        b, mus = np.polyfit([q[0] for q in ok], [q[1] for q in ok], 1)
    else:
        b, mus = float("nan"), float("nan")
    head = ["angle_deg", "mu", "I_median", "I_q25", "I_q75", "layers", "surface_y", "vx_surface", "mean_vx_drift_m_s2", "drift_over_g_sin", "steady", "cpu_s"]
    print(",".join(head))
    for r in rows:
        print(",".join(r))
    print("# fit mu = mu_s + b I over the steady flows: mu_s %.4f, b %.4f (I with d = %g m, rho_s %g)" % (mus, b, 2 * R, RHO))
    write_rows("hybrid_mu_i", head, rows, t_end=a.chute_t_end, average_from=a.chute_t_end / 2, width=CHUTE_W, depth=CHUTE_H, d=2 * R, rho_s=RHO,
               fit_mu_s=float(mus), fit_b=float(b), grains=" ".join(DEM_GRAINS))
    plt = pyplot()
    if plt:
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for deg, Im, mu, I, y, st in pts:
            ax.plot(I, np.full(len(I), mu), ".", ms=3, color="0.6")
            ax.plot([Im], [mu], "o", color="k" if st else "w", mec="k")
        if np.isfinite(b):
            xs = np.linspace(0, max(q[0] for q in ok) * 1.2, 10)
            ax.plot(xs, mus + b * xs, "C3-", label="mu = %.3f + %.3f I" % (mus, b))
        ax.set_xlabel("I = gdot d / sqrt(p / rho_s)  (d = %g mm)" % (2000 * R))
        ax.set_ylabel("mu = tan(theta)")
        ax.set_title("DEM chute flows of the collapse's disks\n(layers grey; median: black steady, open not steady)", fontsize=9)
        ax.legend(fontsize=8)
        save_figure(fig, os.path.join(FIGURES_DIR, "hybrid_mu_i.png"))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--case", choices=("silo", "collapse", "mu_i"), default="silo")
    ap.add_argument("--angles", type=lambda v: [float(x) for x in v.split(",")], default=[16.0, 17.0, 18.0, 19.0], help="mu_i: chute angles [deg]")
    ap.add_argument("--chute_t_end", type=float, default=4.0, help="mu_i: simulated time per angle [s] (averages over the second half)")
    ap.add_argument("--t_end", type=float, default=0.8, help="silo only")
    ap.add_argument("--fit_from", type=float, default=0.3, help="silo only")
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--mu_s", type=float, default=0.274, help="collapse and silo: the MPM's mu_s (MPM-only and the hybrids)")
    ap.add_argument("--b", type=float, default=0.921, help="collapse and silo: the MPM's mu(I) slope b")
    ap.add_argument("--d", type=float, default=2 * R, help="collapse and silo: the MPM's grain diameter -d (m)")
    ap.add_argument("--silo_grains", choices=("collapse", "file"), default="collapse", help="silo: the collapse's disks (r 2 mm +-20%%, mu_roll 0.1, e 0.3: the grains --mu_s/--b/--d were calibrated to) or the opts file's (r 4 mm +-15%%, e 0.5)")
    ap.add_argument("--floor_mu", type=float, default=None, help="collapse: a slip floor with this Coulomb friction instead of the sticky one")
    ap.add_argument("--mpm_dt", type=float, default=1e-4, help="collapse: the MPM's fixed step (s; the hybrid's grains take ceil(dt / 2.5e-5) sub-steps); must divide 0.04 s")
    ap.add_argument("--zone_every", type=int, default=10, help="collapse: -hybrid_zone_every of the zoned hybrid (MPM steps)")
    ap.add_argument("--scale", type=float, default=1.0, help="collapse: L0, H0 and the box times this (the grains and the cell kept; t_end grows as sqrt)")
    ap.add_argument("--methods", type=lambda v: v.split(","), default=None, help="collapse: only these of MPM-only, hybrid fixed band, hybrid zoned (DEM-only always runs: the reference)")
    ap.add_argument("--band_distance", type=float, default=0.0, help="collapse: -hybrid_band_distance of the zoned hybrid (m)")
    ap.add_argument("--cell", type=float, default=0.01, help="collapse: the MPM cell h (m; >= the largest grain diameter, 4.8 mm)")
    ap.add_argument("--repeats", type=int, default=1, help="collapse: runs of each method; the times are the medians (the results are the same)")
    ap.add_argument("--tag", default="", help="collapse and silo: suffix of the CSV and figure names (variants)")
    a = ap.parse_args()
    global CELL, MPM_COLUMN, L0, H0, WIDTH, HEIGHT, BAND
    if a.scale != 1:  # the column and the box scaled, the grains and the cell kept: a larger dense bulk
        L0, H0, WIDTH, HEIGHT = L0 * a.scale, H0 * a.scale, WIDTH * a.scale, HEIGHT * a.scale
        BAND = (round(H0 / 2 - CELL, 12), round(H0 / 2 + CELL, 12))
        MPM_COLUMN[MPM_COLUMN.index("-domain_hi") + 1] = "%r,%r" % (WIDTH, HEIGHT)
    if a.cell != CELL or a.scale != 1:
        CELL = a.cell
        k = MPM_COLUMN.index("-cells")
        MPM_COLUMN[k + 1] = "%d,%d" % (round(WIDTH / CELL), round(HEIGHT / CELL))
    {"silo": silo, "collapse": collapse, "mu_i": mu_i}[a.case](a)


if __name__ == "__main__":
    main()
