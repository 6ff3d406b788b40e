#!/usr/bin/env python3
"""Gallery of the examples: runs every examples/*.opts, renders its particles with
scripts/render.py and writes docs/gallery.md (picture, command, wall-clock time).

usage: scripts/gallery.py [--np 2] [--only NAME ...] [--render-only] [--out docs]
                          [--granmpm PATH] [--mpiexec "mpiexec --oversubscribe"]

Long examples run shortened (SHORTEN below: a smaller -t_end), and the gallery says so.
Run directories go to output/gallery/<name>/. Re-running refreshes the pictures and the
table (rows of examples not run this time are kept from the existing docs/gallery.md).
"""
import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Colour field per example (render.py --field), and what the picture shows.
FIELD = {
    "annulus_local": ("velocity", "annular shear, local mu(I): |v| between the turning disk and the fixed ring"),
    "annulus_nonlocal": ("velocity", "annular shear, nonlocal fluidity: |v|"),
    "bar": ("velocity:X", "elastic bar, first axial mode: v_x"),
    "blade": ("velocity", "flat-blade excavation: |v| of the soil pushed by the blade"),
    "block_3d": ("pressure", "3D hypoelastic block drifting and spinning across periodic x and z: pressure"),
    "block_spin": ("pressure", "2D hypoelastic block drifting and spinning across periodic x: pressure"),
    "chute_dynamic": ("velocity:Y", "vertical chute, dynamical nonlocal model (seed 004): v_y"),
    "chute_local": ("velocity:Y", "vertical chute, local mu(I): v_y"),
    "chute_nonlocal": ("velocity:Y", "vertical chute, steady nonlocal fluidity (the `make run` scene): v_y"),
    "collapse": ("velocity", "granular column collapse, a = 2: |v|"),
    "collapse_3d": ("velocity", "column collapse in a 3D slot: |v|"),
    "column": ("stress_yy", "elastic column settling under gravity: sigma_yy"),
    "silo": ("velocity", "silo discharge through a slot: |v|"),
    "silo_3d": ("velocity", "3D silo discharge through a round orifice: |v|"),
    "taylor_couette_3d_local": ("velocity", "3D Taylor-Couette cell, local mu(I): |v|"),
    "taylor_couette_3d_nonlocal": ("velocity", "3D Taylor-Couette cell, nonlocal: |v|"),
    "wheel": ("velocity", "wheel on soil (dynamic disk, prescribed slip): |v|"),
}
# Examples that take more than a few minutes on 2 cores run to an earlier time.
SHORTEN = {
    "taylor_couette_3d_local": ["-t_end", "0.05"],
    "taylor_couette_3d_nonlocal": ["-t_end", "0.05"],
    "silo_3d": ["-t_end", "0.25"],
    "collapse_3d": ["-t_end", "0.5"],
}


def opt(path, name):
    with open(path) as f:
        for line in f:
            tok = line.split("#")[0].split()
            if len(tok) == 2 and tok[0] == name:
                return tok[1]
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--np", type=int, default=2)
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs"))
    ap.add_argument("--render-only", action="store_true", help="redraw from output/gallery/<name> where a run is there")
    ap.add_argument("--granmpm", default=os.path.join(ROOT, "build", "granmpm"))
    root_flag = " --allow-run-as-root" if os.geteuid() == 0 else ""
    ap.add_argument("--mpiexec", default="mpiexec --oversubscribe" + root_flag)
    a = ap.parse_args()
    if not shutil.which("pvbatch"):
        sys.exit("gallery.py: pvbatch not found: install ParaView (apt-get install paraview python3-paraview xvfb)")
    names = sorted(os.path.basename(p)[:-5] for p in os.listdir(os.path.join(ROOT, "examples")) if p.endswith(".opts"))
    todo = [n for n in names if not a.only or n in a.only]
    pics = os.path.join(a.out, "gallery")
    os.makedirs(pics, exist_ok=True)
    md = os.path.join(a.out, "gallery.md")
    mine = {}  # sections made by this run

    def write_md():
        # Re-read the file and replace only this run's sections, so that the examples not
        # re-run keep theirs (and two gallery runs at once do not drop each other's).
        sections = {}
        if os.path.exists(md):
            for part in open(md).read().split("\n## `")[1:]:
                sections[part.split("`")[0]] = "## `" + part.rstrip("\n") + "\n"
        sections.update(mine)
        with open(md, "w") as f:
            f.write("# Gallery\n\nOne picture per example in `examples/`, rendered by `scripts/render.py` from the run's last\n"
                    "snapshot (particles as discs coloured by the field named; rigid bodies black; the domain grey).\n"
                    f"Made by `scripts/gallery.py` (runs every example on {a.np} ranks and renders it; `--only NAME` for one,\n"
                    "`--render-only` to redraw from the last runs), so it can be refreshed after a change. Run times are\n"
                    "wall-clock on the 2-core development machine, shared with other jobs (load average 6-12 when this\n"
                    "gallery was made, several times an idle machine's times), so they are indicative only. Long\n"
                    "examples run shortened, as noted. Examples without a section here have not been rendered yet:\n"
                    "`scripts/gallery.py --only NAME` adds one.\n")
            for n in names:
                if n in sections:
                    f.write("\n" + sections[n])

    for n in todo:
        ex = os.path.join("examples", n + ".opts")
        field, what = FIELD.get(n, ("velocity", n))
        run_dir = os.path.join("output", "gallery", n)
        extra = SHORTEN.get(n, [])
        shown = f"mpiexec -n {a.np} build/granmpm -options_file {ex}" + (" " + " ".join(extra) if extra else "")
        stamp = os.path.join(ROOT, run_dir, "gallery_wall_seconds.txt")
        if a.render_only and os.path.exists(stamp):
            wall, load = (float(x) for x in open(stamp).read().split())
        else:
            shutil.rmtree(os.path.join(ROOT, run_dir), ignore_errors=True)
            cmd = shlex.split(a.mpiexec) + ["-n", str(a.np), a.granmpm, "-options_file", ex, "-output_dir", run_dir] + extra
            print(f"gallery: {shown}", flush=True)
            t0, load0 = time.time(), os.getloadavg()[0]
            p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
            wall, load = time.time() - t0, 0.5 * (load0 + os.getloadavg()[0])
            if p.returncode != 0:
                print(p.stderr[-2000:])
                sys.exit(f"gallery.py: {n} failed")
            with open(stamp, "w") as f:
                f.write(f"{wall:.1f} {load:.1f}\n")
        png = os.path.join(pics, n + ".png")
        subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "render.py"), os.path.join(ROOT, run_dir), "-o", png, "--field", field,
                        "--size", "1000x620", "--title", n], check=True)
        note = f" Shortened: `{' '.join(extra)}` (the example runs to -t_end {opt(os.path.join(ROOT, ex), '-t_end')})." if extra else ""
        mine[n] = f"## `{n}`\n\n{what}.\n\n`{shown}`: {wall:.0f} s (load average {load:.0f} on 2 cores).{note}\n\n![{n}](gallery/{n}.png)\n"
        print(f"gallery: {n}: {wall:.1f} s, {png}", flush=True)
        write_md()  # after each example: a failure later keeps what was made
    print(f"gallery: {md}")


if __name__ == "__main__":
    main()
