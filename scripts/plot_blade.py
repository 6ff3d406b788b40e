#!/usr/bin/env python3
"""Plot a blade excavation run (examples/blade.opts): the forward (x) and vertical (y)
force of the soil on the blade, per unit depth, against time, from bodies.csv, with the
blade's depth below the initial surface. Prints the mean forces of the drag phase.
Usage: plot_blade.py OUTPUT_DIR [out.png] [--surface 0.15] [--half 0.05] [--drag t0,t1]"""
import argparse
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("out", nargs="?")
    ap.add_argument("--surface", type=float, default=0.15, help="initial soil surface y [m]")
    ap.add_argument("--half", type=float, default=0.05, help="blade half height [m]")
    ap.add_argument("--drag", default="0.5,2.0", help="drag phase t0,t1 [s] (from the path)")
    a = ap.parse_args()
    out = a.out or os.path.join(a.dir, "blade.png")
    d = np.genfromtxt(os.path.join(a.dir, "bodies.csv"), delimiter=",", names=True)
    d = d[d["body"] == 0]
    t, fx, fy = d["time"], d["fx"], d["fy"]
    depth = a.surface - (d["y"] - a.half)
    t0, t1 = (float(v) for v in a.drag.split(","))
    # Steady part of the drag: its second half.
    m = (t > 0.5 * (t0 + t1)) & (t <= t1)
    print("blade: mean over t = %.3g .. %.3g s: forward force fx = %.4g N/m (std %.3g), vertical force fy = %.4g N/m (std %.3g); peak |fx| %.4g N/m"
          % (0.5 * (t0 + t1), t1, fx[m].mean(), fx[m].std(), fy[m].mean(), fy[m].std(), np.abs(fx).max()))
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    a1.plot(t, fx, label="forward force $f_x$ (soil on blade)", color="C0")
    a1.plot(t, fy, label="vertical force $f_y$", color="C3")
    a1.axhline(0, color="k", lw=0.5)
    a1.set_ylabel("force per unit depth [N/m]")
    a1.legend()
    a1.grid(alpha=0.3)
    a2.plot(t, 100 * depth, color="k")
    a2.set_ylabel("blade tip depth [cm]")
    a2.set_xlabel("t [s]")
    a2.grid(alpha=0.3)
    fig.suptitle("Flat-blade excavation (2D plane strain, local $\\mu(I)$)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print("wrote", out)


if __name__ == "__main__":
    main()
