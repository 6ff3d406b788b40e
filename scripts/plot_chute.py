#!/usr/bin/env python3
"""Plot a chute run's profile.csv: vy(x) of GranMPM against the local analytic and the
nonlocal 1D reference. Usage: plot_chute.py profile.csv [out.png]"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def main():
    src = sys.argv[1]
    out = sys.argv[2] if len(sys.argv) > 2 else src.rsplit(".", 1)[0] + ".png"
    d = np.genfromtxt(src, delimiter=",", names=True)
    fig, ax = plt.subplots(figsize=(6, 4.2))
    ax.plot(d["x"], d["vy_ref_local"], "k--", lw=1.2, label="local mu(I), analytic")
    ax.plot(d["x"], d["vy_ref_nonlocal"], "k-", lw=1.2, label="nonlocal, 1D finite differences")
    ax.plot(d["x"], d["vy"], "o", ms=4, mfc="none", color="C0", label="GranMPM")
    err = np.sqrt(np.sum((d["vy"] - d["vy_ref"]) ** 2))
    rel = err / np.sqrt(np.sum(d["vy_ref"] ** 2))
    ax.set_xlabel("x from the left wall [m]")
    ax.set_ylabel("v_y [m/s]")
    ax.set_title("Vertical chute, steady state: relative L2 error %.2e" % rel, fontsize=10)
    ax.legend(fontsize=8, loc="upper center")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print("plot written to", out)


if __name__ == "__main__":
    main()
