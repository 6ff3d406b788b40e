#!/usr/bin/env python3
"""Small scenes on 1 and 2 ranks: microseconds per step of the 80-cell nonlocal chute (issue 16 goal 3).

Runs examples/chute_nonlocal.opts -cells 80,4 -domain_hi 0.5,0.05 (320 particles) for --steps steps, no
output, on 1 and 2 ranks, with the binary of $GRANMPM (default build/granmpm) and, with --base BINARY,
that binary too; interleaved (binary, ranks) within each of --repeats rounds. Prints CSV: one row per
run (wall time of the time loop as granmpm prints it, us per step, CPU seconds of all processes), then
one "median" row per (binary, ranks). On a loaded machine the 2-rank figure measures how often the
partner rank is descheduled at a synchronisation: set MPIEXEC (e.g. "mpiexec --oversubscribe
--allow-run-as-root --mca mpi_yield_when_idle 1") to change how waiting ranks poll.
"""

import argparse
import os
import sys

import _common as C


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--base", help="a second granmpm binary (e.g. a build of main), run interleaved")
    a = ap.parse_args()
    if a.steps < 1 or a.repeats < 1:
        sys.exit("small_ranks: --steps and --repeats must be positive")
    bins = [("this", C.granmpm_binary())] + ([("base", os.path.abspath(a.base))] if a.base else [])
    args = ["-options_file", os.path.join(C.REPO_ROOT, "examples", "chute_nonlocal.opts"), "-cells", "80,4", "-domain_hi", "0.5,0.05",
            "-output_final", "0", "-progress_interval", "0", "-max_steps", str(a.steps)]
    print("binary,ranks,repeat,wall_s,us_per_step,cpu_s,loadavg")
    got = {}
    for r in range(1, a.repeats + 1):
        for np_ in (1, 2):
            for name, path in bins:
                os.environ["GRANMPM"] = path
                res = C.run_granmpm(args, np_=np_)
                if not res["ok"]:
                    sys.exit(f"small_ranks: {name} on {np_} rank(s) failed: {C.error_line(res['output'])}")
                us = res["wall_s"] / a.steps * 1e6
                got.setdefault((name, np_), []).append(us)
                print(f"{name},{np_},{r},{res['wall_s']:.2f},{us:.1f},{res['cpu_s']:.2f},{res['loadavg']:.2f}", flush=True)
    for (name, np_), v in got.items():
        print(f"{name},{np_},median,,{C.median(v):.1f},,")


if __name__ == "__main__":
    main()
