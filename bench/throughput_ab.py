#!/usr/bin/env python3
"""Throughput of two granmpm binaries in one run: the cases of bench/throughput.py (periodic elastic block,
B-splines, APIC, USL, 40 steps) plus two examples whose modules run every step (annulus_local: rigid-body
node pass; silo: the plate constraint), each run on 1 and 2 ranks, new and old interleaved, repeated
(default 3) and the median particle-steps/s taken. Prints CSV: case, ranks, median rate of each binary and
the ratio new/old (> 1: the new binary is faster).

Usage: python3 bench/throughput_ab.py NEW_BINARY [OLD_BINARY] [--repeats 3] [--ranks 1,2] [--quick]
OLD_BINARY defaults to /work/base/build/granmpm. Writes bench/results/throughput_ab.csv.
"""

import argparse
import os
import statistics
import sys

import _common as C
import throughput as T

HERE = os.path.dirname(os.path.abspath(__file__))


def cases(quick):
    sizes = T.SIZES_QUICK if quick else T.SIZES_FULL
    out = [(f"block {d}D {label}", T.block_args(d, cells)) for d, label, cells in sizes if label in ("1e5",)]
    for ex, steps in (("annulus_local", 300), ("silo", 300)):
        out.append((f"example {ex}", ["-options_file", os.path.join(C.REPO_ROOT, "examples", ex + ".opts"), "-max_steps", str(steps), "-output_interval", "0",
                                       "-output_final", "0", "-progress_interval", "0"]))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("new")
    ap.add_argument("old", nargs="?", default="/work/base/build/granmpm")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--ranks", default="1,2")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    bins = {"new": os.path.abspath(a.new), "old": os.path.abspath(a.old)}
    ranks = [int(r) for r in a.ranks.split(",")]
    rates = {}
    for rep in range(a.repeats):
        for name, args in cases(a.quick):
            for np_ in ranks:
                for tag in (("new", "old") if rep % 2 == 0 else ("old", "new")):  # alternate who goes first
                    os.environ["GRANMPM"] = bins[tag]
                    r = C.run_granmpm(args, np_=np_, label=f"{name} np {np_} {tag} rep {rep + 1}")
                    if not r["ok"]:
                        sys.exit(f"throughput_ab: {name} on {np_} rank(s) failed with the {tag} binary:\n" + r["output"][-1500:])
                    rates.setdefault((name, np_, tag), []).append(r["rate"])
    rows = []
    for name, _ in cases(a.quick):
        for np_ in ranks:
            n, o = statistics.median(rates[(name, np_, "new")]), statistics.median(rates[(name, np_, "old")])
            rows.append({"case": name, "ranks": np_, "repeats": a.repeats, "rate_new": n, "rate_old": o, "ratio": n / o})
    path = os.path.join(HERE, "results", "throughput_ab.csv")
    C.write_csv(path, ["case", "ranks", "repeats", "rate_new", "rate_old", "ratio"], rows)
    C.write_meta(path, bins["new"], old=C.binary_provenance(bins["old"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
