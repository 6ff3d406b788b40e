#!/usr/bin/env python3
"""Wheel on soil (examples/wheel.opts) at three slips: runs granmpm for each slip
s = 1 - v/(|omega| R) (v = (1 - s) |omega| R, omega and R from the options file), then
plots the drawbar pull over wheel load DP/W and the sinkage against slip, and the force
histories. DP = fx and W = fy of bodies.csv (soil on wheel), time-averaged over the
second half of the run; sinkage = surface + R - y_centre (mean over the same window and
maximum).
Usage: plot_wheel.py [--granmpm build/granmpm] [--opts examples/wheel.opts]
                     [--slips 0.2,0.4,0.7] [--out output/wheel_slip] [--np 1] [--plot-only]
Writes <out>/wheel_slip.csv and <out>/wheel_slip.png."""
import argparse
import os
import subprocess

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def opt(path, name):
    for line in open(path):
        p = line.split()
        if p and p[0] == name:
            return p[1]
    raise SystemExit("%s not in %s" % (name, path))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--granmpm", default="build/granmpm")
    ap.add_argument("--opts", default="examples/wheel.opts")
    ap.add_argument("--slips", default="0.2,0.4,0.7")
    ap.add_argument("--out", default="output/wheel_slip")
    ap.add_argument("--np", type=int, default=1)
    ap.add_argument("--surface", type=float, default=None, help="soil surface y (default: -body_hi's y)")
    ap.add_argument("--plot-only", action="store_true")
    ap.add_argument("extra", nargs="*", help="more granmpm options (after --)")
    a = ap.parse_args()
    R = float(opt(a.opts, "-body0_radius"))
    w = abs(float(opt(a.opts, "-body0_omega")))
    surface = a.surface if a.surface is not None else float(opt(a.opts, "-body_hi").split(",")[1])
    slips = [float(s) for s in a.slips.split(",")]
    os.makedirs(a.out, exist_ok=True)
    rows = []
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(13, 3.8))
    for s in slips:
        v = (1 - s) * w * R
        d = os.path.join(a.out, "s%.2f" % s)
        if not a.plot_only:
            cmd = ["mpiexec", "--allow-run-as-root", "--oversubscribe", "-n", str(a.np)] if a.np > 1 else []
            cmd += [a.granmpm, "-options_file", a.opts, "-body0_velocity", "%.9g,0" % v, "-output_dir", d, "-output_interval", "0",
                    "-output_final", "0", "-progress_interval", "0", "-output_overwrite"] + a.extra
            print(" ".join(cmd), flush=True)
            subprocess.run(cmd, check=True)
        b = np.genfromtxt(os.path.join(d, "bodies.csv"), delimiter=",", names=True)
        b = b[b["body"] == 0]
        t = b["time"]
        m = t >= 0.5 * t[-1]
        sink = surface + R - b["y"]
        dp, W = b["fx"][m].mean(), b["fy"][m].mean()
        rows.append((s, v, dp, W, dp / W, sink[m].mean(), sink.max(), b["fx"][m].std(), b["fy"][m].std()))
        a1.plot(t, b["fx"], label="DP, s = %.1f" % s)
        a1.plot(t, b["fy"], ls="--", color=a1.lines[-1].get_color(), label="W, s = %.1f" % s)
        a2.plot(t, 1000 * sink, label="s = %.1f" % s)
    r = np.array(rows)
    hdr = "slip,v,drawbar_pull,wheel_load,dp_over_w,sinkage_mean,sinkage_max,dp_std,w_std"
    np.savetxt(os.path.join(a.out, "wheel_slip.csv"), r, delimiter=",", header=hdr, comments="", fmt="%.6g")
    for row in rows:
        print("wheel: slip %.2f (v = %.4g m/s): DP = %.4g N/m, W = %.4g N/m, DP/W = %.4f, sinkage mean %.2f mm, max %.2f mm" %
              (row[0], row[1], row[2], row[3], row[4], 1000 * row[5], 1000 * row[6]))
    a1.set_xlabel("t [s]")
    a1.set_ylabel("force per unit depth [N/m]")
    a1.legend(fontsize=7, ncol=2)
    a1.grid(alpha=0.3)
    a2.set_xlabel("t [s]")
    a2.set_ylabel("sinkage [mm]")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    a3.plot(r[:, 0], r[:, 4], "o-", color="C0", label="DP/W")
    a3.set_xlabel("slip s")
    a3.set_ylabel("DP/W (mean, second half)", color="C0")
    a3.grid(alpha=0.3)
    a4 = a3.twinx()
    a4.plot(r[:, 0], 1000 * r[:, 6], "s--", color="C3", label="max sinkage")
    a4.set_ylabel("max sinkage [mm]", color="C3")
    fig.suptitle("Wheel on soil (2D plane strain, local $\\mu(I)$): drawbar pull / load and sinkage against slip")
    fig.tight_layout()
    png = os.path.join(a.out, "wheel_slip.png")
    fig.savefig(png, dpi=110)
    print("wrote", png, "and", os.path.join(a.out, "wheel_slip.csv"))


if __name__ == "__main__":
    main()
