#!/usr/bin/env python3
"""Elastic bar (first axial mode) convergence under grid refinement, per shape function.

Bar of length 25 fixed at x = 0 (sticky), free at x = 25, E = 100, rho = 1, nu = 0 (wave speed 10,
period T = 10), run for one period with 2x2 particles per cell, FLIP (alpha 1), USF, automatic dt
(CFL 0.5). The domain extends 4 cells beyond the free end; y is 4 cells, periodic.
For shapes linear|gimp|bspline2, n = 25..400 cells along the bar, amplitudes 0.1 and 1e-4, it records
the max over time of the rms velocity error / amplitude, the centre-of-mass velocity error / amplitude
and the max relative energy drift printed by the bar scene, and the observed orders between successive n.
A run that stops with an error is recorded as status 'error'; one that reaches t_end with its energy more
than doubled (the linear-shape cell-crossing instability) as 'blow-up'. Both keep their metrics in the CSV
(where printed) and are excluded from the orders.

Writes bench/results/bar_convergence.csv, docs/figures/bar_convergence.png and the "Elastic bar"
section of docs/verification.md (with --quick: bench/results/quick/, docs untouched).
"""

import math
import os
import sys

import _common as C

NAME = "bar_convergence"
SHAPES = ["linear", "gimp", "bspline2"]
AMPLITUDES = [0.1, 1e-4]
CFL_N, CFL_AMPLITUDE, CFL_NUMBERS = 100, 1e-4, [0.5, 0.25, 0.125]
SCAN_N = [100, 400]
SCAN_AMPLITUDES = [0.1, 0.03, 0.01, 1e-3, 1e-4]
BLOWUP_DRIFT = 1.0  # max |E(t) - E(0)| / E(0) above which a completed run is classed 'blow-up'
COLUMNS = ["amplitude", "shape", "n", "h", "particles", "steps", "status", "v_err_max", "order_v_err_max", "v_err_end", "vcm_err",
           "order_vcm_err", "energy_drift", "order_energy_drift", "wall_s", "message"]
METRICS = [("v_err_max", "max rms velocity error / amplitude"), ("vcm_err", "centre-of-mass velocity error / amplitude"),
           ("energy_drift", "max relative energy drift")]


def bar_args(n, shape, amplitude, ppc=2):
    h = 25.0 / n
    return ["-scene", "bar", "-material", "elastic", "-E", "100", "-nu", "0", "-rho", "1",
            "-domain_lo", "0,0", "-domain_hi", f"{25 + 4 * h:.12g},{4 * h:.12g}", "-body_hi", f"25,{4 * h:.12g}",
            "-cells", f"{n + 4},4", "-bc_xlo", "sticky", "-bc_xhi", "free", "-bc_ylo", "periodic", "-bc_yhi", "periodic",
            "-gravity", "0,0", "-gravity_ramp", "0", "-t_end", "10", "-ppc", str(ppc), "-shape", shape,
            "-transfer", "flip", "-flip_alpha", "1", "-update", "usf", "-bar_amplitude", f"{amplitude:g}",
            "-output_final", "0", "-progress_interval", "0"]


def end_displacement(amplitude, L=25.0, c=10.0):
    """Amplitude of the free-end displacement of the first mode: A / omega, omega = pi c / (2 L)."""
    return amplitude * 2 * L / (math.pi * c)


def order(e_coarse, e_fine, ratio=2.0):
    if e_coarse is None or e_fine is None or e_coarse <= 0 or e_fine <= 0:
        return None
    return math.log(e_coarse / e_fine) / math.log(ratio)


def main():
    ap = C.common_argparser(__doc__.split("\n")[0])
    ap.add_argument("--n", default=None, help="comma-separated cell counts along the bar (default 25,50,100,200,400; quick 25,50,100)")
    ap.add_argument("--amp-scan", dest="amp_scan", action="store_true", default=None,
                    help="also scan the amplitude at n = 100 and 400 (default in the full sweep)")
    ap.add_argument("--no-amp-scan", dest="amp_scan", action="store_false")
    ap.add_argument("--cfl-check", dest="cfl_check", action="store_true", default=None,
                    help="also rerun n = 100, A = 1e-4 with -cfl 0.25 and 0.125 (default in the full sweep)")
    ap.add_argument("--no-cfl-check", dest="cfl_check", action="store_false")
    a = ap.parse_args()
    ns = [int(x) for x in a.n.split(",")] if a.n else ([25, 50, 100] if a.quick else [25, 50, 100, 200, 400])
    amp_scan = (not a.quick) if a.amp_scan is None else a.amp_scan
    cfl_check = (not a.quick) if a.cfl_check is None else a.cfl_check
    csv_path, png_path = C.output_paths(NAME, a.quick)
    scan_path = csv_path.replace(NAME, NAME + "_amplitude")
    cfl_path = csv_path.replace(NAME, NAME + "_cfl")
    if a.replot:
        rows = C.read_csv(csv_path)
        for r in rows:
            r["cmd"] = C.shown_cmd(bar_args(r["n"], r["shape"], r["amplitude"]))
        scan = C.read_csv(scan_path) if os.path.exists(scan_path) else []
        cfl = C.read_csv(cfl_path) if os.path.exists(cfl_path) else []
        plot(rows, png_path)
        if not (a.quick or a.no_docs):
            write_docs(rows, C.read_meta(csv_path), sorted({r["n"] for r in rows}), scan, cfl)
        return 0
    binary = C.granmpm_binary()
    rows = []
    for amp in AMPLITUDES:
        for shape in SHAPES:
            prev = None
            for n in ns:
                r = C.run_granmpm(bar_args(n, shape, amp), label=f"bar amp {amp:g} {shape} n {n}")
                row = {"amplitude": amp, "shape": shape, "n": n, "h": 25.0 / n, "particles": r.get("particles"), "steps": r.get("steps"),
                       "wall_s": r.get("wall_s"), "cmd": r["cmd"]}
                if r["ok"] and "v_err_max" in r:
                    for k in ("v_err_max", "v_err_end", "vcm_err", "energy_drift"):
                        row[k] = r[k]
                    # A run that reaches t_end but whose energy more than doubled has gone unstable without stopping.
                    row["status"] = "ok" if r["energy_drift"] <= BLOWUP_DRIFT else "blow-up"
                    if row["status"] != "ok":
                        row["message"] = f"ran to t_end but energy drift {r['energy_drift']:.3g} > {BLOWUP_DRIFT:g}"
                else:
                    row["status"] = "error" if r["rc"] != 0 else "no-metrics"
                    row["message"] = C.error_line(r["output"]).replace(",", ";")
                if prev is not None and prev["n"] * 2 == n and prev["status"] == "ok" and row["status"] == "ok":
                    for k in ("v_err_max", "vcm_err", "energy_drift"):
                        row["order_" + k] = order(prev.get(k), row.get(k))
                rows.append(row)
                prev = row
    C.write_csv(csv_path, COLUMNS, rows)
    meta = C.write_meta(csv_path, binary)
    scan = []
    if amp_scan:
        # Is the error at A = 0.1 the discretisation or amplitude-dependent (finite strain, particles crossing cells)?
        for shape in SHAPES:
            for n in SCAN_N:
                for amp in SCAN_AMPLITUDES:
                    r = C.run_granmpm(bar_args(n, shape, amp), label=f"bar scan {shape} n {n} amp {amp:g}")
                    row = {"shape": shape, "n": n, "amplitude": amp, "end_displacement_over_h": end_displacement(amp) * n / 25.0}
                    if r["ok"] and "v_err_max" in r:
                        row.update({k: r[k] for k in ("v_err_max", "v_err_end", "vcm_err", "energy_drift")})
                        row["status"] = "ok" if r["energy_drift"] <= BLOWUP_DRIFT else "blow-up"
                    else:
                        row["status"] = "error" if r["rc"] != 0 else "no-metrics"
                    scan.append(row)
        print()
        C.write_csv(scan_path, ["shape", "n", "amplitude", "end_displacement_over_h", "status", "v_err_max", "v_err_end", "vcm_err", "energy_drift"], scan)
    cfl = []
    if cfl_check:
        # Time or space? Same n, smaller time step: a pure time-integration error halves with the CFL number.
        for shape in SHAPES:
            for c in CFL_NUMBERS:
                r = C.run_granmpm(bar_args(CFL_N, shape, CFL_AMPLITUDE) + ["-cfl", f"{c:g}"], label=f"bar cfl {shape} n {CFL_N} cfl {c:g}")
                row = {"shape": shape, "n": CFL_N, "amplitude": CFL_AMPLITUDE, "cfl": c, "steps": r.get("steps"),
                       "status": "ok" if r["ok"] and "v_err_max" in r else "error"}
                row.update({k: r.get(k) for k in ("v_err_max", "vcm_err", "energy_drift")})
                cfl.append(row)
        print()
        C.write_csv(cfl_path, ["shape", "n", "amplitude", "cfl", "steps", "status", "v_err_max", "vcm_err", "energy_drift"], cfl)
    plot(rows, png_path)
    if not (a.quick or a.no_docs):
        write_docs(rows, meta, ns, scan, cfl)


def plot(rows, path):
    plt = C.pyplot()
    if plt is None:
        return
    fig, axes = plt.subplots(len(METRICS), len(AMPLITUDES), figsize=(10, 11), squeeze=False)
    markers = {"linear": "o", "gimp": "s", "bspline2": "^"}
    for j, amp in enumerate(AMPLITUDES):
        for i, (key, label) in enumerate(METRICS):
            ax = axes[i][j]
            for shape in SHAPES:
                sel = [r for r in rows if r["amplitude"] == amp and r["shape"] == shape]
                pts = [(r["h"], r[key]) for r in sel if r["status"] == "ok" and r.get(key, 0) > 0]
                blow = [(r["h"], r[key]) for r in sel if r["status"] == "blow-up" and r.get(key, 0) > 0]
                err = [r["h"] for r in sel if r["status"] not in ("ok", "blow-up")]
                if not (pts or blow):
                    continue
                line, = ax.loglog([p[0] for p in pts], [p[1] for p in pts], marker=markers[shape], label=shape)
                if blow:
                    ax.loglog([p[0] for p in blow], [p[1] for p in blow], linestyle="none", marker="x", markersize=10,
                              color=line.get_color(), label=f"{shape}: blow-up (ran to end)")
                if err:
                    ymin = min(p[1] for p in pts + blow)
                    ax.plot(err, [ymin] * len(err), linestyle="none", marker="v", markersize=10, color=line.get_color(),
                            label=f"{shape}: stopped with error")
            hs = sorted({r["h"] for r in rows})
            ok = [r[key] for r in rows if r["amplitude"] == amp and r["status"] == "ok" and r.get(key, 0) > 0]
            if hs and ok:
                h0, e0 = hs[-1], max(ok)
                for p, ls in ((1, ":"), (2, "--")):
                    ax.loglog(hs, [e0 * (h / h0) ** p for h in hs], color="grey", linestyle=ls, linewidth=0.8, label=f"O(h^{p})")
            ax.set_xlabel("h (bar length 25)")
            ax.set_ylabel(label)
            ax.set_title(f"amplitude {amp:g}", fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=7)
    fig.suptitle("Elastic bar, first mode, one period: error vs cell size (x: blow-up, not in the fitted lines)")
    fig.tight_layout()
    C.save_figure(fig, path)


def write_docs(rows, meta, ns, scan=(), cfl=()):
    def cell(r, key):
        if r["status"] == "blow-up":
            return C.sci(r.get(key), 2) + " (blow-up)"
        if r["status"] != "ok":
            return r["status"]
        return C.sci(r.get(key), 2)

    def ordc(r, key):
        o = r.get("order_" + key)
        return "-" if o is None else f"{o:.2f}"

    parts = []
    parts.append(
        "Produced by `bench/bar_convergence.py` (" + meta["binary"] + ", " + meta["date"] + "). "
        "Elastic bar of length 25 fixed at x = 0 and free at x = 25, E = 100, rho = 1, nu = 0 (wave speed 10, period T = 10), "
        "first axial mode v = A sin(pi x / 50) cos(omega t), run for one period. n cells along the bar (h = 25/n), "
        "2x2 particles per cell, FLIP (alpha 1), USF, automatic dt (CFL 0.5, so dt is proportional to h); "
        "the domain extends 4 cells beyond the free end and is 4 cells high, periodic in y. Command for n = 100, gimp, A = 0.1:\n\n"
        "```\n" + next(r["cmd"] for r in rows if r["n"] == (100 if 100 in ns else ns[0]) and r["shape"] == "gimp") + "\n```\n\n"
        "Errors are normalised by the amplitude A: the max over time of the rms particle velocity error against the linear "
        "theory, the max centre-of-mass velocity error, and the max relative drift of kinetic + strain energy. "
        "The order is log2(e(n/2)/e(n)). Figure: `docs/figures/bar_convergence.png`.\n")
    for amp in AMPLITUDES:
        tab = []
        for shape in SHAPES:
            for r in rows:
                if r["amplitude"] == amp and r["shape"] == shape:
                    tab.append([shape, r["n"], f"{r['h']:.4g}", cell(r, "v_err_max"), ordc(r, "v_err_max"), cell(r, "vcm_err"), ordc(r, "vcm_err"),
                                cell(r, "energy_drift"), ordc(r, "energy_drift")])
        parts.append(f"### Amplitude A = {amp:g}\n")
        parts.append(C.md_table(["shape", "n", "h", "max rms v error / A", "order", "CoM v error / A", "order", "energy drift", "order"], tab,
                                ["l", "r", "r", "r", "r", "r", "r", "r", "r"]) + "\n")
    unstable = [r for r in rows if r["status"] != "ok"]
    if unstable:
        parts.append("Runs that went unstable (status `blow-up`: reached t = 10 but the energy more than doubled; "
                     "status `error`: stopped with an error). They are kept in the CSV and left out of the orders:\n")
        for r in unstable:
            parts.append(f"- A = {r['amplitude']:g}, {r['shape']}, n = {r['n']}: `{r.get('message', '')}`")
        parts.append("")
    parts.append(interpretation(rows))
    if scan:
        parts.append("### Amplitude scan\n")
        parts.append("Same runs at n = " + " and ".join(str(n) for n in SCAN_N) + " for several amplitudes A; \"end displacement / h\" is the amplitude of the "
                     "free-end displacement, A 2L/(pi c), in cells. Errors are divided by A, so a pure discretisation error gives "
                     "the same number for every A.\n")
        st = []
        for shape in SHAPES:
            for n in SCAN_N:
                rs = [r for r in scan if r["shape"] == shape and r["n"] == n]
                for r in rs:
                    e = C.sci(r.get("v_err_max"), 2) + (" (blow-up)" if r["status"] == "blow-up" else "") if r.get("v_err_max") is not None else r["status"]
                    st.append([shape, n, f"{r['amplitude']:g}", f"{r['end_displacement_over_h']:.3g}", e, C.sci(r.get("v_err_end"), 2),
                               C.sci(r.get("energy_drift"), 2)])
        parts.append(C.md_table(["shape", "n", "A", "end displacement / h", "max rms v error / A", "at end / A", "energy drift"], st,
                                ["l", "r", "r", "r", "r", "r", "r"]) + "\n")
    if cfl:
        parts.append("### Time step check\n")
        parts.append(f"n = {CFL_N}, A = {CFL_AMPLITUDE:g}, the same runs with a smaller `-cfl` (default 0.5). An error that halves with "
                     "the CFL number at fixed h is the time-integration error.\n")
        ct = [[r["shape"], f"{r['cfl']:g}", r["steps"] or "-", C.sci(r.get("v_err_max"), 2), C.sci(r.get("vcm_err"), 2), C.sci(r.get("energy_drift"), 2)]
              for r in cfl]
        parts.append(C.md_table(["shape", "CFL", "steps", "max rms v error / A", "CoM v error / A", "energy drift"], ct,
                                ["l", "r", "r", "r", "r", "r"]) + "\n")
    C.replace_doc_section("verification.md", "bar", "Elastic bar", "\n".join(parts), "GranMPM verification")


def interpretation(rows):
    """A short factual reading of the measured orders (no claims beyond the numbers)."""
    lines = ["Reading of the numbers above (generated from the measured orders):\n"]
    for amp in AMPLITUDES:
        for shape in SHAPES:
            rs = [r for r in rows if r["amplitude"] == amp and r["shape"] == shape]
            orders = [r.get("order_v_err_max") for r in rs if r.get("order_v_err_max") is not None]
            ok = [r for r in rs if r["status"] == "ok"]
            if not ok:
                continue
            finest = ok[-1]
            o = ", ".join(f"{x:.2f}" for x in orders) if orders else "none"
            lines.append(f"- A = {amp:g}, {shape}: rms velocity error orders {o}; finest stable n = {finest['n']} gives "
                         f"{finest['v_err_max']:.2e}.")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
