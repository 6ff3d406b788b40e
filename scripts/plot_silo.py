#!/usr/bin/env python3
"""Plot a silo run's silo.csv: discharged mass and discharge rate against time.
Usage: plot_silo.py OUTPUT_DIR [out.png]"""
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def main():
    d = sys.argv[1]
    out = sys.argv[2] if len(sys.argv) > 2 else os.path.join(d, "silo.png")
    t = np.genfromtxt(os.path.join(d, "silo.csv"), delimiter=",", names=True)
    s = np.genfromtxt(os.path.join(d, "silo_summary.csv"), delimiter=",", names=True)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.6))
    a1.plot(t["t"], t["discharged_mass"], color="C0")
    a1.set_xlabel("t [s]")
    a1.set_ylabel("discharged mass [kg (per m in 2D)]")
    a1.grid(alpha=0.3)
    # Rate from a centred difference over ~2% of the run, to show the steady plateau.
    n = max(1, len(t) // 50)
    if len(t) > 2 * n:
        rate = (t["discharged_mass"][2 * n:] - t["discharged_mass"][:-2 * n]) / (t["t"][2 * n:] - t["t"][:-2 * n])
        a2.plot(t["t"][n:-n], rate, color="C0", label="GranMPM")
    a2.axhline(float(s["discharge_rate"]), color="k", ls="--", lw=1, label="fit, middle 60%%: %.4g" % float(s["discharge_rate"]))
    a2.set_xlabel("t [s]")
    a2.set_ylabel("discharge rate [kg/s (per m in 2D)]")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    fig.suptitle("Silo discharge, orifice D = %.3g m" % float(s["orifice"]), fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print("plot written to", out)


if __name__ == "__main__":
    main()
