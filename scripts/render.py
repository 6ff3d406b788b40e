#!/usr/bin/env python3
"""A first look at a GranMPM run without opening the ParaView GUI.

usage: scripts/render.py RUN_DIR [-o picture.png] [--field NAME[:COMPONENT]] [--time T]
                         [--animate FRAMES_DIR] [--size WxH] [--range LO,HI]

Renders the particles of RUN_DIR/particles.xmf (as discs of their own size) coloured by a
field, the rigid bodies of bodies.xmf (black outlines), the domain's outline and the time
stamp, with ParaView's pvbatch (with a private Xvfb when there is no display). The picture is
of the last snapshot, or of the one nearest to --time.

  --field velocity            colour by |velocity| (the default); velocity:X, velocity:Y, ...
  --field pressure            any particle array: pressure, tau, density, stress_xy, gdot,
                              fluidity, id, ... (stress:4, F:1 pick tensor components)
  --animate DIR               also writes DIR/frame_0000.png ... (one per snapshot, same
                              colour range) and, where ffmpeg is installed, DIR/movie.mp4

Runs as a plain script: it starts pvbatch itself. Needs paraview (and xvfb without a
display): apt-get install paraview python3-paraview xvfb.
"""
import argparse
import glob
import math
import os
import shutil
import subprocess
import sys

MARK = "GRANMPM_RENDER_IN_PVBATCH"


def parse():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir")
    ap.add_argument("-o", "--output", help="picture (default RUN_DIR/particles.png)")
    ap.add_argument("--field", default="velocity", help="NAME or NAME:COMPONENT (X, Y, Z, Magnitude or 0-8)")
    ap.add_argument("--time", type=float, help="snapshot nearest to this time (default: the last)")
    ap.add_argument("--animate", metavar="DIR", help="write one PNG per snapshot (and movie.mp4 with ffmpeg)")
    ap.add_argument("--size", default="1600x900", help="picture size in pixels, WxH (H is fitted to the domain in 2D)")
    ap.add_argument("--range", help="colour range LO,HI (default: the data's, over all frames when animating)")
    ap.add_argument("--title", help="text at the top left (default: the run directory's name)")
    return ap.parse_args()


def start_xvfb():
    """A private Xvfb; returns (process, display). -displayfd makes the server pick a free
    display and report it once it accepts connections (xvfb-run -a raced with other
    renders). -noreset: pvbatch connects twice (a capability probe, then the window); without
    it the server resets when the probe disconnects, and a second connection that arrives
    during the reset is dropped ("bad X server connection"). On a loaded machine with other
    renders running that happened to 2 of 3 renders; with -noreset to none of 36.
    """
    xvfb = shutil.which("Xvfb")
    if not xvfb:
        sys.exit("render.py: no X display and no Xvfb: install xvfb (apt-get install xvfb)")
    r, w = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(w), "-screen", "0", "1920x1080x24", "-nolisten", "tcp", "-noreset"], pass_fds=(w,),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(w)
    num = b""
    while not num.endswith(b"\n"):
        chunk = os.read(r, 16)
        if not chunk:
            sys.exit("render.py: Xvfb did not start")
        num += chunk
    os.close(r)
    return proc, ":" + num.decode().strip()


def relaunch():
    """Run this script again inside pvbatch, with a private Xvfb if there is no X display."""
    pvbatch = shutil.which("pvbatch")
    if not pvbatch:
        sys.exit("render.py: pvbatch not found: install ParaView (apt-get install paraview python3-paraview xvfb)")
    cmd = [pvbatch, "--no-mpi", "--disable-registry", os.path.abspath(__file__)] + sys.argv[1:]
    env = dict(os.environ, **{MARK: "1"})
    own = not os.environ.get("DISPLAY")
    # A dropped connection was the server resetting between pvbatch's two connections (fixed
    # by -noreset in start_xvfb); should the X server still refuse pvbatch, a new server is
    # tried, 3 times at most, and each retry is reported.
    for attempt in range(3 if own else 1):
        server = None
        if own:
            server, env["DISPLAY"] = start_xvfb()
        try:
            p = subprocess.run(cmd, env=env, stderr=subprocess.PIPE, text=True)
        finally:
            if server:
                server.terminate()
                server.wait()
        if p.returncode == 0 or "bad X server connection" not in p.stderr:
            break
        print(f"render.py: the X server dropped pvbatch's connection, trying again ({attempt + 1} of 3)", file=sys.stderr)
    sys.stderr.write(p.stderr)
    sys.exit(p.returncode)


def domain(run_dir):
    """(dim, lo, hi) from the newest snapshot's attributes, or None."""
    try:
        import h5py

        snaps = sorted(glob.glob(os.path.join(run_dir, "snap_*.h5")))
        with h5py.File(snaps[-1], "r") as f:
            return int(f.attrs["dim"][0]), list(f.attrs["domain_lo"]), list(f.attrs["domain_hi"])
    except Exception:
        return None


def open_particles(pv, pxmf, field):
    """The particle reader, its times, and the field: (reader, times, name, comp, ci, ncomp)."""
    name, _, comp = field.partition(":")
    parts = pv.Xdmf3ReaderS(FileName=[pxmf])
    parts.UpdatePipelineInformation()
    tv = parts.TimestepValues
    times = [float(t) for t in (tv if hasattr(tv, "__len__") else [tv])] or [0.0]
    parts.UpdatePipeline(times[-1])
    arrays = parts.PointData.keys()
    if name not in arrays:
        sys.exit(f"render.py: no particle field '{name}' in {pxmf}; there are: {', '.join(sorted(arrays))}")
    ncomp = parts.PointData[name].GetNumberOfComponents()
    if not comp:
        comp = "Magnitude" if ncomp > 1 else ""
    ci = LABELS.get(comp, int(comp) if comp.isdigit() else None) if comp else 0
    if ci is None or ci >= ncomp:
        sys.exit(f"render.py: component '{comp}' of {name} ({ncomp} components): use X, Y, Z, Magnitude or 0..{ncomp - 1}")
    return parts, times, name, comp, ci, ncomp


LABELS = {"X": 0, "Y": 1, "Z": 2, "Magnitude": -1}


def show_particles(pv, view, parts, dim, name, comp, ci, ncomp, rng):
    """Particles as discs of the particle spacing (volume^(1/dim); 2D volumes are areas),
    coloured by the field over rng = (lo, hi), with a horizontal colour bar."""
    d = pv.Show(parts, view)
    d.SetRepresentationType("Point Gaussian")
    d.ShaderPreset = "Plain circle"
    vmin = parts.PointData["volume"].GetRange()[0] if "volume" in parts.PointData.keys() else 0
    d.GaussianRadius = 0.5 * vmin ** (1.0 / dim) if vmin > 0 else 0.005
    pv.ColorBy(d, ("POINTS", name, comp if comp in LABELS else str(ci)) if ncomp > 1 else ("POINTS", name))
    lut = pv.GetColorTransferFunction(name)
    lut.ApplyPreset("Viridis (matplotlib)", True)
    if ncomp > 1:
        lut.VectorMode = "Magnitude" if ci < 0 else "Component"
        lut.VectorComponent = max(ci, 0)
    lut.RescaleTransferFunction(*rng)
    bar = pv.GetScalarBar(lut, view)
    bar.Title = name
    bar.ComponentTitle = comp if ncomp > 1 else ""
    bar.TitleColor = bar.LabelColor = [0, 0, 0]
    bar.Orientation = "Horizontal"
    bar.WindowLocation = "Any Location"
    bar.Position = [0.3, 0.02]
    bar.ScalarBarLength = 0.4
    d.SetScalarBarVisibility(view, True)


def show_context(pv, view, run_dir, dim, dom):
    """Rigid bodies (black outlines) and the domain's outline (grey)."""
    bxmf = os.path.join(run_dir, "bodies.xmf")
    if os.path.exists(bxmf):
        bd = pv.Show(pv.Xdmf3ReaderS(FileName=[bxmf]), view)
        bd.ColorArrayName = ["POINTS", ""]
        bd.SetRepresentationType("Wireframe")
        bd.AmbientColor = bd.DiffuseColor = [0, 0, 0]
        bd.LineWidth = 3
    if dom:
        lo, hi = dom[1], dom[2]
        if dim == 2:
            box = pv.PolyLineSource(Points=[lo[0], lo[1], 0, hi[0], lo[1], 0, hi[0], hi[1], 0, lo[0], hi[1], 0], Closed=1)
        else:
            box = pv.Box(Center=[(l + u) / 2 for l, u in zip(lo, hi)], XLength=hi[0] - lo[0], YLength=hi[1] - lo[1], ZLength=hi[2] - lo[2])
        od = pv.Show(box, view)
        od.ColorArrayName = ["POINTS", ""]
        od.SetRepresentationType("Outline" if dim == 3 else "Wireframe")
        od.AmbientColor = od.DiffuseColor = [0.5, 0.5, 0.5]
        od.LineWidth = 1.5


def place_camera(view, dim, dom, w, h):
    """2D: looking down -z, fitted to the domain (not to the particles, which may have left
    it) with room for the colour bar; 3D: from the front-right, above."""
    view.ResetCamera()
    if dim == 2:
        view.InteractionMode = "2D"
        c = [(l + u) / 2 for l, u in zip(dom[1], dom[2])] if dom else view.CameraFocalPoint
        view.CameraFocalPoint = [c[0], c[1], 0]
        view.CameraPosition = [c[0], c[1], 10]
        view.CameraViewUp = [0, 1, 0]
        view.ResetCamera(False)
        if dom:
            half_w = (dom[2][0] - dom[1][0]) / 2 * 1.05
            half_h = (dom[2][1] - dom[1][1]) / 2 * 1.05
            view.CameraParallelScale = max(half_h, half_w * (h - 160) / w) * h / (h - 160)
    elif dom:
        c = [(l + u) / 2 for l, u in zip(dom[1], dom[2])]
        size = math.dist(dom[1], dom[2])
        view.CameraFocalPoint = c
        view.CameraPosition = [c[0] + 0.55 * size, c[1] + 0.45 * size, c[2] + 1.0 * size]
        view.CameraViewUp = [0, 1, 0]
        view.ResetCamera(False)


def render(a):
    from paraview import simple as pv

    run_dir = os.path.abspath(a.run_dir)
    pxmf = os.path.join(run_dir, "particles.xmf")
    if not os.path.exists(pxmf):
        sys.exit(f"render.py: {pxmf} not found (is {a.run_dir} a granmpm -output_dir?)")
    parts, times, name, comp, ci, ncomp = open_particles(pv, pxmf, a.field)
    dom = domain(run_dir)
    bounds = parts.GetDataInformation().GetBounds()
    dim = dom[0] if dom else (3 if bounds[5] > bounds[4] else 2)
    w, h = (int(x) for x in a.size.split("x"))
    if dim == 2 and dom:  # the picture's height follows the domain's aspect
        aspect = (dom[2][1] - dom[1][1]) / max(dom[2][0] - dom[1][0], 1e-300)
        h = int(min(max(w * aspect * 1.15 + 160, 360), 1.5 * w))
    if a.range:
        lo, hi = (float(x) for x in a.range.split(","))
    else:  # this frame's range, or all frames' when animating (one colour scale)
        rs = []
        for t in times if a.animate else [pick(times, a.time)]:
            parts.UpdatePipeline(t)
            rs.append(parts.PointData[name].GetRange(ci))
        lo, hi = min(r[0] for r in rs), max(r[1] for r in rs)
        if hi <= lo:
            hi = lo + (abs(lo) * 1e-6 or 1.0)
    view = pv.CreateView("RenderView")
    view.ViewSize = [w, h]
    view.OrientationAxesVisibility = 0
    view.UseColorPaletteForBackground = 0
    view.Background = [1, 1, 1]
    show_particles(pv, view, parts, dim, name, comp, ci, ncomp, (lo, hi))
    show_context(pv, view, run_dir, dim, dom)
    stamp = pv.Text()
    sd = pv.Show(stamp, view)
    sd.WindowLocation = "Upper Left Corner"
    sd.FontSize = 22
    sd.Color = [0, 0, 0]
    title = a.title if a.title is not None else os.path.basename(run_dir.rstrip("/"))
    view.ViewTime = times[-1]
    place_camera(view, dim, dom, w, h)

    def shot(t, path):
        stamp.Text = f"{title}    t = {t:.4g} s"
        view.ViewTime = t
        parts.UpdatePipeline(t)
        pv.SaveScreenshot(path, view, ImageResolution=[w, h], TransparentBackground=0)

    out = a.output or os.path.join(run_dir, "particles.png")
    t = pick(times, a.time)
    shot(t, out)
    print(f"render.py: {out} ({name}{':' + comp if comp else ''} at t = {t:.4g} s, colour range {lo:.4g} .. {hi:.4g})")
    if a.animate:
        animate(a.animate, times, shot)


def animate(frames_dir, times, shot):
    """One PNG per snapshot, and movie.mp4 from them where ffmpeg is installed."""
    os.makedirs(frames_dir, exist_ok=True)
    for k, t in enumerate(times):
        shot(t, os.path.join(frames_dir, f"frame_{k:04d}.png"))
    print(f"render.py: {len(times)} frames in {frames_dir}/frame_NNNN.png")
    ffmpeg = shutil.which("ffmpeg")
    if ffmpeg:
        movie = os.path.join(frames_dir, "movie.mp4")
        subprocess.run([ffmpeg, "-y", "-loglevel", "error", "-framerate", "10", "-i", os.path.join(frames_dir, "frame_%04d.png"),
                        "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p", movie], check=True)
        print(f"render.py: {movie}")
    else:
        print("render.py: no ffmpeg, so no movie (apt-get install ffmpeg; or open the frames as a sequence)")


def pick(times, t):
    return times[-1] if t is None else min(times, key=lambda x: abs(x - t))


if __name__ == "__main__":
    args = parse()
    if os.environ.get(MARK) != "1":
        relaunch()
    render(args)
