"""What the command-line tests share: their arguments, how a run is launched on n ranks,
and what makes a refusal correct (one 'granmpm: error:' line naming the cause, a non-zero
exit, no trace, no hang)."""
import argparse
import subprocess

# Text on stderr that a clean refusal never prints.
TRACES = ("PETSC ERROR", "Segmentation", "signal", "MPI_ABORT", "core dumped", "HDF5-DIAG")


def arguments(description=None, timeout=60):
    """The options every CLI test takes (the binary, the MPI launcher and a per-run timeout)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--granmpm", required=True)
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--mpiflags", default="--oversubscribe")
    ap.add_argument("--timeout", type=float, default=timeout)
    return ap


def command(a, n, args):
    """granmpm with args on n ranks (n = 1: without the launcher)."""
    pre = [a.granmpm] if n == 1 else [a.mpiexec] + a.mpiflags.split() + ["-n", str(n), a.granmpm]
    return pre + list(args)


def run(cmd, timeout):
    """(exit status or None on timeout, stdout, stderr)."""
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        return p.returncode, p.stdout, p.stderr
    except subprocess.TimeoutExpired:
        return None, "", "TIMEOUT"


def error_lines(err):
    return [l for l in err.splitlines() if l.startswith("granmpm: error:")]


def refusal_problems(rc, err, expect):
    """What is wrong with a run that should have been refused with one error line containing
    every string of expect (a string or a sequence); [] if nothing."""
    expect = [expect] if isinstance(expect, str) else list(expect)
    lines = error_lines(err)
    problems = []
    if rc is None:
        problems.append("timed out (hang)")
    elif rc == 0:
        problems.append("exit status 0")
    if len(lines) != 1:
        problems.append("%d 'granmpm: error:' lines" % len(lines))
    else:
        problems += ["message lacks %r" % e for e in expect if e not in lines[0]]
    problems += ["stderr contains %r" % t for t in TRACES if t in err]
    return problems


def report(name, n, problems, detail="", width=42):
    """One line per check; returns 1 on failure (for summing)."""
    print("%s %-*s ranks=%d  %s" % ("ok  " if not problems else "FAIL", width, name, n, detail))
    if problems:
        print("      problems: " + "; ".join(problems))
    return 1 if problems else 0


def refuse_all(a, cases, make_args):
    """Runs each (name, extra arguments, expected text, also on 2 ranks?) case with
    make_args(k, n, extra) on 1 (and 2) ranks and reports each refusal; (checks, failures)."""
    total = failures = 0
    for k, (name, extra, expect, two) in enumerate(cases):
        for n in ([1, 2] if two else [1]):
            total += 1
            rc, out, err = run(command(a, n, make_args(k, n, extra)), a.timeout)
            lines = error_lines(err)
            failures += report(name, n, refusal_problems(rc, err, expect), lines[0] if lines else err.strip()[:200])
    return total, failures
