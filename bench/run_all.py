#!/usr/bin/env python3
"""Run every GranMPM benchmark: throughput, elastic bar convergence, vertical chute convergence, stability maps,
collapse/silo sweeps, the cost of the nonlocal models and 1 -> 2 rank scaling.

  /usr/bin/python3 bench/run_all.py            full sweeps (about 1.5 h on 2 cores), update docs/*.md
  /usr/bin/python3 bench/run_all.py --quick    small sweeps (a few minutes), results in bench/results/quick/
  /usr/bin/python3 bench/run_all.py --only bar,chute
  /usr/bin/python3 bench/run_all.py --replot   redraw figures and docs sections from bench/results/*.csv

The binary is $GRANMPM (default build/granmpm). Each benchmark runs in its own process, one after another
(never concurrently: timings on a shared machine are noisy enough). The exit status is non-zero if any failed.
"""

import argparse
import os
import subprocess
import sys
import time

BENCH_DIR = os.path.dirname(os.path.abspath(__file__))
BENCHMARKS = {
    "throughput": "throughput.py",
    "bar": "bar_convergence.py",
    "chute": "chute_convergence.py",
    "stability": "stability.py",
    "stability_dynamic": "stability_dynamic.py",
    "scenes": "scenes.py",
    "implicit": "implicit_vs_explicit.py",
    "scaling": "scaling.py",
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smaller sweeps; results in bench/results/quick/, docs untouched")
    ap.add_argument("--no-docs", action="store_true", help="do not update docs/*.md")
    ap.add_argument("--replot", action="store_true", help="run nothing: redraw figures and docs sections from the existing CSVs")
    ap.add_argument("--only", default=",".join(BENCHMARKS), help="comma-separated subset of: " + ", ".join(BENCHMARKS))
    a = ap.parse_args()
    names = [n.strip() for n in a.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        ap.error(f"--only: unknown benchmark(s) {', '.join(unknown)}; choose from {', '.join(BENCHMARKS)}")
    failed = []
    for name in names:
        cmd = [sys.executable, os.path.join(BENCH_DIR, BENCHMARKS[name])]
        if a.quick:
            cmd.append("--quick")
        if a.no_docs:
            cmd.append("--no-docs")
        if a.replot:
            cmd.append("--replot")
        print(f"# run_all: {' '.join(cmd)}", file=sys.stderr, flush=True)
        t0 = time.monotonic()
        rc = subprocess.run(cmd).returncode
        print(f"# run_all: {name} finished with status {rc} in {time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)
        if rc != 0:
            failed.append(name)
    if failed:
        print(f"# run_all: failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
