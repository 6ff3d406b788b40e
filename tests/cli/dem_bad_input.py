#!/usr/bin/env python3
"""Bad input to `granmpm -dem` (issue 17, item 9): each case exits non-zero with one
'granmpm: error:' line naming the cause and the option to change, on 1 and (where marked)
2 ranks, without a PETSc trace, an MPI abort or a hang. Also: -help lists the -dem_ options,
older checkpoints restart, and a standalone run with a rigid body writes bodies.csv."""
import os
import sys
import tempfile

import _cli

# A small 2D box of grains (the base of every case).
BASE = ["-dem", "-dem_dim", "2", "-dem_lo", "0,0", "-dem_hi", "0.2,0.2", "-dem_radius", "0.005", "-dem_kn", "1e5",
        "-dem_block_hi", "0.2,0.1", "-dem_max_steps", "20", "-dem_fields", "0", "-dem_quiet"]

# A rigid body in the standalone run: a disk above the grains.
BODY = ["-body0_shape", "disk", "-body0_center", "0.1,0.16", "-body0_radius", "0.02"]

# (name, extra arguments, text the error line must contain, also on 2 ranks?)
CASES = [
    ("unknown option", ["-dem_foo", "1"], "unknown option -dem_foo", True),
    ("non-numeric value", ["-dem_kn", "abc"], "-dem_kn: invalid value 'abc'", True),
    ("e = 0", ["-dem_e", "0"], "-dem_e must be in (0, 1]", True),
    ("e > 1", ["-dem_e", "1.2"], "-dem_e must be in (0, 1]", False),
    ("wall e > 1", ["-dem_wall_e", "1.5"], "-dem_wall_e must be in (0, 1]", False),
    ("negative mu", ["-dem_mu", "-0.1"], "-dem_mu must be >= 0", True),
    ("negative wall mu", ["-dem_wall_mu", "-1"], "-dem_wall_mu must be >= 0", False),
    ("negative stiffness", ["-dem_kn", "-5"], "-dem_kn must be > 0", True),
    ("negative tangential stiffness", ["-dem_kt_ratio", "-1"], "-dem_kt_ratio must be >= 0", False),
    ("negative rolling resistance", ["-dem_mu_roll", "-0.1"], "-dem_mu_roll must be >= 0", False),
    ("dt above the contact limit", ["-dem_dt", "1e-2"], "above t_c/5", True),
    ("too few steps per contact", ["-dem_steps_per_contact", "3"], "-dem_steps_per_contact must be >= 5", False),
    ("initial overlaps", ["-dem_spacing", "0.008"], "initial grain overlap", True),
    ("grain larger than a broad-phase cell", ["-dem_cell", "0.005"], "-dem_cell", True),
    ("grain larger than the periodic halo", ["-dem_periodic", "x", "-dem_hi", "0.02,0.2", "-dem_block_hi", "0.02,0.1"], "shorter than twice the interaction range", False),
    ("grain leaving a non-periodic face", ["-dem_scene", "list", "-dem_grains", "0.1,0.1,0.005,30,0", "-dem_wall_kn", "1",
                                           "-dem_dt", "1e-5", "-dem_max_steps", "2000"], "left the domain through the upper x face", True),
    ("bad radius distribution", ["-dem_radius_dist", "lognormal"], "-dem_radius_dist 'lognormal' is not one of", False),
    ("radius spread too large", ["-dem_radius_dist", "normal", "-dem_radius_spread", "0.6"], "-dem_radius_spread must be in", False),
    ("negative radius", ["-dem_radius", "-1"], "-dem_radius must be > 0", False),
    ("wrong vector length", ["-dem_gravity", "0,-9.81,0"], "-dem_gravity needs 2", False),
    ("bad periodic letter", ["-dem_periodic", "z"], "-dem_periodic 'z'", False),
    ("grain list of the wrong length", ["-dem_scene", "list", "-dem_grains", "0.1,0.1,0.005,0"], "-dem_grains needs 5 values per grain", False),
    ("no grains in the block", ["-dem_block_hi", "0.001,0.001"], "has no grains", True),
    ("unreadable restart", ["-dem_restart", "/nonexistent/ck.h5"], "-dem_restart: cannot open", True),
    ("negative friction of one face", ["-dem_wall_mu_ylo", "-0.2"], "-dem_wall_mu_ylo must be >= 0", True),
    ("restitution of one face above 1", ["-dem_wall_e_xhi", "1.5"], "-dem_wall_e_xhi must be in (0, 1]", False),
    ("face parameters on a periodic face", ["-dem_periodic", "x", "-dem_wall_mu_xlo", "0.3"], "-dem_wall_mu_xlo: the x faces are periodic", False),
    ("face parameters on an outlet", ["-dem_outlet", "yhi", "-dem_wall_e_yhi", "0.3"], "-dem_wall_e_yhi: the yhi face is an outlet", False),
    ("plate parameters without a plate", ["-dem_wall_mu_plate", "0.3"], "there is no plate: add -dem_plate_y", False),
    ("face option of a 3D box in 2D", ["-dem_wall_mu_zlo", "0.3"], "unknown option -dem_wall_mu_zlo", False),
    ("too many ranks for the box", ["-dem_hi", "0.012,0.012", "-dem_block_hi", "0.012,0.012"], "too few for 2 ranks", "only2"),
    ("initial spin of the wrong length", ["-dem_spin", "1,2,3"], "-dem_spin needs 1 value wz", False),
    ("grid contact option of a body", BODY + ["-body0_friction", "0.3"], "-body0_friction sets the MPM grid's contact", True),
    ("dynamic body without a mass", BODY + ["-body0_motion", "dynamic"], "-body0_mass must be > 0", False),
    ("bad body shape", ["-body0_shape", "sphere"], "-body0_shape", False),
]

# The grains as a species of an MPM run (-hybrid_dem): the host's options decide the box,
# faces, gravity, clock, output and checkpoints.
HBASE = ["-dim", "2", "-scene", "block", "-domain_lo", "0,0", "-domain_hi", "0.4,0.3", "-cells", "16,12", "-body_lo", "0.02,0.02",
         "-body_hi", "0.12,0.12", "-bc_ylo", "slip", "-bc_yhi", "slip", "-gravity_ramp", "0", "-material", "hypoelastic", "-E", "1e5",
         "-rho", "1000", "-max_steps", "5", "-output_final", "0", "-quiet", "-hybrid_dem", "-dem_dim", "2", "-dem_radius", "0.006",
         "-dem_kn", "1e5", "-dem_block_lo", "0.17,0.03", "-dem_block_hi", "0.39,0.2"]
HYBRID_CASES = [
    ("standalone box option with -hybrid_dem", ["-dem_lo", "0,0"], "-dem_lo is the standalone DEM's", True),
    ("standalone clock option with -hybrid_dem", ["-dem_t_end", "1"], "follow the MPM's -t_end: drop -dem_t_end", False),
    ("standalone restart with -hybrid_dem", ["-dem_restart", "x.h5"], "drop -dem_restart", False),
    ("DEM dimension unlike the MPM's", ["-dem_dim", "3", "-dem_block_lo", "0.17,0.03,0", "-dem_block_hi", "0.39,0.2,0.1"], "-dem_dim 3 differs from the MPM's -dim 2", True),
    ("implicit MPM with -hybrid_dem", ["-time_integrator", "implicit"], "-time_integrator explicit", False),
    ("DEM option error inside an MPM run", ["-dem_e", "2"], "-dem_e must be in (0, 1]", True),
    ("band with one value", ["-hybrid_band", "0.1"], "-hybrid_band needs two values lo,hi", False),
    ("band wider than the domain", ["-hybrid_band", "0,0.5"], "-hybrid_band [0.000000, 0.500000] must lie strictly inside the domain", True),
    ("band weight outside [0, 1]", ["-hybrid_band", "0.1,0.15", "-hybrid_band_weight", "1.5"], "-hybrid_band_weight must be in [0, 1]", False),
    ("bad band axis", ["-hybrid_band", "0.1,0.15", "-hybrid_band_axis", "z"], "-hybrid_band_axis 'z'", False),
    ("bad continuum side", ["-hybrid_band", "0.1,0.15", "-hybrid_continuum", "up"], "-hybrid_continuum 'up'", False),
    ("grain larger than an MPM cell", ["-hybrid_band", "0.1,0.15", "-dem_radius", "0.02"], "-dem_radius: the largest grain diameter", False),
    ("material point in the discrete zone", ["-hybrid_band", "0.2,0.25"], "a material point starts", True),
    ("grain in the continuum zone", ["-hybrid_band", "0.13,0.15", "-hybrid_continuum", "lo"], "a DEM grain starts", True),
    ("oracle threshold above 1", ["-hybrid_band", "0.1,0.15", "-hybrid_zone_every", "2", "-hybrid_phi", "1.5"], "-hybrid_phi must be in (0, 1]", False),
    ("negative zone period", ["-hybrid_band", "0.1,0.15", "-hybrid_zone_every", "-1"], "-hybrid_zone_every must be >= 0", False),
    ("negative band half-width", ["-hybrid_band", "0.1,0.15", "-hybrid_zone_every", "2", "-hybrid_band_halfwidth", "-0.1"], "-hybrid_band_halfwidth must be >= 0", False),
    ("zones without a band", ["-hybrid_zone_every", "2"], "-hybrid_zone_every computes zones for the coupling: add -hybrid_dem and -hybrid_band", False),
]
# -hybrid_band without -hybrid_dem.
NODEM = [a for a in HBASE if a != "-hybrid_dem"]


def format1_restart(a, tmp):
    """A checkpoint of the format before the grain mass weights (6 state values, 21 columns)
    restarts to the same bits as the current format; with removed grains (whose mass it lacks)
    it is refused. The old file is made from a current one by dropping what format 2 added."""
    import h5py
    import numpy as np
    run = _cli.run
    fields = BASE[:BASE.index("-dem_max_steps")] + BASE[BASE.index("-dem_max_steps") + 2:]
    new, old = os.path.join(tmp, "ck2.h5"), os.path.join(tmp, "ck1.h5")
    rc, out, err = run([a.granmpm] + fields + ["-dem_max_steps", "20", "-dem_checkpoint", new, "-dem_output_dir", os.path.join(tmp, "ck")], a.timeout)
    with h5py.File(new, "r") as src, h5py.File(old, "w") as dst:
        dst.attrs["state"] = src.attrs["state"][:6]
        dst["grains"] = src["grains"][:, :21]
        dst["springs"] = src["springs"][:]
        for k in src.attrs:
            if k != "state":
                dst.attrs[k] = src.attrs[k]
    ends = []
    for n, ck in enumerate((new, old)):
        end = os.path.join(tmp, "ck_end%d.h5" % n)
        rc, out, err = run([a.granmpm] + fields + ["-dem_max_steps", "20", "-dem_restart", ck, "-dem_checkpoint", end,
                                                   "-dem_output_dir", os.path.join(tmp, "ckr%d" % n)], a.timeout)
        ends.append(end if rc == 0 else None)
    ok = all(ends)
    if ok:
        with h5py.File(ends[0], "r") as x, h5py.File(ends[1], "r") as y:
            ok = np.array_equal(x["grains"][:], y["grains"][:]) and np.array_equal(x["springs"][:], y["springs"][:])
    print("%s a format-1 DEM checkpoint restarts to the same bits as the current format" % ("ok  " if ok else "FAIL"))
    with h5py.File(old, "r+") as f:
        st = f.attrs["state"].copy()
        st[5] = 3
        f.attrs["state"] = st
    rc, out, err = run([a.granmpm] + fields + ["-dem_restart", old, "-dem_output_dir", os.path.join(tmp, "ckr3")], a.timeout)
    lines = _cli.error_lines(err)
    bad = _cli.report("format-1 checkpoint with removed grains", 1, _cli.refusal_problems(rc, err, "without the removed grains' mass"),
                      lines[0] if lines else err.strip()[:200])
    return 2, (not ok) + bad


def format2_restart(a, tmp):
    """A 3D checkpoint of format 2 (7 state values, 22 columns: no orientations) restarts,
    saying once that the spheres restart unrotated: the same grains as the format-3 restart
    (positions, velocities, spins, springs), the orientation from the identity."""
    import h5py
    import numpy as np
    run = _cli.run
    base = ["-dem", "-dem_dim", "3", "-dem_lo", "0,0,0", "-dem_hi", "0.1,0.1,0.1", "-dem_radius", "0.005", "-dem_kn", "1e4",
            "-dem_block_hi", "0.1,0.05,0.1", "-dem_gravity", "0,-9.81,0", "-dem_spin", "5,0,20", "-dem_fields", "0", "-dem_quiet"]
    new, old = os.path.join(tmp, "ck3.h5"), os.path.join(tmp, "ck2.h5")
    rc, out, err = run([a.granmpm] + base + ["-dem_max_steps", "30", "-dem_checkpoint", new, "-dem_output_dir", os.path.join(tmp, "o3")], a.timeout)
    with h5py.File(new, "r") as src, h5py.File(old, "w") as dst:
        dst.attrs["state"] = src.attrs["state"][:7]
        dst["grains"] = src["grains"][:, :22]
        dst["springs"] = src["springs"][:]
    ends, notes = [], []
    for n, ck in enumerate((new, old)):
        end = os.path.join(tmp, "ck3_end%d.h5" % n)
        rc, out, err = run([a.granmpm] + base + ["-dem_max_steps", "10", "-dem_restart", ck, "-dem_checkpoint", end, "-dem_output_dir", os.path.join(tmp, "o3r%d" % n)], a.timeout)
        ends.append(end if rc == 0 else None)
        notes.append(out.count("without grain orientations: the spheres restart with the identity orientation"))
    ok = all(ends) and notes == [0, 1]
    if ok:
        with h5py.File(ends[0], "r") as x, h5py.File(ends[1], "r") as y:
            gx, gy = x["grains"][:], y["grains"][:]
            # The dynamics do not see the orientation; the old one turned only in the 10 steps since the restart.
            ok = np.array_equal(gx[:, :22], gy[:, :22]) and np.array_equal(x["springs"][:], y["springs"][:])
            ok = ok and np.allclose(np.linalg.norm(gy[:, 22:26], axis=1), 1, atol=1e-15) and not np.array_equal(gx[:, 22:26], gy[:, 22:26])
    print("%s a format-2 3D checkpoint restarts unrotated, saying so once, with the same grains%s" % ("ok  " if ok else "FAIL", "" if ok else ": notes %s, ends %s" % (notes, ends)))
    return 1, int(not ok)


def standalone_bodies(a, tmp):
    """granmpm -dem with a rigid body writes bodies.csv: a row per body at the start, every
    -bodies_interval steps and at the end; 1 and 2 ranks write the same rows."""
    run = _cli.run
    fields = BASE[:BASE.index("-dem_max_steps")] + BASE[BASE.index("-dem_max_steps") + 2:]
    rows = []
    for n in (1, 2):
        out = os.path.join(tmp, "bodies%d" % n)
        args = fields + BODY + ["-body0_motion", "dynamic", "-body0_mass", "2", "-dem_gravity", "0,-9.81", "-dem_max_steps", "2000", "-bodies_interval", "500",
                                "-dem_output_dir", out]
        rc, o, err = run(_cli.command(a, n, args), a.timeout)
        path = os.path.join(out, "bodies.csv")
        rows.append(open(path).read().splitlines() if rc == 0 and os.path.exists(path) else [])
    ok = len(rows[0]) == 1 + 5 and rows[0][0].startswith("time,body,x,y,vx,vy,omega,fx,fy,torque,angle") and rows[1] == rows[0]
    # The body falls onto the grains (0.04 m below it): it moves down and feels their push.
    vals = [[float(x) for x in r.split(",")] for r in rows[0][1:]] if ok else []
    ok = ok and vals[-1][3] < 0.14 and max(v[8] for v in vals) > 0
    print("%s granmpm -dem with a body writes bodies.csv (start, every -bodies_interval, end) on 1 and 2 ranks%s" % ("ok  " if ok else "FAIL", "" if ok else ": %r" % rows))
    return 1, int(not ok)


def main():
    a = _cli.arguments(__doc__).parse_args()
    run = _cli.run
    tmp = tempfile.mkdtemp(prefix="granmpm-dem-cli-")
    failures = total = 0
    for k, (name, extra, expect, two) in enumerate(CASES):
        # A fresh directory per case and rank count: a case that ran steps leaves results, and a new run
        # into them is refused (checked below).
        ranks = [2] if two == "only2" else ([1, 2] if two else [1])
        for n in ranks:
            args = BASE + extra + ["-dem_output_dir", os.path.join(tmp, "out%d_%d" % (k, n))]
            total += 1
            rc, out, err = run(_cli.command(a, n, args), a.timeout)
            lines = _cli.error_lines(err)
            failures += _cli.report(name, n, _cli.refusal_problems(rc, err, expect), lines[0] if lines else err.strip()[:200])
    for k, (name, extra, expect, two) in enumerate(HYBRID_CASES):
        for n in ([1, 2] if two else [1]):
            args = HBASE + extra + ["-output_dir", os.path.join(tmp, "hyb%d_%d" % (k, n))]
            total += 1
            rc, out, err = run(_cli.command(a, n, args), a.timeout)
            lines = _cli.error_lines(err)
            failures += _cli.report(name, n, _cli.refusal_problems(rc, err, expect), lines[0] if lines else err.strip()[:200])
    total += 1
    rc, out, err = run(_cli.command(a, 1, NODEM + ["-hybrid_band", "0.1,0.15", "-output_dir", os.path.join(tmp, "hybnodem")]), a.timeout)
    lines = _cli.error_lines(err)
    failures += _cli.report("band without -hybrid_dem", 1, _cli.refusal_problems(rc, err, "add -hybrid_dem"), lines[0] if lines else err.strip()[:200])
    total += 1
    rc, out, err = run(_cli.command(a, 2, [x for x in HBASE if x != "-quiet"] + ["-dem_block_lo", "0.17,0.1", "-hybrid_band", "0.1,0.14", "-hybrid_continuum", "lo",
                                                  "-output_dir", os.path.join(tmp, "hybband")]), a.timeout)
    ok = rc == 0 and "hybrid coupling: band y" in out
    print("%s an MPM run with -hybrid_band exits 0 on 2 ranks%s" % ("ok  " if ok else "FAIL", "" if ok else ": rc %s %r %r" % (rc, out[-300:], err[-300:])))
    failures += not ok
    total += 1
    rc, out, err = run(_cli.command(a, 2, [x for x in HBASE if x != "-quiet"] + ["-dem_block_lo", "0.17,0.1", "-hybrid_band", "0.1,0.14", "-hybrid_continuum", "lo",
                                                  "-hybrid_zone_every", "2", "-output_dir", os.path.join(tmp, "hybzones")]), a.timeout)
    ok = rc == 0 and "zones (phi 0.3" in out and "grains C/B/D" in out
    print("%s an MPM run with the zone oracle reports its zones on 2 ranks%s" % ("ok  " if ok else "FAIL", "" if ok else ": rc %s %r %r" % (rc, out[-300:], err[-300:])))
    print("%s an MPM run with -hybrid_band exits 0 on 2 ranks%s" % ("ok  " if ok else "FAIL", "" if ok else ": rc %s %r %r" % (rc, out[-300:], err[-300:])))
    failures += not ok
    total += 1
    rc, out, err = run(_cli.command(a, 2, HBASE + ["-output_dir", os.path.join(tmp, "hybgood")]), a.timeout)
    ok = rc == 0
    print("%s an MPM run with -hybrid_dem exits 0 on 2 ranks%s" % ("ok  " if ok else "FAIL", "" if ok else ": rc %s %r" % (rc, err[-300:])))
    failures += not ok
    # Every -dem_ option is documented by -help; a good run exits 0 and writes its CSV.
    total += 1
    rc, out, err = run([a.granmpm, "-dem", "-help"], a.timeout)
    missing = [o for o in ("-dem_kn", "-dem_e", "-dem_mu", "-dem_wall_mu", "-dem_law", "-dem_damping", "-dem_skin", "-dem_dt", "-dem_integrator",
                           "-dem_checkpoint", "-dem_restart", "-dem_periodic", "-dem_radius_dist", "-dem_wall_mu_ylo", "-dem_wall_e_xhi",
                           "-dem_wall_mu_plate", "-dem_spin", "-body0_shape", "-body0_motion", "-bodies_interval") if o not in out]
    if rc != 0 or missing:
        failures += 1
        print("FAIL -help: rc %s, missing %s" % (rc, missing))
    else:
        print("ok   -help lists the -dem_ options")
    total += 1
    rc, out, err = run([a.granmpm] + BASE + ["-dem_output_dir", os.path.join(tmp, "good")], a.timeout)
    if rc != 0 or not os.path.exists(os.path.join(tmp, "good", "dem_summary.csv")):
        failures += 1
        print("FAIL good run: rc %s %s" % (rc, err.strip()[:300]))
    else:
        print("ok   a good run exits 0 and writes dem_summary.csv")
    # A new run into the good run's directory is refused, naming the ways out; with
    # -dem_output_overwrite it replaces the old results (the old snapshots are removed).
    good = os.path.join(tmp, "good")
    fields = BASE[:BASE.index("-dem_fields")] + BASE[BASE.index("-dem_fields") + 2:]
    for n in (1, 2):
        total += 1
        rc, out, err = run(_cli.command(a, n, BASE + ["-dem_output_dir", good]), a.timeout)
        lines = _cli.error_lines(err)
        want = ("holds another run's results", "-dem_restart", "-dem_output_overwrite")
        ok = rc not in (0, None) and len(lines) == 1 and all(w in lines[0] for w in want)
        print("%s new run into another run's results refused ranks=%d%s" % ("ok  " if ok else "FAIL", n, "" if ok else ": rc %s %r" % (rc, err[-300:])))
        failures += not ok
    total += 1
    snap = os.path.join(tmp, "snap")
    run([a.granmpm] + fields + ["-dem_fields_every", "5", "-dem_output_dir", snap], a.timeout)
    before = len([f for f in os.listdir(snap) if f.startswith("grains_")])
    rc, out, err = run([a.granmpm] + fields + ["-dem_max_steps", "5", "-dem_fields_every", "5", "-dem_output_dir", snap, "-dem_output_overwrite"], a.timeout)
    after = len([f for f in os.listdir(snap) if f.startswith("grains_")])
    ok = rc == 0 and before > after > 0
    print("%s -dem_output_overwrite replaces the old snapshots (%d -> %d files)%s" % ("ok  " if ok else "FAIL", before, after, "" if ok else ": rc %s %r" % (rc, err[-300:])))
    failures += not ok
    for check in (format1_restart, format2_restart, standalone_bodies):
        t, f = check(a, tmp)
        total += t
        failures += f
    print("%d of %d DEM bad-input checks behaved" % (total - failures, total))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
