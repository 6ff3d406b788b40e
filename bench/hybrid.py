#!/usr/bin/env python3
"""Hybrid silo with a fixed band against DEM-only and MPM-only (issue 18, the "steady silo
with a fixed band" scene; docs/hybrid.md).

Runs examples/hybrid_silo.opts three ways on the same geometry, material and gravity:
  hybrid    the file as it is: MPM above y = 0.2 m, DEM below y = 0.15 m, the band between;
  DEM-only  granmpm -dem with the file's -dem_* options and the grains filling the silo to
            y = 0.5 m (the box, outlet and gravity of the MPM options);
  MPM-only  the file's MPM options with the material points filling the silo from the plate.
Discharge: the mass through the orifice against time (MPM: silo.csv; DEM-only: the removed
count of dem_summary.csv times the mean grain mass; hybrid: the grains' removed mass of
dem_summary.csv plus the material points' silo.csv), the rate a linear fit over
[--fit_from, t_end]. Wall and CPU time (user + system) of each run. Writes
bench/results/hybrid.csv, docs/figures/hybrid_silo.png (/usr/bin/python3 has matplotlib).

Usage: /usr/bin/python3 bench/hybrid.py [--t_end 0.8] [--fit_from 0.3] [--ranks 1]
"""
import argparse
import bisect
import csv
import math
import os
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


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--t_end", type=float, default=0.8)
    ap.add_argument("--fit_from", type=float, default=0.3)
    ap.add_argument("--ranks", type=int, default=1)
    a = ap.parse_args()
    opts = read_opts(OPTS)
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
    write_rows("hybrid", ["method", "discharge_rate", "rel_to_dem", "discharged_mass", "wall_s", "cpu_s", "wall_ratio_dem_over_this", "cpu_ratio_dem_over_this"], rows,
               t_end=a.t_end, fit_from=a.fit_from, ranks=a.ranks, opts="examples/hybrid_silo.opts")
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
        save_figure(fig, os.path.join(FIGURES_DIR, "hybrid_silo.png"))


if __name__ == "__main__":
    main()
