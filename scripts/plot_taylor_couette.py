#!/usr/bin/env python3
"""3D Taylor-Couette (seed 004 section 4.1): omega(r)/Omega at the top surface, local mu(I)
against nonlocal, from the profile.csv of `-scene annulus -dim 3` runs.

usage: plot_taylor_couette.py LOCAL/profile.csv NONLOCAL/profile.csv [out.png]
        [--rho_s 2550 --d 0.004 --omega 0.25]

Left: linear axes, as the seed's figure 9; right: log scale (the seed's inset), where a
local model's shear band has an edge and the nonlocal one an exponential tail. Prints the
largest inertial number of the top layer, I = gdot d / sqrt(p / rho_s), with
gdot = r |d omega/dr| by finite differences between bins and p the layer's mean pressure.
"""
import argparse
import numpy as np
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

ap = argparse.ArgumentParser()
ap.add_argument("local")
ap.add_argument("nonlocal_")
ap.add_argument("out", nargs="?", default="taylor_couette.png")
ap.add_argument("--rho_s", type=float, default=2550.0)
ap.add_argument("--d", type=float, default=0.004)
ap.add_argument("--omega", type=float, default=0.25)
a = ap.parse_args()

fig, ax = plt.subplots(1, 2, figsize=(10, 4))
for path, label, st in [(a.local, "MPM local mu(I)", "s-"), (a.nonlocal_, "MPM nonlocal (steady fluidity)", "o-")]:
    t = np.genfromtxt(path, delimiter=",", names=True)
    w = t["omega_over_Omega"]
    ax[0].plot(t["xi_d"], w, st, label=label)
    ax[1].semilogy(t["xi_d"], np.abs(w), st, label=label)
    r = t["r"]
    gd = r[:-1] * 0.5 + r[1:] * 0.5
    gd = gd * np.abs(np.diff(w * a.omega) / np.diff(r))
    p = 0.5 * (t["p"][:-1] + t["p"][1:])
    I = gd * a.d / np.sqrt(np.maximum(p, 1e-12) / a.rho_s)
    print(f"{label}: top layer, largest inertial number I = {I.max():.3g} (between r = {r[np.argmax(I)]:.4f} and {r[np.argmax(I) + 1]:.4f} m);"
          f" omega/Omega at xi = {t['xi_d'][-1]:.1f}: {w[-1]:.3e}")
for x in ax:
    x.set_xlabel("(r - Ri) / d")
    x.grid(True, which="both", alpha=0.3)
    x.legend()
ax[0].set_ylabel("omega / Omega (top surface)")
ax[1].set_ylabel("|omega / Omega| (top surface)")
ax[1].set_ylim(1e-5, 1.5)
fig.suptitle("3D Taylor-Couette, top surface (seed 004 §4.1 geometry, coarse: see docs/rigid_bodies.md)")
fig.tight_layout()
fig.savefig(a.out, dpi=110)
print("wrote", a.out)
