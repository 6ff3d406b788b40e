#!/usr/bin/env python3
"""Collect the outputs of slurm_strong_scaling.sh / slurm_weak_scaling.sh into one CSV with efficiency columns.

  python3 cluster/collect_scaling.py --mode strong runs/strong > strong.csv
  python3 cluster/collect_scaling.py --mode weak runs/weak -o weak.csv

Reads ROOT/np<ranks>/output.txt (the solver's stdout; any *.out/*.txt containing the summary lines works) and,
if present, ROOT/np<ranks>/log_view.txt for the stage times. Parses
  "GranMPM: <N> particles, grid <nx> x <ny> [x <nz>] nodes on <P> rank(s)"      (RE_SIZES in bench/_common.py)
  "GranMPM: done, <S> steps to t = <t> s in <X> s wall (<R> particle-steps/s)"  (RE_DONE)
The reference is the run with the fewest ranks (P0 ranks, rate R0 particle-steps/s):
  strong: speedup = R / R0 (= W0 / W for the same particles and steps), efficiency = speedup * P0 / P
  weak:   efficiency = (R / P) / (R0 / P0)   (particle-steps per second per rank, so runs with slightly
          different particle or step counts still compare)
The rate is used rather than the wall time because the solver prints the wall time to 0.01 s only.
Also written: rate per rank and the share of each -log_view stage (Migrate, P2G, GridUpdate, G2P, Constitutive,
Fluidity, Output) in their sum. Runs without a "done" line are listed with status 'incomplete'.
"""

import argparse
import csv
import glob
import os
import re
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "bench"))
from _common import RE_DONE, RE_SIZES, parse_log_view_stages  # noqa: E402

STAGES = ["Migrate", "P2G", "GridUpdate", "G2P", "Constitutive", "Fluidity", "Output"]


def parse_run(d):
    text = ""
    for f in sorted(glob.glob(os.path.join(d, "*.txt")) + glob.glob(os.path.join(d, "*.out"))):
        try:
            with open(f, errors="replace") as fh:
                text += fh.read() + "\n"
        except OSError:
            pass
    r = {"dir": os.path.basename(d.rstrip("/"))}
    m = RE_SIZES.search(text)
    if m:
        r["particles"] = int(m.group(1))
        nodes = 1
        for g in m.group(2, 3, 4):
            if g:
                nodes *= int(g)
        r["grid_nodes"] = nodes
        r["ranks"] = int(m.group(5))
    else:
        m = re.search(r"np(\d+)", r["dir"])
        if m:
            r["ranks"] = int(m.group(1))
    m = RE_DONE.search(text)
    if m:
        r["steps"], r["wall_s"], r["rate"] = int(m.group(1)), float(m.group(3)), float(m.group(4))
        r["status"] = "ok"
    else:
        r["status"] = "incomplete"
    st = parse_log_view_stages(text)
    tot = sum(st.get(s, 0.0) for s in STAGES)
    for s in STAGES:
        r[s + "_share"] = st.get(s, 0.0) / tot if tot > 0 else None
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("root", help="directory holding np<ranks>/ subdirectories")
    ap.add_argument("--mode", choices=["strong", "weak"], required=True)
    ap.add_argument("-o", "--output", help="CSV file (default: stdout)")
    a = ap.parse_args()
    dirs = [d for d in glob.glob(os.path.join(a.root, "*")) if os.path.isdir(d)]
    runs = [parse_run(d) for d in dirs]
    runs = [r for r in runs if "ranks" in r]
    runs.sort(key=lambda r: r["ranks"])
    ok = [r for r in runs if r["status"] == "ok"]
    if not ok:
        sys.exit(f"collect_scaling: no completed run under {a.root}")
    ref = ok[0]
    for r in ok:
        r["rate_per_rank"] = r["rate"] / r["ranks"]
        if a.mode == "strong":
            r["speedup"] = r["rate"] / ref["rate"]
            r["efficiency"] = r["speedup"] * ref["ranks"] / r["ranks"]
            if r["particles"] != ref["particles"]:
                r["status"] = "ok (particle count differs from the reference!)"
        else:
            r["efficiency"] = (r["rate"] / r["ranks"]) / (ref["rate"] / ref["ranks"])
        r["particles_per_rank"] = r["particles"] / r["ranks"]
    cols = ["dir", "ranks", "particles", "particles_per_rank", "grid_nodes", "steps", "wall_s", "rate", "rate_per_rank", "speedup",
            "efficiency", "status"] + [s + "_share" for s in STAGES]
    out = open(a.output, "w", newline="") if a.output else sys.stdout
    w = csv.writer(out, lineterminator="\n")
    w.writerow(cols)
    for r in runs:
        w.writerow(["" if r.get(c) is None else (f"{r[c]:.6g}" if isinstance(r[c], float) else r[c]) for c in cols])
    if a.output:
        out.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
