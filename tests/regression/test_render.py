#!/usr/bin/env python3
"""tools/render.py (VTK, off-screen) draws pictures worth looking at, and fails cleanly.

Runs softbody (2 ranks) on the project's own scenes, nothing from ../shared:
1. scenes/beam-scene.txt with gravity -y and a ground at y = -2 (40 steps: the beam is
   struck, falls and lands). Renders 3 frames through the command line
   (-frames 3 -size 320x240 -render_dir DIR -ground -2 -background 1,1,1 -gif -mp4) and
   checks: exit 0, the PNGs listed and of the requested size, not blank; the coloured
   body (saturated pixels left of the colour bar) covers a good part of the image
   (> 5 % of it, bounding box > 40 % of the width or height: the follow camera frames
   the body, not a speck); the first and last frames differ; animation.gif (GIF
   header) and animation.mp4 (only when ffmpeg is on PATH) written and not empty;
   the ground plane is drawn (the picture with -ground differs from the one without).
2. A free unit cube (8 vertices, 6 Kuhn tets) with 0.5 m/s on vertex 0 beside a fixed
   copy: the free body is found free and the fixed one fixed (render.Result.fixed),
   /mesh/body_fixed takes precedence over that inference; render.render_frame() (the
   function other scripts use) writes a PNG of the requested size with color="speed";
   the --name-with-dashes aliases work (--out, --size, --frames, --camera fixed).
3. render.deformation() is zero for a rigid motion (rotation + translation of the
   rest shape) and not for a stretch.
4. The Xvfb a render starts (no $DISPLAY) takes a display number outside :0..:9, the
   ones hwloc's GL plugin opens in every mpiexec and MPI rank (a render ending while a
   simulation started once ended the simulation with "X connection to :0 broken"), and
   the next free one when its first choice is taken; it keeps its state when its last
   client leaves (-noreset: a render reusing a parent's display aborted about one time in
   ten on a loaded machine when it connected during the server's reset).
5. Bad input gives one line on stderr and a non-zero exit, no traceback: a missing
   file, an unknown option, a bad -color, a frame index out of range.
Skips (77) when python3-vtk9 is missing, or when there is no X display and no Xvfb.
"""
import os
import shutil
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TOOLS = os.path.join(ROOT, "tools")
RENDER = os.path.join(TOOLS, "render.py")
SIZE = (320, 240)
BAR_ROOM = 0.16  # right part of the image holding the colour bar (render.BAR_ROOM)


def write_cube_mesh(path):
    """Unit cube, 8 vertices, 6 positively oriented Kuhn tets around the 0-6 diagonal."""
    import numpy as np
    verts = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]  # index x + 2y + 4z
    tets = [(0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 4, 6, 7)]
    oriented = []
    for t in tets:
        a, b, c, d = (np.array(verts[i], float) for i in t)
        det = np.linalg.det(np.array([b - a, c - a, d - a]))
        oriented.append(t if det > 0 else (t[0], t[2], t[1], t[3]))
    with open(path, "w") as f:
        f.write("MeshVersionFormatted 2\nDimension 3\nVertices\n8\n")
        for v in verts:
            f.write("%d %d %d 0\n" % v)
        f.write("Tetrahedra\n6\n")
        for t in oriented:
            f.write(" ".join(str(i + 1) for i in t) + " 0\n")
        f.write("End\n")


def read_png(path):
    """RGB image [rows][columns][3] in 0..1, top row first (read with VTK)."""
    from vtkmodules.vtkIOImage import vtkPNGReader
    from vtkmodules.util.numpy_support import vtk_to_numpy
    reader = vtkPNGReader()
    reader.SetFileName(path)
    reader.Update()
    image = reader.GetOutput()
    width, height, _ = image.GetDimensions()
    pixels = vtk_to_numpy(image.GetPointData().GetScalars()).reshape(height, width, -1)
    return pixels[::-1, :, :3] / 255.0


def distinct_colours(image):
    import numpy as np
    pixels = np.round(np.asarray(image) * 255).astype(np.int64).reshape(-1, 3)
    return len(np.unique(pixels[:, 0] * 65536 + pixels[:, 1] * 256 + pixels[:, 2]))


def body_pixels(image):
    """Mask of the coloured (saturated) pixels left of the colour bar: the free bodies
    (the background, ground, fixed bodies and text are grey or nearly so)."""
    import numpy as np
    left = image[:, : int(image.shape[1] * (1 - BAR_ROOM)), :]
    return (left.max(axis=-1) - left.min(axis=-1)) > 0.15


def run_render(arguments, timeout=300):
    return subprocess.run([sys.executable, RENDER] + [str(a) for a in arguments],
                          capture_output=True, text=True, timeout=timeout)


def check_one_line_failure(checks, what, run, needle=None):
    lines = [line for line in run.stderr.strip().splitlines() if line.strip()]
    ok = (run.returncode != 0 and len(lines) == 1 and "Traceback" not in run.stderr
          and (needle is None or needle in run.stderr))
    checks.check(ok, f"{what} fails with one line (exit {run.returncode}: {run.stderr.strip()[:300]})")


def check_falling_beam(args, checks, work):
    import h5py
    import numpy as np
    result = os.path.join(work, "beam.h5")
    if os.path.exists(result):
        os.remove(result)
    harness.run(args, 2, ["-scene", os.path.join(ROOT, "scenes", "beam-scene.txt"), "-steps", 40,
                          "-gravity", "0,-9.81,0", "-ground", -2, "-output", result])
    out = os.path.join(work, "beam_frames")
    shutil.rmtree(out, ignore_errors=True)
    run = run_render([result, "-frames", 3, "-size", "%dx%d" % SIZE, "-render_dir", out,
                      "-ground", -2, "-background", "1,1,1", "-title", "test_render", "-gif", "-mp4"])
    checks.check(run.returncode == 0, f"render.py exits 0 (got {run.returncode})"
                 + ("" if run.returncode == 0 else ": " + run.stderr.strip()[-2000:]))
    print(run.stdout.strip())
    images = []
    for k in (0, 20, 40):
        path = os.path.join(out, f"frame_{k:05d}.png")
        name = os.path.basename(path)
        if not checks.check(os.path.isfile(path), f"{name} written"):
            images.append(None)
            continue
        checks.check(path in run.stdout, f"{name} listed in the output")
        size = harness.png_size(path)
        checks.check(size == SIZE, f"{name} is a PNG of {SIZE[0]}x{SIZE[1]} pixels (header says {size})")
        image = read_png(path)
        colours = distinct_colours(image)
        checks.check(colours > 50, f"{name} is not blank ({colours} distinct colours)")
        body = body_pixels(image)
        fraction = float(body.mean())
        checks.check(fraction > 0.05, f"{name}: the body covers {100 * fraction:.1f}% of the image "
                     "left of the colour bar (> 5%)")
        if body.any():
            rows, cols = np.nonzero(body)
            width = (cols.max() - cols.min() + 1) / body.shape[1]
            height = (rows.max() - rows.min() + 1) / body.shape[0]
            checks.check(max(width, height) > 0.4, f"{name}: the body spans {100 * width:.0f}% of the "
                         f"width and {100 * height:.0f}% of the height (one of them > 40%)")
        images.append(image)
    if images[0] is not None and images[-1] is not None:
        changed = float(np.mean(np.any(np.abs(images[0] - images[-1]) > 1e-3, axis=-1)))
        checks.check(changed > 0.01, f"frames 0 and 40 differ ({100 * changed:.1f}% of the pixels)")
    gif = os.path.join(out, "animation.gif")
    with open(gif, "rb") if os.path.isfile(gif) else open(os.devnull, "rb") as f:
        head = f.read(6)
    checks.check(head in (b"GIF89a", b"GIF87a"), f"animation.gif written (header {head!r})")
    mp4 = os.path.join(out, "animation.mp4")
    if shutil.which("ffmpeg"):
        checks.check(os.path.isfile(mp4) and os.path.getsize(mp4) > 1000,
                     "animation.mp4 written (ffmpeg is on PATH)")
    else:
        print("note: ffmpeg is not on PATH, the MP4 is not checked")

    # The ground plane: the file records it (root attribute ground_y), so a render
    # without -ground draws it as -ground -2 does, and -ground none leaves it out.
    with h5py.File(result, "r") as f:
        recorded = (float(f.attrs.get("ground_y", np.nan)), list(f.attrs.get("gravity", [])))
    checks.check(recorded == (-2.0, [0.0, -9.81, 0.0]),
                 f"the result file records ground_y -2 and gravity (0, -9.81, 0) (got {recorded})")
    renders = {}
    for name, extra in (("given", ["-ground", -2]), ("recorded", []), ("none", ["-ground", "none"])):
        folder = os.path.join(work, "beam_ground_" + name)
        shutil.rmtree(folder, ignore_errors=True)
        run = run_render([result, "-frames", "40,", "-up", "y", "-size", "%dx%d" % SIZE, "-render_dir",
                          folder, "-background", "1,1,1", "-title", "test_render"] + extra)
        path = os.path.join(folder, "frame_00040.png")
        if checks.check(run.returncode == 0 and os.path.isfile(path),
                        f"render.py with the ground {name} exits 0 (exit {run.returncode}, "
                        f"{(run.stdout + run.stderr).strip()[-300:]})"):
            renders[name] = read_png(path)
    if len(renders) == 3:
        same = float(np.mean(np.any(np.abs(renders["given"] - renders["recorded"]) > 0.05, axis=-1)))
        checks.check(same < 0.01, f"the recorded ground is drawn as -ground -2 ({100 * same:.1f}% differ)")
        changed = float(np.mean(np.any(np.abs(renders["recorded"] - renders["none"]) > 0.05, axis=-1)))
        checks.check(changed > 0.05, f"-ground none leaves the ground out ({100 * changed:.1f}% of the "
                     "pixels change)")


def check_cube_and_api(args, checks, work):
    import numpy as np
    import h5py
    import render
    write_cube_mesh(os.path.join(work, "cube.mesh"))
    scene = os.path.join(work, "scene.txt")
    with open(scene, "w") as f:
        f.write("2\n"
                "cube.mesh 1000 1e5 0.3 0 0 0 0 1 0 0 0\n"
                "cube.mesh 1000 1e5 0.3 1 2 0 0 1 0 0 0\n"
                "1\n"
                "0 0 0.5 0 0\n")
    result = os.path.join(work, "r.h5")
    if os.path.exists(result):
        os.remove(result)
    harness.run(args, 2, ["-scene", scene, "-steps", 10, "-output", result])

    fixed = render.Result(result).fixed
    checks.check(list(fixed) == [False, True], f"free body found free, fixed body fixed ({list(fixed)})")
    flagged = os.path.join(work, "flagged.h5")
    shutil.copyfile(result, flagged)
    with h5py.File(flagged, "a") as f:
        if "mesh/body_fixed" in f:
            del f["mesh/body_fixed"]
        f["mesh/body_fixed"] = np.array([1, 0], dtype=np.int32)
    fixed = render.Result(flagged).fixed
    checks.check(list(fixed) == [True, False], f"/mesh/body_fixed takes precedence ({list(fixed)})")

    single = os.path.join(work, "single.png")
    if os.path.exists(single):
        os.remove(single)
    render.render_frame(result, 7, single, color="speed", size=(200, 150))
    size = harness.png_size(single) if os.path.isfile(single) else None
    checks.check(size == (200, 150), f"render_frame(..., color='speed') wrote a 200x150 PNG (got {size})")
    if size:
        colours = distinct_colours(read_png(single))
        checks.check(colours > 3, f"render_frame's PNG is not blank ({colours} distinct colours)")

    out = os.path.join(work, "cube_frames")
    shutil.rmtree(out, ignore_errors=True)
    run = run_render([result, "--out", out, "--size", "160x120", "--frames", "0,10",
                      "--camera", "fixed", "--color", "displacement"])
    written = [os.path.join(out, f"frame_{k:05d}.png") for k in (0, 10)]
    checks.check(run.returncode == 0 and all(harness.png_size(p) == (160, 120) for p in written if os.path.isfile(p))
                 and all(os.path.isfile(p) for p in written),
                 f"--name-with-dashes aliases work (exit {run.returncode} {run.stderr.strip()[-300:]})")
    return result


def check_deformation(checks):
    import numpy as np
    import render
    rng = np.random.default_rng(1)
    rest = rng.normal(size=(40, 3))
    body = np.repeat([0, 1], 20)
    masses = rng.uniform(0.5, 2.0, size=40)
    angle = 0.7
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    moved = rest @ rotation.T + np.array([3.0, -1.0, 2.0])
    rigid = render.deformation(moved, rest, masses, body, 2)
    checks.check(float(rigid.max()) < 1e-9, f"deformation of a rigid motion is 0 (max {rigid.max():.2e})")
    stretched = moved.copy()
    stretched[:20, 0] *= 1.2
    values = render.deformation(stretched, rest, masses, body, 2)
    checks.check(float(values[:20].max()) > 0.05 and float(values[20:].max()) < 1e-9,
                 f"deformation sees a stretch of body 0 only (max {values[:20].max():.3f} and "
                 f"{values[20:].max():.1e})")


def display_of_own_xvfb():
    """The $DISPLAY render.py's own Xvfb gets (in a child process with $DISPLAY unset)."""
    code = ("import os, sys; sys.path.insert(0, %r); import render; "
            "os.environ.pop('DISPLAY', None); render._DISPLAY.ensure(); print(os.environ['DISPLAY'])"
            % TOOLS)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    return run.stdout.strip() if run.returncode == 0 else "failed: " + run.stderr.strip()[-200:]


# In a child with $DISPLAY unset: render.py's own Xvfb, one client interns an atom and
# disconnects (the server then has no client, the moment a resetting X server resets),
# and a client connecting half a second later looks the atom up. Prints 1 when the atom
# survived (no reset), 0 when it was lost.
KEEPS_STATE = """
import ctypes, ctypes.util, os, sys, time
sys.path.insert(0, %r)
import render
os.environ.pop("DISPLAY", None)
render._DISPLAY.ensure()
xlib = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so.6")
xlib.XOpenDisplay.restype = ctypes.c_void_p
xlib.XOpenDisplay.argtypes = [ctypes.c_char_p]
xlib.XInternAtom.restype = ctypes.c_ulong
xlib.XInternAtom.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int]
xlib.XCloseDisplay.argtypes = [ctypes.c_void_p]
name = b"SOFTBODY_RESET_PROBE"
first = xlib.XOpenDisplay(None)
xlib.XInternAtom(first, name, 0)
xlib.XCloseDisplay(first)
time.sleep(0.5)
second = None
for _ in range(50):
    second = xlib.XOpenDisplay(None)
    if second:
        break
    time.sleep(0.1)
print(1 if xlib.XInternAtom(second, name, 1) else 0)
xlib.XCloseDisplay(second)
"""


def check_virtual_display(checks):
    import render
    run = subprocess.run([sys.executable, "-c", KEEPS_STATE % TOOLS], capture_output=True, text=True, timeout=60)
    checks.check(run.stdout.strip() == "1",
                 "render.py's own Xvfb does not reset when its last client leaves (a render connecting "
                 f"during a reset aborts in GLX) (got {run.stdout.strip() or run.stderr.strip()[-200:]})")
    first = display_of_own_xvfb()
    checks.check(first.startswith(":") and int(first[1:]) >= 10,
                 f"render.py's own Xvfb uses a display outside hwloc's :0..:9 (got {first})")
    taken = render.VirtualDisplay.FIRST_DISPLAY
    squatter = None
    if not os.path.exists("/tmp/.X%d-lock" % taken):
        squatter = subprocess.Popen([shutil.which("Xvfb"), ":%d" % taken, "-nolisten", "tcp"],
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(100):
            if os.path.exists("/tmp/.X11-unix/X%d" % taken):
                break
            time.sleep(0.05)
    try:
        second = display_of_own_xvfb()
        checks.check(second.startswith(":") and int(second[1:]) > taken,
                     f"with :{taken} taken, the next free display is used (got {second})")
    finally:
        if squatter is not None:
            squatter.terminate()
            squatter.wait(timeout=10)


def check_bad_input(checks, work, result):
    check_one_line_failure(checks, "a missing file", run_render([os.path.join(work, "missing.h5")]),
                           "no such file")
    check_one_line_failure(checks, "an unknown option", run_render([result, "-no_such_option", 1]))
    check_one_line_failure(checks, "-color purple", run_render([result, "-color", "purple"]))
    check_one_line_failure(checks, "-frames 0,99", run_render([result, "-frames", "0,99", "-render_dir",
                                                               os.path.join(work, "bad")]),
                           "out of range")


def main():
    args = harness.arguments()
    checks = harness.Checks()
    try:
        import numpy  # noqa: F401
        import h5py  # noqa: F401
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401
    except ImportError as error:
        print(f"SKIP: {error}: tools/render.py needs Debian's python3-vtk9 (./run installs it)")
        sys.exit(harness.SKIP)
    if not os.environ.get("DISPLAY") and shutil.which("Xvfb") is None:
        print("SKIP: no X display and no Xvfb: tools/render.py needs the xvfb package to render off-screen")
        sys.exit(harness.SKIP)
    sys.path.insert(0, TOOLS)
    work = os.path.abspath(args.work)
    has_display = bool(os.environ.get("DISPLAY"))  # before render.py sets it for its own Xvfb
    check_falling_beam(args, checks, work)
    result = check_cube_and_api(args, checks, work)
    check_deformation(checks)
    if not has_display:
        check_virtual_display(checks)
    check_bad_input(checks, work, result)
    checks.exit()


if __name__ == "__main__":
    main()
