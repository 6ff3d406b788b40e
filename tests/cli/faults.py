#!/usr/bin/env python3
"""Faults, restarts and output of issue 14 (part A), each on 1 and 2 ranks:
  empty swarm  a silo that discharges every particle: snapshots, XDMF, checkpoint and CSV
               are written (no .tmp left), and a restart from the empty checkpoint runs;
  corruption   a flipped byte in the checkpoint's mass dataset is refused, naming it;
  overwrite    a new run into another run's results is refused unless -output_overwrite
               (which removes the old snapshots), a restart into it is allowed;
  other dir    a restart into another -output_dir writes XDMF that references only files
               that exist (checked by parsing every DataItem), and says what it links;
  physics      a restart with other -E and -rho is refused, listing both;
  instability  -on_instability checkpoint_and_abort keeps a state from before the first
               sign of instability; a restart from it with the advised smaller -dt runs to
               the end and gives the result of a fresh run with that -dt (byte for byte);
  past t_end   a restart at -t_end says so and reports no throughput;
  write faults a checkpoint path under /proc, a directory in the way of a snapshot's or a
               checkpoint's temporary, and a directory in the way of profile.csv: one
               `granmpm: error:` line with the cause and the option, no temporary left;
  SIGUSR1      writes a checkpoint and the run continues to the end (exit 0);
  bodies.csv   a restart drops the rows written after the checkpoint before appending;
  disk full    (root only: a tiny tmpfs) the failed snapshot stops every rank with the cause
               and leaves no temporary."""
import filecmp
import glob
import math
import os
import re
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

import _cli

QUIET = ["-progress_interval", "0"]
# A small silo (h = 2 cm) with an orifice as wide as the silo: empty after about 0.3 s.
SILO = ["-options_file", None, "-cells", "20,25", "-ppc", "1", "-silo_orifice", "0.4", "-output_interval", "400", "-checkpoint_interval", "700"]


class Runner:
    def __init__(self, a):
        self.a = a
        self.failures = 0

    def cmd(self, n, args):
        return _cli.command(self.a, n, args)

    def run(self, n, args, timeout=300):
        p = subprocess.run(self.cmd(n, args), capture_output=True, text=True, timeout=timeout)
        return p.returncode, p.stdout, p.stderr

    def check(self, name, n, problems):
        print("%s %-58s ranks=%d%s" % ("FAIL" if problems else "ok  ", name, n, (": " + "; ".join(problems)) if problems else ""))
        sys.stdout.flush()
        self.failures += bool(problems)

    def error_case(self, name, n, args, expect):
        """Must exit non-zero with one `granmpm: error:` line containing every string of expect."""
        rc, out, err = self.run(n, args)
        lines = _cli.error_lines(err)
        problems = _cli.refusal_problems(rc, err, expect)
        if problems and lines:
            problems.append("(line %r)" % lines[0])
        elif problems:
            problems.append("(stderr %r)" % err[-400:])
        self.check(name, n, problems)
        return lines[0] if lines else ""


def temporaries(d):
    return [f for f in glob.glob(os.path.join(d, "**", "*.tmp"), recursive=True)]


def xdmf_files(xmf):
    """The HDF5 files every DataItem of an XDMF file references, resolved from its directory."""
    root = ET.parse(xmf).getroot()
    refs = set()
    for item in root.iter("DataItem"):
        if item.get("Format") == "HDF":
            refs.add(os.path.normpath(os.path.join(os.path.dirname(xmf), item.text.strip().split(":")[0])))
    return refs


def particle_counts(xmf):
    root = ET.parse(xmf).getroot()
    return [int(t.get("NumberOfElements")) for t in root.iter("Topology")]


def empty_swarm(R, n, tmp, silo_opts):
    d = os.path.join(tmp, "silo%d" % n)
    args = [x if x is not None else silo_opts for x in SILO] + QUIET
    rc, out, err = R.run(n, args + ["-t_end", "0.5", "-output_dir", d])
    problems = [] if rc == 0 else ["exit %d: %s" % (rc, err[-300:])]
    if not problems:
        for f in ("silo.csv", "silo_summary.csv", "checkpoint.h5", "particles.xmf", "grid.xmf"):
            if not os.path.exists(os.path.join(d, f)):
                problems.append("no " + f)
        counts = particle_counts(os.path.join(d, "particles.xmf"))
        if not counts or counts[0] == 0 or counts[-1] != 0:
            problems.append("particle counts per snapshot %s: expected full at first, empty at the end" % counts)
        if temporaries(d):
            problems.append("temporaries left: %s" % temporaries(d))
        missing = [f for f in xdmf_files(os.path.join(d, "particles.xmf")) if not os.path.exists(f)]
        if missing:
            problems.append("XDMF references missing files %s" % missing)
        m = re.search(r"(\d+) particles left through outlets", out)
        if not m or int(m.group(1)) == 0:
            problems.append("no particle discharged (stdout %r)" % out[-300:])
    R.check("empty swarm: snapshots, XDMF, checkpoint, CSV written", n, problems)
    if problems:
        return
    # Restart from the empty checkpoint (on the other rank count too) and run on.
    for m in (1, 2):
        rc, out, err = R.run(m, args + ["-t_end", "0.6", "-output_dir", d, "-restart", os.path.join(d, "checkpoint.h5")])
        p = [] if rc == 0 else ["exit %d: %s" % (rc, err[-300:])]
        if not p and "restarted from" not in out:
            p.append("no restart message")
        if not p and particle_counts(os.path.join(d, "particles.xmf"))[-1] != 0:
            p.append("the restarted run's last snapshot is not empty")
        R.check("empty swarm: restart from the empty checkpoint on %d rank(s)" % m, n, p)


def corrupt_mass(R, n, tmp):
    d = os.path.join(tmp, "corrupt%d" % n)
    rc, out, err = R.run(1, ["-max_steps", "3", "-checkpoint_interval", "3", "-output_dir", d, "-output_final", "0"] + QUIET)
    ck = os.path.join(d, "checkpoint.h5")
    data = bytearray(open(ck, "rb").read())
    # Default chute: every particle has mass rho (h/ppc)^2 = 1500 * 0.05^2 = 3.75 kg/m (to a
    # few ulps); the 80 of them are the only run of 80 equal such doubles: /particles/mass.
    at, run = -1, b""
    v = 3.75
    for _ in range(4):
        v = math.nextafter(v, 0)
    for _ in range(9):
        run = struct.pack("<d", v) * 80
        at = data.find(run)
        if at >= 0:
            break
        v = math.nextafter(v, 4)
    if at < 0 or data.find(run, at + 1) >= 0:
        R.check("flipped byte in /particles/mass refused", n, ["cannot locate the mass dataset"])
        return
    data[at + 8 * 17 + 6] ^= 0x10  # particle 17: 3.75 -> another finite positive value
    bad = os.path.join(d, "flipped.h5")
    open(bad, "wb").write(data)
    R.error_case("flipped byte in /particles/mass refused", n, ["-output_dir", os.path.join(d, "r"), "-restart", bad], ["/particles/mass", "checksum", "corrupt"])


def overwrite(R, n, tmp):
    d = os.path.join(tmp, "over%d" % n)
    R.run(1, ["-max_steps", "20", "-output_interval", "5", "-output_dir", d] + QUIET)
    R.error_case("new run into another run's results refused", n, ["-max_steps", "3", "-output_dir", d], ["holds another run's results", "-output_overwrite", "-restart"])
    rc, out, err = R.run(n, ["-max_steps", "10", "-output_interval", "5", "-output_dir", d, "-output_overwrite"] + QUIET)
    problems = [] if rc == 0 else ["-output_overwrite: exit %d: %s" % (rc, err[-300:])]
    if not problems:
        snaps = sorted(os.path.basename(f) for f in glob.glob(os.path.join(d, "snap_*.h5")))
        if snaps != ["snap_000000.h5", "snap_000001.h5", "snap_000002.h5"]:
            problems.append("old snapshots mixed in: %s" % snaps)
        if particle_counts(os.path.join(d, "particles.xmf")) != [80, 80, 80]:
            problems.append("particles.xmf does not list exactly the 3 new snapshots")
    R.check("-output_overwrite replaces the old run's snapshots", n, problems)
    rc, out, err = R.run(n, ["-max_steps", "5", "-checkpoint_interval", "5", "-output_dir", d, "-output_overwrite"] + QUIET)
    rc, out, err = R.run(n, ["-max_steps", "10", "-output_dir", d, "-restart", os.path.join(d, "checkpoint.h5")] + QUIET)
    R.check("restart into its own directory allowed", n, [] if rc == 0 else ["exit %d: %s" % (rc, err[-300:])])


def other_dir(R, n, tmp):
    a = os.path.join(tmp, "dirA%d" % n)
    R.run(n, ["-max_steps", "20", "-output_interval", "5", "-checkpoint_interval", "20", "-output_final", "0", "-output_dir", a] + QUIET)
    problems = []
    for sub, drop in (("dirB%d" % n, False), ("dirC%d" % n, True)):
        b = os.path.join(tmp, sub)
        if drop:
            os.remove(os.path.join(a, "snap_000001.h5"))
        rc, out, err = R.run(n, ["-max_steps", "30", "-output_interval", "5", "-output_dir", b, "-restart", os.path.join(a, "checkpoint.h5")] + QUIET)
        if rc != 0:
            problems.append("restart into %s: exit %d: %s" % (sub, rc, err[-300:]))
            continue
        for kind in ("particles", "grid"):
            refs = xdmf_files(os.path.join(b, kind + ".xmf"))
            missing = [f for f in refs if not os.path.exists(f)]
            if missing:
                problems.append("%s/%s.xmf references missing %s" % (sub, kind, missing))
            old = [f for f in refs if os.path.dirname(f) == os.path.normpath(a)]
            if len(old) != (4 if drop else 5):
                problems.append("%s/%s.xmf links %d old snapshots, expected %d" % (sub, kind, len(old), 4 if drop else 5))
            if len(refs) != len(old) + 2:
                problems.append("%s/%s.xmf references %d files, expected %d" % (sub, kind, len(refs), len(old) + 2))
        if "links the %d earlier snapshot" % (4 if drop else 5) not in out or (drop and "1 snapshot(s) no longer there are left out" not in out):
            problems.append("restart into %s does not say what it links (stdout %r)" % (sub, out[-400:]))
    R.check("restart into another -output_dir: XDMF references only existing files", n, problems)


def physics(R, n, tmp, checkpoint):
    R.error_case("restart with changed -E and -rho refused, both listed", n,
                 ["-output_dir", os.path.join(tmp, "phys%d" % n), "-restart", checkpoint, "-E", "2e8", "-rho", "1600"], ["-E is '100000000' there but '200000000' here", "-rho is '1500' there but '1600' here", "2 scene or physics option(s) differ"])
    rc, out, err = R.run(n, ["-output_dir", os.path.join(tmp, "phys%d" % n), "-restart", checkpoint, "-max_steps", "6", "-dt", "1e-4", "-cfl", "0.4", "-output_final", "0"] + QUIET)
    R.check("restart with changed time options accepted", n, [] if rc == 0 else ["exit %d: %s" % (rc, err[-300:])])


def instability(R, n, tmp):
    d = os.path.join(tmp, "unstable%d" % n)
    msg = R.error_case("checkpoint_and_abort on an unstable step", n, ["-t_end", "0.1", "-dt", "1e-3", "-dt_allow_unstable", "-on_instability", "checkpoint_and_abort", "-output_dir", d, "-output_final", "0"] + QUIET,
                       ["the run is unstable", "before the first sign of instability", "checkpoint_last_good.h5"])
    ck = os.path.join(d, "checkpoint_last_good.h5")
    problems = []
    rc, out, err = R.run(n, ["-t_end", "0.1", "-dt", "1e-4", "-output_dir", d, "-output_final", "0", "-restart", ck] + QUIET)
    if rc != 0:
        problems.append("restart with -dt 1e-4: exit %d: %s" % (rc, err[-300:]))
    else:
        f = os.path.join(tmp, "fresh%d" % n)
        rc, out, err = R.run(n, ["-t_end", "0.1", "-dt", "1e-4", "-output_dir", f, "-output_final", "0"] + QUIET)
        # The guards saw the first sign (a fixed step above the CFL limit) at step 0: the last
        # good state is the initial one, so the restart is the fresh run with the smaller dt.
        if rc != 0 or not filecmp.cmp(os.path.join(d, "profile.csv"), os.path.join(f, "profile.csv"), shallow=False):
            problems.append("restart from the last good state differs from a fresh run with -dt 1e-4")
    R.check("restart from the last good state with a smaller -dt runs to the end", n, problems)


def past_end(R, n, tmp, checkpoint):
    rc, out, err = R.run(n, ["-output_dir", os.path.join(tmp, "past%d" % n), "-restart", checkpoint, "-t_end", "1e-4"] + QUIET)
    problems = [] if rc == 0 else ["exit %d: %s" % (rc, err[-300:])]
    if "at or past -t_end" not in out or "nothing to run" not in out:
        problems.append("does not say so (stdout %r)" % out[-300:])
    if "particle-steps/s" in out:
        problems.append("reports a throughput")
    R.check("restart at or past -t_end says so", n, problems)


def write_faults(R, n, tmp):
    d = os.path.join(tmp, "wf%d" % n)
    R.error_case("checkpoint file under /proc", n, ["-max_steps", "4", "-checkpoint_interval", "2", "-checkpoint_file", "/proc/granmpm-nowhere/ck.h5", "-output_dir", d] + QUIET,
                 ["cannot create /proc/granmpm-nowhere/ck.h5.tmp", "does not exist", "-checkpoint_file"])
    for what, blocker, extra, expect in (
        ("snapshot", "snap_000002.h5.tmp", ["-output_interval", "2"], ["cannot create", "snap_000002.h5.tmp", "a directory of that name is in the way", "-output_dir"]),
        ("checkpoint", "checkpoint.h5.tmp", ["-checkpoint_interval", "3"], ["cannot create", "checkpoint.h5.tmp", "in the way", "-checkpoint_file"]),
        ("CSV result", "profile.csv", [], ["cannot write", "profile.csv", "Is a directory", "-output_dir"]),
    ):
        w = os.path.join(d, what.replace(" ", "_"))
        shutil.rmtree(w, ignore_errors=True)
        os.makedirs(os.path.join(w, blocker))
        R.error_case("%s write fails mid-run: stops with the cause" % what, n, ["-max_steps", "6", "-output_dir", w] + extra + QUIET, expect)
        left = temporaries(w)
        left = [f for f in left if os.path.basename(f) != blocker]
        R.check("%s write fails: no temporary left" % what, n, ["left: %s" % left] if left else [])


def bodies_rows(R, n, tmp, examples):
    """A restart appends to bodies.csv: the rows the old run wrote after the checkpoint go."""
    o = ["-options_file", os.path.join(examples, "blade.opts"), "-max_steps", "300", "-bodies_interval", "50", "-output_interval", "0", "-output_final", "0"] + QUIET
    full, part = os.path.join(tmp, "blade_full%d" % n), os.path.join(tmp, "blade_part%d" % n)
    R.run(n, o + ["-output_dir", full])
    R.run(n, o + ["-output_dir", part, "-checkpoint_interval", "200"])  # checkpoint at 200, rows to 300
    rc, out, err = R.run(n, o + ["-output_dir", part, "-restart", os.path.join(part, "checkpoint.h5")])
    same = rc == 0 and filecmp.cmp(os.path.join(full, "bodies.csv"), os.path.join(part, "bodies.csv"), shallow=False)
    R.check("restart: bodies.csv equals the uninterrupted run's (no doubled rows)", n, [] if same else ["rc %d, bodies.csv differs: %s" % (rc, err[-300:])])


def disk_full(R, n, tmp):
    """Optional (root only): a 200 KiB tmpfs fills at the 5th snapshot of the default chute."""
    d = os.path.join(tmp, "full%d" % n)
    os.makedirs(d)
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=200k", "tmpfs", d], capture_output=True).returncode != 0:
        print("skip disk full (needs root and mount)")
        return
    try:
        o = os.path.join(d, "o")
        R.error_case("disk full during a snapshot: stops with the cause", n, ["-output_dir", o, "-output_interval", "1", "-max_steps", "50"] + QUIET,
                     ["HDF5 failed to write", "snap_000004.h5", "enough space; 0 bytes free there"])
        R.check("disk full: no temporary left", n, ["left: %s" % temporaries(o)] if temporaries(o) else [])
    finally:
        subprocess.run(["umount", d], capture_output=True)


def sigusr1(R, n, tmp):
    d = os.path.join(tmp, "usr%d" % n)
    p = subprocess.Popen(R.cmd(n, ["-t_end", "0.3", "-progress_interval", "200", "-output_final", "0", "-output_dir", d]), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = ""
    while True:
        first = p.stdout.readline()
        if not first or first.startswith("step "):
            break
    targets = [p.pid] if n == 1 else [int(k) for k in os.listdir("/proc") if k.isdigit() and _ppid(int(k)) == p.pid]
    for k in targets:
        os.kill(k, signal.SIGUSR1)
    out, err = p.communicate(timeout=300)
    problems = [] if p.returncode == 0 else ["exit %d: %s" % (p.returncode, err[-300:])]
    if "received SIGUSR1" not in out:
        problems.append("no SIGUSR1 message (stdout %r)" % out[-300:])
    if "GranMPM: done" not in out or not os.path.exists(os.path.join(d, "checkpoint.h5")) or not os.path.exists(os.path.join(d, "profile.csv")):
        problems.append("did not checkpoint and run to the end")
    R.check("SIGUSR1 writes a checkpoint and the run continues", n, problems)


def _ppid(pid):
    try:
        with open("/proc/%d/stat" % pid) as f:
            return int(f.read().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return -1


def main():
    ap = _cli.arguments(__doc__)
    ap.add_argument("--examples", required=True)
    a = ap.parse_args()
    R = Runner(a)
    tmp = tempfile.mkdtemp(prefix="granmpm-faults-")
    prep = os.path.join(tmp, "prep")
    subprocess.run([a.granmpm, "-max_steps", "3", "-checkpoint_interval", "3", "-output_dir", prep, "-quiet"], check=True, capture_output=True)
    checkpoint = os.path.join(prep, "checkpoint.h5")
    for n in (1, 2):
        empty_swarm(R, n, tmp, os.path.join(a.examples, "silo.opts"))
        corrupt_mass(R, n, tmp)
        overwrite(R, n, tmp)
        other_dir(R, n, tmp)
        physics(R, n, tmp, checkpoint)
        instability(R, n, tmp)
        past_end(R, n, tmp, checkpoint)
        write_faults(R, n, tmp)
        sigusr1(R, n, tmp)
        bodies_rows(R, n, tmp, a.examples)
        disk_full(R, n, tmp)
    if not R.failures:
        shutil.rmtree(tmp, ignore_errors=True)
    print("%d failure(s)" % R.failures)
    return 1 if R.failures else 0


if __name__ == "__main__":
    sys.exit(main())
