#!/usr/bin/env python3
"""1D model of the steady nonlocal chute error (issue 15 goal 2): what the fluidity discretisation alone costs.

The steady chute is one-dimensional: p = p0, mu(s) = rho g |s| / p0 exactly (the MPM run reproduces the stress
to 1e-5), so everything the MPM solution can get wrong is the fluidity g and the velocity integrated from it.
This script solves, on half the chute (wall to centre line, symmetric), the same Galerkin system GranMPM
assembles at one particle per cell (linear elements, coefficients sampled at the cell centre: "mid"), and
for comparison the same system with the coefficients at 2 Gauss points per cell ("gauss") and with a lumped
reaction term ("lump"); g at the particle is the mean of the cell's two nodes (-fluidity_map interpolate at
the cell centre) and the velocity follows as in MPM at 1 PPC: v_{i+1} - v_i = h mu_c g_c from v = 0 at the
wall. "exact_g" uses the reference g at the particles (the error of the velocity integration alone).
Reference: second-order finite differences on 40001 points. Errors are relative L2 over the columns of
  point        the column value (v_i + v_{i+1})/2 against v_ref at the column centre (what granmpm prints first),
  column_mean  against the mean of v_ref over the column (granmpm's second number),
  nodal        against (v_ref(x_i) + v_ref(x_{i+1}))/2, i.e. the error of the nodal velocities.
Pure Python (no numpy). Prints CSV.
"""
import math
import sys

A, D, B, MU_S, RHO_S, RHO, GRAV, P0, L = 0.48, 0.05, 18.754, 0.3819, 2450.0, 1500.0, 0.8, 900.0, 1.0
K = (A * D) ** 2


def mu_of(y):  # y: distance from the wall
    return RHO * GRAV * abs(L / 2 - y) / P0


def gloc(m):
    return math.sqrt(P0 / (RHO_S * D * D)) * (m - MU_S) / (B * m) if m > MU_S else 0.0


def tridiag(a, b, c, f):
    n = len(b)
    b, f = b[:], f[:]
    for i in range(1, n):
        m = a[i] / b[i - 1]
        b[i] -= m * c[i - 1]
        f[i] -= m * f[i - 1]
    x = [0.0] * n
    x[-1] = f[-1] / b[-1]
    for i in range(n - 2, -1, -1):
        x[i] = (f[i] - c[i] * x[i + 1]) / b[i]
    return x


def interp(tab, ds, y):
    i = min(int(y / ds), len(tab) - 2)
    t = y / ds - i
    return tab[i] * (1 - t) + tab[i + 1] * t


def reference(n=40001):
    ds = (L / 2) / (n - 1)
    a, b, c, f = [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n
    for i in range(n):
        m = mu_of(i * ds)
        w = abs(m - MU_S)
        b[i] = 2 * K / ds ** 2 + w
        f[i] = w * gloc(m)
        if i == 0:
            c[i] = -2 * K / ds ** 2
        elif i == n - 1:
            a[i] = -2 * K / ds ** 2
        else:
            a[i] = c[i] = -K / ds ** 2
    g = tridiag(a, b, c, f)
    v = [0.0] * n
    for i in range(1, n):
        v[i] = v[i - 1] + 0.5 * ds * (mu_of((i - 1) * ds) * g[i - 1] + mu_of(i * ds) * g[i])
    return (lambda y: interp(g, ds, y)), (lambda y: interp(v, ds, y))


def galerkin(N, scheme):
    h, nc = L / N, N // 2
    a, b, c, f = [0.0] * (nc + 1), [0.0] * (nc + 1), [0.0] * (nc + 1), [0.0] * (nc + 1)
    pts = [(0.5, 1.0)] if scheme != "gauss" else [(0.5 - 0.5 / math.sqrt(3), 0.5), (0.5 + 0.5 / math.sqrt(3), 0.5)]
    for e in range(nc):
        for xi, wq in pts:
            m = mu_of((e + xi) * h)
            w = abs(m - MU_S)
            S, dS = [1 - xi, xi], [-1 / h, 1 / h]
            for i in range(2):
                f[e + i] += wq * h * w * gloc(m) * S[i]
                for j in range(2):
                    mass = (0.5 if i == j else 0.0) if scheme == "lump" else S[i] * S[j]
                    v = wq * h * (K * dS[i] * dS[j] + w * mass)
                    if i == j:
                        b[e + i] += v
                    elif i == 0:
                        c[e] += v
                    else:
                        a[e + 1] += v
    g = tridiag(a, b, c, f)
    return [0.5 * (g[e] + g[e + 1]) for e in range(nc)]  # g at the particles (cell centres)


def errors(N, gc, G, V):
    h = L / N
    v = [0.0]
    for e, g in enumerate(gc):
        v.append(v[-1] + h * mu_of((e + 0.5) * h) * g)
    sums = {"point": [0, 0], "column_mean": [0, 0], "nodal": [0, 0]}
    for e in range(len(gc)):
        col = 0.5 * (v[e] + v[e + 1])
        refs = {"point": V((e + 0.5) * h), "nodal": 0.5 * (V(e * h) + V((e + 1) * h)),
                "column_mean": sum(V(e * h + h * j / 64) * (1 if j in (0, 64) else (4 if j % 2 else 2)) for j in range(65)) / 192}
        for k, r in refs.items():
            sums[k][0] += (col - r) ** 2
            sums[k][1] += r * r
    return {k: math.sqrt(s[0] / s[1]) for k, s in sums.items()}, gc[0] / G(0.5 * h) - 1


def main():
    G, V = reference()
    cells = [int(x) for x in (sys.argv[1] if len(sys.argv) > 1 else "20,40,80,160,320").split(",")]
    print("scheme,cells,g_rel_err_first_particle,rel_point,rel_column_mean,rel_nodal")
    for scheme in ["mid", "gauss", "lump", "exact_g"]:
        for N in cells:
            gc = [G((e + 0.5) * L / N) for e in range(N // 2)] if scheme == "exact_g" else galerkin(N, scheme)
            e, g0 = errors(N, gc, G, V)
            print(f"{scheme},{N},{g0:.4e},{e['point']:.4e},{e['column_mean']:.4e},{e['nodal']:.4e}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
