#!/usr/bin/env python3
"""Longer fuzzing sweep of the granmpm command line (issue 14; tests/cli/fuzz.py runs 200
runs of seed 14 in ctest). Runs --runs runs for each seed in --seeds and prints one CSV
row per seed: seed, runs, seconds, clean exits, one-line errors, failures, and the five
most frequent error classes. Failing runs are printed above the CSV with their command.

    python3 bench/fuzz.py --granmpm build/granmpm --seeds 1,2,3 --runs 400
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "cli"))
import fuzz  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--granmpm", default="build/granmpm")
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--mpiflags", default="--oversubscribe" + (" --allow-run-as-root" if os.geteuid() == 0 else ""))
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--runs", type=int, default=400)
    ap.add_argument("--two-rank-fraction", type=float, default=0.2)
    ap.add_argument("--timeout", type=float, default=150)
    a = ap.parse_args()
    rows, failed = [], 0
    for seed in [int(s) for s in a.seeds.split(",")]:
        r = fuzz.fuzz(a.granmpm, a.mpiexec, a.mpiflags, a.runs, seed, 1e9, a.timeout, a.two_rank_fraction)
        s = r["stats"]
        failed += s["failed"]
        top = "; ".join("%s %d" % kv for kv in r["classes"].most_common(5))
        rows.append("%d,%d,%.0f,%d,%d,%d,\"%s\"" % (seed, r["runs"], r["seconds"], s["clean exit"], s["error"], s["failed"], top))
    print("seed,runs,seconds,clean_exits,errors,failures,top_error_classes")
    for row in rows:
        print(row)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
