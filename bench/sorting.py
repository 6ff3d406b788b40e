#!/usr/bin/env python3
"""Particle sorting by cell (-sort_interval): throughput with and without.

  /usr/bin/python3 bench/sorting.py [--quick] [--repeats N]

Cases: the elastic block of bench/throughput.py (3D and 2D, about 1e5 particles, quadratic
B-splines + APIC, 1 rank, 200 steps), and the 2D silo of examples/silo.opts on 2 ranks
(1000 steps: particles flow, migrate and get mixed, which is where order degrades).
Each case with -sort_interval 0 (off) and the given intervals, repeats interleaved, medians.
Writes bench/results/sorting.csv (quick: bench/results/quick/). Docs are written by hand
from the printed table (docs/performance.md, "Particle sorting").
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402
import throughput as T  # noqa: E402
from balance import SCENES  # noqa: E402


def main():
    ap = C.common_argparser(__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--intervals", default="0,20")
    a = ap.parse_args()
    steps = 50 if a.quick else 200
    silo_steps = 200 if a.quick else 1000
    cases = [("block 3D 1e5", T.block_args(3, (25, 25, 20), steps=steps), 1),
             ("block 2D 1e5", T.block_args(2, (250, 100), steps=steps), 1),
             ("silo 2D", SCENES["silo"] + ["-max_steps", str(silo_steps), "-progress_interval", "0"], 2)]
    intervals = [int(x) for x in a.intervals.split(",")]
    runs = []
    for rep in range(a.repeats):
        for name, args, np_ in cases:
            for si in intervals:
                r = C.run_granmpm(args + ["-sort_interval", str(si)], np_=np_, label=f"{name} sort {si} rep {rep + 1}")
                runs.append({"case": name, "ranks": np_, "sort_interval": si, "repeat": rep + 1, "particles": r.get("particles"), "steps": r.get("steps"),
                             "wall_s": r.get("wall_s"), "rate": r.get("rate"), "cpu_s": r["cpu_s"], "loadavg": r["loadavg"], "ok": r["ok"],
                             "cmd": r["cmd"]})
    csv_path, _ = C.output_paths("sorting", a.quick)
    C.write_csv(csv_path, list(runs[0].keys()), runs)
    print()
    rows = []
    for name, args, np_ in cases:
        base = base_cpu = None
        for si in intervals:
            rs = [x for x in runs if x["case"] == name and x["sort_interval"] == si and x["ok"]]
            rate = C.median([x["rate"] for x in rs])
            base = rate if si == 0 else base
            cpu = C.median([x["particles"] * x["steps"] / x["cpu_s"] for x in rs])
            base_cpu = cpu if si == 0 else base_cpu
            rows.append([name, np_, si, f"{rate:.3g}", f"{min(x['rate'] for x in rs):.3g}-{max(x['rate'] for x in rs):.3g}",
                         f"{rate / base:.2f}" if base else "-", f"{cpu:.3g}", f"{cpu / base_cpu:.2f}", f"{sum(x['loadavg'] for x in rs) / len(rs):.1f}"])
    print(C.md_table(["case", "ranks", "-sort_interval", "particle-steps/s (median)", "range", "vs unsorted", "per CPU-second", "vs unsorted",
                      "load avg"], rows, ["l"] + ["r"] * 8))
    for name, args, np_ in cases:
        print(f"\n{name}: " + C.shown_cmd(args + ["-sort_interval", str(intervals[-1])], np_))


if __name__ == "__main__":
    main()
