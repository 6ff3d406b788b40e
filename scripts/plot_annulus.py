#!/usr/bin/env python3
"""Plot an annulus run: v_theta(r) of GranMPM (profile.csv, radial bins) against the local
mu(I) and the nonlocal 1D references (reference.csv, written next to it by the annulus
scene). Usage: plot_annulus.py <output_dir>/profile.csv [out.png]"""
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def main():
    src = sys.argv[1]
    out = sys.argv[2] if len(sys.argv) > 2 else src.rsplit(".", 1)[0] + ".png"
    d = np.genfromtxt(src, delimiter=",", names=True)
    ref = os.path.join(os.path.dirname(src) or ".", "reference.csv")
    fig, ax = plt.subplots(figsize=(6, 4.2))
    if os.path.exists(ref):
        r = np.genfromtxt(ref, delimiter=",", names=True)
        ax.plot(r["r"], r["v_local"], "k--", lw=1.2, label="local mu(I), closed form")
        ax.plot(r["r"], r["v_nonlocal"], "k-", lw=1.2, label="nonlocal, 1D finite differences")
    else:
        ax.plot(d["r"], d["v_ref_local"], "k--", lw=1.2, label="local mu(I)")
        ax.plot(d["r"], d["v_ref_nonlocal"], "k-", lw=1.2, label="nonlocal")
    ax.plot(d["r"], d["v_theta"], "o", ms=4, mfc="none", color="C0", label="GranMPM (radial bins)")
    err = np.sqrt(np.sum((d["v_theta"] - d["v_ref"]) ** 2))
    rel = err / np.sqrt(np.sum(d["v_ref"] ** 2))
    ax.set_xlabel("r [m]")
    ax.set_ylabel("v_theta [m/s]")
    ax.set_title("Annular shear: relative L2 error %.2e against its reference" % rel, fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print("plot written to", out)


if __name__ == "__main__":
    main()
