#!/usr/bin/env python3
"""SIGTERM (what a scheduler sends at the time limit) makes granmpm write a checkpoint
and exit with status 143 (128 + 15, as a shell reports a process killed by SIGTERM) on
every rank count; continuing with -restart gives exactly the uninterrupted result
(profile.csv identical byte for byte), on 1 and 2 ranks. The signal is sent only after the
run printed its first progress line: earlier, the handler may not be installed yet."""
import argparse
import filecmp
import os
import signal
import subprocess
import sys
import tempfile

# The default scene (nonlocal chute, 20 cells): about 4 s on one idle core.
SCENE = ["-progress_interval", "0", "-output_final", "0"]
# The interrupted run prints a progress line every 200 steps (about 0.1 s of CPU).
STEPPING = ["-progress_interval", "200"]


def children(pid):
    """Processes whose parent is pid (the ranks that mpiexec started)."""
    kids = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open("/proc/%s/stat" % d) as f:
                    if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                        kids.append(int(d))
            except (OSError, IndexError, ValueError):
                pass
    return kids


def terminate(p, n):
    """SIGTERM as a batch scheduler sends it at the time limit: to every process of the job,
    that is to the ranks (Open MPI's mpiexec, when signalled itself, forwards the signal but
    exits with status 1 whatever the ranks return)."""
    if n == 1:
        p.send_signal(signal.SIGTERM)
    else:
        for k in children(p.pid):
            os.kill(k, signal.SIGTERM)


def launch(prefix, args, out):
    return subprocess.Popen(prefix + args + ["-output_dir", out], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--granmpm", required=True)
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--mpiflags", default="--oversubscribe")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="granmpm-sig-")
    failures = 0
    for n in (1, 2):
        prefix = [a.granmpm] if n == 1 else [a.mpiexec] + a.mpiflags.split() + ["-n", str(n), a.granmpm]
        full = os.path.join(tmp, "full%d" % n)
        p = launch(prefix, SCENE, full)
        out, err = p.communicate(timeout=600)
        if p.returncode != 0:
            print("FAIL uninterrupted run on %d rank(s): %s" % (n, err.strip()))
            failures += 1
            continue
        part = os.path.join(tmp, "part%d" % n)
        p = launch(prefix, SCENE + STEPPING, part)
        first = ""
        while True:  # wait until it is stepping (the handler is installed before set-up)
            first = p.stdout.readline()
            if not first or first.startswith("step "):
                break
        terminate(p, n)
        out, err = p.communicate(timeout=120)
        out = first + out
        ck = os.path.join(part, "checkpoint.h5")
        problems = []
        if p.returncode != 143:
            problems.append("exit status %s, not 143 (128 + SIGTERM)" % p.returncode)
        if "received signal 15" not in out:
            problems.append("no 'received signal 15' message (stdout: %r, stderr: %r)" % (out[-300:], err[-300:]))
        if not os.path.exists(ck):
            problems.append("no checkpoint written")
        if "PETSC ERROR" in err or "Segmentation" in err:
            problems.append("stderr: " + err[-300:])
        if not problems:
            p = launch(prefix, SCENE + ["-restart", ck], part)
            out, err = p.communicate(timeout=600)
            if p.returncode != 0:
                problems.append("restart failed: " + err.strip())
            elif not filecmp.cmp(os.path.join(full, "profile.csv"), os.path.join(part, "profile.csv"), shallow=False):
                problems.append("restarted profile.csv differs from the uninterrupted one")
        print("%s SIGTERM, checkpoint, restart on %d rank(s)%s" % ("FAIL" if problems else "ok  ", n, (": " + "; ".join(problems)) if problems else ""))
        failures += bool(problems)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
