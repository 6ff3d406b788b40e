#!/usr/bin/env python3
"""Table-driven bad-input test of the granmpm executable.

Each case runs granmpm (on 1 and, where marked, 2 MPI ranks) with an invalid input and
checks: non-zero exit status, a single 'granmpm: error:' line on stderr naming the
option (or cause), no PETSc trace, no segfault or MPI abort, and no hang (timeout)."""
import os
import shutil
import subprocess
import sys
import tempfile

import _cli

# (name, arguments, text that must appear in the error line, also on 2 ranks?)
CASES = [
    ("unknown option", ["-foo", "1"], "unknown option -foo", True),
    ("misspelled option", ["-ppcc", "2"], "unknown option -ppcc", False),
    ("negative E", ["-E", "-5"], "-E must be > 0", True),
    ("nu = 0.5", ["-nu", "0.5"], "-nu must satisfy", True),
    ("nu < -1", ["-nu", "-1.5"], "-nu must satisfy", False),
    ("dim 4", ["-dim", "4"], "-dim must be 2 or 3", True),
    ("non-numeric E", ["-E", "abc"], "-E: invalid value 'abc'", True),
    ("non-integer cells", ["-cells", "20,x"], "-cells: invalid value", False),
    ("wrong number of cells", ["-cells", "20"], "-cells: expected 2", False),
    ("zero cells", ["-cells", "0,4", "-domain_hi", "0.5,0.2"], "-cells must be >= 1", False),
    ("non-square cells", ["-cells", "20,5"], "-cells: cells must be square", False),
    ("empty domain", ["-domain_lo", "0,0", "-domain_hi", "0,1"], "-domain_hi must exceed -domain_lo", False),
    ("ppc 0", ["-ppc", "0"], "-ppc must be in 1..8", False),
    ("mu_2 <= mu_s", ["-mu_2", "0.3"], "-mu_2 must be > -mu_s", True),
    ("d = 0", ["-d", "0"], "-d must be > 0", False),
    ("A < 0", ["-A", "-0.1"], "-A must be >= 0", False),
    ("b = 0", ["-b", "0"], "-b must be > 0", False),
    ("I_0 = 0", ["-I_0", "0"], "-I_0 must be > 0", False),
    ("rho_c > rho_s", ["-rho_c", "3000"], "-rho_c must be in", False),
    ("unknown shape", ["-shape", "cubic"], "-shape: unknown value 'cubic'", False),
    ("unknown material", ["-material", "foam"], "-material: unknown value 'foam'", False),
    ("unknown boundary", ["-bc_xlo", "glue"], "-bc_xlo: unknown value 'glue'", False),
    ("half-periodic direction", ["-bc_xlo", "periodic"], "periodic must be set on both faces", False),
    ("cfl > 1", ["-cfl", "2"], "-cfl must be in (0, 1]", False),
    ("t_end = 0", ["-t_end", "0"], "-t_end must be > 0", False),
    ("flip_alpha > 1", ["-flip_alpha", "1.5"], "-flip_alpha must be in [0, 1]", False),
    ("dt and dt_auto together", ["-dt", "1e-5", "-dt_auto"], "-dt and -dt_auto both given", False),
    ("dt above the CFL limit", ["-dt", "1e-3"], "exceeds the CFL stability limit", True),
    ("explicit plastic step too large", ["-stress_update", "explicit", "-dt", "8e-5", "-cells", "20,4"], "explicit granular stress update", False),
    ("particle leaving a non-periodic domain",
     ["-scene", "block", "-material", "elastic", "-bc_xlo", "free", "-bc_xhi", "free", "-velocity", "3,0", "-body_hi", "0.4,0.2", "-gravity", "0,0", "-p0", "0", "-t_end", "0.2"],
     "left the domain through the xhi face", True),
    ("missing options file", ["-options_file", "/nonexistent/x.opts"], "-options_file: cannot read '/nonexistent/x.opts'", True),
    ("options file is a directory", ["-options_file", "/tmp"], "-options_file: cannot read '/tmp'", False),
    ("malformed options file", ["-options_file", "@BADOPTS@"], "line 1: expected '-option [value]', found 'hello'", True),
    ("two options on one line", ["-options_file", "@TWOOPTS@"], "extra token '-nu'", False),
    ("malformed YAML file", ["-options_file_yaml", "@BADYAML@"], "YAML", True),
    ("output directory not writable", ["-output_dir", "/proc/granmpm-out"], "-output_dir", True),
    ("unreadable restart file", ["-restart", "/nonexistent/ck.h5"], "-restart: cannot read '/nonexistent/ck.h5'", True),
    ("restart file that is not a checkpoint", ["-restart", "@SNAPSHOT@"], "not a GranMPM checkpoint", False),
    ("restart file from another scene", ["-restart", "@CHECKPOINT@", "-cells", "40,4", "-domain_hi", "0.5,0.1"], "another scene: -domain_hi", True),
    ("restart with a rigid body the checkpoint did not have", ["-restart", "@CHECKPOINT@", "-body0_shape", "disk", "-body0_center", "0,0.05", "-body0_radius", "0.05"], "another scene: -body0_shape is 'unset' there", False),
    ("unstable step, abort", ["-dt", "1e-3", "-dt_allow_unstable"], "the run is unstable", True),
    ("unstable step, checkpoint_and_abort", ["-dt", "1e-3", "-dt_allow_unstable", "-on_instability", "checkpoint_and_abort"], "checkpoint_last_good.h5", True),
    ("bad -on_instability", ["-on_instability", "ignore"], "-on_instability: unknown value 'ignore'", False),
    ("fluidity preconditioner interval < 1", ["-fluidity_pc_interval", "0"], "-fluidity_pc_interval must be >= 1", False),
    ("negative checkpoint interval", ["-checkpoint_interval", "-1"], "-checkpoint_interval must be >= 0", False),
    ("balance threshold in (0, 1]", ["-balance_threshold", "0.9"], "-balance_threshold must be > 1", False),
    ("balance threshold of exactly 1", ["-balance_threshold", "1"], "-balance_threshold must be > 1", False),
    ("balance interval < 1", ["-balance_interval", "0"], "-balance_interval must be >= 1", False),
    ("negative sort interval", ["-sort_interval", "-2"], "-sort_interval must be >= 0", False),
    ("unknown time integrator", ["-time_integrator", "rk4"], "-time_integrator: unknown value 'rk4'", True),
    ("implicit with the steady nonlocal model", ["-time_integrator", "implicit"], "-time_integrator implicit does not support -material nonlocal", True),
    ("implicit with the dynamical model", ["-time_integrator", "implicit", "-material", "dynamic"], "-time_integrator implicit does not support -material dynamic", False),
    ("implicit with the USF order", ["-time_integrator", "implicit", "-material", "mu_i", "-update", "usf"], "-update usf|musl order the explicit step only", False),
    ("implicit with wall friction", ["-time_integrator", "implicit", "-material", "mu_i", "-bc_xlo", "slip", "-wall_friction", "0.3"], "-wall_friction", False),
    ("assembled Jacobian for a granular material", ["-time_integrator", "implicit", "-material", "mu_i", "-implicit_jacobian", "assembled"], "-implicit_jacobian assembled is the exact Jacobian only for -material elastic", False),
    ("unknown implicit Jacobian", ["-time_integrator", "implicit", "-material", "mu_i", "-implicit_jacobian", "exact"], "-implicit_jacobian: unknown value 'exact'", False),
    ("unknown implicit tangent", ["-time_integrator", "implicit", "-material", "mu_i", "-implicit_tangent", "exact"], "-implicit_tangent: unknown value 'exact'", False),
    ("implicit theta out of range", ["-time_integrator", "implicit", "-material", "mu_i", "-implicit_theta", "0.3"], "-implicit_theta must be in [0.5, 1]", False),
    ("implicit grow factor < 1", ["-time_integrator", "implicit", "-material", "mu_i", "-implicit_grow_factor", "0.5"], "-implicit_grow_factor must be >= 1", False),
    ("implicit solve that cannot converge, fixed dt", ["-time_integrator", "implicit", "-material", "mu_i", "-dt", "8e-3", "-implicit_dt_adapt", "0", "-implicit_ksp_max_it", "1"], "did not converge", True),
    ("implicit solve that cannot converge, retries exhausted", ["-time_integrator", "implicit", "-material", "mu_i", "-dt", "8e-3", "-implicit_ksp_max_it", "1", "-implicit_max_retries", "1"], "after 1 halvings of dt; raise -implicit_max_retries", True),
    ("implicit solve failing below the minimum dt", ["-time_integrator", "implicit", "-material", "mu_i", "-dt", "8e-3", "-implicit_ksp_max_it", "1", "-implicit_dt_min", "6e-3"], "below -implicit_dt_min", False),
    ("implicit_coupled with a local material", ["-time_integrator", "implicit_coupled", "-material", "mu_i"], "-time_integrator implicit_coupled solves the steady nonlocal fluidity with the momentum and needs -material nonlocal (got mu_i)", False),
    ("implicit_coupled with the dynamical model", ["-time_integrator", "implicit_coupled", "-material", "dynamic"], "needs -material nonlocal (got dynamic)", False),
    ("implicit_coupled with A = 0", ["-time_integrator", "implicit_coupled", "-A", "0"], "-time_integrator implicit_coupled: -A 0 has no fluidity equation", False),
    ("implicit_coupled with Dirichlet fluidity walls", ["-time_integrator", "implicit_coupled", "-fluidity_bc", "dirichlet"], "-fluidity_bc dirichlet is not supported with -time_integrator implicit_coupled", False),
    ("implicit_coupled with the explicit stress update", ["-time_integrator", "implicit_coupled", "-stress_update", "explicit"], "-stress_update explicit is not supported with -time_integrator implicit_coupled", False),
    ("implicit_coupled with theta 0.5", ["-time_integrator", "implicit_coupled", "-implicit_theta", "0.5"], "-implicit_theta must be 1 with -time_integrator implicit_coupled", False),
    ("implicit_coupled solve that cannot converge, fixed dt", ["-time_integrator", "implicit_coupled", "-cells", "20,4", "-domain_hi", "0.5,0.2", "-dt", "8e-3", "-implicit_dt_adapt", "0", "-implicit_ksp_max_it", "1"], "did not converge", False),
    ("implicit with a rigid body", ["-time_integrator", "implicit", "-material", "mu_i", "-body0_shape", "disk"], "-time_integrator implicit does not support rigid bodies", True),
    ("unknown body shape", ["-body0_shape", "sphere"], "-body0_shape: unknown value 'sphere'", True),
    ("negative body radius", ["-body0_shape", "disk", "-body0_radius", "-0.1"], "-body0_radius must be > 0", True),
    ("box body with a zero half extent", ["-body1_shape", "box", "-body1_half", "0.1,0"], "-body1_half must be > 0", False),
    ("unknown body contact", ["-body0_shape", "disk", "-body0_contact", "glue"], "-body0_contact: unknown value 'glue'", False),
    ("negative body friction", ["-body0_shape", "plane", "-body0_contact", "friction", "-body0_friction", "-1"], "-body0_friction must be >= 0", False),
    ("body option without its shape", ["-body2_radius", "0.2"], "unknown option -body2_radius", False),
    ("contact layer out of range", ["-body0_shape", "disk", "-body_contact_layer", "3"], "-body_contact_layer must be in [0, 2]", False),
    ("unknown body motion", ["-body0_shape", "disk", "-body0_motion", "floating"], "-body0_motion: unknown value 'floating'", True),
    ("negative body mass", ["-body0_shape", "disk", "-body0_motion", "dynamic", "-body0_mass", "-1"], "-body0_mass must be > 0", True),
    ("dynamic body without a mass", ["-body0_shape", "disk", "-body0_motion", "dynamic"], "-body0_mass must be > 0", False),
    ("dynamic ring without an inertia", ["-body0_shape", "ring", "-body0_motion", "dynamic", "-body0_mass", "1"], "-body0_inertia must be > 0", False),
    ("zero body inertia", ["-body0_shape", "disk", "-body0_motion", "dynamic", "-body0_mass", "1", "-body0_inertia", "0"], "-body0_inertia must be > 0", False),
    ("negative body damping", ["-body0_shape", "disk", "-body0_motion", "dynamic", "-body0_mass", "1", "-body0_damping", "-2"], "-body0_damping must be >= 0", False),
    ("unknown locked axis", ["-body0_shape", "disk", "-body0_motion", "dynamic", "-body0_mass", "1", "-body0_lock", "x,w"], "-body0_lock: unknown degree of freedom 'w'", False),
    ("z lock in 2D", ["-body0_shape", "disk", "-body0_motion", "dynamic", "-body0_mass", "1", "-body0_lock", "z"], "-body0_lock: unknown degree of freedom 'z'", False),
    ("dynamic-only option on a kinematic body", ["-body0_shape", "disk", "-body0_mass", "1"], "-body0_mass applies to dynamic bodies only", False),
    ("body force of the wrong length", ["-body0_shape", "disk", "-body0_motion", "dynamic", "-body0_mass", "1", "-body0_force", "1,2,3"], "-body0_force: expected 2", False),
    ("path waypoint too short", ["-body0_shape", "box", "-body0_path", "0,0,0.1;1,0.5"], "-body0_path: waypoint 1 '1,0.5' has 2 numbers", True),
    ("path waypoint not a number", ["-body0_shape", "box", "-body0_path", "0,a,0.1;1,0,0"], "-body0_path: waypoint 0 '0,a,0.1' is not t,x,y", False),
    ("path times not increasing", ["-body0_shape", "box", "-body0_path", "0,0,0.1;0,0.5,0.1"], "-body0_path: waypoint times must increase", False),
    ("path with one waypoint", ["-body0_shape", "box", "-body0_path", "0,0,0.1"], "-body0_path: needs at least two waypoints", False),
    ("path and velocity", ["-body0_shape", "box", "-body0_path", "0,0,0.1;1,0.5,0.1", "-body0_velocity", "1,0"], "-body0_path gives the centre and its velocity", False),
    ("dynamic body lighter than its contact nodes (added mass)", ["-scene", "block", "-material", "elastic", "-E", "1e6", "-rho", "1000", "-p0", "0", "-domain_lo", "0,0", "-domain_hi", "1,0.6", "-cells", "20,12", "-body_hi", "1,0.3", "-bc_ylo", "sticky", "-bc_yhi", "free", "-gravity", "0,-9.81", "-body0_shape", "box", "-body0_motion", "dynamic", "-body0_center", "0.5,0.35", "-body0_half", "0.15,0.05", "-body0_mass", "1", "-t_end", "0.01"], "exceeds its mass -body0_mass 1: the explicit body update is unstable (added mass)", True),
    ("path on a dynamic body", ["-body0_shape", "box", "-body0_motion", "dynamic", "-body0_mass", "1", "-body0_path", "0,0,0.1;1,0.5,0.1"], "-body0_path prescribes a kinematic body's motion", False),
    ("annulus inner radius >= outer radius", ["-scene", "annulus", "-annulus_ri", "0.5", "-annulus_ro", "0.4"], "-annulus_ri must be < -annulus_ro", True),
    ("annulus inner radius <= 0", ["-scene", "annulus", "-annulus_ri", "0"], "-annulus_ri must be > 0", False),
    ("annulus ring outside the domain", ["-scene", "annulus"], "the domain must contain the outer ring", False),
    ("annulus with gravity", ["-scene", "annulus", "-domain_lo", "-0.45,-0.45", "-domain_hi", "0.45,0.45", "-cells", "36,36", "-bc_ylo", "sticky", "-bc_yhi", "sticky", "-material", "mu_i"], "set -gravity 0,0", False),
    ("annulus with extra bodies", ["-scene", "annulus", "-domain_lo", "-0.45,-0.45", "-domain_hi", "0.45,0.45", "-cells", "36,36", "-bc_ylo", "sticky", "-bc_yhi", "sticky", "-material", "mu_i", "-gravity", "0,0", "-body0_shape", "disk"], "builds its own two bodies", False),
    ("unknown body fluidity condition", ["-body_fluidity_bc", "dirichlet"], "-body_fluidity_bc: unknown value 'dirichlet'", False),
    ("body fluidity g = 0 without the steady nonlocal model", ["-scene", "annulus", "-material", "mu_i", "-body_fluidity_bc", "zero"], "-body_fluidity_bc zero acts on the steady fluidity solve", False),
    ("body fluidity g = 0 without bodies", ["-material", "nonlocal", "-body_fluidity_bc", "zero"], "-body_fluidity_bc zero needs rigid bodies", False),
    ("3D annulus with gravity across the axis", ["-dim", "3", "-scene", "annulus", "-domain_lo", "-0.45,-0.45,0", "-domain_hi", "0.45,0.45,0.1", "-cells", "18,18,2", "-bc_ylo", "sticky", "-bc_yhi", "sticky", "-bc_zlo", "slip", "-bc_zhi", "free", "-material", "mu_i", "-gravity", "0,-9.81,0"], "gravity must be along the cylinders' axis z", False),
    ("more ranks than the grid can take", ["-da_processors_x", "1", "-da_processors_y", "3"], "cannot split", "only3"),
]


# Issue 14 (part B): options-file cycles, physically impossible combinations, material
# outside the domain, non-finite values, empty or thin material boxes, the rank layout
# and memory. (name, arguments, expected text, also on 2 ranks?)
CASES += [
    ("options file including itself", ["-options_file", "@SELFOPTS@"], "self.opts includes itself (", True),
    ("options files including each other", ["-options_file", "@CYCLEA@"], "cycle_a.opts includes itself (", False),
    ("options file including a missing file", ["-options_file", "@INCMISSING@"], "cannot read '/nonexistent/inc.opts' (included from", False),
    ("infinite Young's modulus", ["-E", "inf"], "-E: 'inf' is not a finite number", True),
    ("NaN density", ["-rho", "nan"], "-rho: 'nan' is not a finite number", False),
    ("infinite velocity component", ["-velocity", "inf,0"], "-velocity: 'inf,0' is not a finite number (component 1)", True),
    ("NaN gravity component", ["-gravity", "0,nan"], "-gravity: '0,nan' is not a finite number (component 2)", False),
    ("real option overflowing to inf", ["-p0", "1e400"], "-p0: '1e400' is not a finite number", False),
    ("infinite body option", ["-body0_shape", "disk", "-body0_radius", "-inf"], "-body0_radius: '-inf' is not a finite number", False),
    ("infinite domain corner", ["-domain_hi", "0.5,inf"], "-domain_hi: '0.5,inf' is not a finite number (component 2)", False),
    ("chute with no confining pressure", ["-p0", "0"], "-scene chute with -p0 0: the chute has no confining pressure", True),
    ("bulk density above the grain density", ["-rho", "3000"], "-rho 3000 exceeds the grain density -rho_s 2450", False),
    ("grain larger than the domain", ["-d", "1"], "-d: the grain diameter 1 m is not smaller than the domain", False),
    ("pressure beyond the bulk modulus", ["-E", "1000"], "-p0 900 Pa reaches the bulk modulus", False),
    ("wave faster than light", ["-E", "1e30", "-rho", "1e-3", "-rho_s", "1"], "reaches the speed of light", False),
    ("time step below the resolution of t", ["-dt", "1e-20", "-t_end", "1e6"], "t + dt rounds to t in double precision", False),
    ("cells below the coordinate resolution", ["-domain_lo", "1e9,0", "-domain_hi", "1000000000.0625,0.015625", "-cells", "4,1", "-bc_ylo", "sticky", "-bc_yhi", "sticky", "-scene", "block", "-material", "elastic", "-p0", "0"], "below the resolution of double-precision coordinates", False),
    ("silo orifice opening no node", ["-options_file", "@SILO@", "-silo_orifice", "0.004", "-silo_orifice_x", "0.2025"], "-silo_orifice 0.004 m centred at -silo_orifice_x 0.2025 opens no node", False),
    ("material box partly outside the domain", ["-body_lo", "-0.7,0", "-body_hi", "0.5,0.2"], "the material box extends outside the domain in x (lo -0.7 < -0.5); 16 particles of it would be dropped", True),
    ("material box outside the domain", ["-body_lo", "0.6,0", "-body_hi", "0.9,0.2"], "the material box lies outside the domain in x", False),
    ("material box with lo > hi", ["-body_lo", "0.2,0", "-body_hi", "-0.2,0.2"], "the material box is empty in x (lo 0.2 >= hi -0.2)", True),
    ("material box thinner than the particle spacing", ["-body_lo", "0.01,0", "-body_hi", "0.02,0.2"], "the material box is 0.01 m thin in x, less than the particle spacing h/ppc = 0.05 m", True),
    ("da_processors product against the rank count", ["-da_processors_x", "3"], "-da_processors_x/y/z ask for 3 ranks, which does not divide the", True),
    ("da_processors in a direction 2D lacks", ["-da_processors_z", "2"], "-da_processors_z 2 splits a direction a 2D run does not have", False),
    ("integer beyond PetscInt (would wrap to 1)", ["-ppc", "4294967297"], "-ppc: '4294967297' is beyond the integer range", True),
    ("integer vector component beyond PetscInt", ["-cells", "20,99999999999"], "-cells: '20,99999999999' is beyond the integer range of this build (2147483647) (component 2)", False),
    ("denormal Courant number", ["-cfl", "4.9e-324"], "(-cfl 4.94066e-324 times h/(c + |v|)): t + dt rounds to t", False),
    ("explicit damping reversing velocities", ["-damping", "1e5"], "the explicit damping factor 1 - damping dt", False),
    ("bar amplitude at the wave speed", ["-options_file", "@BAR@", "-bar_amplitude", "10"], "-bar_amplitude 10 m/s reaches the wave speed 10 m/s", False),
    ("grain diameter below the number range (was a NaN reference)", ["-d", "4.9e-324"], "a grain below a nanometre", False),
    ("rotation at the speed of light (was 'reduce -dt')", ["-options_file", "@ANNULUS@", "-annulus_omega", "1.7976931348623157e308"], "-annulus_omega (times -annulus_ri) gives a speed of", False),
    ("DEM option with an infinite value (ran to NaN)", ["-options_file", "@DEMBLOCK@", "-dem_density", "inf"], "-dem_density: 'inf' is not a finite number", True),
    ("DEM vector option with a NaN component", ["-options_file", "@DEMBLOCK@", "-dem_gravity", "0,nan,0"], "-dem_gravity: '0,nan,0' is not a finite number (component 2)", False),
    ("grid too large for memory (20000 x 8000)", ["-cells", "20000,8000", "-domain_hi", "0.5,0.4"], "are available (MemAvailable of /proc/meminfo summed over the 1 node(s) of the run)", True),
]

def main():
    a = _cli.arguments(__doc__).parse_args()
    tmp = tempfile.mkdtemp(prefix="granmpm-cli-")
    badopts = os.path.join(tmp, "bad.opts")
    with open(badopts, "w") as f:
        f.write("hello world\n-E 1e8\n")
    twoopts = os.path.join(tmp, "two.opts")
    with open(twoopts, "w") as f:
        f.write("# two options on one line\n-E 1e8 -nu 0.3\n")
    files = {"@SELFOPTS@": ("self.opts", "-E 1e8\n-options_file {dir}/self.opts\n"),
             "@CYCLEA@": ("cycle_a.opts", "-nu 0.3\n-options_file {dir}/cycle_b.opts\n"),
             "@CYCLEB@": ("cycle_b.opts", "-options_file {dir}/cycle_a.opts\n"),
             "@INCMISSING@": ("inc_missing.opts", "-options_file /nonexistent/inc.opts\n")}
    subst = {}
    for key, (fname, text) in files.items():
        subst[key] = os.path.join(tmp, fname)
        with open(subst[key], "w") as f:
            f.write(text.format(dir=tmp))
    subst["@ANNULUS@"] = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples", "annulus_nonlocal.opts")
    subst["@DEMBLOCK@"] = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples", "dem_block.opts")
    subst["@BAR@"] = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples", "bar.opts")
    subst["@SILO@"] = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples", "silo.opts")
    badyaml = os.path.join(tmp, "bad.yaml")
    with open(badyaml, "w") as f:
        f.write("E: [1, 2\n  foo: {\n")
    # A checkpoint and a snapshot of the default scene, for the restart cases.
    prep = os.path.join(tmp, "prep")
    subprocess.run([a.granmpm, "-max_steps", "3", "-checkpoint_interval", "3", "-output_dir", prep, "-quiet"], check=True, capture_output=True)
    checkpoint = os.path.join(prep, "checkpoint.h5")
    snapshot = os.path.join(prep, "snap_000000.h5")
    failures = 0
    total = 0
    for name, args, expect, two in CASES:
        args = [x.replace("@BADOPTS@", badopts).replace("@BADYAML@", badyaml).replace("@TWOOPTS@", twoopts).replace("@CHECKPOINT@", checkpoint).replace("@SNAPSHOT@", snapshot) for x in args]
        for key, val in subst.items():
            args = [x.replace(key, val) for x in args]
        base = args + ["-output_dir", os.path.join(tmp, "out")] if "-output_dir" not in args else args
        ranks = [3] if two == "only3" else ([1, 2] if two else [1])
        for n in ranks:
            total += 1
            shutil.rmtree(os.path.join(tmp, "out"), ignore_errors=True)  # a fresh run: a run into another run's results is refused
            rc, out, err = _cli.run(_cli.command(a, n, base), a.timeout)
            lines = _cli.error_lines(err)
            failures += _cli.report(name, n, _cli.refusal_problems(rc, err, expect), lines[0] if lines else err.strip()[:200], width=40)
    print("%d of %d bad-input cases behaved" % (total - failures, total))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
