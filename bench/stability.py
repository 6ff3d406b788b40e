#!/usr/bin/env python3
"""Stability stress test: fixed time steps from 0.25x to 4x the CFL limit, per model, shape and transfer.

Every run takes a fixed number of steps (STEPS = 400; -max_steps 400 -t_end 400*dt) with a fixed -dt equal to a
factor f times the CFL limit dt_CFL = h / (c + |v|max(t=0)), c = sqrt((K + 4G/3)/rho), computed here from E, nu,
rho, h and the initial velocity field (and checked against the "CFL limit" line granmpm prints). The sweeps, each
around a base point (one parameter varied at a time, f always varied):

  elastic, hypoelastic   scene "bar": bar of length 1 m fixed at x = 0, free at x = 1, 4 cells high (periodic),
                         rho 1000, nu 0.3, first-mode velocity amplitude 1 m/s; base E = 1e7, 20 cells, 2 PPC.
                         Varied: E = 1e5..1e9, cells 10/20/40, PPC 1/2/4, transfer pic/flip/apic.
                         scene "block": a 1 m square block spinning (2 rad/s) and drifting (2,1) m/s through a fully
                         periodic 2 m box (free surfaces on all sides), E 1e7, 2 PPC; transfer pic/flip/apic.
  mu_i, nonlocal         scene "chute": seed 000 vertical chute (defaults: rho 1500, p0 900 Pa, mu_s 0.3819, b 18.754,
                         d 0.05, rho_s 2450, A 0.48), started sheared (-chute_prestress -gravity_ramp 0), 4 cells high;
                         base E = 1e8, 20 cells across, 1 PPC, gravity 0.8 (wall friction rho g (L/2) / p0 = 1.75 mu_s).
                         Varied: E, cells, PPC, transfer, and the wall friction ratio 1.01/1.05/1.2 mu_s (via -gravity);
                         with -stress_update explicit: E (and cells) again, with f down to 1/16 to find the plastic
                         limit G dt / eta < 2, eta = b d sqrt(rho_s p0).

Each configuration is first run as a user would (without -dt_allow_unstable): the result is the 'guard' column
(accepted, refused at set-up, refused at run time, or the instability guard that stopped it). When the solver
refused the step, the run is repeated with -dt_allow_unstable, and that run gives the 'outcome': stable, energy
growth (ran to the end, but the energy grew: see GROWTH_TOL), nan, energy (kinetic-energy guard), runaway
(a particle moved more than a cell in a step), left (a particle left the domain), ksp, error, timeout.

Writes bench/results/stability.csv, docs/figures/stability_<model>_<shape>.png, docs/figures/stability_summary.png
and the generated sections of docs/stability.md (with --quick: a small sweep into bench/results/quick/, docs untouched).
"""

import concurrent.futures
import math
import os
import re
import shutil
import sys
import time

import _common as C

NAME = "stability"
STEPS = 400
FACTORS = [0.25, 0.5, 0.75, 0.9, 1.0, 1.1, 1.25, 1.5, 2.0, 3.0, 4.0]
EXPLICIT_FACTORS = [0.0625, 0.125] + FACTORS
QUICK_FACTORS = [0.25, 0.5, 0.75, 1.0, 1.5, 4.0]
QUICK_EXPLICIT_FACTORS = [0.125, 0.25, 0.5, 1.0, 2.0]
MODELS = ["elastic", "hypoelastic", "mu_i", "nonlocal"]
SHAPES = ["linear", "gimp", "bspline2"]
TRANSFERS = ["pic", "flip", "apic"]
E_VALUES = [1e5, 1e6, 1e7, 1e8, 1e9]
CELLS = [10, 20, 40]
PPCS = [1, 2, 4]
MU_RATIOS = [1.01, 1.05, 1.2]
GRANULAR = ("mu_i", "nonlocal")

# Energy-conserving scenes (bar, block: no gravity, no damping): a run that reaches the end is 'stable' if its
# energy never exceeds (1 + GROWTH_TOL) times the initial energy (bar: kinetic + strain energy from the solver's
# bar.csv; block: kinetic energy, which cannot exceed the initial kinetic energy of the stress-free block).
GROWTH_TOL = 0.10
# Chute (dissipative, driven by the initial shear stress): a completed run is flagged 'deviates' if its kinetic
# energy at the end time of the smallest stable step of the same configuration differs from that run's by more
# than a factor CHUTE_KE_TOL (in either direction); such runs count as not stable. Not applied to PIC (see
# chute_reference_check) nor to chutes that do not flow.
CHUTE_KE_TOL = 1.25
KE_FLOOR = 1e-12  # no comparison when the reference kinetic energy is below this fraction of m g L (no flow)

BAR = dict(L=1.0, rho=1000.0, nu=0.3, amplitude=1.0, E=1e7, cells=20, ppc=2)
BLOCK = dict(box=2.0, lo=0.5, hi=1.5, rho=1000.0, nu=0.3, E=1e7, cells=40, ppc=2, v0=(2.0, 1.0), spin=2.0)
CHUTE = dict(L=1.0, rho=1500.0, nu=0.3, p0=900.0, g=0.8, mu_s=0.3819, b=18.754, d=0.05, rho_s=2450.0, E=1e8, cells=20, ppc=1)

COLUMNS = ["model", "scene", "shape", "transfer", "stress_update", "E", "cells", "h", "ppc", "gravity", "mu_ratio", "wall_ratio", "dt_mode",
           "factor", "dt",
           "auto_dt_min_factor", "dt_cfl",
           "dt_cfl_printed", "dt_plastic", "dt_plastic_solver", "steps_target", "guard", "outcome", "completed_steps", "fail_step", "fail_time", "energy_growth",
           "energy_loss", "ke_ratio_ref", "max_speed", "wall_s", "message"]
OUTCOME_STYLE = {  # marker, colour, label
    "stable": ("o", "tab:green", "stable"),
    "deviates": ("h", "darkorange", "completed, KE > 25% off the smallest-dt run (chute)"),
    "growth": ("*", "black", "completed, energy grew > 10% (no error!)"),
    "nan": ("X", "tab:red", "stopped: non-finite value"),
    "energy": ("^", "tab:red", "stopped: kinetic-energy guard"),
    "runaway": ("s", "tab:purple", "stopped: particle moved > 1 cell/step"),
    "left": ("D", "tab:blue", "stopped: particle left the domain"),
    "ksp": ("P", "tab:brown", "stopped: fluidity solve diverged"),
    "error": ("x", "grey", "stopped: other error"),
    "timeout": ("x", "black", "timeout"),
}
UNSTABLE = ("deviates", "growth", "nan", "energy", "runaway", "left", "ksp", "error", "timeout")

RE_PROGRESS = re.compile(r"^step\s+(\d+)\s+t\s+(\S+)\s+dt\s+(\S+)\s+KE\s+(\S+)", re.M)
RE_AT_T = re.compile(r"at t = (" + C._FLOAT + ")")
RE_PLASTIC = re.compile(r"exceeds the stability limit (" + C._FLOAT + r") s of the explicit granular")


# --------------------------------------------------------------------------------------
# Cases


def moduli(E, nu):
    K = E / (3.0 * (1.0 - 2.0 * nu))
    G = E / (2.0 * (1.0 + nu))
    return K, G


def wave_speed(E, nu, rho):
    K, G = moduli(E, nu)
    return math.sqrt((K + 4.0 * G / 3.0) / rho)


class Case:
    """One configuration (everything but the time-step factor) of one scene."""

    def __init__(self, model, shape, transfer="apic", E=None, cells=None, ppc=None, mu_ratio=None, stress_update="implicit", scene=None):
        """mu_ratio (chute): tau / (mu_s p) of the outermost particle column at t = 0, set through the gravity; default:
        the seed's gravity 0.8 m/s^2."""
        self.model, self.shape, self.transfer, self.stress_update = model, shape, transfer, stress_update
        self.scene = scene or ("chute" if model in GRANULAR else "bar")
        base = {"bar": BAR, "block": BLOCK, "chute": CHUTE}[self.scene]
        self.E = E if E is not None else base["E"]
        self.cells = cells if cells is not None else base["cells"]
        self.ppc = ppc if ppc is not None else base["ppc"]
        self.g = None
        if self.scene == "chute":
            self.g = CHUTE["g"] if mu_ratio is None else mu_ratio * CHUTE["mu_s"] * CHUTE["p0"] / (CHUTE["rho"] * self.x_outer())
        self.mu_ratio = self.g * CHUTE["rho"] * self.x_outer() / CHUTE["p0"] / CHUTE["mu_s"] if self.g else None
        self.wall_ratio = self.g * CHUTE["rho"] * CHUTE["L"] / 2 / CHUTE["p0"] / CHUTE["mu_s"] if self.g else None

    def x_outer(self):
        """Distance from the chute's centre line of the outermost particle column (the largest initial shear stress)."""
        return CHUTE["L"] / 2 - 0.5 * self.h / self.ppc

    def key(self):
        return (self.model, self.scene, self.shape, self.transfer, self.stress_update, self.E, self.cells, self.ppc,
                None if self.g is None else round(self.g, 9))

    @property
    def h(self):
        if self.scene == "bar":
            return BAR["L"] / self.cells
        if self.scene == "block":
            return BLOCK["box"] / self.cells
        return CHUTE["L"] / self.cells

    def dt_cfl(self):
        """h / (c + |v|max) at t = 0, as the solver computes it (c from the P-wave modulus)."""
        h, ppc = self.h, self.ppc
        if self.scene == "bar":
            X = BAR["L"] - 0.5 * h / ppc  # outermost particle (lattice at (q + 1/2) h / ppc)
            vmax = BAR["amplitude"] * math.sin(math.pi * X / (2 * BAR["L"]))
            return h / (wave_speed(self.E, BAR["nu"], BAR["rho"]) + vmax)
        if self.scene == "block":
            r = (BLOCK["hi"] - BLOCK["lo"]) / 2 - 0.5 * h / ppc
            w, (vx, vy) = BLOCK["spin"], BLOCK["v0"]
            vmax = max(math.hypot(vx - w * sy * r, vy + w * sx * r) for sx in (-1, 1) for sy in (-1, 1))
            return h / (wave_speed(self.E, BLOCK["nu"], BLOCK["rho"]) + vmax)
        return h / wave_speed(self.E, CHUTE["nu"], CHUTE["rho"])

    def dt_plastic(self):
        """Limit of the explicit granular update, 2 eta / G with eta = b d sqrt(rho_s p0) (the chute's pressure stays ~p0)."""
        if self.scene != "chute":
            return None
        _, G = moduli(self.E, CHUTE["nu"])
        return 2.0 * CHUTE["b"] * CHUTE["d"] * math.sqrt(CHUTE["rho_s"] * CHUTE["p0"]) / G

    def gravity(self):
        return self.g

    def args(self, dt, steps=STEPS):
        h = self.h
        a = ["-material", self.model, "-E", f"{self.E:g}", "-ppc", str(self.ppc), "-shape", self.shape, "-transfer", self.transfer]
        if self.scene == "bar":
            L = BAR["L"]
            a += ["-scene", "bar", "-nu", f"{BAR['nu']:g}", "-rho", f"{BAR['rho']:g}", "-domain_lo", "0,0",
                  "-domain_hi", f"{L + 4 * h:.12g},{4 * h:.12g}", "-body_hi", f"{L:g},{4 * h:.12g}", "-cells", f"{self.cells + 4},4",
                  "-bc_xlo", "sticky", "-bc_xhi", "free", "-bc_ylo", "periodic", "-bc_yhi", "periodic", "-gravity", "0,0",
                  "-gravity_ramp", "0", "-bar_amplitude", f"{BAR['amplitude']:g}"]
        elif self.scene == "block":
            B = BLOCK
            a += ["-scene", "block", "-nu", f"{B['nu']:g}", "-rho", f"{B['rho']:g}", "-domain_lo", "0,0",
                  "-domain_hi", f"{B['box']:g},{B['box']:g}", "-cells", f"{self.cells},{self.cells}", "-body_lo", f"{B['lo']:g},{B['lo']:g}",
                  "-body_hi", f"{B['hi']:g},{B['hi']:g}", "-bc_xlo", "periodic", "-bc_xhi", "periodic", "-bc_ylo", "periodic",
                  "-bc_yhi", "periodic", "-velocity", f"{B['v0'][0]:g},{B['v0'][1]:g}", "-spin", f"{B['spin']:g}", "-p0", "0",
                  "-gravity", "0,0", "-gravity_ramp", "0"]
        else:
            a += ["-scene", "chute", "-domain_lo", "-0.5,0", "-domain_hi", f"0.5,{4 * h:.12g}", "-cells", f"{self.cells},4",
                  "-chute_prestress", "-gravity_ramp", "0", "-gravity", f"0,-{self.gravity():.12g}", "-stress_update", self.stress_update]
        if dt is None:  # the solver's automatic step (default -cfl 0.5), at most `steps` steps
            a += ["-max_steps", str(steps), "-t_end", f"{steps * 0.5 * self.dt_cfl():.12g}"]
        else:
            a += ["-dt", f"{dt:.12g}", "-max_steps", str(steps), "-t_end", f"{steps * dt:.12g}"]
        a += ["-output_final", "0", "-progress_interval", "1"]
        return a


def build_cases(quick):
    """(case, factors) pairs: one-at-a-time sweeps around each scene's base point, duplicates removed."""
    F, FX = (QUICK_FACTORS, QUICK_EXPLICIT_FACTORS) if quick else (FACTORS, EXPLICIT_FACTORS)
    out = {}

    def add(case, factors):
        k = case.key()
        if k in out:
            out[k] = (out[k][0], sorted(set(out[k][1]) | set(factors)))
        else:
            out[k] = (case, list(factors))

    for model in MODELS:
        for shape in SHAPES:
            if quick:
                add(Case(model, shape), F)
                if model in GRANULAR:
                    add(Case(model, shape, stress_update="explicit"), FX)
                continue
            for E in E_VALUES:
                add(Case(model, shape, E=E), F)
            for n in CELLS:
                add(Case(model, shape, cells=n), F)
            for p in PPCS:
                add(Case(model, shape, ppc=p), F)
            for t in TRANSFERS:
                add(Case(model, shape, transfer=t), F)
            if model in GRANULAR:
                for mr in MU_RATIOS:
                    add(Case(model, shape, mu_ratio=mr), F)
                for E in E_VALUES:
                    add(Case(model, shape, E=E, stress_update="explicit"), FX)
                for n in CELLS:
                    add(Case(model, shape, cells=n, stress_update="explicit"), FX)
            else:
                for t in TRANSFERS:
                    add(Case(model, shape, transfer=t, scene="block"), F)
                for E in E_VALUES:
                    add(Case(model, shape, E=E, scene="block"), F)
    if quick:
        for shape in SHAPES:
            add(Case("hypoelastic", shape, scene="block"), F)
    return list(out.values())


# --------------------------------------------------------------------------------------
# Running and classifying


def classify_error(text):
    """(outcome, message) of a run that stopped with an error."""
    line = next((l.strip() for l in text.splitlines() if l.startswith("granmpm: error:")), "")
    if not line:
        line = C.error_line(text)
    m = line.replace("granmpm: error: ", "")
    if "exceeds the CFL stability limit" in m:
        return "refused-cfl", m
    if "of the explicit granular stress update" in m:
        return "refused-plastic", m
    if "exceed the CFL limit" in m:
        return "refused-cfl-runtime", m
    if "non-finite" in m or "not finite" in m:
        return "nan", m
    if "kinetic energy reached" in m:
        return "energy", m
    if "cells in one step" in m:
        return "runaway", m
    if "left the domain" in m:
        return "left", m
    if "fluidity solve did not converge" in m:
        return "ksp", m
    return "error", m


def progress(text):
    """[(step, t, dt, KE)] from the progress lines (-progress_interval 1)."""
    return [(int(m.group(1)), float(m.group(2)), float(m.group(3)), float(m.group(4))) for m in RE_PROGRESS.finditer(text)]


def bar_energy(out_dir):
    """(max growth, loss at end) of kinetic + strain energy relative to t = 0, from the solver's bar.csv."""
    try:
        rows = C.read_csv(os.path.join(out_dir, "bar.csv"))
    except OSError:
        return None, None
    tot = [r["total"] for r in rows if isinstance(r.get("total"), float)]
    if not tot or tot[0] <= 0:
        return None, None
    return max(tot) / tot[0] - 1.0, 1.0 - tot[-1] / tot[0]


def block_ke0(case):
    """Initial kinetic energy of the block (per unit depth) from its lattice of particles."""
    B, h, ppc = BLOCK, case.h, case.ppc
    n = int(round((B["hi"] - B["lo"]) / h)) * ppc
    c = 0.5 * (B["lo"] + B["hi"])
    m = B["rho"] * (h / ppc) ** 2
    ke = 0.0
    for i in range(n):
        x = B["lo"] + (i + 0.5) * h / ppc - c
        for j in range(n):
            y = B["lo"] + (j + 0.5) * h / ppc - c
            vx, vy = B["v0"][0] - B["spin"] * y, B["v0"][1] + B["spin"] * x
            ke += 0.5 * m * (vx * vx + vy * vy)
    return ke


def one_run(case, factor, timeout):
    """One run at dt = factor * dt_CFL, or (factor None) with the solver's automatic step (-cfl 0.5)."""
    dt_cfl = case.dt_cfl()
    if factor is None:
        dt = None
    else:
        dt = factor * dt_cfl
        if factor == 1.0:
            dt *= 1 - 1e-9  # stay on the accepted side of round-off at exactly the limit
    args = case.args(dt)
    row = {"model": case.model, "scene": case.scene, "shape": case.shape, "transfer": case.transfer, "stress_update": case.stress_update,
           "E": case.E, "cells": case.cells, "h": case.h, "ppc": case.ppc, "gravity": case.g, "mu_ratio": case.mu_ratio,
           "wall_ratio": case.wall_ratio, "factor": factor, "dt": dt,
           "dt_mode": "auto" if factor is None else "fixed",
           "dt_cfl": dt_cfl, "dt_plastic": case.dt_plastic() if case.stress_update == "explicit" else None, "steps_target": STEPS}
    t0 = time.monotonic()
    r = C.run_granmpm(args, timeout=timeout, keep_dir=True)
    guard = None
    if r["ok"]:
        guard = "accepted"
    elif r["rc"] == "timeout":
        guard = "timeout"
    else:
        guard, msg = classify_error(r["output"])
        if guard == "refused-plastic":
            m = RE_PLASTIC.search(msg)
            if m:
                row["dt_plastic_solver"] = float(m.group(1))
        if guard.startswith("refused"):
            shutil.rmtree(r["dir"], ignore_errors=True)
            r = C.run_granmpm(args + ["-dt_allow_unstable"], timeout=timeout, keep_dir=True)
    row["guard"] = guard
    row["cmd"] = r["cmd"]
    text = r["output"]
    if "cfl_limit" in r:
        row["dt_cfl_printed"] = r["cfl_limit"]
    prog = progress(text)
    row["completed_steps"] = prog[-1][0] if prog else 0
    row["series"] = [(t, ke) for (_, t, _, ke) in prog]
    if factor is None and prog:
        row["dt"] = min(d for (_, _, d, _) in prog)  # the smallest automatic step taken
        row["auto_dt_min_factor"] = row["dt"] / dt_cfl
    if r["ok"]:
        outcome = "stable"
        if case.scene == "bar":
            g, l = bar_energy(r["dir"])
            row["energy_growth"], row["energy_loss"] = g, l
            if g is None or g > GROWTH_TOL:
                outcome = "growth"
        elif case.scene == "block":
            ke0 = block_ke0(case)
            kes = [ke for (_, ke) in row["series"]]
            if kes:
                row["energy_growth"] = max(kes) / ke0 - 1.0
                row["energy_loss"] = 1.0 - kes[-1] / ke0
                if row["energy_growth"] > GROWTH_TOL:
                    outcome = "growth"
        row["outcome"] = outcome
        if outcome == "growth":
            row["message"] = f"ran all {STEPS} steps but the energy grew by {100 * (row.get('energy_growth') or float('nan')):.0f}%"
    elif r["rc"] == "timeout":
        row["outcome"] = "timeout"
        row["message"] = f"no result within {timeout:g} s"
    else:
        outcome, msg = classify_error(text)
        row["outcome"] = outcome
        row["message"] = msg
        row["fail_step"] = row["completed_steps"] + 1
        m = RE_AT_T.search(msg)
        row["fail_time"] = float(m.group(1)) if m else (prog[-1][1] if prog else 0.0)
    # The largest particle speed is not printed; the kinetic-energy guard names the fastest particle.
    m = re.search(r"with speed (" + C._FLOAT + ") m/s", row.get("message", "") or "")
    if m:
        row["max_speed"] = float(m.group(1))
    row["wall_s"] = time.monotonic() - t0
    shutil.rmtree(r["dir"], ignore_errors=True)
    return row


def ke_at(series, t):
    """Kinetic energy at time t by linear interpolation of [(t, KE)] (None outside the series)."""
    if not series or t > series[-1][0] * (1 + 1e-9):
        return None
    prev = (0.0, 0.0)
    for (ti, ke) in series:
        if ti >= t * (1 - 1e-12):
            if ti == prev[0]:
                return ke
            return prev[1] + (ke - prev[1]) * (t - prev[0]) / (ti - prev[0])
        prev = (ti, ke)
    return series[-1][1]


def chute_reference_check(rows):
    """Compare each completed chute run with the smallest completed step of its configuration, at that run's end time."""
    groups = {}
    for r in rows:
        if r["scene"] == "chute":
            groups.setdefault(config_key(r), []).append(r)
    for rs in groups.values():
        done = sorted([r for r in rs if r["outcome"] == "stable" and r["factor"] is not None], key=lambda r: r["factor"])
        if not done:
            continue
        ref = done[0]
        tc = ref["series"][-1][0] if ref["series"] else None
        ke_ref = ke_at(ref["series"], tc) if tc else None
        # A chute that does not flow (no particle above mu_s p) keeps round-off kinetic energy (~1e-34 J): no comparison.
        floor = KE_FLOOR * CHUTE["rho"] * CHUTE["L"] * 4 * ref["h"] * ref["gravity"] * CHUTE["L"]
        if not ke_ref or ke_ref < floor:
            continue
        for r in [r for r in rs if r["outcome"] == "stable"]:  # fixed steps and the automatic step
            ke = ke_at(r["series"], tc)
            if ke is None:
                continue
            r["ke_ratio_ref"] = ke / ke_ref
            # PIC's numerical dissipation grows as the step shrinks (more transfers per unit time): its smallest step
            # is not the most accurate, so PIC runs are not classified by this comparison (the ratio is still recorded).
            if r["transfer"] != "pic" and not (1.0 / CHUTE_KE_TOL <= r["ke_ratio_ref"] <= CHUTE_KE_TOL):
                r["outcome"] = "deviates"
                r["message"] = (f"kinetic energy at t = {tc:.4g} s is {r['ke_ratio_ref']:.3g} times that of the f = {ref['factor']:g} run")


def config_key(r):
    return (r["model"], r["scene"], r["shape"], r["transfer"], r["stress_update"], float(r["E"]), int(r["cells"]), int(r["ppc"]),
            None if r.get("gravity") in (None, "") else round(float(r["gravity"]), 9))


def run_all(cases, jobs, timeout):
    tasks = [(c, f) for (c, fs) in cases for f in list(fs) + [None]]
    n = len(tasks)
    print(f"# stability: {n} configurations x factors on {jobs} job(s), {STEPS} steps each", file=sys.stderr, flush=True)
    rows = []
    t0 = time.monotonic()
    with concurrent.futures.ThreadPoolExecutor(max_workers=jobs) as ex:
        futs = {ex.submit(one_run, c, f, timeout): (c, f) for (c, f) in tasks}
        for i, fut in enumerate(concurrent.futures.as_completed(futs), 1):
            c, f = futs[fut]
            row = fut.result()
            rows.append(row)
            extra = "" if row["outcome"] == "stable" else f" ({(row.get('message') or '')[:90]})"
            print(f"# [{i}/{n} {time.monotonic() - t0:.0f} s] {c.model} {c.scene} {c.shape} {c.transfer} {c.stress_update} E {c.E:g} "
                  f"cells {c.cells} ppc {c.ppc}{'' if c.mu_ratio is None else f' mu/mu_s {c.mu_ratio:.3g}'} {'auto dt' if f is None else f'f {f:g}'}: "
                  f"guard {row['guard']}, "
                  f"{row['outcome']}{extra}", file=sys.stderr, flush=True)
    for r in rows:
        p = r.get("dt_cfl_printed")
        if p and abs(p / r["dt_cfl"] - 1) > 1e-4:
            print(f"# warning: CFL limit printed {p:g} differs from the computed {r['dt_cfl']:g} ({r['cmd']})", file=sys.stderr)
    chute_reference_check(rows)
    order = {k: i for i, k in enumerate(MODELS)}
    rows.sort(key=lambda r: (order[r["model"]], r["scene"], SHAPES.index(r["shape"]), r["stress_update"], r["transfer"], r["E"], r["cells"],
                             r["ppc"], r.get("mu_ratio") or 0, -1 if r["factor"] is None else r["factor"]))
    return rows, time.monotonic() - t0


# --------------------------------------------------------------------------------------
# Summaries


def largest_stable(rows):
    """Largest factor f such that every run with factor <= f is stable (None if the smallest is not), and the
    smallest unstable factor."""
    rs = sorted(rows, key=lambda r: r["factor"])
    best = None
    for r in rs:
        if r["outcome"] == "stable":
            best = r["factor"]
        else:
            break
    first_bad = next((r["factor"] for r in rs if r["outcome"] in UNSTABLE), None)
    return best, first_bad


def base_value(scene, key):
    return {"bar": BAR, "block": BLOCK, "chute": CHUTE}[scene][key]


def select(rows, model, scene, shape, stress_update="implicit", vary=None, transfer="apic", auto=False):
    """Rows of one sweep: everything at the scene's base point except `vary` (and the factor)."""
    out = []
    for r in rows:
        if (r["model"], r["scene"], r["shape"], r["stress_update"]) != (model, scene, shape, stress_update):
            continue
        if (r["dt_mode"] == "auto") != auto:
            continue
        ok = True
        if vary != "transfer" and r["transfer"] != transfer:
            ok = False
        for k in ("E", "cells", "ppc"):
            if vary != k and float(r[k]) != float(base_value(scene, k)):
                ok = False
        if scene == "chute" and vary != "mu_ratio" and abs(float(r["gravity"]) - CHUTE["g"]) > 1e-9:
            ok = False
        if ok:
            out.append(r)
    return out


def summary_table(rows):
    """[(model, scene, shape, transfer, stress_update, largest stable f, first unstable f, how it failed)] at each base point."""
    table = []
    for model in MODELS:
        scenes = ["chute"] if model in GRANULAR else ["bar", "block"]
        for scene in scenes:
            for su in (["implicit", "explicit"] if model in GRANULAR else ["implicit"]):
                for shape in SHAPES:
                    for tr in TRANSFERS:
                        rs = select(rows, model, scene, shape, su, transfer=tr)
                        if not rs:
                            continue
                        best, bad = largest_stable(rs)
                        how = next((r["outcome"] for r in sorted(rs, key=lambda r: r["factor"]) if r["factor"] == bad), None)
                        table.append((model, scene, shape, tr, su, best, bad, how))
    return table


# --------------------------------------------------------------------------------------
# Figures


def plot_panel(ax, rows, vary, xvals, xlabel, plastic=None, log_x=False, xticklabels=None):
    seen = set()
    for r in rows:
        x = r[vary]
        if isinstance(x, str):
            x = xvals.index(x)
        st = OUTCOME_STYLE.get(r["outcome"], OUTCOME_STYLE["error"])
        face = "none" if str(r.get("guard", "")).startswith("refused") else st[1]
        ax.plot([x], [r["factor"]], marker=st[0], color=st[1], markerfacecolor=face, markersize=8, linestyle="none")
        seen.add(r["outcome"])
    ax.axhline(1.0, color="k", linewidth=1.2, label="CFL limit h/(c+|v|)")
    ax.axhline(0.5, color="k", linewidth=0.8, linestyle=":", label="default -cfl 0.5")
    if plastic:
        xs, ys = plastic[0], plastic[1]
        if len(plastic) > 2:
            ax.plot(xs, ys, color="grey", linewidth=1.0, linestyle="--", label=plastic[2])
        else:
            ax.plot(xs, ys, color="tab:red", linewidth=1.2, linestyle="--", label="plastic limit G dt/eta = 2")
    ax.set_yscale("log", base=2)
    ax.set_yticks([0.0625, 0.125, 0.25, 0.5, 1, 2, 4])
    ax.set_yticklabels(["1/16", "1/8", "1/4", "1/2", "1", "2", "4"])
    ax.set_ylim(0.05 if plastic else 0.2, 5)
    if log_x:
        ax.set_xscale("log")
    if xticklabels:
        ax.set_xticks(range(len(xticklabels)))
        ax.set_xticklabels(xticklabels)
        ax.set_xlim(-0.5, len(xticklabels) - 0.5)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("dt / dt_CFL")
    ax.grid(True, which="major", alpha=0.3)
    return seen


def plastic_curve(vary, case_kw, xs):
    ys = []
    for x in xs:
        kw = dict(case_kw)
        kw[vary] = x
        c = Case(**kw)
        ys.append(c.dt_plastic() / c.dt_cfl())
    return xs, ys


def plot_model_shape(rows, model, shape, path):
    plt = C.pyplot()
    if plt is None:
        return
    granular = model in GRANULAR
    if granular:
        panels = [("E", "implicit", "chute"), ("cells", "implicit", "chute"), ("ppc", "implicit", "chute"), ("transfer", "implicit", "chute"),
                  ("mu_ratio", "implicit", "chute"), ("E", "explicit", "chute"), ("cells", "explicit", "chute")]
    else:
        panels = [("E", "implicit", "bar"), ("cells", "implicit", "bar"), ("ppc", "implicit", "bar"), ("transfer", "implicit", "bar"),
                  ("E", "implicit", "block"), ("transfer", "implicit", "block")]
    ncol = 4 if granular else 3
    nrow = math.ceil(len(panels) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.3 * ncol, 4.0 * nrow + 0.8), squeeze=False)
    seen = set()
    labels = {"E": "E [Pa]", "cells": "cells (along the bar / across the chute)", "ppc": "particles per cell per direction",
              "transfer": "transfer", "mu_ratio": "tau / (mu_s p) of the outermost particles at t = 0"}
    for i, (vary, su, scene) in enumerate(panels):
        ax = axes[i // ncol][i % ncol]
        rs = select(rows, model, scene, shape, su, vary=vary)
        if not rs:
            ax.set_visible(False)
            continue
        plastic = None
        if vary in ("E", "cells") and (su == "explicit" or (model == "nonlocal" and vary == "E")):
            if vary == "E":
                xs = [10 ** (5 + k / 10) for k in range(41)]
            else:
                xs = sorted({r["cells"] for r in rs})
                xs = [xs[0] * (xs[-1] / xs[0]) ** (k / 20) for k in range(21)]
            plastic = plastic_curve(vary, dict(model=model, shape=shape, stress_update="explicit"), xs)
            if su != "explicit":
                plastic = plastic + ("G dt/eta = 2 (limit of the explicit update; reference)",)
        if vary == "transfer":
            seen |= plot_panel(ax, rs, "transfer", TRANSFERS, labels[vary], xticklabels=TRANSFERS)
        else:
            seen |= plot_panel(ax, rs, vary, None, labels[vary], plastic=plastic, log_x=vary in ("E", "cells", "ppc", "mu_ratio"))
            vals = sorted({r[vary] for r in rs})
            if vary in ("cells", "ppc", "mu_ratio"):
                ax.set_xticks(vals)
                ax.set_xticklabels([f"{v:.3g}" for v in vals])
                ax.minorticks_off()
            if vary in ("cells", "ppc"):
                ax.set_xlim(vals[0] / 1.4, vals[-1] * 1.4)
        title = f"{scene}" + (f", {su} stress update" if granular else "") + f": dt vs {vary}"
        ax.set_title(title, fontsize=9)
    for j in range(len(panels), nrow * ncol):
        axes[j // ncol][j % ncol].set_visible(False)
    from matplotlib.lines import Line2D

    handles, labs = [], []
    for k, (mk, col, lb) in OUTCOME_STYLE.items():
        if k in seen:
            handles.append(Line2D([], [], marker=mk, color=col, linestyle="none", markersize=8))
            labs.append(lb)
    handles.append(Line2D([], [], marker="o", color="k", markerfacecolor="none", linestyle="none", markersize=8))
    labs.append("open marker: refused without -dt_allow_unstable, outcome with it")
    for ax in axes.flat:
        for hd, lb in zip(*ax.get_legend_handles_labels()):
            if lb not in labs:
                handles.append(hd)
                labs.append(lb)
    fig.legend(handles, labs, loc="lower center", ncol=4, fontsize=8, frameon=False)
    base = (f"bar base E {BAR['E']:g}, {BAR['cells']} cells, {BAR['ppc']} PPC, APIC" if not granular else
            f"chute base E {CHUTE['E']:g}, {CHUTE['cells']} cells, {CHUTE['ppc']} PPC, APIC, wall friction 1.75 mu_s")
    fig.suptitle(f"Stability map: {model}, {shape} shape functions ({STEPS} fixed steps; {base})", fontsize=10)
    fig.tight_layout(rect=(0, 0.07 if nrow > 1 else 0.12, 1, 0.96))
    C.save_figure(fig, path)
    plt.close(fig)


def plot_summary(table, path):
    plt = C.pyplot()
    if plt is None:
        return
    import numpy as np

    rowsets = []
    for model in MODELS:
        for scene in (["chute"] if model in GRANULAR else ["bar", "block"]):
            for su in (["implicit", "explicit"] if model in GRANULAR else ["implicit"]):
                rowsets.append((model, scene, su))
    cols = [(s, t) for s in SHAPES for t in TRANSFERS]
    M = np.full((len(rowsets), len(cols)), np.nan)
    lookup = {(m, sc, sh, tr, su): best for (m, sc, sh, tr, su, best, bad, how) in table}
    for i, (m, sc, su) in enumerate(rowsets):
        for j, (sh, tr) in enumerate(cols):
            v = lookup.get((m, sc, sh, tr, su), "missing")
            if v == "missing":
                continue
            M[i, j] = v if v is not None else 0.0
    fig, ax = plt.subplots(figsize=(10, 0.55 * len(rowsets) + 2))
    import matplotlib

    cmap = matplotlib.colormaps["RdYlGn"].copy()
    cmap.set_bad("lightgrey")
    with np.errstate(invalid="ignore", divide="ignore"):
        L = np.ma.masked_invalid(np.log2(np.where(M > 0, M, 2.0 ** -5)))
    L = np.ma.masked_where(np.isnan(M), L)
    im = ax.imshow(L, cmap=cmap, vmin=-3, vmax=2, aspect="auto")
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            v = M[i, j]
            low = min(EXPLICIT_FACTORS if rowsets[i][2] == "explicit" else FACTORS)
            ax.text(j, i, "not run" if np.isnan(v) else (f"< {low:g}" if v == 0 else f"{v:g}"), ha="center", va="center", fontsize=8)
    ax.set_xticks(range(len(cols)))
    ax.set_xticklabels([f"{s}\n{t}" for s, t in cols], fontsize=8)
    ax.set_yticks(range(len(rowsets)))
    ax.set_yticklabels([f"{m} ({sc}{', explicit' if su == 'explicit' else ''})" for m, sc, su in rowsets], fontsize=8)
    cb = fig.colorbar(im, ax=ax)
    cb.set_label("log2 of the largest stable dt / dt_CFL")
    ax.set_title(f"Largest dt / dt_CFL with every smaller tested step stable (base points, {STEPS} steps)", fontsize=10)
    fig.tight_layout()
    C.save_figure(fig, path)
    plt.close(fig)


# --------------------------------------------------------------------------------------
# Docs


def ffac(r):
    return "auto" if r["factor"] is None else f"{r['factor']:g}"


def fmt_f(v):
    return "none" if v is None else f"{v:g}"


def write_docs(rows, table, meta, wall):
    parts = []
    parts.append(
        f"Produced by `bench/stability.py` ({meta['binary']}, {meta['date']}; {meta.get('load', '')}), {len(rows)} runs, "
        f"1 MPI rank each, {meta.get('jobs', 1)} at a time; full sweep {wall / 60:.0f} min wall. "
        f"Every run takes {STEPS} fixed steps (`-dt f*dt_CFL -max_steps {STEPS} -t_end {STEPS}*dt`), "
        "dt_CFL = h/(c + |v|max at t = 0) with c = sqrt((K + 4G/3)/rho) computed by the script (it agrees with the "
        "solver's `CFL limit` line to 5 digits). The guard column is the run without `-dt_allow_unstable`; when that was "
        "refused, the outcome is from the same run with `-dt_allow_unstable`.\n")
    ex = {}
    for r in rows:
        ex.setdefault((r["scene"], r["stress_update"]), r)
    parts.append("Example commands (one per scene; the sweep changes -E, -cells, -ppc, -shape, -transfer, -gravity, -dt):\n\n```")
    for k in sorted(ex):
        r = ex[k]
        parts.append(r["cmd"].replace("-output_dir D", "-output_dir D") + ("" if "-dt_allow_unstable" in r["cmd"] else " [-dt_allow_unstable]"))
    parts.append("```\n")
    tab = []
    for (m, sc, sh, tr, su, best, bad, how) in table:
        tab.append([m, sc + (" (explicit)" if su == "explicit" else ""), sh, tr, fmt_f(best), fmt_f(bad), how or "-"])
    parts.append("Largest stable dt/dt_CFL at each base point: the largest tested factor f such that every tested factor up to f "
                 "ran stably (`none`: even f = " + f"{min(FACTORS):g}" + " (explicit: " + f"{min(EXPLICIT_FACTORS):g}" +
                 ") was unstable), and the smallest unstable factor with how it failed:\n")
    parts.append(C.md_table(["model", "scene", "shape", "transfer", "largest stable f", "first unstable f", "failure"], tab,
                            ["l", "l", "l", "l", "r", "r", "l"]))
    # Per-sweep summaries.
    parts.append("\nLargest stable f along each sweep (APIC unless the transfer is varied; other parameters at the base point):\n")
    sweep_rows = []
    for model in MODELS:
        sweeps = []
        if model in GRANULAR:
            sweeps = [("chute", "implicit", v) for v in ("E", "cells", "ppc", "mu_ratio")] + [("chute", "explicit", v) for v in ("E", "cells")]
        else:
            sweeps = [("bar", "implicit", v) for v in ("E", "cells", "ppc")] + [("block", "implicit", "E")]
        for (scene, su, vary) in sweeps:
            for shape in SHAPES:
                if True:
                    rs = select(rows, model, scene, shape, su, vary=vary)
                    vals = sorted({r[vary] for r in rs})
                    if len(vals) < 2:
                        continue
                    cells = []
                    for v in vals:
                        best, bad = largest_stable([r for r in rs if r[vary] == v])
                        cells.append(f"{v:.3g}: {fmt_f(best)}")
                    sweep_rows.append([model, scene + (" (explicit)" if su == "explicit" else ""), shape, vary, "; ".join(cells)])
    parts.append(C.md_table(["model", "scene", "shape", "varied", "value: largest stable f"], sweep_rows, ["l", "l", "l", "l", "l"]))
    # Guard summary.
    n_ref = sum(1 for r in rows if r["guard"] == "refused-cfl")
    n_ref_rt = sum(1 for r in rows if r["guard"] == "refused-cfl-runtime" and r["dt_mode"] == "fixed")
    n_pl = sum(1 for r in rows if r["guard"] == "refused-plastic")
    fixed = [r for r in rows if r["dt_mode"] == "fixed"]
    above = [r for r in fixed if r["factor"] > 1.0]
    parts.append(f"\nGuards without `-dt_allow_unstable`: {n_ref} of the {len(above)} runs above the CFL limit were refused at set-up "
                 f"({sum(1 for r in above if r['guard'] != 'refused-cfl')} were not); {n_ref_rt} runs at or below it were stopped later "
                 f"because |v|max grew (`refused-cfl-runtime`); {n_pl} explicit granular runs were stopped by the plastic-limit check.\n")
    silent = [r for r in rows if r["outcome"] in ("growth", "deviates")]
    silent_default = [r for r in silent if r["guard"] == "accepted"]
    low = [r for r in fixed if r["outcome"] in UNSTABLE and r["factor"] <= 0.5]
    auto = [r for r in rows if r["dt_mode"] == "auto"]
    auto_bad = [r for r in auto if r["outcome"] != "stable"]
    parts.append(f"Runs that reached the end although unstable (`growth` or `deviates`, no error from the solver): {len(silent)}, "
                 f"of which {len(silent_default)} also without `-dt_allow_unstable`. "
                 f"Runs unstable at or below f = 0.5: {len(low)}. "
                 f"Default automatic step (`-cfl 0.5`, no `-dt`, {STEPS} steps) in each of the {len(auto)} configurations: "
                 f"{len(auto) - len(auto_bad)} stable, {len(auto_bad)} not.\n")
    for title, rs in (("Completed but unstable (no error)", silent), ("Unstable at f <= 0.5", low),
                      ("Not stable with the default automatic step", auto_bad)):
        if not rs:
            continue
        parts.append(f"{title}:\n")
        parts.append(C.md_table(["model", "scene", "shape", "transfer", "update", "E", "cells", "PPC", "f", "guard", "outcome", "step", "message"],
                                [[r["model"], r["scene"], r["shape"], r["transfer"], r["stress_update"], f"{r['E']:g}", r["cells"], r["ppc"],
                                  ffac(r), r["guard"], r["outcome"], r.get("fail_step") or "-", (r.get("message") or "")[:160]] for r in rs[:60]],
                                ["l"] * 5 + ["r"] * 4 + ["l", "l", "r", "l"]))
        if len(rs) > 60:
            parts.append(f"\n({len(rs) - 60} more in `bench/results/stability.csv`)")
        parts.append("")
    figs = "\n".join(f"![{m} {s}](figures/stability_{m}_{s}.png)" for m in MODELS for s in SHAPES)
    parts.append("Figures (one per model and shape; marker = outcome; filled = ran as given, open = refused without "
                 "`-dt_allow_unstable` and then run with it; solid line CFL = 1, dotted line the default -cfl 0.5, dashed "
                 "red the plastic limit of the explicit granular update):\n\n![summary](figures/stability_summary.png)\n\n" + figs)
    C.replace_doc_section("stability.md", "stability", "Results (generated)", "\n".join(parts), "GranMPM stability stress tests")


# --------------------------------------------------------------------------------------


def main():
    ap = C.common_argparser(__doc__.split("\n")[0])
    ap.add_argument("--jobs", type=int, default=int(os.environ.get("STABILITY_JOBS", "2")),
                    help="runs at a time (default 2, or $STABILITY_JOBS; each run is 1 rank and mostly waits on start-up)")
    ap.add_argument("--timeout", type=float, default=300, help="per-run timeout [s]")
    a = ap.parse_args()
    csv_path, _ = C.output_paths(NAME, a.quick)
    fig_dir = os.path.dirname(csv_path) if a.quick else C.FIGURES_DIR
    series_path = os.path.splitext(csv_path)[0] + "_series.csv"
    if a.replot:
        rows = C.read_csv(csv_path, strings=("transfer",))
        meta = C.read_meta(csv_path)
        wall = float(meta.get("wall_s", 0))
    else:
        binary = C.granmpm_binary()
        cases = build_cases(a.quick)
        la = C.loadavg()
        rows, wall = run_all(cases, a.jobs, a.timeout)
        seen = set()
        for r in rows:
            r["message"] = (r.get("message") or "").replace("\n", " ")
            # The full command only for the first run of each scene (the docs' examples); the
            # others differ in the columns above, and 2900 command lines would double the CSV.
            key = (r["scene"], r["stress_update"])
            if key in seen:
                r["cmd"] = ""
            seen.add(key)
        C.write_csv(csv_path, COLUMNS + ["cmd"], rows)
        meta = C.write_meta(csv_path, binary, jobs=a.jobs, wall_s=round(wall, 1),
                            load=f"1-minute load average {la:.1f} at the start, {C.loadavg():.1f} at the end")
        print(f"# stability: {len(rows)} runs in {wall:.0f} s", file=sys.stderr)
    table = summary_table(rows)
    for m in MODELS:
        for s in SHAPES:
            plot_model_shape(rows, m, s, os.path.join(fig_dir, f"stability_{m}_{s}.png"))
    plot_summary(table, os.path.join(fig_dir, "stability_summary.png"))
    print("# largest stable dt/dt_CFL (base points):", file=sys.stderr)
    for t in table:
        print(f"#   {t[0]:12s} {t[1]:6s} {t[2]:9s} {t[3]:5s} {t[4]:9s} largest stable {fmt_f(t[5]):>6s}  first unstable {fmt_f(t[6]):>6s} ({t[7]})",
              file=sys.stderr)
    if not (a.quick or a.no_docs):
        write_docs(rows, table, meta, wall)
    return 0


if __name__ == "__main__":
    sys.exit(main())
