#!/usr/bin/env python3
"""Load balance: the column collapse and the silo on 2, 3 and 4 ranks with and without
-balance_threshold (imbalance before/after, wall time, same result), and an offline
comparison of the tensor-product split GranMPM uses with a METIS partition of the
particle-weighted node graph (imbalance and edge cut / ghost nodes).

  /usr/bin/python3 bench/balance.py [--quick] [--no-docs]

Writes bench/results/balance_runs.csv, bench/results/balance_metis.csv and the section
"Load balance: measured" of docs/scaling.md. 3 and 4 ranks are oversubscribed on a 2-core
machine: their wall times mean little; the imbalance numbers do not depend on it.

METIS: called through ctypes from the system libmetis (Debian libmetis-dev,
METIS_PartGraphKway, 32-bit idx_t); GranMPM itself does not link METIS.
"""

import ctypes
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

MU_I = ["-material", "mu_i", "-mu_s", "0.3", "-b", "18.754", "-d", "1e-3", "-rho_s", "2450", "-rho", "1500", "-rho_c", "1350",
        "-E", "1e6", "-nu", "0.3", "-ppc", "2", "-shape", "gimp", "-transfer", "apic", "-gravity_ramp", "0", "-geostatic", "-p0", "0",
        "-t_end", "10", "-output_final", "0"]
# examples/collapse.opts (a = 2, h = L0/20) and examples/silo.opts (h = 5 mm).
SCENES = {
    "collapse": ["-scene", "collapse", "-domain_lo", "0,0", "-domain_hi", "0.9,0.5", "-cells", "90,50", "-body_hi", "0.2,0.4",
                 "-bc_xlo", "slip", "-bc_xhi", "slip", "-bc_ylo", "sticky", "-bc_yhi", "free", "-gravity", "0,-9.81"] + MU_I,
    "silo": ["-scene", "silo", "-domain_lo", "0,0", "-domain_hi", "0.4,0.5", "-cells", "80,100", "-body_lo", "0,0.1", "-body_hi", "0.4,0.45",
             "-silo_plate_y", "0.1", "-silo_orifice", "0.06", "-silo_orifice_x", "0.2", "-bc_xlo", "slip", "-bc_xhi", "slip", "-bc_ylo", "outlet",
             "-bc_yhi", "free", "-gravity", "0,-9.81"] + MU_I,
}

RE_LB = re.compile(r"load balance: particles per rank max/mean ([\d.]+) at the start, ([\d.]+) at the end; (\d+) repartition")
RE_REB = re.compile(r"step (\d+): rebalanced, particles per rank max/mean ([\d.]+) -> ([\d.]+)")
RE_KE = re.compile(r"step\s+\d+\s+t \S+\s+dt \S+\s+KE (\S+)\s+particles (\d+)")


def run_case(scene, np_, thr, steps, interval):
    args = SCENES[scene] + ["-max_steps", str(steps), "-progress_interval", str(steps), "-balance_threshold", str(thr),
                            "-balance_interval", str(interval)]
    r = C.run_granmpm(args, np_=np_, label=f"{scene} {np_} ranks, -balance_threshold {thr}")
    row = {"scene": scene, "ranks": np_, "threshold": thr, "steps": steps, "wall_s": r.get("wall_s"), "cmd": r["cmd"]}
    m = RE_LB.search(r["output"])
    if m:
        row.update(imb_start=float(m.group(1)), imb_end=float(m.group(2)), repartitions=int(m.group(3)))
    rebs = RE_REB.findall(r["output"])
    row["first_before"] = float(rebs[0][1]) if rebs else None
    row["first_after"] = float(rebs[0][2]) if rebs else None
    row["max_after"] = max(float(x[2]) for x in rebs) if rebs else None
    kes = RE_KE.findall(r["output"])
    row["ke_end"] = float(kes[-1][0]) if kes else None
    row["particles_end"] = int(kes[-1][1]) if kes else None
    if not r["ok"]:
        print(r["output"][-2000:], file=sys.stderr)
    return row


# --------------------------------------------------------------------------------------
# Offline partition comparison


def balanced_ranges(w, parts, min_nodes=2):
    """The same cuts as granmpm::balanced_ranges (src/grid.cpp)."""
    cum = np.concatenate([[0.0], np.cumsum(w)])
    n, total = len(w), cum[-1]
    b = [0] * (parts + 1)
    b[parts] = n
    for r in range(1, parts):
        if total <= 0:
            b[r] = n * r // parts
            continue
        t = total * r / parts
        i = int(np.searchsorted(cum, t, side="left"))
        if i > 0 and t - cum[i - 1] < cum[i] - t:
            i -= 1
        b[r] = i
    for r in range(1, parts):
        b[r] = max(b[r], b[r - 1] + min_nodes)
    for r in range(parts - 1, 0, -1):
        b[r] = min(b[r], b[r + 1] - min_nodes)
    return [b[r + 1] - b[r] for r in range(parts)]


def choose_split(M, nranks):
    """Grid<dim>::choose_split: the factorisation with the smallest cut surface."""
    best, cost_best = None, None
    dim = len(M)
    for m in range(1, nranks + 1):
        if nranks % m:
            continue
        for n in range(1, nranks // m + 1):
            if (nranks // m) % n:
                continue
            p = nranks // (m * n)
            if dim == 2 and p != 1:
                continue
            f = [m, n, p][:dim]
            if any(M[d] // f[d] < 2 for d in range(dim)):
                continue
            cost = sum((f[d] - 1) * np.prod([M[e] for e in range(dim) if e != d]) for d in range(dim))
            if cost_best is None or cost < cost_best:
                best, cost_best = f, cost
    return best


def tensor_parts(counts, nranks):
    """Rank of every node under GranMPM's balanced tensor-product split (2D counts[i, j])."""
    M = counts.shape
    f = choose_split(M, nranks)
    owner = []
    for d in range(2):
        marg = counts.sum(axis=1 - d)
        l = balanced_ranges(marg, f[d])
        owner.append(np.repeat(np.arange(f[d]), l))
    return owner[0][:, None] + f[0] * owner[1][None, :]


def metis_parts(counts, nranks, node_weight):
    """METIS k-way partition of the 4-neighbour node graph; vertex weight = node_weight x
    particles + 1 (the +1 is the node's own grid work, about 1/node_weight of a particle's)."""
    lib = ctypes.CDLL("libmetis.so.5")
    idx = ctypes.c_int32
    nx, ny = counts.shape
    nv = nx * ny
    vid = lambda i, j: i + nx * j  # noqa: E731
    xadj, adj = [0], []
    for j in range(ny):
        for i in range(nx):
            for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                a, b = i + di, j + dj
                if 0 <= a < nx and 0 <= b < ny:
                    adj.append(vid(a, b))
            xadj.append(len(adj))
    vw = (node_weight * counts.T.reshape(-1) + 1).astype(np.int32)
    A = lambda v: (idx * len(v))(*[int(x) for x in v])  # noqa: E731
    nvtxs, ncon, nparts, objval = idx(nv), idx(1), idx(nranks), idx(0)
    part = (idx * nv)()
    opts = (idx * 40)()
    lib.METIS_SetDefaultOptions(opts)
    opts[8] = 1  # METIS_OPTION_SEED (enum position 8 in metis.h 5.1): fixed for reproducibility
    rc = lib.METIS_PartGraphKway(ctypes.byref(nvtxs), ctypes.byref(ncon), A(xadj), A(adj), A(vw), None, None, ctypes.byref(nparts), None, None, opts,
                                 ctypes.byref(objval), part)
    if rc != 1:
        raise RuntimeError(f"METIS_PartGraphKway returned {rc}")
    return np.array(part[:], dtype=int).reshape(ny, nx).T


def evaluate(counts, parts, nranks):
    """Particle imbalance max/mean, graph edge cut (4-neighbour node pairs in different parts)
    and ghost nodes: the nodes each rank needs from others for the width-2 box stencil, summed
    over ranks (what the halo exchange moves)."""
    per = np.array([counts[parts == r].sum() for r in range(nranks)], dtype=float)
    imb = per.max() / per.mean()
    cut = int((parts[1:, :] != parts[:-1, :]).sum() + (parts[:, 1:] != parts[:, :-1]).sum())
    ghosts = 0
    nx, ny = parts.shape
    for r in range(nranks):
        mine = parts == r
        near = np.zeros_like(mine)
        for di in range(-2, 3):
            for dj in range(-2, 3):
                sh = np.zeros_like(mine)
                xs = slice(max(di, 0), nx + min(di, 0))
                xd = slice(max(-di, 0), nx + min(-di, 0))
                ys = slice(max(dj, 0), ny + min(dj, 0))
                yd = slice(max(-dj, 0), ny + min(-dj, 0))
                sh[xd, yd] = mine[xs, ys]
                near |= sh
        ghosts += int((near & ~mine).sum())
    return imb, cut, ghosts


def snapshot_counts(scene, steps):
    """Per-node particle counts (owner node of each particle's cell) at step 0 and `steps`."""
    import glob

    import h5py

    args = SCENES[scene] + ["-max_steps", str(steps), "-progress_interval", "0", "-output_interval", str(steps)]
    r = C.run_granmpm(args, keep_dir=True, label=f"{scene} snapshots (1 rank)")
    lo = [float(x) for x in args[args.index("-domain_lo") + 1].split(",")]
    hi = [float(x) for x in args[args.index("-domain_hi") + 1].split(",")]
    cells = [int(x) for x in args[args.index("-cells") + 1].split(",")]
    h = (hi[0] - lo[0]) / cells[0]
    M = [c + 1 + 4 for c in cells]  # non-periodic: 2 padding cells each side
    out = []
    for path in sorted(glob.glob(os.path.join(r["dir"], "snap_*.h5"))):
        with h5py.File(path, "r") as f:
            x = f["/particles/position"][:, :2]
        c = [np.clip(np.floor((x[:, d] - (lo[d] - 2 * h)) / h).astype(int), 0, M[d] - 1) for d in range(2)]
        cnt = np.zeros(M)
        np.add.at(cnt, (c[0], c[1]), 1)
        step = int(re.search(r"snap_(\d+)", path).group(1)) * steps  # frame k is step k x -output_interval
        out.append((step, cnt))
    import shutil

    shutil.rmtree(r["dir"], ignore_errors=True)
    return out


def main():
    ap = C.common_argparser(__doc__)
    a = ap.parse_args()
    steps = 400 if a.quick else 1500
    interval = 50
    rows = []
    for scene in SCENES:
        for np_ in (2, 3, 4):
            for thr in (0, 1.1):
                rows.append(run_case(scene, np_, thr, steps, interval))
    runs_csv, _ = C.output_paths("balance_runs", a.quick)
    cols = ["scene", "ranks", "threshold", "steps", "imb_start", "imb_end", "repartitions", "first_before", "first_after", "max_after", "wall_s",
            "ke_end", "particles_end", "cmd"]
    C.write_csv(runs_csv, cols, rows)

    # Node weight 20: the calibrated model of docs/scaling.md gives a grid node about 1/10 (2D)
    # to 1/20 (3D) of a particle's cost per step.
    mrows = []
    for scene in SCENES:
        for step, cnt in snapshot_counts(scene, steps):
            for nr in (2, 4, 8, 16):
                t = evaluate(cnt, tensor_parts(cnt, nr), nr)
                m = evaluate(cnt, metis_parts(cnt, nr, 20), nr)
                mrows.append({"scene": scene, "step": step, "ranks": nr, "particles": int(cnt.sum()), "tensor_imbalance": t[0], "tensor_edge_cut": t[1],
                              "tensor_ghost_nodes": t[2], "metis_imbalance": m[0], "metis_edge_cut": m[1], "metis_ghost_nodes": m[2]})
                print(f"# {scene} step {step} {nr} parts: tensor {t}, metis {m}", file=sys.stderr)
    metis_csv, _ = C.output_paths("balance_metis", a.quick)
    C.write_csv(metis_csv, list(mrows[0].keys()), mrows)

    if a.quick or a.no_docs:
        return
    t1 = C.md_table(["scene", "ranks", "-balance_threshold", "max/mean at start", "first repartition", "repartitions", "max/mean at end",
                     "wall [s]", "final KE [J]", "particles"],
                    [[r["scene"], r["ranks"], r["threshold"], f"{r.get('imb_start', float('nan')):.3f}",
                      "-" if r["first_before"] is None else f"{r['first_before']:.3f} -> {r['first_after']:.3f}", r.get("repartitions", "-"),
                      f"{r.get('imb_end', float('nan')):.3f}", f"{r['wall_s']:.2f}" if r.get("wall_s") else "-", r["ke_end"], r["particles_end"]] for r in rows],
                    ["l"] + ["r"] * 9)
    t2 = C.md_table(["scene", "step", "ranks", "tensor: max/mean", "METIS: max/mean", "tensor: edge cut", "METIS: edge cut", "tensor: ghost nodes",
                     "METIS: ghost nodes"],
                    [[r["scene"], r["step"], r["ranks"], f"{r['tensor_imbalance']:.3f}", f"{r['metis_imbalance']:.3f}", r["tensor_edge_cut"],
                      r["metis_edge_cut"], r["tensor_ghost_nodes"], r["metis_ghost_nodes"]] for r in mrows], ["l"] + ["r"] * 8)
    load = C.loadavg()
    body = (f"Produced by `/usr/bin/python3 bench/balance.py` ({C.host_description()}, 1-minute load average {load:.1f} at the end); "
            f"{steps} steps per run, imbalance checked every {interval} steps. Command of the collapse on 2 ranks with balancing:\n\n```\n"
            + [r for r in rows if r["ranks"] == 2 and r["threshold"] > 0][0]["cmd"] + "\n```\n\n" + t1 +
            "\n\nmax/mean: particles on the most loaded rank over the mean. 'first repartition': the imbalance before and after the first "
            "repartition (at step 0). Final KE is printed with 7 digits; equal digits with and without balancing mean equal to that precision. "
            "3 and 4 ranks run oversubscribed on 2 cores, so their wall times are not speed-ups.\n\n"
            "### Tensor-product split against METIS\n\nParticle distributions of the same scenes (1-rank run, snapshots at step 0 and "
            f"{steps}), partitioned offline into 2-16 parts: GranMPM's balanced tensor-product split (the same cuts as `balanced_ranges`, on the "
            "factorisation `choose_split` picks) and METIS_PartGraphKway (libmetis 5.1, seed 1) on the 4-neighbour node graph with vertex "
            "weight 20 x particles + 1 (a node costs about 1/10-1/20 of a particle per step, from the calibrated model above). Edge cut: "
            "neighbour node pairs in different parts; ghost nodes: nodes each part needs from others for the width-2 box stencil, summed "
            "over parts.\n\n" + t2 + "\n\nRaw data: `bench/results/balance_runs.csv`, `bench/results/balance_metis.csv`.\n")
    C.replace_doc_section("scaling.md", "balance", "Load balance: measured", body, "GranMPM scaling")


if __name__ == "__main__":
    main()
