#!/usr/bin/env python3
"""Plot a column-collapse run: the final surface (collapse.csv) against the initial column,
with the runout of GranMPM and of the 2D law of Lube et al. (2005) marked.
Usage: plot_collapse.py OUTPUT_DIR [out.png]"""
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def main():
    d = sys.argv[1]
    out = sys.argv[2] if len(sys.argv) > 2 else os.path.join(d, "collapse.png")
    prof = np.genfromtxt(os.path.join(d, "collapse.csv"), delimiter=",", names=True)
    s = np.genfromtxt(os.path.join(d, "collapse_summary.csv"), delimiter=",", names=True)
    a, runout, lube = float(s["aspect_ratio"]), float(s["runout"]), float(s["lube_runout"])
    # L0 from the runout: the tip is at L0 (1 + runout); recover L0 from the deposit tip.
    x, h = prof["x"], prof["height"]
    tip = x[h > 0].max() if np.any(h > 0) else 0.0
    L0 = tip / (1.0 + runout) if runout > -1 else 1.0
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot([0, L0, L0], [a * L0, a * L0, 0], "k:", lw=1, label="initial column (a = %.3g)" % a)
    ax.step(x, h, where="mid", color="C0", label="GranMPM final surface")
    ax.axvline(L0 * (1 + runout), color="C0", ls="--", lw=1, label="GranMPM runout %.3g" % runout)
    ax.axvline(L0 * (1 + lube), color="C3", ls="-.", lw=1, label="Lube et al. 2005: %.3g" % lube)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("height [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("Column collapse: (L_f - L0)/L0 = %.3g, law %.3g (%+.0f%%)" % (runout, lube, 100 * (runout / lube - 1)), fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print("plot written to", out)


if __name__ == "__main__":
    main()
