#!/usr/bin/env python3
"""Seeded, reproducible fuzzing of the granmpm command line (issue 14).

The option table is read from `granmpm -help` (name, kind, default, choices). Each run
takes one of the examples/ scenes, changes 1-4 options drawn from that table with valid,
boundary, non-finite or nonsense values (scene, material and boundary options included,
so their combinations are drawn too), caps the run at a few steps and checks that it

  - exits 0 and every CSV it wrote is finite (no nan/inf), or
  - exits non-zero with exactly one line 'granmpm: error: ...' on stderr and no PETSc
    trace,

and never dies by a signal, an MPI abort or a timeout (a hang). A failing run is printed
with its full command line, so it can be reproduced by hand. `--runs`, `--seed` and
`--budget` (seconds: runs stop being started after it, the count run is printed) set the
size; bench/fuzz.py runs the longer sweep and writes the counts as CSV.
"""
import argparse
import collections
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
EXAMPLES = os.path.normpath(os.path.join(HERE, "..", "..", "examples"))
# The scenes runs start from (the slowest example, the resolved 3D Taylor-Couette
# nonlocal cell, is left out to keep the suite short).
BASES = ["annulus_local", "annulus_nonlocal", "bar", "blade", "block_3d", "block_spin", "chute_dynamic", "chute_local",
         "chute_nonlocal", "collapse", "collapse_3d", "column", "silo", "silo_3d", "taylor_couette_3d_local", "wheel", None]
# Options not drawn: output location and run length are set by the fuzzer; -memory_check 0
# would let a drawn huge grid allocate until the machine refuses; -help/-quiet change
# nothing to check.
SKIP = {"-output_dir", "-checkpoint_file", "-max_steps", "-memory_check", "-help", "-quiet", "-progress_interval"}
MAX_STEPS = 4
# A 3D implicit step of silo_3d costs ~14 s of CPU (4 Newton, 21 Krylov iterations): 3D bases
# run 2 steps, so that a slow but progressing run stays well inside the hang timeout.
MAX_STEPS_3D = 2
LINE = re.compile(r"^\s+(-\w+)(:)?\s*<([^>]*)>:?\s*(.*)$")
NONFINITE = re.compile(r"(?<![a-z])(nan|inf|infinity)(?![a-z])", re.I)


def option_table(granmpm):
    """[(name, kind, default, choices)] from -help; kind: bool|int|real|string|array."""
    p = subprocess.run([granmpm, "-help", "-output_dir", tempfile.mkdtemp(prefix="granmpm-fuzz-help-")], capture_output=True, text=True, timeout=120)
    table, seen = [], set()
    started = False
    for line in p.stdout.splitlines():
        if line.startswith("GranMPM options"):
            started = True
            continue
        if not started:
            continue
        if line and not line.startswith(" "):
            break  # the next PETSc section
        m = LINE.match(line)
        if not m or m.group(1) in seen:
            continue
        name, colon, inside, desc = m.group(1), m.group(2), m.group(3), m.group(4)
        seen.add(name)
        if colon:
            kind, default = "bool", inside.split(":")[0].strip()
        elif inside.startswith("now "):
            default = inside[4:].split(" : ")[0].strip()
            kind = "int" if re.fullmatch(r"-?\d+", default) else "string"
        elif " : " in inside:
            kind, default = "real", inside.split(" : ")[0].strip()
        else:
            kind, default = "array", inside.strip()
        choices = []
        if kind == "string" and "|" in desc:
            # "...: a|b|c (...)" or "a (...) | b (...)": the word before each '|' and after.
            pieces = desc.split("|")
            first = re.match(r"[^:]*:\s*([a-z0-9_]+)", pieces[0])
            choices = ([first.group(1)] if first else []) + [re.match(r"\s*([a-z0-9_]*)", x).group(1) for x in pieces[1:]]
            choices = [c for c in choices if c]
            if name.endswith("_contact"):
                choices = ["sticky", "friction"]
        table.append((name, kind, default, choices))
    return table


def real_value(rng, default):
    try:
        d = float(default)
    except ValueError:
        d = 1.0
    cls = rng.choices(["valid", "boundary", "nonfinite", "nonsense"], [0.45, 0.25, 0.15, 0.15])[0]
    if cls == "valid":
        v = d * rng.uniform(0.5, 2.0) if d != 0 else rng.uniform(0, 1)
        return "%.6g" % v, cls
    if cls == "boundary":
        return rng.choice(["0", "-0", "-1", "1", "1e-300", "1e300", "-1e-12", "1e-12", "4.9e-324", "1.7976931348623157e308"]), cls
    if cls == "nonfinite":
        return rng.choice(["inf", "-inf", "nan", "NaN", "1e400", "-1e999", "Infinity"]), cls
    return rng.choice(["abc", "1,2", "0x1p3", "1e", "--", "1.5.2", "one"]), cls


def int_value(rng, default):
    try:
        d = int(default)
    except ValueError:
        d = 1
    cls = rng.choices(["valid", "boundary", "nonsense"], [0.5, 0.3, 0.2])[0]
    if cls == "valid":
        return str(max(0, d + rng.randint(-2, 3))), cls
    if cls == "boundary":
        return rng.choice(["0", "-1", "1", "2147483647", "2147483648", "-2147483648", "99999999999"]), cls
    return rng.choice(["1.5", "x", "3e2", "inf", "nan", "--"]), cls


def array_value(rng, name, default):
    n = rng.choice([2, 2, 3]) if rng.random() < 0.9 else rng.choice([1, 4])
    integer = name in ("-cells",)
    comps, cls = [], "valid"
    for _ in range(n):
        if integer:
            v, c = int_value(rng, "8")
            if c == "valid":
                v = str(rng.randint(1, 24))
        else:
            v, c = real_value(rng, default)
        comps.append(v)
        if c != "valid":
            cls = c
    return ",".join(comps), cls


def draw(rng, table):
    name, kind, default, choices = rng.choice(table)
    if kind == "bool":
        return [name, rng.choice(["true", "false", "0", "1", "maybe"])], "valid"
    if kind == "int":
        v, c = int_value(rng, default)
        return [name, v], c
    if kind == "real":
        v, c = real_value(rng, default)
        return [name, v], c
    if kind == "array":
        v, c = array_value(rng, name, default)
        return [name, v], c
    if name == "-restart":
        return [name, rng.choice(["/nonexistent/ck.h5", "/dev/null", EXAMPLES + "/bar.opts"])], "nonsense"
    if name.endswith("_path"):
        return [name, rng.choice(["0,0,0.1;1,0.2,0.1", "0,0,0;0,1,1", "x", "0,inf,0;1,0,0", "0,0,0.1"])], "valid"
    if choices and rng.random() < 0.85:
        return [name, rng.choice(choices)], "valid"
    return [name, rng.choice(["xyz", "none", "1", ""])], "nonsense"


def make_runs(rng, table, nruns, two_rank_fraction):
    runs = []
    for _ in range(nruns):
        base = rng.choice(BASES)
        args = ["-options_file", os.path.join(EXAMPLES, base + ".opts")] if base else []
        classes = []
        for _ in range(rng.choice([1, 1, 2, 2, 3, 4])):
            a, c = draw(rng, table)
            args += a
            classes.append(c)
        if rng.random() < 0.3:
            args += ["-output_interval", "2"]
        ranks = 2 if rng.random() < two_rank_fraction else 1
        runs.append((base or "default", args, classes, ranks))
    return runs


def nonfinite_csv(outdir):
    bad = []
    for root, _, files in os.walk(outdir):
        for f in files:
            if not f.endswith(".csv"):
                continue
            with open(os.path.join(root, f), errors="replace") as fh:
                for n, line in enumerate(fh):
                    if NONFINITE.search(line):
                        bad.append("%s line %d: %s" % (f, n + 1, line.strip()[:120]))
                        break
    return bad


def error_class(line):
    """A short class for an error line: the option it names, or its first words."""
    text = line[len("granmpm: error: "):]
    m = re.match(r"(-[A-Za-z0-9_/]+)", text)
    if m:
        return m.group(1).split("/")[0]
    return " ".join(text.split()[:4])


KINDS = [("non-finite value", ("is not a finite number",)),
         ("unparsable value or wrong count", ("invalid value", "unknown value", "expected ", "unknown degree", "is not t,x,y", "numbers, expected", "cannot read")),
         ("unknown or unused option", ("unknown option",)),
         ("run-time guard", ("unstable", "left the domain", "did not converge", "moved", "cannot split", "exceeds its mass")),
         ("value out of range", ("must be", "must satisfy", "must lie", "must exceed", "must increase", "needs at least", "must not")),
         ]


def error_kind(line):
    """Coarse kind of an error line; what matches none is a refused combination."""
    for kind, keys in KINDS:
        if any(k in line for k in keys):
            return kind
    return "refused combination or physics check"


def check(rc, err, outdir):
    problems = []
    if rc is None:
        return ["timed out (hang)"]
    lines = [l for l in err.splitlines() if l.startswith("granmpm: error:")]
    for bad in ("PETSC ERROR", "Segmentation", "signal ", "MPI_ABORT", "core dumped", "Aborted", "terminate called"):
        if bad in err:
            problems.append("stderr contains %r" % bad)
    if rc < 0:
        problems.append("killed by signal %d" % -rc)
    elif rc == 0:
        if lines:
            problems.append("exit 0 with an error line")
        problems += ["non-finite CSV: " + b for b in nonfinite_csv(outdir)]
    else:
        if len(lines) != 1:
            problems.append("exit %d with %d 'granmpm: error:' lines" % (rc, len(lines)))
    return problems


def fuzz(granmpm, mpiexec, mpiflags, runs, seed, budget, timeout, two_rank_fraction=0.1, verbose=False):
    rng = random.Random(seed)
    table = [t for t in option_table(granmpm) if t[0] not in SKIP]
    if len(table) < 50:
        raise SystemExit("fuzz: only %d options parsed from granmpm -help" % len(table))
    plan = make_runs(rng, table, runs, two_rank_fraction)
    tmp = tempfile.mkdtemp(prefix="granmpm-fuzz-")
    stats = collections.Counter()
    classes = collections.Counter()
    kinds = collections.Counter()
    drawn = collections.Counter()
    failures = []
    t0 = time.time()
    done = 0
    for i, (base, args, value_classes, ranks) in enumerate(plan):
        if time.time() - t0 > budget:
            break
        outdir = os.path.join(tmp, "run%04d" % i)
        steps = MAX_STEPS_3D if base.endswith("_3d") or base == "taylor_couette_3d_local" else MAX_STEPS
        full = args + ["-max_steps", str(steps), "-output_dir", outdir, "-progress_interval", "0"]
        cmd = ([granmpm] if ranks == 1 else [mpiexec] + mpiflags.split() + ["-n", str(ranks), granmpm]) + full
        try:
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
            rc, err = p.returncode, p.stderr
        except subprocess.TimeoutExpired:
            rc, err = None, ""
        done += 1
        for c in value_classes:
            drawn[c] += 1
        problems = check(rc, err, outdir)
        if problems:
            stats["failed"] += 1
            failures.append((i, cmd, problems, err))
            print("FAIL run %d (%s, %d rank%s): %s\n     %s" % (i, base, ranks, "s" if ranks > 1 else "", "; ".join(problems), " ".join(cmd)))
            print("     stderr: " + err.strip().replace("\n", "\n             ")[:1500])
        elif rc == 0:
            stats["clean exit"] += 1
        else:
            stats["error"] += 1
            line = [l for l in err.splitlines() if l.startswith("granmpm: error:")][0]
            classes[error_class(line)] += 1
            kinds[error_kind(line)] += 1
            if verbose:
                print("ok   run %d: %s" % (i, line[:160]))
        shutil.rmtree(outdir, ignore_errors=True)
    shutil.rmtree(tmp, ignore_errors=True)
    return {"runs": done, "planned": len(plan), "seconds": time.time() - t0, "stats": stats, "classes": classes, "kinds": kinds,
            "drawn": drawn, "failures": failures, "options": len(table)}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--granmpm", required=True)
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--mpiflags", default="--oversubscribe")
    ap.add_argument("--runs", type=int, default=240)
    ap.add_argument("--seed", type=int, default=14)
    ap.add_argument("--budget", type=float, default=210, help="seconds after which no run is started")
    ap.add_argument("--timeout", type=float, default=150, help="seconds after which a run counts as hung (a 3D implicit step takes ~4 s unloaded)")
    ap.add_argument("--verbose", action="store_true")
    a = ap.parse_args()
    r = fuzz(a.granmpm, a.mpiexec, a.mpiflags, a.runs, a.seed, a.budget, a.timeout, verbose=a.verbose)
    s = r["stats"]
    print("fuzz: seed %d, %d options from -help, %d of %d planned runs in %.0f s: %d clean exits, %d one-line errors, %d failures"
          % (a.seed, r["options"], r["runs"], r["planned"], r["seconds"], s["clean exit"], s["error"], s["failed"]))
    print("values drawn: " + ", ".join("%s %d" % kv for kv in sorted(r["drawn"].items())))
    print("errors by kind: " + ", ".join("%s %d" % kv for kv in r["kinds"].most_common()))
    print("errors by option named: " + ", ".join("%s %d" % kv for kv in r["classes"].most_common()))
    return 1 if s["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
