#!/usr/bin/env python3
"""Pressure drift diagnosis for the annulus scene (docs/rigid_bodies.md).

usage: annulus_volume_check.py FIRST.h5 LAST.h5 E nu [Ri Ro]

Both a particle's volume (V *= exp(dt tr L)) and its pressure (p -= K tr L dt) follow the
same tr L, so ln(V/V0) = -(p - p0)/K per particle unless something else changes the
stress. Prints both, volume-weighted, in rings 0.025 m wide, and their difference.
"""
import sys
import h5py
import numpy as np

a, b = h5py.File(sys.argv[1])["particles"], h5py.File(sys.argv[2])["particles"]
E, nu = float(sys.argv[3]), float(sys.argv[4])
Ri = float(sys.argv[5]) if len(sys.argv) > 5 else 0.2
Ro = float(sys.argv[6]) if len(sys.argv) > 6 else 0.4
K = E / (3 * (1 - 2 * nu))
ia, ib = np.argsort(a["id"][:]), np.argsort(b["id"][:])
assert np.array_equal(a["id"][:][ia], b["id"][:][ib])
V0, V = a["volume"][:][ia], b["volume"][:][ib]
p0, p = a["pressure"][:][ia], b["pressure"][:][ib]
ev, ep = np.log(V / V0), -(p - p0) / K
wm = lambda f, m: (V[m] * f[m]).sum() / V[m].sum()
allp = np.ones_like(V, bool)
print(f"all: mean p {wm(p0, allp):.1f} -> {wm(p, allp):.1f} Pa; ln(V/V0) {wm(ev, allp):+.3e}, -(p-p0)/K {wm(ep, allp):+.3e}; largest |difference| {np.abs(ev - ep).max():.3e}")
x = b["position"][:][ib]
r = np.hypot(x[:, 0], x[:, 1])  # the annulus centred at the origin, as in examples/annulus_*.opts
for lo in np.arange(Ri, Ro - 1e-9, 0.025):
    m = (r >= lo) & (r < lo + 0.025)
    if m.any():
        print(f"r {lo:.3f}-{lo + 0.025:.3f}: ln(V/V0) {wm(ev, m):+.3e}  -(p-p0)/K {wm(ep, m):+.3e}  difference {wm(ev - ep, m):+.3e}")
