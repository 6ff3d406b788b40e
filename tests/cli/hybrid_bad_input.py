#!/usr/bin/env python3
"""Bad -hybrid_ input (issue 18): every unparsable or out-of-range -hybrid_ value, and every
-hybrid_ option given without the option that uses it, exits non-zero with one
'granmpm: error:' line naming the option, on 1 and (where marked) 2 ranks, without a PETSc
trace, an MPI abort or a hang. Also: -help lists every -hybrid_ option the source registers,
and a zoned run's summary reports its conversions as mass handed over with a round-off
mass balance."""
import os
import re
import sys
import tempfile

import _cli

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.join(HERE, "..", "..", "src", "modules", "hybrid.cpp")

# An MPM block with grains on top of it (the base of every case): points y in [0.02, 0.12],
# grains y in [0.1, 0.2].
HBASE = ["-dim", "2", "-scene", "block", "-domain_lo", "0,0", "-domain_hi", "0.4,0.3", "-cells", "16,12", "-body_lo", "0.02,0.02",
         "-body_hi", "0.12,0.12", "-bc_ylo", "slip", "-bc_yhi", "slip", "-gravity_ramp", "0", "-material", "hypoelastic", "-E", "1e5",
         "-rho", "1000", "-max_steps", "5", "-output_final", "0", "-quiet", "-hybrid_dem", "-dem_dim", "2", "-dem_radius", "0.006",
         "-dem_kn", "1e5", "-dem_block_lo", "0.17,0.1", "-dem_block_hi", "0.39,0.2"]
# A band that accepts both species (continuum below it).
BAND = ["-hybrid_band", "0.1,0.14", "-hybrid_continuum", "lo"]
ZONES = BAND + ["-hybrid_zone_every", "2"]

# (name, extra arguments, text the error line must contain, also on 2 ranks?)
CASES = [
    # Values PETSc cannot parse: the option and the value.
    ("non-numeric band weight", BAND + ["-hybrid_band_weight", "abc"], "-hybrid_band_weight: invalid value 'abc'", True),
    ("non-numeric band entry", ["-hybrid_band", "0.1,abc"], "-hybrid_band: invalid value '0.1,abc'", False),
    ("fractional zone period", ZONES[:-1] + ["2.5"], "-hybrid_zone_every: invalid value '2.5'", True),
    ("zone period beyond an integer", ZONES[:-1] + ["99999999999999999999"], "-hybrid_zone_every: invalid value", False),
    ("non-numeric threshold", ZONES + ["-hybrid_phi", "dense"], "-hybrid_phi: invalid value 'dense'", False),
    ("non-numeric band distance", ZONES + ["-hybrid_band_distance", "1cm"], "-hybrid_band_distance: invalid value '1cm'", False),
    ("non-numeric band half-width", ZONES + ["-hybrid_band_halfwidth", "x"], "-hybrid_band_halfwidth: invalid value 'x'", False),
    ("non-boolean homogenise", ZONES + ["-hybrid_homogenise", "maybe"], "-hybrid_homogenise: invalid value 'maybe'", False),
    ("non-boolean enrich", ZONES + ["-hybrid_enrich", "2"], "-hybrid_enrich: invalid value '2'", False),
    ("non-boolean -hybrid_dem", ["-hybrid_dem", "sometimes"], "-hybrid_dem: invalid value 'sometimes'", False),
    ("unknown -hybrid_ option", BAND + ["-hybrid_foo", "1"], "-hybrid_foo", True),
    # Out of range.
    ("band weight above 1", BAND + ["-hybrid_band_weight", "1.5"], "-hybrid_band_weight must be in [0, 1]", True),
    ("negative band weight", BAND + ["-hybrid_band_weight", "-0.1"], "-hybrid_band_weight must be in [0, 1]", False),
    ("band weight nan", BAND + ["-hybrid_band_weight", "nan"], "-hybrid_band_weight must be in [0, 1]", False),
    ("band with one value", ["-hybrid_band", "0.1"], "-hybrid_band needs two values lo,hi", False),
    ("band with three values", ["-hybrid_band", "0.1,0.12,0.14"], "-hybrid_band needs two values lo,hi", False),
    ("band with lo above hi", ["-hybrid_band", "0.14,0.1"], "-hybrid_band needs two values lo,hi with lo < hi", False),
    ("band outside the domain", ["-hybrid_band", "0,0.5"], "-hybrid_band [0.000000, 0.500000] must lie strictly inside the domain", True),
    ("band axis z in 2D", BAND + ["-hybrid_band_axis", "z"], "-hybrid_band_axis 'z'", False),
    ("band axis not a letter", BAND + ["-hybrid_band_axis", "xy"], "-hybrid_band_axis 'xy'", False),
    ("continuum side not lo/hi", ["-hybrid_band", "0.1,0.14", "-hybrid_continuum", "up"], "-hybrid_continuum 'up'", False),
    ("negative zone period", ZONES[:-1] + ["-1"], "-hybrid_zone_every must be >= 0", True),
    ("threshold 0", ZONES + ["-hybrid_phi", "0"], "-hybrid_phi must be in (0, 1]", False),
    ("threshold above 1", ZONES + ["-hybrid_phi", "1.5"], "-hybrid_phi must be in (0, 1]", True),
    ("infinite band distance", ZONES + ["-hybrid_band_distance", "inf"], "-hybrid_band_distance must be a finite distance", False),
    ("negative band half-width", ZONES + ["-hybrid_band_halfwidth", "-0.1"], "-hybrid_band_halfwidth must be >= 0", False),
    ("infinite band half-width", ZONES + ["-hybrid_band_halfwidth", "inf"], "-hybrid_band_halfwidth must be >= 0", False),
    # An option without the one that uses it (it would be ignored).
    ("zones without a band", ["-hybrid_zone_every", "2"], "-hybrid_zone_every computes zones for the coupling", False),
    ("threshold without zones", BAND + ["-hybrid_phi", "0.4"], "-hybrid_phi sets the zone oracle: add -hybrid_zone_every", True),
    ("band distance without zones", BAND + ["-hybrid_band_distance", "0.01"], "-hybrid_band_distance sets the zone oracle", False),
    ("band half-width without zones", BAND + ["-hybrid_band_halfwidth", "0.01"], "-hybrid_band_halfwidth sets the zone oracle", False),
    ("homogenise without zones", BAND + ["-hybrid_homogenise", "0"], "-hybrid_homogenise converts grains where the oracle's zones say so", False),
    ("enrich without zones", BAND + ["-hybrid_enrich"], "-hybrid_enrich converts material points where the oracle's zones say so", False),
    ("band weight without a band", ["-hybrid_band_weight", "0.3"], "-hybrid_band_weight shapes the band of -hybrid_band", False),
    ("band axis without a band", ["-hybrid_band_axis", "x"], "-hybrid_band_axis shapes the band of -hybrid_band", False),
    ("continuum side without a band", ["-hybrid_continuum", "lo"], "-hybrid_continuum shapes the band of -hybrid_band", False),
]
# (-hybrid_band without -hybrid_dem: tests/cli/dem_bad_input.py.)


def registered_options():
    """The -hybrid_ options the source registers with PETSc (every PetscOptions* call)."""
    text = open(SOURCE).read()
    return sorted(set(re.findall(r'PetscOptions\w+\("(-hybrid_\w+)"', text)))


def main():
    a = _cli.arguments(__doc__).parse_args()
    run = _cli.run
    tmp = tempfile.mkdtemp(prefix="granmpm-hybrid-cli-")
    # Each case in its own directory (a run that started leaves results a new run refuses).
    total, failures = _cli.refuse_all(a, CASES, lambda k, n, extra: HBASE + extra + ["-output_dir", os.path.join(tmp, "c%d_%d" % (k, n))])
    # -help lists every registered -hybrid_ option.
    total += 1
    opts = registered_options()
    rc, out, err = run([a.granmpm, "-help"], a.timeout)
    missing = [o for o in opts if o not in out]
    ok = rc == 0 and len(opts) >= 11 and not missing
    print("%s -help lists the %d -hybrid_ options the source registers%s" % ("ok  " if ok else "FAIL", len(opts), "" if ok else ": rc %s, missing %s" % (rc, missing)))
    failures += not ok
    # A good zoned run on 2 ranks: the summary reports the conversions as mass handed over and
    # a mass balance of round-off.
    total += 1
    rc, out, err = run(_cli.command(a, 2, [x for x in HBASE if x not in ("-quiet",)] + ZONES + ["-max_steps", "20", "-output_dir", os.path.join(tmp, "zoned")]),
                       a.timeout)
    m = re.search(r"mass balance of the zone updates ([-+0-9.e]+) kg", out)
    handed = re.search(r"mass handed over\): ([-+0-9.e]+) kg material points -> grains, ([-+0-9.e]+) kg grains -> material points", out)
    ok = rc == 0 and m is not None and handed is not None and abs(float(m.group(1))) < 1e-12
    print("%s a zoned run reports mass handed over (%s) and a mass balance of %s kg on 2 ranks%s" %
          ("ok  " if ok else "FAIL", handed.group(0) if handed else "?", m.group(1) if m else "?", "" if ok else ": rc %s %r %r" % (rc, out[-400:], err[-300:])))
    failures += not ok
    # A zoned silo past its first grains' exit through the outlet face: the grains' rebuild at a
    # zone update removes those that crossed it since the last one, which is outflow and not a
    # conversion's loss (the mass check once stopped this run at step 800 with "changed the
    # total mass"), 1 and 2 ranks.
    silo = os.path.join(HERE, "..", "..", "examples", "hybrid_silo.opts")
    for n in (1, 2):
        total += 1
        rc, out, err = run(_cli.command(a, n, ["-options_file", silo, "-hybrid_zone_every", "10", "-hybrid_band_distance", "0.03", "-max_steps", "900",
                                               "-output_final", "0", "-progress_interval", "0", "-output_dir", os.path.join(tmp, "silo%d" % n)]), a.timeout)
        m = re.search(r"mass balance of the zone updates ([-+0-9.e]+) kg", out)
        gone = re.search(r"DEM grains: \d+ grains \((\d+) removed\)", out)
        ok = rc == 0 and m is not None and gone is not None and int(gone.group(1)) > 0 and abs(float(m.group(1))) < 1e-10
        print("%s a zoned silo on %d rank(s): %s grains left through the outlet, mass balance of the zone updates %s kg%s" %
              ("ok  " if ok else "FAIL", n, gone.group(1) if gone else "?", m.group(1) if m else "?", "" if ok else ": rc %s %r %r" % (rc, out[-400:], err[-300:])))
        failures += not ok
    print("%d of %d hybrid bad-input checks behaved" % (total - failures, total))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
