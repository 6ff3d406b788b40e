#!/usr/bin/env python3
"""Taylor-Couette (seed 004 section 4.1, issue 20 item 1): the top-surface profile under h -> h/2.

The cell of examples/taylor_couette_3d_{local,nonlocal,dynamic}.opts (the seed's Table 1 second set,
E 3 MPa, d 4 mm) with the inner cylinder at 0.25 rad/s (10x the seed's 0.025: the flow is quasi-static
either way, docs/scenes.md) at h = 20, 10, 5 mm (= 5, 2.5, 1.25 d; 2 particles per cell per direction;
dt = 2e-4, 1e-4, 5e-5 s, 0.51 of the elastic CFL limit at every h; gravity ramped over 0.02 s instead of the
default 0.5 s, so that the window has full gravity), on the short window t = 0 .. 0.3 s.
Each run is split into segments of --segment s (default 0.1 s) chained through checkpoints
(-checkpoint_file / -restart: bitwise the uninterrupted run), so one run gives the profile at every
segment end: the change from one segment to the next says whether the profile is steady.

Per (model, h, t): omega/Omega at the top surface interpolated (log-linear) at (r - Ri) = 2.5, 5, 10 d,
the distance where omega/Omega falls to 0.1, and the decay length (least squares of log(omega/Omega)
against (r - Ri)/d over the bins with 1e-3 < omega/Omega < 0.2; the seed: 1.3 d). Profiles are kept in
bench/results/taylor_couette_conv/<model>_h<h>_t<t>.csv; a segment whose profile exists is not rerun
(its checkpoint must still be in --work for the next segment).

Writes bench/results/taylor_couette_convergence.csv (+ .meta.json; also printed), the figures
docs/figures/taylor_couette_convergence.png and taylor_couette_models.png (the three models on one axes at
the same h and t, linear and log) and the section 'taylor_couette_convergence' of docs/scenes.md.
--only MODEL[,MODEL] and --h 20,10,5 restrict the runs (two invocations can share the 2 cores);
--replot runs nothing.
"""

import math
import os
import shutil
import sys

import _common as C

MODELS = ["local", "nonlocal", "dynamic"]
NAMES = {"local": "local mu(I)", "nonlocal": "steady nonlocal", "dynamic": "dynamical nonlocal (seed's)"}
H_MM = [20, 10, 5]
D = 0.004
OMEGA = "0.25"
GRAVITY_RAMP = "0.02"  # full gravity from 20 ms (7 vertical wave periods 4 H / c = 3 ms), not the default 0.5 s, so the window has it
PROF_DIR = os.path.join(C.RESULTS_DIR, "taylor_couette_conv")
XI_AT = [5.0, 7.5, 10.0, 15.0]


def case_args(model, h_mm):
    n, nz = round(0.44 / (h_mm * 1e-3)), round(0.06 / (h_mm * 1e-3))
    return ["-options_file", os.path.join(C.REPO_ROOT, "examples", f"taylor_couette_3d_{model}.opts"), "-annulus_omega", OMEGA,
            "-cells", f"{n},{n},{nz}", "-dt", f"{1e-4 * h_mm / 10:.3g}", "-gravity_ramp", GRAVITY_RAMP, "-progress_interval", "0", "-output_final", "0", "-bodies_interval", "1000000"]


def prof_path(model, h_mm, t):
    return os.path.join(PROF_DIR, f"{model}_h{h_mm:g}_t{t:.2f}.csv")


def run_case(model, h_mm, t_end, seg, work, np_):
    """Chain the segments of one case; returns the per-segment cost rows of the segments run now."""
    os.makedirs(PROF_DIR, exist_ok=True)
    os.makedirs(work, exist_ok=True)
    dt = 1e-4 * h_mm / 10
    steps = round(seg / dt)
    nseg = round(t_end / seg)
    cost = []
    prev = None
    for k in range(1, nseg + 1):
        t = k * seg
        ck = os.path.join(work, f"{model}_h{h_mm:g}_t{t:.2f}.h5")
        if os.path.exists(prof_path(model, h_mm, t)) and os.path.exists(ck):
            prev = ck
            continue
        args = case_args(model, h_mm) + ["-t_end", f"{t:.6g}", "-checkpoint_interval", str(steps), "-checkpoint_file", ck]
        if prev:
            args += ["-restart", prev]
        r = C.run_granmpm(args, np_=np_, keep_dir=True, label=f"taylor-couette {model} h = {h_mm} mm, t = {t:.2f} s")
        if not r["ok"] or not os.path.exists(ck):
            print(f"# {model} h {h_mm}: segment to t = {t:.2f} failed or wrote no checkpoint: {C.error_line(r['output'])}", file=sys.stderr)
            shutil.rmtree(r.get("dir", ""), ignore_errors=True)
            return cost
        shutil.copy(os.path.join(r["dir"], "profile.csv"), prof_path(model, h_mm, t))
        shutil.rmtree(r["dir"], ignore_errors=True)
        cost.append(dict(model=model, h_mm=h_mm, t=t, particles=r.get("particles"), cpu_s=r["cpu_s"], wall_s=r["elapsed"], loadavg=r["loadavg"],
                         ranks=np_, cmd=r["cmd"]))
        if prev:
            os.remove(prev)  # only the newest checkpoint is needed
        prev = ck
    return cost


DT_DIR = os.path.join(C.RESULTS_DIR, "taylor_couette_dt")
DT_CFL = [0.25, 0.5, 0.9]


def dt_args(model, cfl):
    """h = 20 mm with the step from -cfl (0.51 is the convergence runs' Courant number)."""
    a = case_args(model, 20)
    i = a.index("-dt")
    return a[:i] + ["-dt", "0", "-cfl", f"{cfl:g}"] + a[i + 2:] + ["-t_end", "0.3"]


def run_dt_study():
    """The time step at fixed h: local and dynamical model, h = 20 mm, t = 0.3 s, -cfl 0.25 / 0.5 / 0.9."""
    os.makedirs(DT_DIR, exist_ok=True)
    for m in ("local", "dynamic"):
        for cfl in DT_CFL:
            dst = os.path.join(DT_DIR, f"{m}_cfl{cfl:g}.csv")
            if os.path.exists(dst):
                continue
            r = C.run_granmpm(dt_args(m, cfl), keep_dir=True, label=f"taylor-couette {m} h = 20 mm, cfl {cfl:g}")
            if r["ok"]:
                shutil.copy(os.path.join(r["dir"], "profile.csv"), dst)
            shutil.rmtree(r.get("dir", ""), ignore_errors=True)


def dt_rows():
    rows = []
    for m in ("local", "dynamic"):
        for cfl in DT_CFL:
            p = os.path.join(DT_DIR, f"{m}_cfl{cfl:g}.csv")
            if not os.path.exists(p):
                continue
            q = C.read_csv(p)
            xi, w = [x["xi_d"] for x in q], [x["omega_over_Omega"] for x in q]
            rows.append(dict(model=m, cfl=cfl, decay_length_d=decay_length(xi, w), xi_at_0p1=crossing(xi, w),
                             **{f"w_bin{k}": w[k] for k in range(min(4, len(w)))}, **{f"xi_bin{k}": xi[k] for k in range(min(4, len(w)))}))
    return rows


def interp_log(xi, w, x0):
    """log-linear interpolation of w at x0 over the positive bins; None outside them."""
    pts = [(x, y) for x, y in zip(xi, w) if y > 0]
    for (xa, ya), (xb, yb) in zip(pts, pts[1:]):
        if xa <= x0 <= xb:
            return math.exp(math.log(ya) + (math.log(yb) - math.log(ya)) * (x0 - xa) / (xb - xa))
    return None


def crossing(xi, w, level=0.1):
    for (xa, ya), (xb, yb) in zip(zip(xi, w), list(zip(xi, w))[1:]):
        if ya >= level > yb and ya > 0 and yb > 0:
            return xa + (xb - xa) * (math.log(level) - math.log(ya)) / (math.log(yb) - math.log(ya))
    return None


def decay_length(xi, w, lo=1e-3, hi=0.2):
    pts = [(x, math.log(y)) for x, y in zip(xi, w) if lo < y < hi]
    if len(pts) < 2:
        return None
    n = len(pts)
    mx, my = sum(p[0] for p in pts) / n, sum(p[1] for p in pts) / n
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    sxy = sum((p[0] - mx) * (p[1] - my) for p in pts)
    return -sxx / sxy if sxy < 0 else None


def load_profiles():
    prof = {}
    if not os.path.isdir(PROF_DIR):
        return prof
    for f in sorted(os.listdir(PROF_DIR)):
        m, hs, ts = f[:-4].split("_")
        rows = C.read_csv(os.path.join(PROF_DIR, f))
        prof[(m, float(hs[1:]), float(ts[1:]))] = ([q["xi_d"] for q in rows], [q["omega_over_Omega"] for q in rows])
    return prof


def summary_rows(prof):
    rows = []
    for (m, h, t), (xi, w) in sorted(prof.items(), key=lambda kv: (MODELS.index(kv[0][0]), -kv[0][1], kv[0][2])):
        row = dict(model=m, h_mm=h, t=t, decay_length_d=decay_length(xi, w), xi_at_0p1=crossing(xi, w), n_bins_fit=sum(1 for y in w if 1e-3 < y < 0.2))
        for x in XI_AT:
            row[f"w_at_{x:g}d"] = interp_log(xi, w, x)
        rows.append(row)
    return rows


def rel(a, b):
    return None if a is None or b is None or b == 0 else a / b - 1


def plot(prof, path):
    plt = C.pyplot()
    if not plt or not prof:
        return
    fig, ax = plt.subplots(2, 3, figsize=(15, 7.5), sharex=True)
    hstyle = {20: ("C0", ":"), 10: ("C1", "-."), 5: ("C3", "-")}
    for j, m in enumerate(MODELS):
        last = {h: max(t for (mm, hh, t) in prof if mm == m and hh == h) for h in H_MM if any(mm == m and hh == h for (mm, hh, t) in prof)}
        tc = min(last.values()) if last else 0  # the latest time every h reached: bold
        for h in H_MM:
            if h not in last:
                continue
            for t in sorted({tc, last[h]}):  # and thin: the same h at its last segment end (steadiness)
                xi, w = prof[(m, h, t)]
                c, ls = hstyle[h]
                lw, a = (1.8, 1.0) if t == tc else (0.8, 0.6)
                lab = f"h = {h:g} mm = {h / 4:g} d, t = {t:g} s"
                ax[0][j].plot(xi, w, ls, color=c, lw=lw, alpha=a, marker="o", ms=3, label=lab)
                ax[1][j].semilogy([x for x, y in zip(xi, w) if y > 0], [y for y in w if y > 0], ls, color=c, lw=lw, alpha=a, marker="o", ms=3, label=lab)
        ax[0][j].set_title(f"{NAMES[m]}", fontsize=10)
        ax[1][j].set_ylim(1e-5, 1.5)
        ax[1][j].set_xlabel("(r - Ri) / d")
        for a_ in (ax[0][j], ax[1][j]):
            a_.grid(alpha=0.3, which="both")
            a_.legend(fontsize=7)
    ax[0][0].set_ylabel("omega / Omega, top surface")
    ax[1][0].set_ylabel("omega / Omega (log)")
    fig.suptitle("Taylor-Couette, seed 004 parameters, Omega = 0.25 rad/s: h -> h/2 on the window 0 .. 0.3 s (bold: the latest t every h reached; thin: later t at the same h)", fontsize=10)
    fig.tight_layout()
    C.save_figure(fig, path)


# The three models side by side at the same h and t (the coarse cell: h = 20 mm at the window's end,
# and h = 10 mm at the latest t the steady nonlocal model reached there).
MODEL_CMP = [(20, 0.3), (10, 0.05)]
MSTYLE = {"local": ("C0", "s", "--"), "nonlocal": ("C2", "^", ":"), "dynamic": ("C3", "o", "-")}


def plot_models(prof, path):
    plt = C.pyplot()
    cases = [(h, t) for h, t in MODEL_CMP if all((m, h, t) in prof for m in MODELS)]
    if not plt or not cases:
        return
    fig, ax = plt.subplots(len(cases), 2, figsize=(11, 3.8 * len(cases)), squeeze=False)
    for i, (h, t) in enumerate(cases):
        for m in MODELS:
            xi, w = prof[(m, h, t)]
            c, mk, ls = MSTYLE[m]
            lab = f"{NAMES[m]}, decay length {C.fmt(decay_length(xi, w))} d"
            ax[i][0].plot(xi, w, ls, color=c, marker=mk, ms=4, label=lab)
            ax[i][1].semilogy([x for x, y in zip(xi, w) if y > 0], [y for y in w if y > 0], ls, color=c, marker=mk, ms=4, label=lab)
        ax[i][0].set_title(f"h = {h:g} mm = {h / 4:g} d, t = {t:g} s: linear", fontsize=10)
        ax[i][1].set_title(f"h = {h:g} mm = {h / 4:g} d, t = {t:g} s: log (the seed's inset)", fontsize=10)
        ax[i][1].set_ylim(1e-5, 1.5)
        ax[i][0].set_ylabel("omega / Omega, top surface")
        for a_ in ax[i]:
            a_.set_xlabel("(r - Ri) / d")
            a_.grid(alpha=0.3, which="both")
            a_.legend(fontsize=7)
    fig.suptitle("Taylor-Couette, seed 004 parameters, Omega = 0.25 rad/s: local, steady nonlocal and dynamical model at the same h and t", fontsize=10)
    fig.tight_layout()
    C.save_figure(fig, path)


def dt_section():
    rows = dt_rows()
    if not rows:
        return ""
    C.write_csv(os.path.join(C.RESULTS_DIR, "taylor_couette_dt.csv"), list(rows[0].keys()), rows)
    x = rows[0]
    tab = [[NAMES[r["model"]], f"{r['cfl']:g}", C.fmt(r["decay_length_d"]), C.fmt(r["xi_at_0p1"])] + [f"{r.get(f'w_bin{k}', 0):.4g}" for k in range(4)]
           for r in rows]
    return ("\n\nThe time step at fixed h (`--dt_study`: h = 20 mm, t = 0.3 s, -dt 0 -cfl C; the runs above use C = 0.51). Command:\n\n```\n"
            + C.shown_cmd(dt_args("dynamic", 0.9)) + "\n```\n\n"
            + C.md_table(["model", "cfl", "decay length [d]", "omega/Omega = 0.1 at [d]"] + [f"omega/Omega at {x[f'xi_bin{k}']:.3g} d" for k in range(4)], tab))


def main():
    ap = C.common_argparser(__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(MODELS))
    ap.add_argument("--h", default=",".join(str(h) for h in H_MM), help="resolutions in mm")
    ap.add_argument("--t_end", type=float, default=0.3)
    ap.add_argument("--segment", type=float, default=0.1)
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--work", default=os.path.join("/tmp", "granmpm-tc-conv"), help="checkpoints between segments")
    ap.add_argument("--dt_study", action="store_true", help="also the time step at fixed h (h = 20 mm, -cfl 0.25 / 0.5 / 0.9)")
    a = ap.parse_args()
    if a.dt_study and not a.replot:
        run_dt_study()
    cost_path = os.path.join(C.RESULTS_DIR, "taylor_couette_convergence_cost.csv")
    if not a.replot:
        for m in a.only.split(","):
            for h in [float(x) for x in a.h.split(",")]:
                h = int(h) if h == int(h) else h
                new = run_case(m, h, a.t_end, a.segment, a.work, a.ranks)
                # re-read before writing: two invocations may share the file
                old = C.read_csv(cost_path, strings=("model", "cmd")) if os.path.exists(cost_path) else []
                merged = {(r["model"], r["h_mm"], round(r["t"], 6)): r for r in old + new}
                C.write_csv(cost_path, ["model", "h_mm", "t", "particles", "ranks", "cpu_s", "wall_s", "loadavg", "cmd"],
                            sorted(merged.values(), key=lambda r: (MODELS.index(r["model"]), -r["h_mm"], r["t"])))
    prof = load_profiles()
    rows = summary_rows(prof)
    cols = ["model", "h_mm", "t", "decay_length_d", "n_bins_fit", "xi_at_0p1"] + [f"w_at_{x:g}d" for x in XI_AT]
    out = os.path.join(C.RESULTS_DIR, "taylor_couette_convergence.csv")
    C.write_csv(out, cols, rows)
    C.write_meta(out, C.granmpm_binary(), omega=OMEGA, segment=a.segment)
    plot(prof, os.path.join(C.FIGURES_DIR, "taylor_couette_convergence.png"))
    plot_models(prof, os.path.join(C.FIGURES_DIR, "taylor_couette_models.png"))
    if a.no_docs:
        return
    by = {(r["model"], r["h_mm"], r["t"]): r for r in rows}
    tab = []
    for r in rows:
        prev = by.get((r["model"], r["h_mm"], round(r["t"] - a.segment, 6)))
        coarse = by.get((r["model"], r["h_mm"] * 2, r["t"]))
        tab.append([NAMES[r["model"]], C.fmt(r["h_mm"]), f"{r['t']:g}", C.fmt(r["decay_length_d"]), C.fmt(r["xi_at_0p1"])]
                   + [C.sci(r[f"w_at_{x:g}d"]) if r[f"w_at_{x:g}d"] else "" for x in XI_AT]
                   + [f"{rel(r['w_at_5d'], prev['w_at_5d']):+.0%}" if prev and rel(r["w_at_5d"], prev["w_at_5d"]) is not None else "",
                      f"{rel(r['w_at_5d'], coarse['w_at_5d']):+.0%}" if coarse and rel(r["w_at_5d"], coarse["w_at_5d"]) is not None else ""])
    body = ("Produced by `bench/taylor_couette_convergence.py` (1 rank per case, segments of 0.1 s chained by checkpoints, and runs to "
            "t = 0.05 s with `--segment 0.05 --t_end 0.05`; the h = 5 mm dynamical run to 0.05 s was chained by hand, 1 then 2 ranks, "
            "see the text above; profiles in bench/results/taylor_couette_conv/). Command (h = 5 mm, dynamical model, first segment):\n\n```\n"
            + C.shown_cmd(case_args("dynamic", 5) + ["-t_end", "0.1", "-checkpoint_interval", "2000", "-checkpoint_file", "CK"]) + "\n```\n\n"
            "Decay length: least squares of log(omega/Omega) against (r - Ri)/d over the bins with 1e-3 < omega/Omega < 0.2 (the seed: 1.3 d). "
            "Change of omega/Omega at 5 d: against the same h 0.1 s earlier (steadiness) and against 2h at the same t (convergence).\n\n"
            + C.md_table(["model", "h [mm]", "t [s]", "decay length [d]", "omega/Omega = 0.1 at [d]", "omega/Omega at 5 d", "at 7.5 d", "at 10 d", "at 15 d",
                          "at 5 d vs t - 0.1 s", "at 5 d vs 2h"], tab)
            + dt_section()
            + "\n\n![Taylor-Couette convergence](figures/taylor_couette_convergence.png)\n"
            + "\nThe three models at the same h and t (" + ", ".join(f"h = {h:g} mm, t = {t:g} s" for h, t in MODEL_CMP) + "; the same profiles):\n"
            + "\n![Taylor-Couette models](figures/taylor_couette_models.png)\n")
    C.replace_doc_section("scenes.md", "taylor_couette_convergence", "Taylor-Couette: the top-surface profile under h -> h/2 (short window)", body, "GranMPM scenes")


if __name__ == "__main__":
    main()
