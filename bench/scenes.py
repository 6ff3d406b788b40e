#!/usr/bin/env python3
"""Free-surface scenes and the cost of the dynamical fluidity (issue 4).

collapse  Granular column collapse, 2D plane strain, a = H0/L0 in 0.5, 1, 2, 4, 8 at h = L0/20 (the
          parameters of examples/collapse.opts: local mu(I), mu_s = 0.3, d = 1 mm, rho_c = 0.9 rho, sticky
          floor, slip back wall, geostatic start, t_end = 6 sqrt(H0/g)); the runout (L_f - L0)/L0 against the
          2D laws of Lube et al. (2005). Also a = 2 in the 3D quasi-2D slot (examples/collapse_3d.opts,
          h = L0/10) beside the 2D run at the same h.
silo      2D silo (examples/silo.opts), orifice D in 0.04 ... 0.12 m: discharge rate W (slope of the discharged
          mass over the middle 60% of the discharge) against D; fit W = C (D - k)^n (free n, and n = 3/2 as in
          the 2D Beverloo law) by least squares in log W over a grid of k.
ngf_cost  Throughput of the dynamical nonlocal fluidity (implicit and explicit grid step) and of the steady
          nonlocal model against local mu(I) on the same 3D scene (3D vertical chute from the steady state,
          40 x 8 x 8 cells, 2 particles per cell per direction, fixed dt, 200 steps), median of repeats.
taylor_couette  (issue 20) seed 004's Taylor-Couette cell (examples/taylor_couette_3d_{local,nonlocal,dynamic}.opts,
          Omega 0.25 rad/s) at h = 10 mm and t = 0.3/0.59/1.19 s, h = 20/10/5 mm on shorter windows: top-surface
          omega/Omega against (r - Ri)/d, decay length; profiles kept in bench/results/taylor_couette_<case>.csv
          (a case whose CSV exists is not rerun), figure docs/figures/taylor_couette_seed004.png.
excavation  (issue 20) examples/excavation_3d.opts, relaxed modulus, dynamical model and its local limit A = 0 (and
          the full modulus to 0.3 s): blade forces against time, side-wall particles at t = 1 s.
wheel     (issue 20) examples/wheel_3d.opts at h = 6.67 mm, slip 0.2/0.4/0.7: drawbar pull, load, sinkage.

Writes bench/results/collapse.csv, silo.csv, ngf_cost.csv, figures docs/figures/collapse.png, silo.png and a
section of docs/scenes.md (with --quick: fewer cases, bench/results/quick/, docs untouched).
"""

import math
import os
import sys

import _common as C

G = 9.81
L0 = 0.2
MATERIAL = ["-material", "mu_i", "-mu_s", "0.3", "-b", "18.754", "-d", "1e-3", "-rho_s", "2450", "-rho", "1500", "-rho_c", "1350",
            "-E", "1e6", "-nu", "0.3", "-ppc", "2", "-shape", "gimp", "-transfer", "apic", "-gravity_ramp", "0", "-geostatic", "-p0", "0",
            "-progress_interval", "0", "-output_final", "0"]


def lube(a):
    lo, hi = 1.2 * a, 1.9 * a ** (2.0 / 3.0)
    return lo if a <= 1.8 else (hi if a >= 2.8 else lo + (hi - lo) * (a - 1.8))


def collapse_args(a, h, dim=2):
    H0 = a * L0
    W = round((L0 * (1 + 1.3 * max(1.2 * a, 1.9 * a ** (2 / 3))) + 0.1) / h) * h
    Ht = round((1.1 * H0 + 0.06) / h) * h
    nx, ny = round(W / h), round(Ht / h)
    args = ["-scene", "collapse", "-bc_xlo", "slip", "-bc_xhi", "slip", "-bc_ylo", "sticky", "-bc_yhi", "free",
            "-t_end", f"{6 * math.sqrt(H0 / G):.6g}"] + MATERIAL
    if dim == 2:
        args += ["-domain_lo", "0,0", "-domain_hi", f"{W:.6g},{Ht:.6g}", "-cells", f"{nx},{ny}", "-body_hi", f"{L0},{H0:.6g}", "-gravity", f"0,-{G}"]
    else:
        Z = 4 * h
        args += ["-dim", "3", "-domain_lo", "0,0,0", "-domain_hi", f"{W:.6g},{Ht:.6g},{Z:.6g}", "-cells", f"{nx},{ny},4",
                 "-body_hi", f"{L0},{H0:.6g},{Z:.6g}", "-gravity", f"0,-{G},0", "-bc_zlo", "slip", "-bc_zhi", "slip"]
    return args


def read_summary(r, name):
    path = os.path.join(r["dir"], name)
    rows = C.read_csv(path) if os.path.exists(path) else []
    return rows[0] if rows else {}


def run_collapse(quick):
    cases = [(2, a, L0 / 20) for a in ([0.5, 2] if quick else [0.5, 1, 2, 4, 8])]
    cases += [(2, 2, L0 / 10), (3, 2, L0 / 10)]
    rows = []
    for dim, a, h in cases:
        args = collapse_args(a, h, dim)
        r = C.run_granmpm(args, keep_dir=True, label=f"collapse {dim}D a = {a}, h = L0/{round(L0 / h)}")
        s = read_summary(r, "collapse_summary.csv") if r["ok"] else {}
        rows.append(dict(dim=dim, a=a, h=h, ok=r["ok"], runout=s.get("runout"), runout_99=s.get("runout_99"), lube=lube(a),
                         rel_dev=(s["runout"] / lube(a) - 1) if s else None, final_height=s.get("final_height"), particles=r.get("particles"),
                         steps=r.get("steps"), wall_s=r.get("wall_s"), cmd=r["cmd"], message="" if r["ok"] else C.error_line(r["output"])))
        if "dir" in r:
            import shutil

            shutil.rmtree(r["dir"], ignore_errors=True)
    return rows


def fit_power(D, W, n_fixed=None):
    """Least squares in log W of W = C (D - k)^n over a grid of k in [-0.5 Dmin, 0.95 Dmin]; returns (C, k, n, rms)."""
    best = None
    Dmin = min(D)
    for i in range(400):
        k = -0.5 * Dmin + 1.45 * Dmin * i / 399
        x = [math.log(d - k) for d in D]
        y = [math.log(w) for w in W]
        m = len(x)
        if n_fixed is None:
            xb, yb = sum(x) / m, sum(y) / m
            sxx = sum((xi - xb) ** 2 for xi in x)
            n = sum((xi - xb) * (yi - yb) for xi, yi in zip(x, y)) / sxx
            lc = yb - n * xb
        else:
            n = n_fixed
            lc = sum(yi - n * xi for xi, yi in zip(x, y)) / m
        rms = math.sqrt(sum((lc + n * xi - yi) ** 2 for xi, yi in zip(x, y)) / m)
        if best is None or rms < best[3]:
            best = (math.exp(lc), k, n, rms)
    return best


def run_silo(quick):
    widths = [0.04, 0.06, 0.08, 0.10] if quick else [0.04, 0.05, 0.06, 0.08, 0.10, 0.12]
    rows = []
    for D in widths:
        args = ["-options_file", os.path.join(C.REPO_ROOT, "examples", "silo.opts"), "-silo_orifice", f"{D:g}",
                "-output_interval", "0", "-output_final", "0", "-progress_interval", "0"]
        r = C.run_granmpm(args, keep_dir=True, label=f"silo D = {D}")
        s = read_summary(r, "silo_summary.csv") if r["ok"] else {}
        series = []
        p = os.path.join(r.get("dir", ""), "silo.csv")
        if os.path.exists(p):
            series = C.read_csv(p)
        rows.append(dict(D=D, D_eff=s.get("orifice_effective"), ok=r["ok"], rate=s.get("discharge_rate"), discharged_mass=s.get("discharged_mass"),
                         discharged_particles=s.get("discharged_particles"), wall_s=r.get("wall_s"), cmd=r["cmd"],
                         message="" if r["ok"] else C.error_line(r["output"]), series=series))
        if "dir" in r:
            import shutil

            shutil.rmtree(r["dir"], ignore_errors=True)
    return rows


def run_ngf_cost(quick):
    base = ["-dim", "3", "-scene", "chute", "-cells", "40,8,8", "-domain_lo", "-0.5,0,0", "-domain_hi", "0.5,0.2,0.2", "-ppc", "2",
            "-chute_prestress", "-gravity_ramp", "0", "-dt", "2e-5", "-max_steps", "60" if quick else "200", "-t_end", "1",
            "-output_final", "0", "-progress_interval", "0"]
    models = [("mu_i", ["-material", "mu_i"]), ("nonlocal (steady)", ["-material", "nonlocal"]),
              ("dynamic, implicit step", ["-material", "dynamic", "-fluidity_step", "implicit"]),
              ("dynamic, explicit step", ["-material", "dynamic", "-fluidity_step", "explicit", "-t0", "1e-3"])]
    repeats = 1 if quick else 3
    runs = {m: [] for m, _ in models}
    for rep in range(repeats):  # interleaved, so that load changes hit every model alike
        for m, extra in models:
            r = C.run_granmpm(base + extra, label=f"ngf_cost {m} #{rep + 1}")
            runs[m].append(r)
    rows = []
    ref = C.median([r.get("rate") for r in runs["mu_i"] if r["ok"]])
    for m, extra in models:
        rates = [r.get("rate") for r in runs[m] if r["ok"]]
        med = C.median(rates)
        rows.append(dict(model=m, repeats=len(rates), rate_median=med, rate_min=min(rates) if rates else None, rate_max=max(rates) if rates else None,
                         cost_vs_mu_i=(ref / med) if rates and med == med else None, particles=runs[m][0].get("particles"), cmd=runs[m][0]["cmd"]))
    return rows


# --------------------------------------------------------------------------------------
# Taylor-Couette (seed 004 section 4.1, issue 20)

TC_OMEGA = "0.25"  # 10x the seed's 0.025 rad/s: quasi-static either way, a steady band in 1/10 of the time
TC_CASES = [  # key, model, h [mm], t_end [s]
    ("local_h10_t0.3", "local", 10, 0.3), ("local_h10", "local", 10, 0.59), ("local_h10_t1.19", "local", 10, 1.19),
    ("dynamic_h10_t0.3", "dynamic", 10, 0.3), ("dynamic_h10", "dynamic", 10, 0.59), ("nonlocal_h10", "nonlocal", 10, 0.59),
    ("dynamic_h20_t0.3", "dynamic", 20, 0.3), ("local_h20_t0.3", "local", 20, 0.3), ("nonlocal_h20", "nonlocal", 20, 0.59),
    ("local_h20_t0.1", "local", 20, 0.1), ("local_h10_t0.1", "local", 10, 0.1), ("local_h5_t0.1", "local", 5, 0.1),
]
TC_D = 0.004


def tc_args(model, h_mm, t_end):
    n = round(0.44 / (h_mm * 1e-3))
    nz = round(0.06 / (h_mm * 1e-3))
    return ["-options_file", os.path.join(C.REPO_ROOT, "examples", f"taylor_couette_3d_{model}.opts"), "-annulus_omega", TC_OMEGA,
            "-cells", f"{n},{n},{nz}", "-dt", f"{1e-4 * h_mm / 10:.3g}", "-t_end", f"{t_end:g}", "-progress_interval", "0"]


def tc_profile_path(key):
    return os.path.join(C.RESULTS_DIR, f"taylor_couette_{key}.csv")


def run_taylor_couette(only_missing=True):
    """Runs the cases whose profile is not yet in bench/results/ (1 rank each) and copies profile.csv there."""
    import shutil

    for key, model, h, t_end in TC_CASES:
        dst = tc_profile_path(key)
        if only_missing and os.path.exists(dst):
            continue
        r = C.run_granmpm(tc_args(model, h, t_end), keep_dir=True, label=f"taylor-couette {key}")
        if r["ok"]:
            shutil.copy(os.path.join(r["dir"], "profile.csv"), dst)
        shutil.rmtree(r["dir"], ignore_errors=True)


def decay_length(xi, w, lo=1e-3, hi=0.2):
    """Least-squares slope of log(omega/Omega) against (r - Ri)/d where lo < w < hi: -1/slope (in d)."""
    pts = [(x, math.log(y)) for x, y in zip(xi, w) if lo < y < hi]
    if len(pts) < 3:
        return None
    n = len(pts)
    mx = sum(p[0] for p in pts) / n
    my = sum(p[1] for p in pts) / n
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    sxy = sum((p[0] - mx) * (p[1] - my) for p in pts)
    return -sxx / sxy if sxy < 0 else None


def taylor_couette_section():
    prof = {}
    for key, model, h, t_end in TC_CASES:
        if os.path.exists(tc_profile_path(key)):
            prof[key] = C.read_csv(tc_profile_path(key))
    rows = []
    for key, model, h, t_end in TC_CASES:
        if key not in prof:
            continue
        xi = [q["xi_d"] for q in prof[key]]
        w = [q["omega_over_Omega"] for q in prof[key]]
        rows.append(dict(case=key, model=model, h_mm=h, t=t_end, decay_length_d=decay_length(xi, w), w_first=w[0], xi_first=xi[0],
                         w_at_10d=next((y for x, y in zip(xi, w) if x >= 10), None)))
    plt = C.pyplot()
    if plt and prof:
        fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
        styles = {"local": "s-", "nonlocal": "^-", "dynamic": "o-"}
        names = {"local": "MPM local mu(I)", "nonlocal": "MPM steady nonlocal", "dynamic": "MPM dynamical nonlocal (seed's)"}
        def curve(key):
            xi = [q["xi_d"] for q in prof[key]]
            w = [q["omega_over_Omega"] for q in prof[key]]
            return xi, w, [x for x, y in zip(xi, w) if y > 0], [y for y in w if y > 0]

        tstyle = {0.3: ":", 0.59: "-", 1.19: "--"}
        for key, model, h, t_end in TC_CASES:  # h = 10 mm at the three times (steadiness)
            if key not in prof or h != 10 or "t0.1" in key:
                continue
            xi, w, xp, wp = curve(key)
            st = styles[model][0] + tstyle[t_end]
            c = {"local": "C0", "nonlocal": "C2", "dynamic": "C3"}[model]
            ax[0].plot(xi, w, st, color=c, mfc="none", label=f"{names[model]}, t = {t_end} s")
            ax[1].semilogy(xp, wp, st, color=c, mfc="none", label=f"{names[model]}, t = {t_end} s")
        for key, model, h, t_end in TC_CASES:  # h -> h/2
            if key not in prof or not (t_end == 0.3 or "t0.1" in key or key == "nonlocal_h20" or key == "nonlocal_h10"):
                continue
            xi, w, xp, wp = curve(key)
            c = {"local": "C0", "nonlocal": "C2", "dynamic": "C3"}[model]
            ax[2].semilogy(xp, wp, styles[model][0] + {20: ":", 10: "-", 5: "--"}[h], color=c if t_end != 0.1 else "C7", mfc="none", label=f"{model}, h = {h} mm, t = {t_end} s")
        ax[0].set_ylabel("omega / Omega (top surface)")
        ax[1].set_ylabel("omega / Omega (log)")
        ax[2].set_ylabel("omega / Omega (log)")
        ax[1].set_ylim(1e-5, 1.5)
        ax[2].set_ylim(1e-5, 1.5)
        ax[0].set_title("seed 004 fig. 9 form: linear", fontsize=10)
        ax[1].set_title("log scale (the seed's inset)", fontsize=10)
        ax[2].set_title("h -> h/2: 20 -> 10 mm (t = 0.3, 0.59 s), 10 -> 5 mm (local, t = 0.1 s)", fontsize=9)
        for x in ax:
            x.set_xlabel("(r - Ri) / d")
            x.grid(alpha=0.3, which="both")
            x.legend(fontsize=7)
        fig.tight_layout()
        C.save_figure(fig, os.path.join(C.FIGURES_DIR, "taylor_couette_seed004.png"))
    return rows


# --------------------------------------------------------------------------------------
# Excavation and wheel (seed 004 sections 4.2-4.3, issue 20): coarse runs

def ex(name):
    return ["-options_file", os.path.join(C.REPO_ROOT, "examples", name)]


EXC_CASES = [  # key, extra options (examples/excavation_3d.opts: relaxed E 0.15 MPa, h 6.67 mm)
    ("excavation_dynamic", ["-dt", "2.5e-4"]),
    ("excavation_local", ["-dt", "2.5e-4", "-A", "0"]),
    ("excavation_full_E", ["-dt", "2.5e-5", "-E", "15e6", "-t_end", "0.3"]),
] + [  # h = 10 mm (coarse: 8.7K particles, the blade 8 mm thick is under one cell), z widened to 7 cells, y to 0.14 m (at 0.1 m the heap the blade pushes up left the top face at t = 1.7 s)
    ("excavation_h10_" + k, ["-cells", "26,14,7", "-domain_hi", "0.26,0.14,0.07", "-body_hi", "0.26,0.06,0.07"] + e)
    for k, e in [("dynamic", ["-dt", "3.5e-4"]), ("local", ["-dt", "3.5e-4", "-A", "0"]),
                 ("full_E", ["-dt", "3.5e-5", "-E", "15e6", "-t_end", "0.6"])]
]
WHEEL_SLIPS = [0.2, 0.4, 0.7]


def keep(r, src, key):
    import shutil

    if r["ok"] and os.path.exists(os.path.join(r["dir"], src)):
        shutil.copy(os.path.join(r["dir"], src), os.path.join(C.RESULTS_DIR, key))


def run_excavation(only_missing=True):
    """bodies.csv of each case into bench/results/<key>_bodies.csv; the side-wall particles at t = 1.0 s (0.5 s into
    the drag; a separate run to -t_end 1.0) into <key>_side_wall.csv."""
    import shutil

    for key, extra in EXC_CASES:
        if not (only_missing and os.path.exists(os.path.join(C.RESULTS_DIR, key + "_bodies.csv"))):
            r = C.run_granmpm(ex("excavation_3d.opts") + extra + ["-progress_interval", "0"], keep_dir=True, label=f"excavation {key}")
            keep(r, "bodies.csv", key + "_bodies.csv")
            shutil.rmtree(r.get("dir", ""), ignore_errors=True)
        if "full" in key or (only_missing and os.path.exists(os.path.join(C.RESULTS_DIR, key + "_side_wall.csv"))):
            continue
        r = C.run_granmpm(ex("excavation_3d.opts") + extra + ["-t_end", "1.0", "-progress_interval", "0"], keep_dir=True, label=f"excavation {key} to 1 s")
        keep(r, "side_wall.csv", key + "_side_wall.csv")
        shutil.rmtree(r.get("dir", ""), ignore_errors=True)


# The sweep runs at h = 6.67 mm (2x the example's), in a slice 4 cells = 26.7 mm wide: load
# 164 N x 26.7/125 = 35 N = weight of 1 kg + 25.2 N applied.
WHEEL_COARSE = ["-cells", "60,30,4", "-domain_hi", "0.4,0.2,0.0266666666666667", "-body_hi", "0.4,0.05,0.0266666666666667",
                "-body0_center", "0.12,0.2,0.0133333333333333", "-body0_mass", "1.0", "-body0_force", "0,-25.2,0"]


def wheel_args(slip):
    R, w = 0.15, 1.0
    return ex("wheel_3d.opts") + WHEEL_COARSE + ["-body0_velocity", f"{(1 - slip) * w * R:.6g},0,0", "-t_end", "1.0", "-progress_interval", "0"]


def run_wheel(only_missing=True):
    for slip in WHEEL_SLIPS:
        key = f"wheel_slip{round(100 * slip)}_bodies.csv"
        if only_missing and os.path.exists(os.path.join(C.RESULTS_DIR, key)):
            continue
        r = C.run_granmpm(wheel_args(slip), keep_dir=True, label=f"wheel slip {slip}")
        keep(r, "bodies.csv", key)
        import shutil

        shutil.rmtree(r.get("dir", ""), ignore_errors=True)


def body_series(path, body=0):
    rows = C.read_csv(path)
    return [q for q in rows if q["body"] == body]


def excavation_section():
    plt = C.pyplot()
    out = []
    series = {k: body_series(os.path.join(C.RESULTS_DIR, k + "_bodies.csv")) for k, _ in EXC_CASES if os.path.exists(os.path.join(C.RESULTS_DIR, k + "_bodies.csv"))}
    for k, s in series.items():
        row = dict(case=k)
        for lab, t0, t1 in [("dive", 0.3, 0.5), ("drag", 1.0, 2.5)]:
            sel = [q for q in s if t0 <= q["time"] <= t1]
            for comp in ("fx", "fy", "fz"):
                row[f"{comp}_{lab}"] = sum(q[comp] for q in sel) / len(sel) if sel else None
        out.append(row)
    if plt and series:
        fig, ax = plt.subplots(1, 3, figsize=(15, 4))
        for k, s in series.items():
            for i, comp in enumerate(["fx", "fy", "fz"]):
                ax[i].plot([q["time"] for q in s], [-q[comp] if comp == "fx" else q[comp] for q in s], label=k.replace("excavation_", ""), lw=1)
        for i, t in enumerate(["forward force -fx (resistance) [N]", "vertical force fy [N]", "lateral force fz [N]"]):
            ax[i].set_xlabel("t [s]")
            ax[i].set_ylabel(t)
            ax[i].grid(alpha=0.3)
            ax[i].legend(fontsize=8)
        fig.tight_layout()
        C.save_figure(fig, os.path.join(C.FIGURES_DIR, "excavation_forces.png"))
        walls = [(k, os.path.join(C.RESULTS_DIR, k + "_side_wall.csv")) for k, _ in EXC_CASES]
        walls = [(k, p) for k, p in walls if os.path.exists(p)]
        if walls:
            fig, ax = plt.subplots(1, len(walls), figsize=(7 * len(walls), 3.2))
            ax = ax if len(walls) > 1 else [ax]
            for a_, (k, p) in zip(ax, walls):
                w = C.read_csv(p)
                sc = a_.scatter([q["x"] for q in w], [q["y"] for q in w], c=[q["speed"] for q in w], s=4, vmin=0, vmax=0.05, cmap="inferno")
                a_.set_aspect("equal")
                a_.set_title(f"{k.replace('excavation_', '')}: |v| of the particles along the side wall z = 0, end of the run", fontsize=9)
                fig.colorbar(sc, ax=a_, label="|v| [m/s]")
            fig.tight_layout()
            C.save_figure(fig, os.path.join(C.FIGURES_DIR, "excavation_side_wall.png"))
    return out


def wheel_section():
    plt = C.pyplot()
    out = []
    runs = {}
    for slip in WHEEL_SLIPS:
        p = os.path.join(C.RESULTS_DIR, f"wheel_slip{round(100 * slip)}_bodies.csv")
        if os.path.exists(p):
            runs[slip] = body_series(p)
    for slip, s in runs.items():
        late = [q for q in s if q["time"] >= 0.5 * s[-1]["time"]]
        dp = sum(q["fx"] for q in late) / len(late)
        W = sum(q["fy"] for q in late) / len(late)
        out.append(dict(slip=slip, drawbar_pull=dp, wheel_load=W, dp_over_w=dp / W if W else None, sinkage_max=max(0.05 - (q["y"] - 0.15) for q in s),
                        t_end=s[-1]["time"]))
    if plt and runs:
        fig, ax = plt.subplots(1, 3, figsize=(15, 4))
        for slip, s in runs.items():
            t = [q["time"] for q in s]
            ax[0].plot(t, [q["fx"] for q in s], label=f"drawbar pull, slip {slip:g}")
            ax[0].plot(t, [q["fy"] for q in s], "--", label=f"wheel load, slip {slip:g}")
            ax[1].plot(t, [0.05 - (q["y"] - 0.15) for q in s], label=f"slip {slip:g}")
        ax[2].plot([r["slip"] for r in out], [r["dp_over_w"] for r in out], "o-", label="DP / W")
        ax2 = ax[2].twinx()
        ax2.plot([r["slip"] for r in out], [r["sinkage_max"] * 1000 for r in out], "s--", color="C1", label="max sinkage [mm]")
        ax[0].set_ylabel("force [N] (4-cell slice)")
        ax[1].set_ylabel("sinkage (bed top - wheel bottom) [m]")
        ax[2].set_ylabel("drawbar pull / wheel load")
        ax2.set_ylabel("max sinkage [mm]")
        ax[2].set_xlabel("slip")
        for a_ in ax[:2]:
            a_.set_xlabel("t [s]")
            a_.legend(fontsize=7)
        for a_ in ax:
            a_.grid(alpha=0.3)
        fig.tight_layout()
        C.save_figure(fig, os.path.join(C.FIGURES_DIR, "wheel_3d.png"))
    return out


def plot_collapse(rows, path):
    plt = C.pyplot()
    if not plt:
        return
    fig, ax = plt.subplots(figsize=(6, 4.2))
    a = [x / 20 for x in range(4, 201)]
    ax.plot([x for x in a if x <= 1.8], [1.2 * x for x in a if x <= 1.8], "k-", lw=1, label="Lube et al. 2005: 1.2 a")
    ax.plot([x for x in a if x >= 2.8], [1.9 * x ** (2 / 3) for x in a if x >= 2.8], "k--", lw=1, label="Lube et al. 2005: 1.9 a^(2/3)")
    ax.plot([x for x in a if 1.8 <= x <= 2.8], [lube(x) for x in a if 1.8 <= x <= 2.8], "k:", lw=1, label="interpolated (transition)")
    for dim, h, mk, lab in [(2, L0 / 20, "o", "GranMPM 2D, h = L0/20"), (2, L0 / 10, "s", "GranMPM 2D, h = L0/10"), (3, L0 / 10, "^", "GranMPM 3D slot, h = L0/10")]:
        sel = [r for r in rows if r["dim"] == dim and abs(r["h"] - h) < 1e-9 and r["runout"] is not None]
        if sel:
            ax.plot([r["a"] for r in sel], [r["runout"] for r in sel], mk, mfc="none", ms=7, label=lab)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("aspect ratio a = H0/L0")
    ax.set_ylabel("runout (L_f - L0)/L0")
    ax.set_title("Column collapse, local mu(I) (mu_s = 0.3)", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    C.save_figure(fig, path)


def plot_silo(rows, fits, path):
    plt = C.pyplot()
    if not plt:
        return
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    for r in rows:
        s = r.get("series") or []
        if s:
            a1.plot([x["t"] for x in s], [x["discharged_mass"] for x in s], label=f"D = {r['D']:g} m")
    a1.set_xlabel("t [s]")
    a1.set_ylabel("discharged mass [kg per m depth]")
    a1.legend(fontsize=8)
    a1.grid(alpha=0.3)
    ok = [r for r in rows if r["rate"]]
    a2.plot([r["D"] for r in ok], [r["rate"] for r in ok], "o", mfc="none", label="GranMPM 2D")
    d0, d1 = min(r["D"] for r in ok), max(r["D"] for r in ok)
    xs = [0.9 * d0 + (1.05 * d1 - 0.9 * d0) * i / 119 for i in range(120)]
    for (Cc, k, n, rms), st in zip(fits, ["k-", "k--"]):
        a2.plot(xs, [Cc * max(x - k, 1e-12) ** n for x in xs], st, lw=1, label=f"W = {Cc:.3g} (D - {k:.3g})^{n:.2f}")
    a2.set_xlabel("orifice width D [m]")
    a2.set_ylabel("discharge rate W [kg/s per m depth]")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    fig.tight_layout()
    C.save_figure(fig, path)


def main():
    ap = C.common_argparser(__doc__.split("\n")[0])
    ap.add_argument("--only", default="collapse,silo,ngf_cost", help="also: taylor_couette, excavation, wheel (issue 20)")
    a = ap.parse_args()
    parts = a.only.split(",")
    binary = C.granmpm_binary()
    docs = []
    if "collapse" in parts:
        path, png = C.output_paths("collapse", a.quick)
        cols = ["dim", "a", "h", "ok", "runout", "runout_99", "lube", "rel_dev", "final_height", "particles", "steps", "wall_s", "cmd", "message"]
        if a.replot:
            rows = C.read_csv(path, strings=("cmd", "message"))
        else:
            rows = run_collapse(a.quick)
            C.write_csv(path, cols, rows)
            C.write_meta(path, binary)
        plot_collapse(rows, png.replace("collapse.png", "collapse.png"))
        t = C.md_table(["dim", "a", "h", "runout (tip)", "99% mass front", "Lube et al.", "deviation", "H_f/L0", "wall [s]"],
                       [[r["dim"], r["a"], f"L0/{round(L0 / r['h'])}", C.fmt(r["runout"]), C.fmt(r["runout_99"]), C.fmt(r["lube"]),
                         f"{100 * r['rel_dev']:+.1f}%" if r["rel_dev"] is not None else r["message"], C.fmt(r["final_height"]), C.fmt(r["wall_s"])]
                        for r in rows])
        docs.append(("collapse", "Column collapse: runout against aspect ratio",
                     "Produced by `bench/scenes.py --only collapse`; one run per case, 1 rank. Example command:\n\n```\n" + rows[0]["cmd"] +
                     "\n```\n\n" + t + "\n\n![collapse](figures/collapse.png)\n"))
    if "silo" in parts:
        path, png = C.output_paths("silo", a.quick)
        cols = ["D", "D_eff", "ok", "rate", "discharged_mass", "discharged_particles", "wall_s", "cmd", "message"]
        if a.replot:
            rows = C.read_csv(path, strings=("cmd", "message"))
        else:
            rows = run_silo(a.quick)
            C.write_csv(path, cols, rows)
            C.write_meta(path, binary)
        ok = [r for r in rows if r["rate"]]
        fits = []
        if len(ok) >= 3:
            fits = [fit_power([r["D"] for r in ok], [r["rate"] for r in ok]), fit_power([r["D"] for r in ok], [r["rate"] for r in ok], 1.5)]
            for Cc, k, n, rms in fits:
                print(f"# silo fit: W = {Cc:.4g} (D - {k:.4g})^{n:.3f}, rms log residual {rms:.3g}", file=sys.stderr)
        plot_silo(rows, fits, png)
        t = C.md_table(["D [m]", "on the grid [m]", "W [kg/s/m]", "discharged mass [kg/m]", "wall [s]"],
                       [[r["D"], C.fmt(r["D_eff"]), C.fmt(r["rate"]), C.fmt(r["discharged_mass"]), C.fmt(r["wall_s"])] for r in rows])
        ftxt = "\n".join(f"- W = {Cc:.4g} (D - {k:.4g} m)^{n:.3f} (rms residual of log W {rms:.2g})" for Cc, k, n, rms in fits)
        docs.append(("silo", "Silo discharge: rate against orifice width",
                     "Produced by `bench/scenes.py --only silo` (examples/silo.opts, h = 5 mm, with -silo_orifice D). Fits (free exponent, then the "
                     "2D Beverloo exponent 3/2):\n\n" + ftxt + "\n\n" + t + "\n\n![silo](figures/silo.png)\n"))
    if "ngf_cost" in parts:
        path, _ = C.output_paths("ngf_cost", a.quick)
        cols = ["model", "repeats", "rate_median", "rate_min", "rate_max", "cost_vs_mu_i", "particles", "cmd"]
        if a.replot:
            rows = C.read_csv(path, strings=("model", "cmd"))
        else:
            rows = run_ngf_cost(a.quick)
            C.write_csv(path, cols, rows)
            C.write_meta(path, binary)
        t = C.md_table(["model", "runs", "median particle-steps/s", "min", "max", "time per step / mu(I)'s"],
                       [[r["model"], r["repeats"], C.fmt(r["rate_median"]), C.fmt(r["rate_min"]), C.fmt(r["rate_max"]), C.fmt(r["cost_vs_mu_i"])] for r in rows],
                       ["l", "r", "r", "r", "r", "r"])
        docs.append(("ngf_cost", "Cost of the nonlocal models against local mu(I), 3D",
                     "Produced by `bench/scenes.py --only ngf_cost`: the 3D chute from its steady state, 40 x 8 x 8 cells, 2 particles per cell per "
                     "direction, dt = 2e-5 s, 200 steps, 1 rank, repeats interleaved. Target of issue 4: the dynamical model costs <= 10% more than "
                     "mu(I). Command (mu(I)):\n\n```\n" + rows[0]["cmd"] + "\n```\n\n" + t + "\n"))
    if "taylor_couette" in parts:
        if not a.replot:
            run_taylor_couette()
        rows = taylor_couette_section()
        t = C.md_table(["case", "model", "h [mm]", "t [s]", "omega/Omega, first bin", "first bin at (r - Ri) >= 10 d", "decay length [d]"],
                       [[r["case"], r["model"], r["h_mm"], r["t"], C.fmt(r["w_first"]), C.sci(r["w_at_10d"]), C.fmt(r["decay_length_d"])] for r in rows],
                       ["l", "l", "r", "r", "r", "r", "r"])
        docs.append(("taylor_couette", "Taylor-Couette (seed 004 4.1): top-surface angular velocity",
                     "Produced by `bench/scenes.py --only taylor_couette` (1 rank per case; profiles kept in bench/results/taylor_couette_*.csv). "
                     "Command (h = 10 mm, dynamical model; MODEL = local|nonlocal|dynamic, -cells 22,22,3 / 44,44,6 / 88,88,12 and -dt 2e-4 / 1e-4 / 5e-5 "
                     "for h = 20 / 10 / 5 mm):\n\n```\n" + C.shown_cmd(tc_args("dynamic", 10, 0.59)) + "\n```\n\nDecay length: least squares of "
                     "log(omega/Omega) against (r - Ri)/d over the bins with 1e-3 < omega/Omega < 0.2.\n\n" + t +
                     "\n\n![Taylor-Couette](figures/taylor_couette_seed004.png)\n"))
    if "excavation" in parts:
        if not a.replot:
            run_excavation()
        rows = excavation_section()
        t = C.md_table(["case", "fx dive (0.3-0.5 s) [N]", "fy dive [N]", "fx drag (1 s .. 2.5 s or the end of the data) [N]", "fy drag [N]", "fz drag [N]"],
                       [[r["case"], C.fmt(r["fx_dive"]), C.fmt(r["fy_dive"]), C.fmt(r["fx_drag"]), C.fmt(r["fy_drag"]), C.fmt(r["fz_drag"])] for r in rows],
                       ["l"] + ["r"] * 5)
        docs.append(("excavation", "Excavation (seed 004 4.2): blade forces and the failure surface",
                     "Produced by `bench/scenes.py --only excavation` (1 rank per case; forces in bench/results/excavation_*_bodies.csv, N, on the "
                     "blade: fx < 0 resists the forward motion). Cases: " + "; ".join(f"`{k}`: examples/excavation_3d.opts {' '.join(e)}" for k, e in EXC_CASES) +
                     ".\n\n" + t + "\n\n![forces](figures/excavation_forces.png)\n\n![side wall](figures/excavation_side_wall.png)\n"))
    if "wheel" in parts:
        if not a.replot:
            run_wheel()
        rows = wheel_section()
        t = C.md_table(["slip", "drawbar pull [N]", "wheel load [N]", "DP/W", "max sinkage [mm]", "t_end [s]"],
                       [[r["slip"], C.fmt(r["drawbar_pull"]), C.fmt(r["wheel_load"]), C.fmt(r["dp_over_w"]), C.fmt(1000 * r["sinkage_max"]), r["t_end"]] for r in rows])
        docs.append(("wheel", "Wheel (seed 004 4.3): drawbar pull, load and sinkage against slip",
                     "Produced by `bench/scenes.py --only wheel` (examples/wheel_3d.opts with -body0_velocity (1 - s) |omega| R; 1 rank; means over the "
                     "second half of the run). Command (20% slip):\n\n```\n" + C.shown_cmd(wheel_args(0.2)) + "\n```\n\n" + t +
                     "\n\n![wheel](figures/wheel_3d.png)\n"))
    if not a.quick and not a.no_docs:
        for key, title, body in docs:
            C.replace_doc_section("scenes.md", key, title, body, "GranMPM scenes: column collapse, silo discharge")


if __name__ == "__main__":
    main()
