"""Shared helpers for the GranMPM benchmark scripts (bench/*.py).

Only the standard library is required; matplotlib is needed for the PNG figures
(without it the scripts still write CSV and markdown and print a warning).

Environment:
  GRANMPM   path of the granmpm binary (default: <repo>/build/granmpm)
  MPIEXEC   MPI launcher command (default: "mpiexec --oversubscribe", plus
            --allow-run-as-root when run as root)
"""

import csv
import io
import os
import re
import resource
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

BENCH_DIR = os.path.dirname(os.path.abspath(__file__))
REPO_ROOT = os.path.dirname(BENCH_DIR)
RESULTS_DIR = os.path.join(BENCH_DIR, "results")
FIGURES_DIR = os.path.join(REPO_ROOT, "docs", "figures")
DOCS_DIR = os.path.join(REPO_ROOT, "docs")


def granmpm_binary():
    path = os.environ.get("GRANMPM", os.path.join(REPO_ROOT, "build", "granmpm"))
    path = os.path.abspath(path)
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        sys.exit(f"bench: granmpm binary not found at {path}; build it (make build) or set GRANMPM=/path/to/granmpm")
    return path


def mpiexec_prefix(np_):
    cmd = os.environ.get("MPIEXEC")
    if cmd:
        base = shlex.split(cmd)
    else:
        base = ["mpiexec", "--oversubscribe"]
        if hasattr(os, "geteuid") and os.geteuid() == 0:
            base.append("--allow-run-as-root")
    return base + ["-n", str(np_)]


def binary_provenance(binary):
    """A short description of the binary: the git commit of the source tree it was built from, if known."""
    d = os.path.dirname(binary)
    for cand in (d, os.path.dirname(d)):
        try:
            out = subprocess.run(["git", "-C", cand, "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10)
            if out.returncode == 0 and out.stdout.strip():
                dirty = subprocess.run(["git", "-C", cand, "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True, timeout=10)
                flag = "" if dirty.returncode == 0 and not dirty.stdout.strip() else " (+ uncommitted changes)"
                return f"commit {out.stdout.strip()}{flag}"
        except (OSError, subprocess.SubprocessError):
            pass
    return "commit unknown"


def write_meta(csv_path, binary, **extra):
    """Record where a result came from next to its CSV (<name>.meta.json); returns the dict."""
    import json

    meta = {"binary": binary_provenance(binary), "host": host_description(), "date": time.strftime("%Y-%m-%d %H:%M %Z")}
    meta.update(extra)
    with open(os.path.splitext(csv_path)[0] + ".meta.json", "w") as f:
        json.dump(meta, f, indent=1)
        f.write("\n")
    return meta


def read_meta(csv_path):
    import json

    try:
        with open(os.path.splitext(csv_path)[0] + ".meta.json") as f:
            return json.load(f)
    except (OSError, ValueError):
        return {"binary": "commit unknown", "host": "unknown host", "date": "unknown date"}


def host_description():
    cpu = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical cores"


def loadavg():
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


# --------------------------------------------------------------------------------------
# Running granmpm and parsing its summary lines

_FLOAT = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
RE_DONE = re.compile(rf"GranMPM: done, (\d+) steps to t = ({_FLOAT}) s in ({_FLOAT}) s wall \(({_FLOAT}) particle-steps/s\)")
RE_MEM = re.compile(rf"GranMPM: peak memory ({_FLOAT}) MiB over (\d+) rank")
RE_SIZES = re.compile(r"GranMPM: (\d+) particles, grid (\d+) x (\d+)(?: x (\d+))? nodes on (\d+) rank")
RE_CFL = re.compile(rf"wave speed ({_FLOAT}) m/s, CFL limit ({_FLOAT}) s")
RE_CHUTE = re.compile(rf"chute: .*L2 error absolute ({_FLOAT}) m/s, relative ({_FLOAT})")
RE_BAR = re.compile(rf"bar: rms velocity error / amplitude: max ({_FLOAT}), at end ({_FLOAT}); centre-of-mass velocity error ({_FLOAT}); energy drift ({_FLOAT})")
RE_STAGE = re.compile(rf"^\s*\d+:\s+(\S[^:]*):\s+({_FLOAT})\s+({_FLOAT})%")


def parse_output(text):
    r = {}
    m = RE_SIZES.search(text)
    if m:
        r["particles"] = int(m.group(1))
        nodes = [int(g) for g in m.group(2, 3, 4) if g]
        r["grid_nodes"] = 1
        for n in nodes:
            r["grid_nodes"] *= n
        r["ranks"] = int(m.group(5))
    m = RE_CFL.search(text)
    if m:
        r["wave_speed"] = float(m.group(1))
        r["cfl_limit"] = float(m.group(2))
    m = RE_DONE.search(text)
    if m:
        r["steps"] = int(m.group(1))
        r["t_final"] = float(m.group(2))
        r["wall_s"] = float(m.group(3))
        r["rate"] = float(m.group(4))
    m = RE_MEM.search(text)
    if m:
        r["mem_mib"] = float(m.group(1))
    m = RE_CHUTE.search(text)
    if m:
        r["abs_err"] = float(m.group(1))
        r["rel_err"] = float(m.group(2))
    m = RE_BAR.search(text)
    if m:
        r["v_err_max"], r["v_err_end"], r["vcm_err"], r["energy_drift"] = (float(g) for g in m.groups())
    stages = parse_log_view_stages(text)
    if stages:
        r["stages"] = stages
    return r


def parse_log_view_stages(text):
    """Stage name -> max-over-ranks-average time [s] from the 'Summary of Stages' block of -log_view."""
    i = text.find("Summary of Stages:")
    if i < 0:
        return {}
    stages = {}
    for line in text[i:].splitlines()[2:]:
        m = RE_STAGE.match(line)
        if not m:
            break
        stages[m.group(1).strip()] = float(m.group(2))
    return stages


def error_line(text):
    for line in text.splitlines():
        if "error" in line.lower() and "L2 error" not in line and "velocity error" not in line:
            return line.strip()
    lines = [l for l in text.splitlines() if l.strip()]
    return lines[-1].strip() if lines else ""


def run_granmpm(args, np_=1, timeout=None, keep_dir=False, label=None):
    """Run granmpm with `args` (list of str) on np_ ranks in a fresh output directory.

    Returns the parsed summary (dict) plus 'rc', 'ok', 'output' (stdout+stderr), 'elapsed' (s, as seen from
    outside, including start-up), 'cpu_s' (user + system CPU time of all the processes of the run, including
    start-up and MPI busy-waiting), 'cmd' (the command line, output dir shown as D) and 'loadavg' (1-min load
    average before the run). The output directory is deleted unless keep_dir.
    """
    binary = granmpm_binary()
    out_dir = tempfile.mkdtemp(prefix="granmpm-bench-")
    full = [binary] + list(args) + ["-output_dir", out_dir]
    if np_ > 1:
        full = mpiexec_prefix(np_) + full
    la = loadavg()
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    try:
        p = subprocess.run(full, capture_output=True, text=True, timeout=timeout)
        rc, text = p.returncode, p.stdout + p.stderr
    except subprocess.TimeoutExpired as e:
        rc = "timeout"
        text = (e.stdout or b"").decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
    elapsed = time.monotonic() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    r = parse_output(text)
    r.update(rc=rc, output=text, elapsed=elapsed, cpu_s=cpu, loadavg=la)
    r["ok"] = rc == 0 and "steps" in r
    r["cmd"] = shown_cmd(args, np_)
    if keep_dir:
        r["dir"] = out_dir
    else:
        shutil.rmtree(out_dir, ignore_errors=True)
    if label:
        status = "ok" if r["ok"] else f"FAILED (rc {rc}): {error_line(text)}"
        print(f"# {label}: {status}, {elapsed:.1f} s", file=sys.stderr, flush=True)
    return r


def median(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else float("nan")


# --------------------------------------------------------------------------------------
# Output: CSV, figures, markdown


def output_paths(name, quick):
    """CSV and PNG paths for benchmark `name`; quick runs go to bench/results/quick/ (git-ignored)."""
    if quick:
        d = os.path.join(RESULTS_DIR, "quick")
        return os.path.join(d, name + ".csv"), os.path.join(d, name + ".png")
    return os.path.join(RESULTS_DIR, name + ".csv"), os.path.join(FIGURES_DIR, name + ".png")


def fmt(v):
    if isinstance(v, float):
        if v != v:
            return ""
        return f"{v:.6g}"
    return "" if v is None else str(v)


def write_rows(name, head, rows, **meta):
    """Write list rows with a header to bench/results/<name>.csv and its meta file (the binary
    from granmpm_binary() plus meta); returns the path."""
    os.makedirs(RESULTS_DIR, exist_ok=True)
    path = os.path.join(RESULTS_DIR, name + ".csv")
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(head)
        w.writerows(rows)
    write_meta(path, granmpm_binary(), **meta)
    return path


def write_csv(path, columns, rows):
    """Write rows (list of dict) to `path` and print the same CSV to stdout."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for row in rows:
        w.writerow([fmt(row.get(c)) for c in columns])
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(buf.getvalue())
    sys.stdout.write(buf.getvalue())
    sys.stdout.flush()
    print(f"# wrote {os.path.relpath(path, REPO_ROOT)}", file=sys.stderr)


def _convert(v):
    if v == "":
        return None
    for t in (int, float):
        try:
            return t(v)
        except ValueError:
            pass
    return {"True": True, "False": False}.get(v, v)


def read_csv(path, strings=()):
    """Rows of a CSV written by write_csv, with numbers converted back (empty -> None) except in `strings` columns."""
    with open(path) as f:
        return [{k: (v if k in strings else _convert(v)) for k, v in row.items()} for row in csv.DictReader(f)]


def shown_cmd(args, np_=1):
    shown = ([] if np_ == 1 else ["mpiexec", "-n", str(np_)]) + ["granmpm"] + list(args) + ["-output_dir", "D"]
    return " ".join(shlex.quote(a) for a in shown).replace(REPO_ROOT + os.sep, "")


def pyplot():
    """matplotlib.pyplot with the Agg backend, or None (with a warning) if matplotlib is missing."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        return plt
    except ImportError:
        print("# matplotlib not available: no figure written (use /usr/bin/python3 or install matplotlib)", file=sys.stderr)
        return None


def save_figure(fig, path):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=90)
    print(f"# wrote {os.path.relpath(path, REPO_ROOT)}", file=sys.stderr)


def md_table(header, rows, align=None):
    align = align or ["r"] * len(header)
    sep = ["---:" if a == "r" else ":---" for a in align]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(sep) + " |"]
    for r in rows:
        lines.append("| " + " | ".join(str(c) for c in r) + " |")
    return "\n".join(lines)


def sci(v, digits=3):
    if v is None or (isinstance(v, float) and v != v):
        return "-"
    return f"{v:.{digits}e}"


def replace_doc_section(doc_name, key, title, body, doc_title):
    """Insert or replace the section delimited by <!-- bench:key begin/end --> in docs/<doc_name>.

    Everything outside the markers is left as it is; a missing file is created with `doc_title`.
    """
    path = os.path.join(DOCS_DIR, doc_name)
    begin, end = f"<!-- bench:{key} begin -->", f"<!-- bench:{key} end -->"
    block = f"{begin}\n## {title}\n\n{body.rstrip()}\n{end}\n"
    text = open(path).read() if os.path.exists(path) else f"# {doc_title}\n\n"
    if begin in text and end in text:
        a = text.index(begin)
        b = text.index(end) + len(end)
        if b < len(text) and text[b] == "\n":
            b += 1
        text = text[:a] + block + text[b:]
    else:
        if not text.endswith("\n\n"):
            text = text.rstrip("\n") + "\n\n"
        text += block
    os.makedirs(DOCS_DIR, exist_ok=True)
    with open(path, "w") as f:
        f.write(text)
    print(f"# updated section '{title}' of {os.path.relpath(path, REPO_ROOT)}", file=sys.stderr)


def ab_argparser(doc):
    """Arguments of a script that compares two binaries: NEW [OLD] (default the old main's build) and --ranks."""
    import argparse

    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("new", help="granmpm binary under test")
    ap.add_argument("old", nargs="?", default="/work/base/build/granmpm", help="reference granmpm binary")
    ap.add_argument("--ranks", default="1,2", help="comma-separated MPI rank counts")
    return ap


def common_argparser(description):
    import argparse

    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--quick", action="store_true", help="smaller sweep; results go to bench/results/quick/ and docs are not touched")
    ap.add_argument("--no-docs", action="store_true", help="do not update docs/*.md")
    ap.add_argument("--replot", action="store_true", help="run nothing: redraw the figure and the docs section from the existing CSV")
    return ap
