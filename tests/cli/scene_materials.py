#!/usr/bin/env python3
"""Every scene accepts every material (issue 20): a scene whose reference does not apply to
the run's material runs to the end (exit 0, no error line, no trace) and prints exactly one
'reference skipped' note naming the material; where the reference applies it is compared
(no note). Two steps per run, coarse grids: a few seconds in all."""
import os
import shutil
import sys
import tempfile

import _cli

EX = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples")
ANNULUS = ["-options_file", os.path.join(EX, "annulus_nonlocal.opts"), "-cells", "36,36"]
TC = ["-options_file", os.path.join(EX, "taylor_couette_3d_dynamic.opts"), "-cells", "22,22,3", "-dt", "2e-4"]

# (name, arguments, text that the scene's result line must contain, a 'reference skipped' note expected?)
CASES = [
    ("2D annulus, dynamical model", ANNULUS + ["-material", "dynamic"], "annulus: reference skipped: the 1D references cover -material mu_i|nonlocal (got dynamic)", True),
    ("2D annulus, Drucker-Prager", ANNULUS + ["-material", "drucker_prager"], "(got drucker_prager)", True),
    ("2D annulus, elastic", ANNULUS + ["-material", "elastic"], "(got elastic)", True),
    ("2D annulus, mu(I) (reference applies)", ANNULUS + ["-material", "mu_i"], "annulus: v_theta against the local mu(I)", False),
    ("3D Taylor-Couette, dynamical model", TC, "taylor-couette: omega/Omega at the top surface", False),
    ("3D Taylor-Couette, elastic", TC + ["-material", "elastic"], "taylor-couette: omega/Omega at the top surface", False),
    ("chute, elastic", ["-scene", "chute", "-material", "elastic"], "chute: reference skipped: the 1D references cover -material mu_i|nonlocal|dynamic (got elastic)", True),
    ("chute, dynamical model (reference applies)", ["-scene", "chute", "-material", "dynamic"], "chute: vy against the dynamical-model steady", False),
    ("collapse, elastic", ["-scene", "collapse", "-material", "elastic"], "reference skipped: Lube et al. 2005 covers granular materials, -material mu_i|nonlocal|dynamic|drucker_prager (got elastic)", True),
    ("collapse, hypoelastic", ["-scene", "collapse", "-material", "hypoelastic"], "(got hypoelastic)", True),
    ("collapse, dynamical model (reference applies)", ["-scene", "collapse", "-material", "dynamic"], "Lube et al. 2005: ", False),
]


def problems(rc, out, err, expect, skipped):
    p = []
    if rc is None:
        p.append("timed out")
    elif rc != 0:
        p.append("exit status %d" % rc)
    if _cli.error_lines(err):
        p.append("error line: " + _cli.error_lines(err)[0])
    p += ["stderr contains %r" % t for t in _cli.TRACES if t in err]
    if expect not in out:
        p.append("stdout lacks %r" % expect)
    notes = [l for l in out.splitlines() if "reference skipped" in l]
    if len(notes) != (1 if skipped else 0):
        p.append("%d 'reference skipped' lines (expected %d)" % (len(notes), 1 if skipped else 0))
    return p


def main():
    a = _cli.arguments(__doc__).parse_args()
    tmp = tempfile.mkdtemp(prefix="granmpm-scene-materials-")
    failures = 0
    for k, (name, args, expect, skipped) in enumerate(CASES):
        cmd = _cli.command(a, 1, args + ["-max_steps", "2", "-output_final", "0", "-progress_interval", "0", "-output_dir", os.path.join(tmp, str(k))])
        rc, out, err = _cli.run(cmd, a.timeout)
        line = next((l for l in out.splitlines() if expect in l), "")
        failures += _cli.report(name, 1, problems(rc, out, err, expect, skipped), line[:150], width=46)
    print("%d of %d scene/material cases behaved" % (len(CASES) - failures, len(CASES)))
    shutil.rmtree(tmp, ignore_errors=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
