#!/usr/bin/env python3
"""SIGTERM (what a scheduler sends at the time limit) makes granmpm write a checkpoint
and exit with status 143 (128 + 15, as a shell reports a process killed by SIGTERM) on
every rank count; continuing with -restart gives exactly the uninterrupted result
(profile.csv identical byte for byte), on 1 and 2 ranks. The signal is sent only after the
run printed its first progress line: earlier, the handler may not be installed yet.
The DEM (`granmpm -dem`) does the same: checkpoint, status 143, and a restart whose
dem_summary.csv is byte-identical to the uninterrupted run's."""
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


# A 2D box of about 600 disks settling under gravity: about 1 s on one idle core.
DEM = ["-dem", "-dem_dim", "2", "-dem_lo", "0,0", "-dem_hi", "0.2,0.2", "-dem_radius", "0.004", "-dem_kn", "1e5",
       "-dem_block_hi", "0.2,0.1", "-dem_fields", "0", "-dem_gravity", "0,-9.81", "-dem_t_end", "2", "-dem_output_every", "500"]


def dem_case(prefix, n, tmp):
    """SIGTERM to a DEM run after its first summary row past step 0; restart; compare."""
    full, part = os.path.join(tmp, "dem_full%d" % n), os.path.join(tmp, "dem_part%d" % n)
    p = subprocess.run(prefix + DEM + ["-dem_output_dir", full], capture_output=True, text=True, timeout=600)
    if p.returncode != 0:
        return ["uninterrupted DEM run: exit %d: %s" % (p.returncode, p.stderr.strip()[-300:])]
    p = subprocess.Popen(prefix + DEM + ["-dem_output_dir", part], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    while True:  # stepping once the row of step 500 is out
        line = p.stdout.readline()
        if not line or line.startswith("dem step 500 "):
            break
    terminate(p, n)
    out, err = p.communicate(timeout=120)
    ck = os.path.join(part, "dem_checkpoint.h5")
    problems = []
    if p.returncode != 143:
        problems.append("exit status %s, not 143" % p.returncode)
    if "received signal 15" not in out or not os.path.exists(ck):
        problems.append("no signal message or no %s (stdout %r, stderr %r)" % (ck, out[-300:], err[-300:]))
    if "PETSC ERROR" in err or "Segmentation" in err:
        problems.append("stderr: " + err[-300:])
    if not problems:
        p = subprocess.run(prefix + DEM + ["-dem_output_dir", part, "-dem_restart", ck], capture_output=True, text=True, timeout=600)
        if p.returncode != 0:
            problems.append("restart failed: " + p.stderr.strip()[-300:])
        elif not filecmp.cmp(os.path.join(full, "dem_summary.csv"), os.path.join(part, "dem_summary.csv"), shallow=False):
            problems.append("restarted dem_summary.csv differs from the uninterrupted one")
    return problems


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
        problems = dem_case(prefix, n, tmp)
        print("%s DEM: SIGTERM, checkpoint, restart on %d rank(s)%s" % ("FAIL" if problems else "ok  ", n, (": " + "; ".join(problems)) if problems else ""))
        failures += bool(problems)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
