#!/usr/bin/env python3
"""SIGTERM (what a scheduler sends at the time limit) makes granmpm write a checkpoint
and exit cleanly; continuing with -restart gives exactly the uninterrupted result
(profile.csv identical byte for byte), on 1 and 2 ranks."""
import argparse
import filecmp
import os
import signal
import subprocess
import sys
import tempfile
import time

# The default scene (nonlocal chute, 20 cells): about 4 s on one idle core.
SCENE = ["-progress_interval", "0", "-output_final", "0"]


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
        p = launch(prefix, SCENE, part)
        time.sleep(1.0 if n == 1 else 2.0)
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=120)
        ck = os.path.join(part, "checkpoint.h5")
        problems = []
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
